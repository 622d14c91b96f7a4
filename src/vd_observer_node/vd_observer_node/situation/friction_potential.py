"""Online road-friction potential: maximum available mu per axle from (slip, mu) pairs.

Model (the similarity method, Pacejka, *Tire and Vehicle Dynamics*, 3rd ed., sec. 4.3.2): on
another road the tyre's mu-slip curve is the dry curve scaled by the road's friction scale
``r`` in both axes, ``mu(s; r) = r * mu1(s / r)``: the peak scales with ``r`` while the slope
at zero slip (the carcass stiffness) does not. ``mu1`` is the vehicle's own Magic Formula at
the sample's load (the vehicle file the simulator uses; ``vd_common.vehicle.tire``). The
one unknown ``r`` is found on a fixed grid of road scales by exponentially forgotten least
squares per axle; ``mu_max = r * peak1(load)`` and ``slip_peak = r * slip1(load)``.

Why one parameter and not a free curve: with only (slip, mu) samples from the linear part of
the curve, every peak fits, and the first design here (a bank of Burckhardt curves with a free
scale) then drifted to whatever the noise favoured -- 3 on the dry paper cruise, 0.3 with a
96-count encoder. With the stiffness fixed by the tyre, linear-region samples fit all scales
alike and say nothing, as they should; samples past the linear part pin ``r`` quickly.

Errors in variables: the slip is noisy (speed and encoder noise divided by the slip's
denominator ``max(|omega R|, |v|)``). Each residual is weighted by the variance it would have
if the curve were right, ``mu_noise_std^2 + (d mu/d s)^2 sigma_s^2`` with
``sigma_s = slip_velocity_noise / denominator`` (the effective-variance method): a steep
(dry) curve is not blamed for a slip error, a flat (icy) one is. Samples whose slip is within
``min_slip_sigmas`` of zero, or whose denominator is below ``min_slip_speed``, are not used.

Confidence (profile likelihood): the least extra weighted cost of any road scale whose peak
is more than ``confidence_margin`` from the estimate, per sample times ``evidence_samples``
(correlated samples are not independent evidence), mapped linearly from ``evidence_low``
(0) to ``evidence_high`` (1). Below ``class_min_confidence`` the reported values are shrunk
towards the prior road; the road class (dry / wet / snow / ice) is UNKNOWN there.

Pure step functions (`fit_step`, `fit_solution`, `fit_confidence`, `classify_road`) and a
stateful wrapper (`FrictionPotentialEstimator`) the node calls per estimate. Axles: 0 front
(FL, FR), 1 rear (RL, RR). Time in seconds.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field, fields, replace
from typing import Any, Final

import numpy as np
from numpy.typing import ArrayLike, NDArray
from vd_common.vehicle.friction import (
    ROAD_CLASS_BOUNDS,
    ROAD_DRY,
    ROAD_ICE,
    ROAD_SNOW,
    ROAD_UNKNOWN,
    ROAD_WET,
    FrictionTable,
    friction_table,
    unit_peak,
)
from vd_common.vehicle.params import TireParams
from vd_common.vehicle.tire import magic_formula_fx

from vd_observer_node.errors import InputShapeError, ObserverError

__all__ = [
    'AXLE_OF_WHEEL',
    'ROAD_CLASS_NAMES',
    'ROAD_DRY',
    'ROAD_ICE',
    'ROAD_SNOW',
    'ROAD_UNKNOWN',
    'ROAD_WET',
    'FitState',
    'FrictionConfigError',
    'FrictionPotential',
    'FrictionPotentialConfig',
    'FrictionPotentialEstimator',
    'TyreCurves',
    'classify_road',
    'fit_confidence',
    'fit_solution',
    'fit_step',
    'initial_fit_state',
    'unfloored_slip',
]

FloatArray = NDArray[np.float64]

#: Axle index of each wheel FL, FR, RL, RR (0 front, 1 rear).
AXLE_OF_WHEEL: Final = (0, 0, 1, 1)
#: Name of each road class code.
ROAD_CLASS_NAMES: Final = ('unknown', 'ice', 'snow', 'wet', 'dry')
_AXLES: Final = np.asarray(AXLE_OF_WHEEL)
#: [-] slip step of the numerical slope d mu / d s.
_SLOPE_STEP: Final = 1e-4


class FrictionConfigError(ObserverError):
    """A friction-potential setting is invalid (names the setting and the rule)."""


def _default_scales() -> tuple[float, ...]:
    return tuple(float(x) for x in np.geomspace(0.05, 1.6, 80))


@dataclass(frozen=True)
class FrictionPotentialConfig:
    """Settings of the friction-potential estimator.

    Attributes:
        road_scales: candidate road friction scales r [-] (increasing, > 0); 0.05..1.6
            covers ice to a grippy dry road (the dry tyre's own road is 1).
        forgetting_time: time constant [s] of the exponential forgetting of the fit data; the
            data are forgotten only while new usable samples arrive, so an estimate is kept
            while the tyre is not excited.
        load_time: time constant [s] of the axle load and force direction the reported peak
            is evaluated at.
        prior_road_scale: road scale r [-] assumed without evidence (1: the dry road).
        shrink_to_prior: below class_min_confidence report w * fit + (1 - w) * prior,
            w = confidence / class_min_confidence, instead of the bare fit.
        min_slip: |slip| below this [-] is ignored.
        max_slip: |slip| is clipped to this [-].
        min_slip_speed: [m/s] samples whose slip denominator max(|omega R|, |v|) is below
            this are ignored (at walking pace the slip is mostly noise).
        slip_velocity_noise: [m/s] noise bound of the slip velocity omega R - v (about 3
            standard deviations: 0.07 m/s measured with a 96-count encoder and 0.05 m/s speed
            noise); sigma_s = this / denominator.
        min_slip_sigmas: samples with |slip| < this * sigma_s are ignored (their sign and
            size are noise).
        mu_noise_std: [-] noise of the mu estimates.
        confidence_margin: [-] the confidence says how firmly the data exclude peaks further
            than this from the estimate (the accuracy goal, 0.1).
        evidence_samples: the forgotten data count as this many independent samples: the
            evidence is the mean weighted cost advantage per sample times this. Consecutive
            samples are correlated (one observer filters them) and a small systematic model
            error summed over a thousand samples a second would otherwise become certainty.
        evidence_hold_time: [s] the confidence decays as exp(-age / this), age = time since
            the axle's last usable sample: a friction potential measured a kilometre back
            says little about the road here, and a wrong estimate must not outlive its
            evidence for minutes of cruising. 0 keeps the confidence forever.
        evidence_low: evidence at and below which the confidence is 0.
        evidence_high: evidence at and above which the confidence is 1.
        class_bounds: mu_max boundaries ice|snow, snow|wet, wet|dry [-], increasing.
        class_margin: hysteresis margin [-] on the class boundaries.
        class_min_confidence: below this confidence the class is UNKNOWN [-].
    """

    road_scales: tuple[float, ...] = field(default_factory=_default_scales)
    forgetting_time: float = 0.25
    load_time: float = 0.05
    prior_road_scale: float = 1.0
    shrink_to_prior: bool = True
    min_slip: float = 0.002
    max_slip: float = 1.0
    min_slip_speed: float = 2.0
    slip_velocity_noise: float = 0.2
    min_slip_sigmas: float = 2.0
    mu_noise_std: float = 0.05
    confidence_margin: float = 0.1
    evidence_samples: float = 100.0
    evidence_hold_time: float = 5.0
    evidence_low: float = 10.0
    evidence_high: float = 100.0
    class_bounds: tuple[float, float, float] = ROAD_CLASS_BOUNDS
    class_margin: float = 0.03
    class_min_confidence: float = 0.5

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, float) and not (math.isfinite(value) and value >= 0.0):
                raise FrictionConfigError(f'{f.name} must be finite and >= 0, got {value}')
        for name in (
            'forgetting_time',
            'load_time',
            'prior_road_scale',
            'max_slip',
            'min_slip_speed',
            'mu_noise_std',
            'confidence_margin',
            'evidence_samples',
        ):
            if getattr(self, name) <= 0.0:
                raise FrictionConfigError(f'{name} must be > 0, got {getattr(self, name)}')
        scales = np.asarray(self.road_scales, dtype=float)
        if (
            scales.size < 2
            or not np.all(np.isfinite(scales))
            or np.any(scales <= 0.0)
            or np.any(np.diff(scales) <= 0.0)
        ):
            raise FrictionConfigError(
                f'road_scales must be >= 2 finite, positive, increasing values: {scales}'
            )
        if not self.evidence_low < self.evidence_high:
            raise FrictionConfigError(
                f'evidence_low must be < evidence_high, got {self.evidence_low}, '
                f'{self.evidence_high}'
            )
        b = self.class_bounds
        if len(b) != 3 or not 0.0 < b[0] < b[1] < b[2]:
            raise FrictionConfigError(f'class_bounds must be 3 increasing positives, got {b}')
        if self.class_margin >= (b[1] - b[0]) / 2 or self.class_margin >= (b[2] - b[1]) / 2:
            raise FrictionConfigError(
                f'class_margin {self.class_margin} must be below half the class widths'
            )
        if self.class_min_confidence > 1.0:
            raise FrictionConfigError(
                f'class_min_confidence must be in [0, 1], got {self.class_min_confidence}'
            )

    @classmethod
    def from_mapping(cls, data: dict[str, Any]) -> FrictionPotentialConfig:
        """Build from a flat mapping (e.g. ROS parameters; lists become tuples).

        Raises:
            FrictionConfigError: unknown key or invalid value.
        """
        known = {f.name for f in fields(cls)}
        unknown = set(data) - known
        if unknown:
            raise FrictionConfigError(f'unknown friction settings: {sorted(unknown)}')
        clean: dict[str, Any] = {
            k: tuple(v) if isinstance(v, list) else v for k, v in data.items()
        }
        return cls(**clean)


def unfloored_slip(slip_velocity: ArrayLike, speed: float) -> tuple[FloatArray, FloatArray]:
    """Slip ratio without the floor of `vd_common.vehicle.tire.slip_ratio`, and its denominator.

    The fit gates samples on the denominator itself (``min_slip_speed``) and weights them by
    the slip noise it implies, so it needs the true denominator, not a floored one.

    Args:
        slip_velocity: shape (4,), [m/s] omega R - v.
        speed: body speed v [m/s].

    Returns:
        (slip, denominator): shape (4,) each; slip [-] = (omega R - v) / max(|omega R|, |v|),
        positive driving, nan where the denominator is 0; denominator [m/s].
    """
    sv = np.asarray(slip_velocity, dtype=float)
    den: FloatArray = np.maximum(np.abs(sv + speed), abs(speed))
    slip: FloatArray = np.full(sv.shape, math.nan)
    np.divide(sv, den, out=slip, where=den > 0.0)
    return slip, den


@dataclass(frozen=True)
class TyreCurves:
    """The tyre's mu-slip curves for the similarity model.

    Attributes:
        tire: Magic Formula coefficients (vehicle file ``tire``).
        table: its peak mu and slip at road scale 1 against the load.
    """

    tire: TireParams
    table: FrictionTable

    @classmethod
    def from_tire(cls, tire: TireParams) -> TyreCurves:
        """Curves of the vehicle file's tyre."""
        return cls(tire, friction_table(tire))

    def mu(self, slip: FloatArray, load: FloatArray, scales: FloatArray) -> FloatArray:
        """mu(s; r) = Fx(s, Fz, r) / Fz for every sample and road scale.

        Args:
            slip: shape (n,), [-] signed.
            load: shape (n,), [N] (> 0).
            scales: shape (M,), [-] road scales.

        Returns:
            shape (n, M), [-].
        """
        z = load[:, None]
        out: FloatArray = magic_formula_fx(slip[:, None], z, scales[None, :], self.tire) / z
        return out

    def slope(self, slip: FloatArray, load: FloatArray, scales: FloatArray) -> FloatArray:
        """d mu / d s at every sample and road scale, shape (n, M) (central difference)."""
        return self.mu_and_slope(slip, load, scales)[1]

    def mu_and_slope(
        self, slip: FloatArray, load: FloatArray, scales: FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        """`mu` and `slope` from one Magic Formula call (three slips stacked: a third of the
        per-call overhead, which dominates for the few samples of one stamp)."""
        h = _SLOPE_STEP
        n = slip.shape[0]
        stacked = self.mu(
            np.concatenate([slip, slip + h, slip - h]), np.concatenate([load, load, load]), scales
        )
        mu: FloatArray = stacked[:n]
        slope: FloatArray = (stacked[n : 2 * n] - stacked[2 * n :]) / (2.0 * h)
        return mu, slope

    def peak(self, load: FloatArray, driving: NDArray[np.bool_]) -> tuple[FloatArray, FloatArray]:
        """Peak mu and its slip at road scale 1 (`vd_common.vehicle.friction.unit_peak`).

        Args:
            load: [N], any shape.
            driving: same shape; True for the driving side (slip > 0).

        Returns:
            (peak mu [-], slip at the peak [-]), same shape.
        """
        return unit_peak(self.table, load, driving)


@dataclass(frozen=True)
class FitState:
    """Forgotten statistics per axle (A = 2 axles, M road scales).

    Attributes:
        cost: shape (A, M), forgotten sum of weighted squared residuals per road scale.
        count: shape (A,), forgotten number of used samples.
        load: shape (A,), [N] smoothed wheel load of the used samples.
        direction: shape (A,), smoothed sign of their force (> 0 driving, < 0 braking).
        t: stamp of the last step [s] (nan before the first).
        last_sample: shape (A,), [s] stamp of the axle's last usable sample (nan if none).
    """

    cost: FloatArray
    count: FloatArray
    load: FloatArray
    direction: FloatArray
    t: float
    last_sample: FloatArray


def initial_fit_state(config: FrictionPotentialConfig, static_load: ArrayLike) -> FitState:
    """Empty statistics.

    Args:
        config: settings (the number of road scales).
        static_load: shape (2,), [N] wheel load per axle before any sample.
    """
    load = np.asarray(static_load, dtype=float)
    if load.shape != (2,):
        raise InputShapeError(f'static_load must have shape (2,), got {load.shape}')
    return FitState(
        cost=np.zeros((2, len(config.road_scales))),
        count=np.zeros(2),
        load=load.copy(),
        direction=np.ones(2),
        t=math.nan,
        last_sample=np.full(2, math.nan),
    )


@dataclass(frozen=True)
class FrictionPotential:
    """Friction potential for one stamp (per-axle arrays shape (2,), 0 front, 1 rear).

    Attributes:
        t: stamp [s].
        mu_max: [-] maximum available friction coefficient.
        slip_peak: [-] slip magnitude at which mu_max is reached.
        confidence: [0..1] how firmly the data exclude peaks further than
            ``confidence_margin`` from the fit (0 without informative data).
        road_class: ROAD_* code per axle (UNKNOWN while the confidence is too low).
        road_scale: [-] fitted road friction scale r (before shrinking to the prior).
    """

    t: float
    mu_max: FloatArray
    slip_peak: FloatArray
    confidence: FloatArray
    road_class: NDArray[np.int64]
    road_scale: FloatArray

    def wheel_mu_max(self) -> FloatArray:
        """mu_max of each wheel's axle, shape (4,), order FL, FR, RL, RR."""
        out: FloatArray = self.mu_max[_AXLES]
        return out

    def wheel_slip_peak(self) -> FloatArray:
        """slip_peak of each wheel's axle, shape (4,), order FL, FR, RL, RR."""
        out: FloatArray = self.slip_peak[_AXLES]
        return out

    def vehicle_road_class(self) -> int:
        """Class of the most confident axle with a known class (UNKNOWN if none)."""
        known = self.road_class != ROAD_UNKNOWN
        if not np.any(known):
            return ROAD_UNKNOWN
        conf = np.where(known, self.confidence, -1.0)
        return int(self.road_class[int(np.argmax(conf))])


def _wheels(name: str, value: ArrayLike, dtype: type = float) -> NDArray[Any]:
    array: NDArray[Any] = np.asarray(value, dtype=dtype)
    if array.shape != (4,):
        raise InputShapeError(f'{name} must have shape (4,), got {array.shape}')
    return array


def fit_step(
    state: FitState,
    t: float,
    slip_velocity: ArrayLike,
    speed: float,
    mu: ArrayLike,
    mu_valid: ArrayLike,
    load: ArrayLike,
    curves: TyreCurves,
    config: FrictionPotentialConfig,
) -> FitState:
    """Add one stamp's wheel samples to the statistics (pure).

    Args:
        state: statistics before the stamp.
        t: stamp [s]; a non-finite or non-increasing stamp returns ``state`` unchanged.
        slip_velocity: shape (4,), [m/s] omega R - v, order FL, FR, RL, RR.
        speed: [m/s] body speed v.
        mu: shape (4,), [-] utilised friction Fx/Fz.
        mu_valid: shape (4,), bool.
        load: shape (4,), [N] estimated wheel loads Fz.
        curves: the tyre's curves.
        config: settings.

    Returns:
        The updated statistics. Ignored samples: invalid or non-finite values, a load <= 0,
        a slip denominator below ``min_slip_speed``, |slip| below ``min_slip`` or
        ``min_slip_sigmas`` slip noise, and a mu of the opposite sign of the slip (a tyre
        force has the sign of its slip; the opposite is an estimation transient).

    Raises:
        InputShapeError: an input is not shape (4,).
    """
    sv = _wheels('slip_velocity', slip_velocity)
    m = _wheels('mu', mu)
    ok = _wheels('mu_valid', mu_valid, bool)
    fz = _wheels('load', load)
    if not math.isfinite(t) or (math.isfinite(state.t) and t <= state.t):
        return state
    if not math.isfinite(speed):
        return replace(state, t=t)
    slip, den = unfloored_slip(sv, speed)
    with np.errstate(invalid='ignore', divide='ignore'):
        sigma_s = config.slip_velocity_noise / den
        use = ok & np.isfinite(slip) & np.isfinite(m) & np.isfinite(fz) & (fz > 0.0)
        use &= den >= config.min_slip_speed
        use &= np.abs(slip) >= np.maximum(config.min_slip, config.min_slip_sigmas * sigma_s)
        use &= np.sign(slip) == np.sign(m)
    if not use.any():
        return replace(state, t=t)
    dt = 0.0 if not math.isfinite(state.t) else t - state.t
    s = np.clip(slip[use], -config.max_slip, config.max_slip)
    z = fz[use]
    scales = np.asarray(config.road_scales, dtype=float)
    predicted, slope = curves.mu_and_slope(s, z, scales)
    variance = config.mu_noise_std**2 + (slope * sigma_s[use][:, None]) ** 2
    weighted = (m[use][:, None] - predicted) ** 2 / variance
    axle_of = _AXLES[use]
    cost, count = state.cost.copy(), state.count.copy()
    axle_load, direction = state.load.copy(), state.direction.copy()
    last_sample = state.last_sample.copy()
    lam = math.exp(-dt / config.forgetting_time)
    blend = 1.0 - math.exp(-dt / config.load_time) if dt > 0.0 else 1.0
    for axle in (0, 1):
        rows = axle_of == axle
        if not rows.any():
            continue
        cost[axle] = lam * cost[axle] + weighted[rows].sum(axis=0)
        count[axle] = lam * count[axle] + float(np.count_nonzero(rows))
        axle_load[axle] += blend * (float(np.mean(z[rows])) - axle_load[axle])
        direction[axle] += blend * (float(np.mean(np.sign(s[rows]))) - direction[axle])
        last_sample[axle] = t
    return FitState(cost, count, axle_load, direction, t, last_sample)


def _fitted(
    state: FitState, curves: TyreCurves
) -> tuple[NDArray[np.int64], FloatArray, FloatArray]:
    """Best scale index, unit peak mu and unit peak slip per axle."""
    best = np.argmin(state.cost, axis=1).astype(np.int64)
    unit_mu, unit_slip = curves.peak(state.load, state.direction >= 0.0)
    return best, unit_mu, unit_slip


def fit_confidence(
    state: FitState, curves: TyreCurves, config: FrictionPotentialConfig
) -> FloatArray:
    """Confidence per axle that the fitted peak is within ``confidence_margin`` (pure).

    The least extra weighted cost of a road scale whose peak lies further than the margin
    from the best one's, per sample times ``evidence_samples``, mapped linearly from
    ``evidence_low`` (0) to ``evidence_high`` (1), decayed with the time since the axle's last
    usable sample (``evidence_hold_time``).

    Returns:
        shape (2,), [0..1]; 0 for an axle without samples.
    """
    best, unit_mu, _ = _fitted(state, curves)
    return _confidence(state, config, best, unit_mu)


def _confidence(
    state: FitState,
    config: FrictionPotentialConfig,
    best: NDArray[np.int64],
    unit_mu: FloatArray,
) -> FloatArray:
    """`fit_confidence` for the winners `_fitted` already found."""
    scales = np.asarray(config.road_scales, dtype=float)
    peaks = scales[None, :] * unit_mu[:, None]
    rows = np.arange(2)
    far = np.abs(peaks - peaks[rows, best][:, None]) > config.confidence_margin
    rival = np.where(far, state.cost, np.inf).min(axis=1)
    informed = (state.count > 0.0) & np.isfinite(rival)
    advantage = np.where(informed, rival - state.cost[rows, best], 0.0)
    evidence = advantage / np.maximum(state.count, 1.0) * config.evidence_samples
    span = config.evidence_high - config.evidence_low
    out: FloatArray = np.clip((evidence - config.evidence_low) / span, 0.0, 1.0)
    if config.evidence_hold_time > 0.0:
        age = np.where(np.isfinite(state.last_sample), state.t - state.last_sample, 0.0)
        out *= np.exp(-np.maximum(age, 0.0) / config.evidence_hold_time)
    return out


def classify_road(
    mu_max: float, confidence: float, previous: int, config: FrictionPotentialConfig
) -> int:
    """Road class from mu_max with hysteresis (pure).

    Args:
        mu_max: [-] estimated friction potential.
        confidence: [0..1].
        previous: class of the previous stamp (ROAD_* code).
        config: class bounds, margin and minimum confidence.

    Returns:
        ROAD_UNKNOWN if confidence < class_min_confidence; otherwise the class whose band
        holds mu_max, keeping ``previous`` while mu_max is within class_margin outside its band.
    """
    if not math.isfinite(mu_max) or confidence < config.class_min_confidence:
        return ROAD_UNKNOWN
    b = config.class_bounds
    raw = ROAD_ICE + bisect.bisect_right(b, mu_max)
    if previous in (ROAD_ICE, ROAD_SNOW, ROAD_WET, ROAD_DRY) and raw != previous:
        lo = -math.inf if previous == ROAD_ICE else b[previous - ROAD_ICE - 1]
        hi = math.inf if previous == ROAD_DRY else b[previous - ROAD_ICE]
        if lo - config.class_margin <= mu_max < hi + config.class_margin:
            return previous
    return raw


def fit_solution(
    state: FitState,
    curves: TyreCurves,
    config: FrictionPotentialConfig,
    previous_class: ArrayLike = (ROAD_UNKNOWN, ROAD_UNKNOWN),
) -> FrictionPotential:
    """Friction potential from the statistics (pure).

    Args:
        state: statistics.
        curves: the tyre's curves.
        config: settings.
        previous_class: shape (2,), road class per axle at the previous stamp (hysteresis).

    Returns:
        The estimate for ``state.t``.
    """
    best, unit_mu, unit_slip = _fitted(state, curves)
    scales = np.asarray(config.road_scales, dtype=float)
    fitted = np.where(state.count > 0.0, scales[best], config.prior_road_scale)
    confidence = _confidence(state, config, best, unit_mu)
    # Unexcited, every scale fits the linear part of the curve: report the prior road there.
    weight = np.clip(confidence / max(config.class_min_confidence, 1e-9), 0.0, 1.0)
    scale = (
        weight * fitted + (1.0 - weight) * config.prior_road_scale
        if config.shrink_to_prior
        else fitted
    )
    mu_max: FloatArray = scale * unit_mu
    prev = np.asarray(previous_class, dtype=np.int64)
    road = np.array(
        [
            classify_road(float(mu_max[a]), float(confidence[a]), int(prev[a]), config)
            for a in (0, 1)
        ],
        dtype=np.int64,
    )
    return FrictionPotential(
        t=state.t,
        mu_max=mu_max,
        slip_peak=scale * unit_slip,
        confidence=confidence,
        road_class=road,
        road_scale=fitted,
    )


class FrictionPotentialEstimator:
    """Stateful wrapper: the node calls `update` once per estimate."""

    def __init__(
        self,
        curves: TyreCurves,
        static_load: ArrayLike,
        config: FrictionPotentialConfig | None = None,
    ) -> None:
        """Create the estimator.

        Args:
            curves: the tyre's curves (`TyreCurves.from_tire(vehicle.tire)`).
            static_load: shape (2,), [N] static wheel load per axle (front, rear).
            config: settings; defaults if None.
        """
        self.curves = curves
        self.config = config or FrictionPotentialConfig()
        self.static_load = np.asarray(static_load, dtype=float)
        self.reset()

    def reset(self) -> None:
        """Forget all data (prior road, confidence 0)."""
        self.state = initial_fit_state(self.config, self.static_load)
        self._classes = np.full(2, ROAD_UNKNOWN, dtype=np.int64)
        self.last = fit_solution(self.state, self.curves, self.config, self._classes)

    def update(
        self,
        t: float,
        slip_velocity: ArrayLike,
        speed: float,
        mu: ArrayLike,
        mu_valid: ArrayLike,
        load: ArrayLike,
    ) -> FrictionPotential:
        """Add one stamp's samples and return the current potential.

        Args:
            t: stamp [s] (non-finite or non-increasing: previous result returned).
            slip_velocity: shape (4,), [m/s] omega R - v, order FL, FR, RL, RR.
            speed: [m/s] body speed.
            mu: shape (4,), [-] utilised friction.
            mu_valid: shape (4,), bool.
            load: shape (4,), [N] wheel loads.

        Raises:
            InputShapeError: an input is not shape (4,).
        """
        before = self.state
        self.state = fit_step(
            self.state, t, slip_velocity, speed, mu, mu_valid, load, self.curves, self.config
        )
        if self.state is before:
            return self.last
        result = fit_solution(self.state, self.curves, self.config, self._classes)
        self._classes = result.road_class.copy()
        self.last = result
        return result
