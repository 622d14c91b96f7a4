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
(correlated samples are not independent evidence; fewer if the window holds fewer), mapped
linearly from ``evidence_low`` (0) to ``evidence_high`` (1). Once no usable sample comes, it
decays with the age of the evidence over ``evidence_hold_time``, faster by the misfit (the
mean weighted squared residual per sample at the best scale, about 1 or less when one road's
curve explains the data): data that no curve explains (a road change inside the forgetting
window, a force transient) are not a road the car can keep claiming. Below
``class_min_confidence`` the reported values are shrunk towards the prior road; the road class
(dry / wet / snow / ice) is UNKNOWN there.

The per-sample math is in `vd_observer_node.situation.friction_fit` (step functions on named
records, compiled); here are the settings, the result, and the stateful wrapper
(`FrictionPotentialEstimator`) the node calls per estimate. Axles: 0 front (FL, FR), 1 rear
(RL, RR). Time in seconds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
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
)
from vd_common.vehicle.params import TireParams

from vd_observer_node.errors import InputShapeError, ObserverError
from vd_observer_node.kernel._jit import new_record, record_array
from vd_observer_node.situation.friction_fit import (
    FIT_STATE,
    FRICTION_PARAMS,
    POTENTIAL,
    TYRE,
    FrictionFit,
    fit_reset,
    friction_update,
    vehicle_road_class,
)
from vd_observer_node.situation.records import record_of

__all__ = [
    'AXLE_OF_WHEEL',
    'ROAD_CLASS_NAMES',
    'ROAD_DRY',
    'ROAD_ICE',
    'ROAD_SNOW',
    'ROAD_UNKNOWN',
    'ROAD_WET',
    'FrictionConfigError',
    'FrictionPotential',
    'FrictionPotentialConfig',
    'FrictionPotentialEstimator',
    'TyreCurves',
    'friction_params',
]

FloatArray = NDArray[np.float64]

#: Axle index of each wheel FL, FR, RL, RR (0 front, 1 rear).
AXLE_OF_WHEEL: Final = (0, 0, 1, 1)
#: Name of each road class code.
ROAD_CLASS_NAMES: Final = ('unknown', 'ice', 'snow', 'wet', 'dry')
_AXLES: Final = np.asarray(AXLE_OF_WHEEL)


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
        evidence_samples: the forgotten data count as this many independent samples at
            most (as many as they hold, if fewer): the evidence is the mean weighted cost
            advantage per sample times this. Consecutive samples are correlated (one
            observer filters them) and a small systematic model error summed over a thousand
            samples a second would otherwise become certainty; and two samples after a pause
            are two, not a hundred.
        evidence_hold_time: [s] the confidence decays as exp(-age * max(misfit, 1) / this),
            age = time since the axle's last usable sample, misfit = the mean weighted
            squared residual per sample at the best road scale: a friction potential measured
            a kilometre back says little about the road here, a wrong estimate must not
            outlive its evidence for minutes of cruising, and data no curve explains (two
            roads in one forgetting window) must not outlive it for seconds. 0 keeps the
            confidence forever.
        evidence_low: evidence at and below which the confidence is 0.
        evidence_high: evidence at and above which the confidence is 1.
        change_time: time constant [s] of the recent statistics the road-change test
            compares with the whole window (0: the last stamp's samples alone).
        change_evidence: a road change is detected, and the window restarted from the
            recent statistics, where these reject the window's best road by this much
            evidence (the confidence's measure, on the recent samples) with peaks more than
            ``confidence_margin`` apart. Without it a road change mixes two roads in one
            window for about ``forgetting_time``, and the fit between them is confidently
            wrong. 0 turns the test off.
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
    change_time: float = 0.05
    change_evidence: float = 300.0
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

    def record(self) -> Any:
        """The Magic Formula coefficients the fit evaluates, as a `TYRE` record."""
        return record_of(TYRE, self.tire)

    def peak_table(self) -> FloatArray:
        """shape (5, L): the peaks at road scale 1 against the load (`friction_fit`)."""
        tb = self.table
        table = np.stack([tb.load, tb.mu_drive, tb.slip_drive, tb.mu_brake, tb.slip_brake])
        return np.ascontiguousarray(table, dtype=np.float64)


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
        return int(vehicle_road_class(self.road_class, self.confidence))

    @classmethod
    def from_record(cls, pot: Any) -> FrictionPotential:
        """The potential held in a `POTENTIAL` record (read in one ``item()`` call, whose
        arrays are views into the record: copied)."""
        v = dict(zip(pot.dtype.names, pot.item(), strict=True))
        return cls(
            t=float(v['t']),
            mu_max=v['mu_max'].copy(),
            slip_peak=v['slip_peak'].copy(),
            confidence=v['confidence'].copy(),
            road_class=v['road_class'].copy(),
            road_scale=v['road_scale'].copy(),
        )


def friction_params(config: FrictionPotentialConfig) -> Any:
    """The scalar settings as a `FRICTION_PARAMS` record (the fit's step functions read it)."""
    return record_of(FRICTION_PARAMS, config)


def _wheels(name: str, value: ArrayLike, dtype: type = np.float64) -> NDArray[Any]:
    array: NDArray[Any] = np.ascontiguousarray(value, dtype=dtype)
    if array.shape != (4,):
        raise InputShapeError(f'{name} must have shape (4,), got {array.shape}')
    return array


class FrictionPotentialEstimator:
    """Stateful wrapper over `friction_fit.friction_update`: the node calls `update` per estimate.

    Attributes:
        params: `FRICTION_PARAMS` record of `config`.
        tyre: `TYRE` record of the curves.
        scales: shape (M,), [-] the road scales.
        table: shape (5, L), the tyre's unit peaks.
        state: `FIT_STATE` record.
        cost: shape (2, M), the weighted squared residuals per axle and road scale.
        recent: shape (2, M), the same forgotten over ``change_time``.
        potential: `POTENTIAL` record of the last solution.
        last: the last solution as a `FrictionPotential`.
    """

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

        Raises:
            InputShapeError: static_load is not shape (2,).
        """
        self.curves = curves
        self.config = config or FrictionPotentialConfig()
        self.static_load = np.ascontiguousarray(static_load, dtype=np.float64)
        if self.static_load.shape != (2,):
            raise InputShapeError(
                f'static_load must have shape (2,), got {self.static_load.shape}'
            )
        self.params = friction_params(self.config)
        self.tyre = curves.record()
        self.table = curves.peak_table()
        self.scales = np.asarray(self.config.road_scales, dtype=np.float64)
        self.state = new_record(FIT_STATE)
        self.cost = np.zeros((2, self.scales.shape[0]))
        self.recent = np.zeros_like(self.cost)
        self.potential = new_record(POTENTIAL)
        r = record_array
        #: the records above (never replaced: every reset works in place) as the step
        #: functions take them
        self.parts = FrictionFit(
            r(self.params), r(self.tyre), self.scales, self.table, self.static_load,
            r(self.state), self.cost, self.recent, r(self.potential),
        )  # fmt: skip
        self.reset()

    def reset(self) -> None:
        """Forget all data (prior road, confidence 0)."""
        fit_reset(self.parts)
        self.last = FrictionPotential.from_record(self.potential)

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
        taken = friction_update(
            self.parts,
            float(t),
            _wheels('slip_velocity', slip_velocity),
            float(speed),
            _wheels('mu', mu),
            _wheels('mu_valid', mu_valid, np.bool_),
            _wheels('load', load),
        )
        if taken:
            self.last = FrictionPotential.from_record(self.potential)
        return self.last
