"""Online road-friction potential: maximum available mu per axle from (slip, mu) pairs.

Model: a bank of Burckhardt-shaped curves (Burckhardt 1993; Kiencke & Nielsen, *Automotive
Control Systems*, 2005)::

    mu(s) = a * shape(|s|),     shape(x) = 1 - exp(-c2 x) - kappa x

one member per (c2, kappa) pair of a fixed grid, each with a single free scale ``a`` fitted by
exponentially forgotten, regularised least squares on the axle's valid samples
(``y = mu * sign(s)``, ``x = |s|``). The regulariser pulls ``a`` towards the scale that gives
the prior slip stiffness ``a * (c2 - kappa) = slip_stiffness`` (the tyre's initial slope barely
changes with the road, its peak does), so a member is chosen by how well it explains the data
AND the tyre's known stiffness. The member of least cost wins; its curve peak is ``mu_max`` and
the slip there ``slip_peak``. Without informative data every member's cost is its small
tie-break term and the prior road (``prior_mu_max``) is reported with confidence 0.

Confidence: the forgotten maximum utilisation ``|mu| / mu_max`` seen on the axle (the peak is
only observable once the tyre has been pushed towards it), mapped linearly from
``confidence_utilisation_low`` (0) to ``confidence_utilisation_high`` (1).

Road class from ``mu_max`` with a hysteresis margin; ``UNKNOWN`` while the confidence is below
``class_min_confidence``.

Pure step functions (`fit_step`, `fit_solution`, `classify_road`) and a stateful wrapper
(`FrictionPotentialEstimator`) that the node calls per estimate. Axles: 0 front (FL, FR),
1 rear (RL, RR).
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field, fields, replace
from typing import Any, Final

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vd_observer_node.errors import InputShapeError, ObserverError

__all__ = [
    'AXLE_OF_WHEEL',
    'ROAD_CLASS_NAMES',
    'ROAD_DRY',
    'ROAD_ICE',
    'ROAD_SNOW',
    'ROAD_UNKNOWN',
    'ROAD_WET',
    'CurveBank',
    'FitState',
    'FrictionConfigError',
    'FrictionPotential',
    'FrictionPotentialConfig',
    'FrictionPotentialEstimator',
    'burckhardt_shape',
    'classify_road',
    'fit_solution',
    'fit_step',
    'floored_slip',
    'initial_fit_state',
    'make_bank',
    'shape_peak',
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: Axle index of each wheel FL, FR, RL, RR (0 front, 1 rear).
AXLE_OF_WHEEL: Final = (0, 0, 1, 1)
ROAD_UNKNOWN: Final = 0
ROAD_ICE: Final = 1
ROAD_SNOW: Final = 2
ROAD_WET: Final = 3
ROAD_DRY: Final = 4
#: Name of each road class code.
ROAD_CLASS_NAMES: Final = ('unknown', 'ice', 'snow', 'wet', 'dry')


class FrictionConfigError(ObserverError):
    """A friction-potential setting is invalid (names the setting and the rule)."""


@dataclass(frozen=True)
class FrictionPotentialConfig:
    """Settings of the friction-potential estimator.

    Attributes:
        forgetting_time: time constant [s] of the exponential forgetting of the fit data; the
            data are forgotten only while new informative samples arrive, so an estimate is
            kept (with decaying confidence) while the tyre is not excited.
        confidence_time: time constant [s] of the forgotten maximum utilisation.
        sharpness: Burckhardt c2 values of the bank [-] (> 0, increasing); c2 ~ stiffness /
            mu_max, so 5..600 covers dry asphalt to ice.
        falloff: Burckhardt kappa values of the bank [-] (>= 0, < 1): the post-peak decline
            relative to the scale.
        slip_stiffness: the tyre's initial slope d mu / d s at zero slip [-] (MF
            pKx1 of the vehicle file, 18 for the Clio's tyre).
        stiffness_weight: weight of the stiffness prior, in equivalent samples of unit
            regressor (small: the data override it once they cover the linear region).
        prior_mu_max: road assumed without data [-] (tie-break among equally good members).
        prior_weight: weight of that tie-break on (mu_max - prior_mu_max)^2.
        shrink_to_prior: below class_min_confidence report w * fit + (1 - w) * prior_mu_max,
            w = confidence / class_min_confidence, instead of the bare fit (the utilisation
            behind the confidence uses the bare fit).
        min_slip: |slip| below this [-] carries no information on the peak (noise, sign
            errors) and is ignored.
        max_slip: the curve peak is searched on (0, max_slip] [-]; larger |slip| is clipped.
        slip_floor_speed: [m/s] denominator floor of the slip the fit uses
            (`FrictionPotentialEstimator.fit_slip`): at walking pace the textbook slip ratio of
            two small speeds is dominated by speed noise and is not what the tyre reacts to
            (the vehicle file's ``tire.low_speed_velocity``, 1 m/s).
        confidence_utilisation_low: utilisation [-] giving confidence 0.
        confidence_utilisation_high: utilisation [-] giving confidence 1.
        class_bounds: mu_max boundaries ice|snow, snow|wet, wet|dry [-], increasing.
        class_margin: hysteresis margin [-] on the class boundaries.
        class_min_confidence: below this confidence the class is UNKNOWN [-].
    """

    forgetting_time: float = 1.0
    confidence_time: float = 3.0
    sharpness: tuple[float, ...] = field(
        default_factory=lambda: tuple(float(x) for x in np.geomspace(5.0, 600.0, 28))
    )
    falloff: tuple[float, ...] = (0.0, 0.1, 0.2, 0.3, 0.4, 0.5)
    slip_stiffness: float = 18.0
    stiffness_weight: float = 5.0
    prior_mu_max: float = 1.0
    prior_weight: float = 1e-3
    shrink_to_prior: bool = True
    min_slip: float = 0.002
    max_slip: float = 1.0
    slip_floor_speed: float = 1.0
    confidence_utilisation_low: float = 0.25
    confidence_utilisation_high: float = 0.75
    class_bounds: tuple[float, float, float] = (0.2, 0.45, 0.75)
    class_margin: float = 0.03
    class_min_confidence: float = 0.5

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, float) and not (math.isfinite(value) and value >= 0.0):
                raise FrictionConfigError(f'{f.name} must be finite and >= 0, got {value}')
        for name in (
            'forgetting_time',
            'confidence_time',
            'slip_stiffness',
            'max_slip',
            'slip_floor_speed',
        ):
            if getattr(self, name) <= 0.0:
                raise FrictionConfigError(f'{name} must be > 0, got {getattr(self, name)}')
        sharp = np.asarray(self.sharpness, dtype=float)
        if sharp.size == 0 or not np.all(np.isfinite(sharp)) or np.any(sharp <= 0.0):
            raise FrictionConfigError(f'sharpness must be non-empty, finite, > 0: {sharp}')
        fall = np.asarray(self.falloff, dtype=float)
        if fall.size == 0 or not np.all(np.isfinite(fall)) or np.any((fall < 0) | (fall >= 1)):
            raise FrictionConfigError(f'falloff values must be in [0, 1): {fall}')
        if np.any(sharp[:, None] <= fall[None, :]):
            raise FrictionConfigError('every sharpness must exceed every falloff (positive slope)')
        if not self.confidence_utilisation_low < self.confidence_utilisation_high:
            raise FrictionConfigError(
                'confidence_utilisation_low must be < confidence_utilisation_high, got '
                f'{self.confidence_utilisation_low}, {self.confidence_utilisation_high}'
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


def floored_slip(slip_velocity: ArrayLike, speed: float, floor: float) -> FloatArray:
    """Slip ratio with a floored denominator, as the tyre model defines it.

    Args:
        slip_velocity: shape (4,), [m/s] omega R - v.
        speed: body speed v [m/s].
        floor: [m/s] denominator floor (> 0).

    Returns:
        shape (4,), [-] (omega R - v) / max(|omega R|, |v|, floor), positive driving.
    """
    sv = np.asarray(slip_velocity, dtype=float)
    den = np.maximum(np.maximum(np.abs(sv + speed), abs(speed)), floor)
    out: FloatArray = sv / den
    return out


def burckhardt_shape(slip: ArrayLike, sharpness: ArrayLike, falloff: ArrayLike) -> FloatArray:
    """Unit-scale Burckhardt curve 1 - exp(-c2 |s|) - kappa |s| (odd in s).

    Args:
        slip: [-], any shape broadcastable with the others.
        sharpness: c2 [-].
        falloff: kappa [-].

    Returns:
        shape(s) * sign(s), [-], broadcast shape.
    """
    s = np.asarray(slip, dtype=float)
    x = np.abs(s)
    c2 = np.asarray(sharpness, dtype=float)
    kappa = np.asarray(falloff, dtype=float)
    out: FloatArray = np.sign(s) * (-np.expm1(-c2 * x) - kappa * x)
    return out


def shape_peak(
    sharpness: ArrayLike, falloff: ArrayLike, max_slip: float
) -> tuple[FloatArray, FloatArray]:
    """Peak of the unit-scale curve on (0, max_slip].

    Args:
        sharpness: c2 [-], any shape.
        falloff: kappa [-], broadcastable.
        max_slip: upper end of the slip range [-].

    Returns:
        (peak value [-], slip at the peak [-]), broadcast shape. For kappa = 0 the curve rises
        monotonically and the peak is at max_slip.
    """
    c2 = np.asarray(sharpness, dtype=float)
    kappa = np.asarray(falloff, dtype=float)
    with np.errstate(divide='ignore'):
        stationary = np.where(kappa > 0.0, np.log(c2 / np.maximum(kappa, 1e-300)) / c2, np.inf)
    s_peak: FloatArray = np.minimum(stationary, max_slip)
    value: FloatArray = -np.expm1(-c2 * s_peak) - kappa * s_peak
    return value, s_peak


@dataclass(frozen=True)
class CurveBank:
    """The fixed member grid (B members).

    Attributes:
        sharpness: shape (B,), c2 [-].
        falloff: shape (B,), kappa [-].
        peak: shape (B,), unit-scale peak value [-].
        slip_peak: shape (B,), slip at the peak [-].
        stiffness_scale: shape (B,), the scale a giving the prior slip stiffness [-].
    """

    sharpness: FloatArray
    falloff: FloatArray
    peak: FloatArray
    slip_peak: FloatArray
    stiffness_scale: FloatArray


def make_bank(config: FrictionPotentialConfig) -> CurveBank:
    """All (sharpness, falloff) combinations of the config, with their peaks."""
    c2, kappa = np.meshgrid(
        np.asarray(config.sharpness, dtype=float),
        np.asarray(config.falloff, dtype=float),
        indexing='ij',
    )
    c2, kappa = c2.ravel(), kappa.ravel()
    peak, s_peak = shape_peak(c2, kappa, config.max_slip)
    return CurveBank(
        sharpness=c2,
        falloff=kappa,
        peak=peak,
        slip_peak=s_peak,
        stiffness_scale=config.slip_stiffness / (c2 - kappa),
    )


@dataclass(frozen=True)
class FitState:
    """Forgotten sufficient statistics per axle and member (A = 2 axles, B members).

    Attributes:
        s_pp: shape (A, B), sum of w * phi^2.
        s_py: shape (A, B), sum of w * phi * y.
        s_yy: shape (A,), sum of w * y^2.
        utilisation: shape (A,), forgotten maximum |mu| / mu_max [-].
        t: stamp of the last step [s] (nan before the first).
        member: shape (A,), least-cost member for these statistics.
        scale: shape (A,), its fitted scale a [-].
    """

    s_pp: FloatArray
    s_py: FloatArray
    s_yy: FloatArray
    utilisation: FloatArray
    t: float
    member: NDArray[np.int64]
    scale: FloatArray


def initial_fit_state(bank: CurveBank) -> FitState:
    """Empty statistics for the bank."""
    b = bank.sharpness.size
    empty = FitState(
        s_pp=np.zeros((2, b)),
        s_py=np.zeros((2, b)),
        s_yy=np.zeros(2),
        utilisation=np.zeros(2),
        t=math.nan,
        member=np.zeros(2, dtype=np.int64),
        scale=np.zeros(2),
    )
    return _with_best(empty, bank, FrictionPotentialConfig())


@dataclass(frozen=True)
class FrictionPotential:
    """Friction potential for one stamp (per axle arrays shape (2,), 0 front, 1 rear).

    Attributes:
        t: stamp [s].
        mu_max: [-] maximum available friction coefficient.
        slip_peak: [-] slip magnitude at which mu_max is reached.
        confidence: [0..1] how far the tyre has been pushed towards its peak.
        road_class: ROAD_* code per axle (UNKNOWN while confidence is too low).
        member: index of the winning bank member per axle.
    """

    t: float
    mu_max: FloatArray
    slip_peak: FloatArray
    confidence: FloatArray
    road_class: NDArray[np.int64]
    member: NDArray[np.int64]

    def wheel_mu_max(self) -> FloatArray:
        """mu_max of each wheel's axle, shape (4,), order FL, FR, RL, RR."""
        out: FloatArray = self.mu_max[list(AXLE_OF_WHEEL)]
        return out

    def vehicle_road_class(self) -> int:
        """Class of the most confident axle with a known class (UNKNOWN if none)."""
        known = self.road_class != ROAD_UNKNOWN
        if not np.any(known):
            return ROAD_UNKNOWN
        conf = np.where(known, self.confidence, -1.0)
        return int(self.road_class[int(np.argmax(conf))])


def _member_costs(
    state: FitState, bank: CurveBank, config: FrictionPotentialConfig
) -> tuple[FloatArray, FloatArray]:
    """Scale and cost per axle and member, shapes (A, B)."""
    a0 = bank.stiffness_scale[None, :]
    w = config.stiffness_weight
    scale = (state.s_py + w * a0) / (state.s_pp + w)
    sse = state.s_yy[:, None] - 2.0 * scale * state.s_py + scale * scale * state.s_pp
    mu_max = scale * bank.peak[None, :]
    cost = sse + w * (scale - a0) ** 2 + config.prior_weight * (mu_max - config.prior_mu_max) ** 2
    return scale, cost


def fit_step(
    state: FitState,
    t: float,
    slip: ArrayLike,
    mu: ArrayLike,
    mu_valid: ArrayLike,
    bank: CurveBank,
    config: FrictionPotentialConfig,
) -> FitState:
    """Add one stamp's wheel samples to the statistics (pure).

    Args:
        state: statistics before the stamp.
        t: stamp [s]; a non-finite or non-increasing stamp returns ``state`` unchanged.
        slip: shape (4,), [-], positive driving, order FL, FR, RL, RR.
        mu: shape (4,), [-] utilised friction Fx/Fz.
        mu_valid: shape (4,), bool; invalid or non-finite samples, |slip| < min_slip and
            samples whose mu has the opposite sign of the slip (a tyre force always has the
            sign of its slip: such a pair is an estimation transient) are ignored.
        bank: member grid from `make_bank(config)`.
        config: settings.

    Returns:
        The updated statistics.

    Raises:
        InputShapeError: an input is not shape (4,).
    """
    s = np.asarray(slip, dtype=float)
    m = np.asarray(mu, dtype=float)
    ok = np.asarray(mu_valid, dtype=bool)
    if s.shape != (4,) or m.shape != (4,) or ok.shape != (4,):
        raise InputShapeError(
            f'slip, mu, mu_valid must have shape (4,), got {s.shape}, {m.shape}, {ok.shape}'
        )
    if not math.isfinite(t) or (math.isfinite(state.t) and t <= state.t):
        return state
    dt = 0.0 if not math.isfinite(state.t) else t - state.t
    use = ok & np.isfinite(s) & np.isfinite(m) & (np.abs(s) >= config.min_slip)
    use &= np.sign(s) == np.sign(m)
    utilisation = state.utilisation * math.exp(-dt / config.confidence_time)
    if not use.any():
        return replace(state, utilisation=utilisation, t=t)
    x = np.minimum(np.abs(s[use]), config.max_slip)
    y = m[use] * np.sign(s[use])
    phi = -np.expm1(-np.outer(x, bank.sharpness)) - np.outer(x, bank.falloff)
    axle_of = np.asarray(AXLE_OF_WHEEL)[use]
    s_pp, s_py, s_yy = state.s_pp.copy(), state.s_py.copy(), state.s_yy.copy()
    lam = math.exp(-dt / config.forgetting_time)
    for axle in (0, 1):
        rows = axle_of == axle
        if not rows.any():
            continue
        s_pp[axle] = lam * s_pp[axle] + np.einsum('ij,ij->j', phi[rows], phi[rows])
        s_py[axle] = lam * s_py[axle] + y[rows] @ phi[rows]
        s_yy[axle] = lam * s_yy[axle] + float(y[rows] @ y[rows])
    new = _with_best(
        FitState(s_pp, s_py, s_yy, utilisation, t, state.member, state.scale), bank, config
    )
    mu_max = new.scale * bank.peak[new.member]
    ratio = np.abs(m[use]) / np.maximum(mu_max[axle_of], 1e-9)
    np.maximum.at(utilisation, axle_of, ratio)
    return replace(new, utilisation=np.minimum(utilisation, 1.0))


def _with_best(state: FitState, bank: CurveBank, config: FrictionPotentialConfig) -> FitState:
    scale, cost = _member_costs(state, bank, config)
    member = np.argmin(cost, axis=1).astype(np.int64)
    return replace(state, member=member, scale=scale[np.arange(2), member])


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
    bank: CurveBank,
    config: FrictionPotentialConfig,
    previous_class: ArrayLike = (ROAD_UNKNOWN, ROAD_UNKNOWN),
) -> FrictionPotential:
    """Friction potential from the statistics (pure).

    Args:
        state: statistics.
        bank: member grid.
        config: settings.
        previous_class: shape (2,), road class per axle at the previous stamp (hysteresis).

    Returns:
        The estimate for ``state.t``.
    """
    member = state.member
    fitted = state.scale * bank.peak[member]
    s_peak: FloatArray = bank.slip_peak[member]
    span = config.confidence_utilisation_high - config.confidence_utilisation_low
    confidence = np.clip((state.utilisation - config.confidence_utilisation_low) / span, 0, 1)
    # Unexcited, the fit only knows the linear region and its peak is arbitrary (it drifted to
    # 3 on the dry paper cruise): report the prior there, the fit once the tyre was pushed.
    weight = np.clip(confidence / max(config.class_min_confidence, 1e-9), 0.0, 1.0)
    mu_max: FloatArray = (
        weight * fitted + (1.0 - weight) * config.prior_mu_max
        if config.shrink_to_prior
        else fitted
    )
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
        slip_peak=s_peak,
        confidence=confidence,
        road_class=road,
        member=member,
    )


class FrictionPotentialEstimator:
    """Stateful wrapper: the node calls `update` once per estimate."""

    def __init__(self, config: FrictionPotentialConfig | None = None) -> None:
        """Create the estimator.

        Args:
            config: settings; defaults if None.
        """
        self.config = config or FrictionPotentialConfig()
        self.bank = make_bank(self.config)
        self.reset()

    def reset(self) -> None:
        """Forget all data (prior road, confidence 0)."""
        self.state = initial_fit_state(self.bank)
        self._classes = np.full(2, ROAD_UNKNOWN, dtype=np.int64)
        self.last: FrictionPotential | None = None

    def fit_slip(self, slip_velocity: ArrayLike, speed: float) -> FloatArray:
        """Slip for the fit: `floored_slip` with ``config.slip_floor_speed``."""
        return floored_slip(slip_velocity, speed, self.config.slip_floor_speed)

    def update(
        self, t: float, slip: ArrayLike, mu: ArrayLike, mu_valid: ArrayLike
    ) -> FrictionPotential:
        """Add one stamp's samples and return the current potential.

        Args:
            t: stamp [s] (non-finite or non-increasing: previous result returned).
            slip: shape (4,), [-] positive driving, order FL, FR, RL, RR.
            mu: shape (4,), [-] utilised friction.
            mu_valid: shape (4,), bool.

        Raises:
            InputShapeError: an input is not shape (4,).
        """
        before = self.state
        self.state = fit_step(self.state, t, slip, mu, mu_valid, self.bank, self.config)
        if self.state is before and self.last is not None:
            return self.last
        result = fit_solution(self.state, self.bank, self.config, self._classes)
        self._classes = result.road_class.copy()
        self.last = result
        return result
