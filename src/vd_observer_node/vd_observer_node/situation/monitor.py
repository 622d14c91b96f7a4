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
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from vd_common.vehicle.tire import slip_ratio

from vd_observer_node.errors import ConfigurationError, InputShapeError
from vd_observer_node.estimation.cascade import CascadeResult
from vd_observer_node.estimation.observer import ObserverConfig, WheelObserver
from vd_observer_node.situation.alerts import (
    ALERT_KINDS,
    Alert,
    AlertConfig,
    AlertMonitor,
    slip_velocity,
)
from vd_observer_node.situation.friction_potential import (
    FrictionPotential,
    FrictionPotentialConfig,
    FrictionPotentialEstimator,
    TyreCurves,
)

__all__ = [
    'Situation',
    'SituationConfig',
    'SituationMonitor',
    'SituationSeries',
    'run_situation',
]

FloatArray = NDArray[np.float64]


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


class SituationMonitor:
    """Fast wheel observer + friction potential + alerts, fed once per stamp."""

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
        self.friction = FrictionPotentialEstimator(curves, static_load, friction)
        self.monitor = AlertMonitor(alerts)
        self.reset()

    def reset(self) -> None:
        """Back to the initial state (after a time jump or a new bag)."""
        self.fast = WheelObserver(self.observer_config)
        self.friction.reset()
        self.monitor.reset()
        self.last: Situation | None = None

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
        if self.last is not None and t < self.last.t - self.observer_config.max_gap:
            # a looped bag or a restarted source: start again, as the observers do
            self.reset()
        fast = self.fast.update(t, wheel_angle)
        v = float(speed)
        sv_fast = np.where(fast.valid, slip_velocity(fast.omega, v, self.radius), 0.0)
        slip = slip_ratio(sv_fast, v, self.config.slip_floor_speed)
        sv_cascade = slip_velocity(omega, v, self.radius)
        # While the two observers disagree the cascade's omega (and its omega-dot, hence mu)
        # lags a fast wheel transient: such (slip, mu) pairs lie off the tyre's curve.
        gate = self.config.max_observer_disagreement
        steady = np.abs(sv_fast - sv_cascade) <= gate if gate > 0.0 else np.ones(4, bool)
        potential = self.friction.update(
            t, sv_cascade, v, mu, np.asarray(mu_valid, dtype=bool) & steady, load
        )
        alerts = self.monitor.update(
            t,
            slip,
            sv_fast,
            wheel_torque,
            mu,
            mu_valid,
            potential.wheel_mu_max(),
            potential.wheel_slip_peak(),
        )
        self.last = Situation(t, potential, alerts, slip)
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
    for k in range(n):
        out = monitor.update(
            float(cascade.t[k]),
            angles[k],
            float(speeds[k]),
            torques[k],
            cascade.omega[k],
            cascade.mu[k],
            cascade.mu_valid[k],
            cascade.fz[k],
        )
        for i, a in enumerate(out.alerts):
            level[k, i // 4, a.wheel] = a.level
            onset[k, i // 4, a.wheel] = a.onset
            detected[k, i // 4, a.wheel] = a.detected
        pot = out.potential
        axle['mu_max'][k] = pot.mu_max
        axle['slip_peak'][k] = pot.slip_peak
        axle['confidence'][k] = pot.confidence
        road[k] = pot.road_class
        vehicle_road[k] = pot.vehicle_road_class()
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
