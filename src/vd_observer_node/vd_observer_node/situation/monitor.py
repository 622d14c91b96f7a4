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
from typing import Any, Final

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vd_observer_node.errors import ConfigurationError, InputShapeError
from vd_observer_node.estimation.cascade import CascadeResult
from vd_observer_node.estimation.differentiator import LevantDifferentiator
from vd_observer_node.estimation.observer import WHEEL_INPUTS, ObserverConfig
from vd_observer_node.kernel._jit import jit
from vd_observer_node.situation.alerts import (
    ALERT_KINDS,
    Alert,
    AlertConfig,
    AlertMonitor,
    alert_records,
    alerts_update,
)
from vd_observer_node.situation.friction_fit import friction_update, vehicle_road_class
from vd_observer_node.situation.friction_potential import (
    FrictionPotential,
    FrictionPotentialConfig,
    FrictionPotentialEstimator,
    TyreCurves,
)
from vd_observer_node.situation.records import new_record

__all__ = [
    'LEVELS_CHANGED',
    'MONITOR_PARAMS',
    'MONITOR_STATE',
    'POTENTIAL_MOVED',
    'Situation',
    'SituationConfig',
    'SituationMonitor',
    'SituationSeries',
    'monitor_restarts',
    'monitor_step',
    'run_situation',
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: Settings of `monitor_step` besides those of its parts: radius [m] the effective rolling
#: radius; slip_floor_speed, max_observer_disagreement [m/s] as `SituationConfig`; max_gap
#: [s] the observers' (a stamp older than the last by more than this restarts the monitor).
MONITOR_PARAMS: Final = np.dtype(
    [
        ('radius', 'f8'),
        ('slip_floor_speed', 'f8'),
        ('max_observer_disagreement', 'f8'),
        ('max_gap', 'f8'),
    ],
    align=True,
)
#: State of `monitor_step` besides its parts': t [s] the stamp of the last call (nan before).
MONITOR_STATE: Final = np.dtype([('t', 'f8')], align=True)
#: `monitor_step` flags: the friction potential took the stamp (new solution)...
POTENTIAL_MOVED: Final = 1
#: ...a reported alert level changed.
LEVELS_CHANGED: Final = 2


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


@jit
def monitor_restarts(p: Any, s: Any, t: float) -> bool:
    """Whether stamp t must restart the monitor: older than the last call's stamp by more than
    ``max_gap`` (a looped bag or a restarted source), as the observers restart."""
    return not math.isnan(s.t) and t < s.t - p.max_gap


@jit
def monitor_step(
    p: Any,
    s: Any,
    fp: Any,
    tyre: Any,
    scales: FloatArray,
    table: FloatArray,
    fs: Any,
    cost: FloatArray,
    pot: Any,
    ap: Any,
    al: Any,
    t: float,
    fast_omega: FloatArray,
    fast_valid: BoolArray,
    speed: float,
    torque: FloatArray,
    omega: FloatArray,
    mu: FloatArray,
    mu_valid: BoolArray,
    fz: FloatArray,
    slip: FloatArray,
) -> int:
    """One stamp of the monitor after its fast observer: friction potential, then alerts.

    Args:
        p: `MONITOR_PARAMS` record.
        s: `MONITOR_STATE` record.
        fp, tyre, scales, table, fs, cost, pot: the friction fit's settings and state
            (`friction_fit.friction_update`).
        ap, al: the alerts' settings and state (`alerts.alerts_update`).
        t: stamp [s].
        fast_omega: shape (4,), [rad/s] the fast observer's wheel speed at t.
        fast_valid: shape (4,), its validity.
        speed: [m/s] measured body speed.
        torque: shape (4,), [N m] drive minus brake torque.
        omega: shape (4,), [rad/s] the cascade observer's wheel speed.
        mu: shape (4,), [-] utilised friction (estimator).
        mu_valid: shape (4,), bool.
        fz: shape (4,), [N] wheel loads (estimator).
        slip: shape (4,), written: [-] the fast slip the traction and lock alerts see.

    Returns:
        `POTENTIAL_MOVED` | `LEVELS_CHANGED` flags.
    """
    radius, gate = p.radius, p.max_observer_disagreement
    sv_fast = np.empty(4)
    sv_cascade = np.empty(4)
    steady = np.empty(4, dtype=np.bool_)
    for i in range(4):
        sv_fast[i] = fast_omega[i] * radius - speed if fast_valid[i] else 0.0
        # vd_common.vehicle.tire.slip_ratio: the denominator floored at slip_floor_speed
        slip[i] = sv_fast[i] / max(max(abs(sv_fast[i] + speed), abs(speed)), p.slip_floor_speed)
        sv_cascade[i] = omega[i] * radius - speed
        # While the two observers disagree the cascade's omega (and its omega-dot, hence mu)
        # lags a fast wheel transient: such (slip, mu) pairs lie off the tyre's curve.
        agree = abs(sv_fast[i] - sv_cascade[i]) <= gate if gate > 0.0 else True
        steady[i] = agree and mu_valid[i]
    flags = 0
    if friction_update(
        fp, tyre, scales, table, fs, cost, pot, t, sv_cascade, speed, mu, steady, fz
    ):
        flags |= POTENTIAL_MOVED
    wheel_mu_max = np.empty(4)
    wheel_slip_peak = np.empty(4)
    for i in range(4):
        wheel_mu_max[i] = pot.mu_max[i // 2]
        wheel_slip_peak[i] = pot.slip_peak[i // 2]
    if alerts_update(
        ap, al, t, slip, sv_fast, torque, mu, mu_valid, wheel_mu_max, wheel_slip_peak
    ):
        flags |= LEVELS_CHANGED
    s.t = t
    return flags


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
        self.slip = np.zeros(4)
        self.reset()
        # compile (or load from numba's cache) now, not at the first sample; on copies
        zeros, ones = np.zeros(4), np.ones(4)
        valid = zeros != 0.0
        self.step_records(0.0, zeros, valid, 1.0, zeros, zeros, zeros, valid, ones, copy=True)

    def reset(self) -> None:
        """Back to the initial state (after a time jump or a new bag)."""
        self.fast.reset()
        self.friction.reset()
        self.monitor.reset()
        self.state.t = math.nan
        self.last: Situation | None = None

    def step_records(
        self,
        t: float,
        fast_omega: FloatArray,
        fast_valid: BoolArray,
        speed: float,
        torque: FloatArray,
        omega: FloatArray,
        mu: FloatArray,
        mu_valid: BoolArray,
        load: FloatArray,
        *,
        copy: bool = False,
    ) -> int:
        """`monitor_step` on this monitor's records (``copy``: on copies of them, which stay
        untouched); contiguous float64 (bool) arrays of shape (4,). Returns its flags."""
        f, a = self.friction, self.monitor
        records: tuple[Any, ...] = (self.state, f.state, f.cost, f.potential, a.state)
        if copy:
            records = tuple(r.copy() for r in records)
        s, fs, cost, pot, al = records
        flags: int = monitor_step(
            self.params, s, f.params, f.tyre, f.scales, f.table, fs, cost, pot, a.params, al,
            float(t), fast_omega, fast_valid, float(speed), torque, omega, mu, mu_valid, load,
            self.slip,
        )  # fmt: skip
        return flags

    def advance(
        self,
        t: float,
        wheel_angle: ArrayLike,
        speed: float,
        wheel_torque: ArrayLike,
        omega: ArrayLike,
        mu: ArrayLike,
        mu_valid: ArrayLike,
        load: ArrayLike,
    ) -> int:
        """`update` without building the result: the records, and `slip`, hold it.

        Returns:
            The `monitor_step` flags.

        Raises:
            InputShapeError: an array input has the wrong shape.
        """
        angles = _floats('wheel_angle', wheel_angle)
        inputs = (
            _floats('wheel_torque', wheel_torque),
            _floats('omega', omega),
            _floats('mu', mu),
            _floats('mu_valid', mu_valid, np.bool_),
            _floats('load', load),
        )
        if monitor_restarts(self.params, self.state, float(t)):
            # a looped bag or a restarted source: start again, as the observers do
            self.reset()
        fast = self.fast.update(t, angles)
        torque, omega_c, mu_c, valid, fz = inputs
        return self.step_records(
            t,
            np.ascontiguousarray(fast.first, dtype=np.float64),
            np.ascontiguousarray(fast.valid, dtype=np.bool_),
            speed,
            torque,
            omega_c,
            mu_c,
            valid,
            fz,
        )

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
        """Advance to stamp t.

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
        self.refresh(self.advance(t, wheel_angle, speed, wheel_torque, omega, mu, mu_valid, load))
        self.last = Situation(float(t), self.friction.last, self.monitor.last, self.slip.copy())
        return self.last


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
    """Feed a whole record through `monitor`, one stamp at a time, as the node would.

    Args:
        monitor: the monitor (its state carries on; `reset` it for a new record).
        wheel_angle: shape (N, 4), [rad] at the cascade's stamps.
        speed: shape (N,), [m/s] measured body speed.
        wheel_torque: shape (N, 4), [N m].
        cascade: the cascade's result on the same stamps (`run_cascade`).

    Raises:
        InputShapeError: inconsistent shapes.
    """
    angles = np.asarray(wheel_angle, dtype=np.float64)
    speeds = np.asarray(speed, dtype=np.float64)
    torques = np.asarray(wheel_torque, dtype=np.float64)
    n = cascade.t.shape[0]
    if angles.shape != (n, 4) or speeds.shape != (n,) or torques.shape != (n, 4):
        raise InputShapeError(
            f'expected wheel_angle ({n}, 4), speed ({n},), wheel_torque ({n}, 4); got '
            f'{angles.shape}, {speeds.shape}, {torques.shape}'
        )
    kinds = len(ALERT_KINDS)
    level = np.zeros((n, kinds, 4), dtype=np.int64)
    onset = np.full((n, kinds, 4), math.nan)
    detected = np.full((n, kinds, 4), math.nan)
    axle = {k: np.zeros((n, 2)) for k in ('mu_max', 'slip_peak', 'confidence')}
    road = np.zeros((n, 2), dtype=np.int64)
    vehicle_road = np.zeros(n, dtype=np.int64)
    # the records are updated in place, also by a restart
    pot, al = monitor.friction.potential, monitor.monitor.state
    flags = 0
    for k in range(n):
        flags |= monitor.advance(
            float(cascade.t[k]),
            angles[k],
            float(speeds[k]),
            torques[k],
            cascade.omega[k],
            cascade.mu[k],
            cascade.mu_valid[k],
            cascade.fz[k],
        )
        level[k] = al.level
        onset[k] = al.onset
        detected[k] = al.detected
        axle['mu_max'][k] = pot.mu_max
        axle['slip_peak'][k] = pot.slip_peak
        axle['confidence'][k] = pot.confidence
        road[k] = pot.road_class
        vehicle_road[k] = vehicle_road_class(pot.road_class, pot.confidence)
    monitor.refresh(flags)
    return SituationSeries(
        t=cascade.t.copy(),
        level=level,
        onset=onset,
        detected=detected,
        mu_max=axle['mu_max'],
        slip_peak=axle['slip_peak'],
        confidence=axle['confidence'],
        road_class=road,
        vehicle_road_class=vehicle_road,
    )
