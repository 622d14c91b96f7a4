"""Situation monitor: friction potential and early alerts from one stamp's measurements.

What the alerts node runs per stamp, and offline replay and the evaluation with it, so all
three give the same result (ROS-free):

* a **fast wheel observer** (Levant differentiator with a large Lipschitz constant,
  ``alert_wheel_lipschitz``) on the wheel angles, for the slip of the traction and lock
  alerts. The cascade's observer is tuned for accurate omega-dot and mu with noisy encoders
  (L 300 rad/s^3); it lags a locking wheel by ~100 ms, which would be the alert's delay.
  The fast one follows within ~20 ms and is noisier, which the alerts' slip-velocity, torque
  and force-sign gates absorb;
* `FrictionPotentialEstimator` on the cascade's own wheel speed and mu (same observer, so the
  (slip, mu) pairs are consistent in time);
* `AlertMonitor` on the fast slip, the wheel torques, mu and the friction potential.

One stamp of all but the fast observer is one compiled step function on named records,
`monitor_step` (it calls `friction_fit.friction_update` and `alerts.alerts_update`);
`SituationMonitor` owns the records and the fast observer, and `run_situation` feeds it a
whole record.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vd_observer_node.errors import ConfigurationError, InputShapeError
from vd_observer_node.estimation.cascade import CascadeResult
from vd_observer_node.estimation.differentiator import LevantDifferentiator
from vd_observer_node.estimation.observer import WHEEL_INPUTS, ObserverConfig
from vd_observer_node.kernel._jit import new_record, record_array
from vd_observer_node.situation.alerts import (
    ALERT_KINDS,
    Alert,
    AlertConfig,
    AlertMonitor,
    alert_records,
)
from vd_observer_node.situation.friction_potential import (
    FrictionPotential,
    FrictionPotentialConfig,
    FrictionPotentialEstimator,
    TyreCurves,
)
from vd_observer_node.situation.monitor_step import (
    LEVELS_CHANGED,
    MONITOR_PARAMS,
    MONITOR_STATE,
    POTENTIAL_MOVED,
    situation_block,
)

__all__ = [
    'LEVELS_CHANGED',
    'MONITOR_PARAMS',
    'MONITOR_STATE',
    'POTENTIAL_MOVED',
    'Situation',
    'SituationBlock',
    'SituationConfig',
    'SituationInputs',
    'SituationMonitor',
    'SituationSeries',
    'run_situation',
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class SituationConfig:
    """Settings of the situation monitor beyond those of the alerts and the friction fit.

    Attributes:
        alert_wheel_lipschitz: L [rad/s^3] of the fast wheel observer whose slip the traction
            and lock alerts use (the cascade's observer keeps its own L).
        slip_floor_speed: [m/s] denominator floor of the alerts' slip ratio (the vehicle
            file's ``tire.low_speed_velocity``): at walking pace the ratio of two small
            speeds is not what the tyre reacts to.
        max_observer_disagreement: [m/s] when > 0, a wheel's (slip, mu) pair is left out of
            the friction fit while the fast and the cascade's wheel speeds differ by more
            than this (times R): the cascade lags a wheel transient there. 0 (default) keeps
            every pair: the gate cleans the dry-road estimate after a wheel spin but also
            drops the informative samples of a locking wheel (docs/alerts.md, 4.3).
    """

    alert_wheel_lipschitz: float = 3000.0
    slip_floor_speed: float = 1.0
    max_observer_disagreement: float = 0.0

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ConfigurationError(f'{f.name} must be finite and >= 0, got {value}')
        for name in ('alert_wheel_lipschitz', 'slip_floor_speed'):
            if getattr(self, name) <= 0.0:
                raise ConfigurationError(f'{name} must be > 0, got {getattr(self, name)}')

    @classmethod
    def from_mapping(cls, data: dict[str, Any]) -> SituationConfig:
        """Build from a flat mapping (e.g. ROS parameters).

        Raises:
            ConfigurationError: unknown key or invalid value.
        """
        unknown = set(data) - {f.name for f in fields(cls)}
        if unknown:
            raise ConfigurationError(f'unknown situation settings: {sorted(unknown)}')
        return cls(**{k: float(v) for k, v in data.items()})


@dataclass(frozen=True)
class Situation:
    """Result of one stamp.

    Attributes:
        t: stamp [s].
        potential: friction potential per axle.
        alerts: the 12 alert records (kinds in ALERT_KINDS order, wheels 0..3 within each).
        slip: shape (4,), [-] slip of the fast observer, as the slip alerts saw it.
    """

    t: float
    potential: FrictionPotential
    alerts: tuple[Alert, ...]
    slip: FloatArray


def _floats(name: str, value: ArrayLike, dtype: type = np.float64) -> NDArray[Any]:
    array: NDArray[Any] = np.ascontiguousarray(value, dtype=dtype)
    if array.shape != (4,):
        raise InputShapeError(f'{name} must have shape (4,), got {array.shape}')
    return array


class SituationMonitor:
    """Fast wheel observer + friction potential + alerts, fed once per stamp.

    Attributes:
        fast: the fast wheel observer's differentiator (4 channels).
        friction: the friction potential (its records are `monitor_step`'s).
        monitor: the alerts (its records are `monitor_step`'s).
        params: `MONITOR_PARAMS` record.
        state: `MONITOR_STATE` record.
        slip: shape (4,), [-] the fast slip of the last stamp.
        last: the result of the last `update` (None before the first or after a reset).
    """

    def __init__(
        self,
        curves: TyreCurves,
        static_load: ArrayLike,
        radius: float,
        *,
        observer: ObserverConfig | None = None,
        alerts: AlertConfig | None = None,
        friction: FrictionPotentialConfig | None = None,
        situation: SituationConfig | None = None,
    ) -> None:
        """Create the monitor.

        Args:
            curves: the tyre's curves (`TyreCurves.from_tire`).
            static_load: shape (2,), [N] static wheel load per axle.
            radius: [m] effective rolling radius.
            observer: the cascade's observer settings; the fast observer shares all but the
                wheel Lipschitz constant.
            alerts: alert settings.
            friction: friction-potential settings.
            situation: fast-observer settings.
        """
        self.config = situation or SituationConfig()
        base = observer or ObserverConfig()
        self.observer_config = replace(base, wheel_lipschitz=self.config.alert_wheel_lipschitz)
        self.radius = float(radius)
        fc = self.observer_config
        self.fast = LevantDifferentiator(
            fc.wheel_lipschitz,
            n_channels=4,
            gains=fc.gains,
            discretization=fc.discretization,
            init=fc.init,
            max_gap=fc.max_gap,
            init_baseline=fc.init_baseline,
            input_derivative=WHEEL_INPUTS.index(fc.wheel_input),
        )
        self.friction = FrictionPotentialEstimator(curves, static_load, friction)
        self.monitor = AlertMonitor(alerts)
        self.params = new_record(MONITOR_PARAMS)
        self.params.radius = self.radius
        self.params.slip_floor_speed = self.config.slip_floor_speed
        self.params.max_observer_disagreement = self.config.max_observer_disagreement
        self.params.max_gap = fc.max_gap
        self.state = new_record(MONITOR_STATE)
        self._args: tuple[Any, ...] | None = None
        self.slip = np.zeros(4)
        #: the output buffers of `update` (one stamp)
        self._one = SituationBlock.empty(1)
        self.reset()
        # compile (or load from numba's cache) now, not at the first sample: on copies
        zeros = np.zeros((1, 4))
        block: Any = situation_block
        block(
            *(a.copy() for a in self.args()), np.zeros(1), zeros, np.ones(1), zeros, zeros,
            zeros, zeros != 0.0, np.ones((1, 4)), *SituationBlock.empty(1).outputs(),
            np.zeros(4),
        )  # fmt: skip

    def reset(self) -> None:
        """Back to the initial state (after a time jump or a new bag)."""
        self.fast.reset()
        self.friction.reset()
        self.monitor.reset()
        self.state.t = math.nan
        self.last: Situation | None = None

    def args(self) -> tuple[Any, ...]:
        """`monitor_step.situation_block`'s leading arguments (the records as the 1-element
        arrays they live in, advanced in place)."""
        if self._args is not None:
            return self._args
        f, m, r = self.friction, self.monitor, record_array
        fp, flip, fs, fch = self.fast.kernel_args
        plain = fch.view(np.ndarray)  # a recarray's attributes are Python lookups
        # the records are never replaced (every reset works in place): built once
        self._args = (
            r(fp), flip, r(fs), plain, r(self.params), r(self.state), r(f.params), r(f.tyre),
            f.scales, f.table, f.static_load, r(f.state), f.cost, r(f.potential),
            r(m.params), r(m.state),
        )  # fmt: skip
        return self._args

    def run(self, t: FloatArray, inputs: SituationInputs, out: SituationBlock) -> int:
        """`situation_block` over the N stamps `t` [s] (contiguous arrays, checked by the
        callers); returns the or-ed `monitor_step` flags and keeps `last` up to date."""
        block: Any = situation_block  # its arguments come as tuples
        flags: int = block(*self.args(), t, *inputs, *out.outputs(), self.slip)
        self.refresh(flags)
        if t.shape[0]:
            self.last = Situation(
                float(t[-1]), self.friction.last, self.monitor.last, self.slip.copy()
            )
        return flags

    def refresh(self, flags: int = POTENTIAL_MOVED | LEVELS_CHANGED) -> None:
        """Rebuild the wrapped parts' results (`last`) from the records after ``flags``."""
        if flags & POTENTIAL_MOVED:
            self.friction.last = FrictionPotential.from_record(self.friction.potential)
        if flags & LEVELS_CHANGED:
            self.monitor.last = alert_records(self.monitor.state)

    def update(
        self,
        t: float,
        wheel_angle: ArrayLike,
        speed: float,
        wheel_torque: ArrayLike,
        omega: ArrayLike,
        mu: ArrayLike,
        mu_valid: ArrayLike,
        load: ArrayLike,
    ) -> Situation:
        """Advance to stamp t (`situation_block` on one stamp).

        Args:
            t: stamp [s].
            wheel_angle: shape (4,), [rad] unwrapped wheel angles (sensor), or speeds [rad/s]
                with ``wheel_input='speed'``.
            speed: [m/s] measured body speed.
            wheel_torque: shape (4,), [N m] drive minus brake torque (sensor).
            omega: shape (4,), [rad/s] the cascade observer's wheel speed.
            mu: shape (4,), [-] utilised friction (estimator).
            mu_valid: shape (4,), bool.
            load: shape (4,), [N] wheel loads (estimator).

        Returns:
            The situation at t. Non-finite or stale inputs are absorbed by the parts (see
            their docs); the outputs stay finite. A stamp older than the last one by more
            than the observer's ``max_gap`` resets everything (a looped bag).

        Raises:
            InputShapeError: an array input has the wrong shape.
        """
        inputs = SituationInputs(
            _floats('wheel_angle', wheel_angle)[None],
            np.array([float(speed)]),
            _floats('wheel_torque', wheel_torque)[None],
            _floats('omega', omega)[None],
            _floats('mu', mu)[None],
            _floats('mu_valid', mu_valid, np.bool_)[None],
            _floats('load', load)[None],
        )
        self.run(np.array([float(t)]), inputs, self._one)
        assert self.last is not None  # run just set it
        return self.last


class SituationInputs(NamedTuple):
    """The monitor's inputs over N stamps (contiguous; `situation_block`'s order).

    Attributes:
        angles: shape (N, 4), [rad] wheel angles (or speeds [rad/s]).
        speeds: shape (N,), [m/s] measured body speed.
        torques: shape (N, 4), [N m].
        omega: shape (N, 4), [rad/s] the cascade's wheel speed.
        mu: shape (N, 4), [-].
        mu_valid: shape (N, 4), bool.
        fz: shape (N, 4), [N].
    """

    angles: FloatArray
    speeds: FloatArray
    torques: FloatArray
    omega: FloatArray
    mu: FloatArray
    mu_valid: BoolArray
    fz: FloatArray


@dataclass
class SituationBlock:
    """The monitor's outputs over N stamps (`situation_block` writes them; see
    `SituationSeries` for the fields)."""

    level: NDArray[np.int64]
    onset: FloatArray
    detected: FloatArray
    mu_max: FloatArray
    slip_peak: FloatArray
    confidence: FloatArray
    road_class: NDArray[np.int64]
    vehicle_road_class: NDArray[np.int64]

    @classmethod
    def empty(cls, n: int) -> SituationBlock:
        """Buffers for N stamps."""
        kinds = len(ALERT_KINDS)
        return cls(
            np.zeros((n, kinds, 4), dtype=np.int64), np.full((n, kinds, 4), math.nan),
            np.full((n, kinds, 4), math.nan), np.zeros((n, 2)), np.zeros((n, 2)),
            np.zeros((n, 2)), np.zeros((n, 2), dtype=np.int64), np.zeros(n, dtype=np.int64),
        )  # fmt: skip

    def outputs(self) -> tuple[Any, ...]:
        """`situation_block`'s written arguments (before ``slip``)."""
        return (
            self.level, self.onset, self.detected, self.mu_max, self.slip_peak,
            self.confidence, self.road_class, self.vehicle_road_class,
        )  # fmt: skip


@dataclass(frozen=True)
class SituationSeries:
    """The monitor's outputs over a record of N stamps (offline replay, evaluation, tests).

    Attributes:
        t: shape (N,), [s].
        level: shape (N, 3, 4), alert level per kind (ALERT_KINDS order) and wheel.
        onset: shape (N, 3, 4), [s] onset stamp (nan while inactive).
        detected: shape (N, 3, 4), [s] detection stamp (nan while inactive).
        mu_max: shape (N, 2), [-] per axle.
        slip_peak: shape (N, 2), [-] per axle.
        confidence: shape (N, 2), [0..1] per axle.
        road_class: shape (N, 2), ROAD_* code per axle.
        vehicle_road_class: shape (N,), ROAD_* code.
    """

    t: FloatArray
    level: NDArray[np.int64]
    onset: FloatArray
    detected: FloatArray
    mu_max: FloatArray
    slip_peak: FloatArray
    confidence: FloatArray
    road_class: NDArray[np.int64]
    vehicle_road_class: NDArray[np.int64]


def run_situation(
    monitor: SituationMonitor,
    wheel_angle: ArrayLike,
    speed: ArrayLike,
    wheel_torque: ArrayLike,
    cascade: CascadeResult,
) -> SituationSeries:
    """Feed a whole record (or a block of one) through `monitor` (`situation_block`), as the
    nodes feed it stamp by stamp.

    Args:
        monitor: the monitor (its state carries on; `reset` it for a new record).
        wheel_angle: shape (N, 4), [rad] at the cascade's stamps.
        speed: shape (N,), [m/s] measured body speed.
        wheel_torque: shape (N, 4), [N m].
        cascade: the cascade's result on the same stamps (`run_cascade`).

    Raises:
        InputShapeError: inconsistent shapes.
    """
    f64 = np.ascontiguousarray
    angles = f64(wheel_angle, dtype=np.float64)
    speeds = f64(speed, dtype=np.float64)
    torques = f64(wheel_torque, dtype=np.float64)
    n = cascade.t.shape[0]
    if angles.shape != (n, 4) or speeds.shape != (n,) or torques.shape != (n, 4):
        raise InputShapeError(
            f'expected wheel_angle ({n}, 4), speed ({n},), wheel_torque ({n}, 4); got '
            f'{angles.shape}, {speeds.shape}, {torques.shape}'
        )
    inputs = SituationInputs(
        angles, speeds, torques, f64(cascade.omega, dtype=np.float64),
        f64(cascade.mu, dtype=np.float64), f64(cascade.mu_valid, dtype=np.bool_),
        f64(cascade.fz, dtype=np.float64),
    )  # fmt: skip
    out = SituationBlock.empty(n)
    t = f64(cascade.t, dtype=np.float64)
    monitor.run(t, inputs, out)
    return SituationSeries(
        t=t.copy(),
        level=out.level,
        onset=out.onset,
        detected=out.detected,
        mu_max=out.mu_max,
        slip_peak=out.slip_peak,
        confidence=out.confidence,
        road_class=out.road_class,
        vehicle_road_class=out.vehicle_road_class,
    )
