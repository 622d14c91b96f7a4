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
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vd_observer_node.errors import ConfigurationError, InputShapeError
from vd_observer_node.estimation.cascade import CascadeResult
from vd_observer_node.estimation.differentiator import LevantDifferentiator
from vd_observer_node.estimation.observer import WHEEL_INPUTS, ObserverConfig
from vd_observer_node.kernel._jit import FixedCall, new_record, record_array
from vd_observer_node.situation.alerts import (
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
    AlertParts,
    MonitorParts,
    SituationBlock,
    SituationInputs,
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
            settings=fc.differentiator(),
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
        #: the output buffers of `update` (one stamp)
        self._one = SituationBlock.empty(1)
        r = record_array
        f, m = self.friction, self.monitor
        #: the records above as `situation_block` takes them (never replaced: every reset
        #: works in place, so they are built once)
        self.parts = MonitorParts(
            r(self.params), r(self.state),
            self.fast.parts(),
            f.parts, AlertParts(r(m.params), r(m.state), r(m.input)),
        )  # fmt: skip
        self.reset()
        # compiled (or loaded from numba's cache) now, not at the first sample
        zeros = np.zeros((1, 4))
        self._block = FixedCall(
            situation_block, (self.parts,),
            (
                np.zeros(1),
                SituationInputs(zeros, np.ones(1), zeros, zeros, zeros, zeros != 0.0, zeros),
                SituationBlock.empty(1),
            ),
        )  # fmt: skip

    def reset(self) -> None:
        """Back to the initial state (after a time jump or a new bag)."""
        self.fast.reset()
        self.friction.reset()
        self.monitor.reset()
        self.state.t = math.nan
        self.last: Situation | None = None

    def run(self, t: FloatArray, inputs: SituationInputs, out: SituationBlock) -> int:
        """`situation_block` over the N stamps `t` [s] (contiguous arrays, checked by the
        callers); returns the or-ed `monitor_step` flags and keeps `last` up to date."""
        flags: int = self._block(t, inputs, out)
        self.refresh(flags)
        if t.shape[0]:
            self.slip = out.slip[-1].copy()
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


#: The monitor's outputs over a whole record (`run_situation`): the block it writes.
SituationSeries = SituationBlock


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
    monitor.run(f64(cascade.t, dtype=np.float64), inputs, out)
    return out
