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

from vd_observer_node.alerts import Alert, AlertConfig, AlertMonitor, slip_velocity
from vd_observer_node.errors import ConfigurationError
from vd_observer_node.friction_potential import (
    FrictionPotential,
    FrictionPotentialConfig,
    FrictionPotentialEstimator,
    TyreCurves,
)
from vd_observer_node.observer import ObserverConfig, WheelObserver

__all__ = ['Situation', 'SituationConfig', 'SituationMonitor', 'floored_slip']

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
    """

    alert_wheel_lipschitz: float = 3000.0
    slip_floor_speed: float = 1.0

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not (math.isfinite(value) and value > 0.0):
                raise ConfigurationError(f'{f.name} must be finite and > 0, got {value}')

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


def floored_slip(slip_vel: ArrayLike, speed: float, floor: float) -> FloatArray:
    """Slip ratio with a floored denominator, as the tyre model defines it.

    Args:
        slip_vel: shape (4,), [m/s] omega R - v.
        speed: body speed v [m/s].
        floor: [m/s] denominator floor (> 0).

    Returns:
        shape (4,), [-] (omega R - v) / max(|omega R|, |v|, floor), positive driving.
    """
    sv = np.asarray(slip_vel, dtype=float)
    den = np.maximum(np.maximum(np.abs(sv + speed), abs(speed)), floor)
    out: FloatArray = sv / den
    return out


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
            wheel_angle: shape (4,), [rad] unwrapped wheel angles (sensor).
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
        v = float(speed) if math.isfinite(speed) else math.nan
        sv_fast = np.where(fast.valid, slip_velocity(fast.omega, v, self.radius), 0.0)
        slip = floored_slip(sv_fast, v, self.config.slip_floor_speed)
        potential = self.friction.update(
            t, slip_velocity(omega, v, self.radius), v, mu, mu_valid, load
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
