"""The whole per-stamp chain in one object: observers -> estimator -> situation monitor.

What ``pipeline_node`` runs per stamp-matched set of sensor messages (wheel angles, body speed,
wheel torques), ROS-free. It computes exactly what offline replay computes on the same stamps
(:func:`vd_observer_node.estimation.cascade.run_cascade` followed by
:func:`vd_observer_node.situation.monitor.run_situation`): the wheel and speed observers, the
estimator fed the measured (or the observer's) speed, and the situation monitor fed the sensors and
the cascade's omega, mu and Fz.

Two implementations behind one interface, chosen by `ChainSettings.kernel`:

* ``'python'``: the reference objects (`Observer`, `Estimator`, `SituationMonitor`);
* ``'compiled'``: the numba kernel (:mod:`vd_observer_node.kernel`), tested equal to the
  reference.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Final, NamedTuple, Protocol

import numpy as np
from numpy.typing import ArrayLike

from vd_observer_node.errors import ConfigurationError
from vd_observer_node.estimation.estimator import Estimates, Estimator, EstimatorConfig
from vd_observer_node.estimation.faults import FaultReport, merge_reports
from vd_observer_node.estimation.observer import (
    ObserverConfig,
    SpeedObserver,
    SpeedState,
    WheelObserver,
    WheelState,
)
from vd_observer_node.estimation.vehicle import EstimatorVehicle
from vd_observer_node.situation.alerts import AlertConfig
from vd_observer_node.situation.friction_potential import FrictionPotentialConfig, TyreCurves
from vd_observer_node.situation.monitor import Situation, SituationConfig, SituationMonitor

__all__ = [
    'ESTIMATOR_SPEEDS',
    'KERNELS',
    'Chain',
    'ChainOutput',
    'ChainSettings',
    'PythonChain',
    'make_chain',
]

#: Implementations of the per-stamp math: the compiled kernel, or the Python reference.
KERNELS: Final = ('compiled', 'python')
#: Speed fed to the estimator: the measured body speed, or the observer's filtered one.
ESTIMATOR_SPEEDS: Final = ('measured', 'observer')


@dataclass(frozen=True)
class ChainSettings:
    """Everything the chain needs.

    Attributes:
        vehicle: estimator vehicle parameters.
        curves: the tyre's curves (friction potential).
        observer: observer settings (the situation monitor's fast observer shares all but L).
        estimator: estimator settings.
        alerts: alert settings.
        friction: friction-potential settings.
        situation: fast-observer and gate settings of the monitor.
        estimator_speed: one of `ESTIMATOR_SPEEDS`.
        kernel: one of `KERNELS`.
    """

    vehicle: EstimatorVehicle
    curves: TyreCurves
    observer: ObserverConfig = field(default_factory=ObserverConfig)
    estimator: EstimatorConfig = field(default_factory=EstimatorConfig)
    alerts: AlertConfig = field(default_factory=AlertConfig)
    friction: FrictionPotentialConfig = field(default_factory=FrictionPotentialConfig)
    situation: SituationConfig = field(default_factory=SituationConfig)
    estimator_speed: str = 'measured'
    kernel: str = 'compiled'

    def __post_init__(self) -> None:
        if self.estimator_speed not in ESTIMATOR_SPEEDS:
            raise ConfigurationError(
                f'estimator_speed must be one of {ESTIMATOR_SPEEDS}, got {self.estimator_speed!r}'
            )
        if self.kernel not in KERNELS:
            raise ConfigurationError(f'kernel must be one of {KERNELS}, got {self.kernel!r}')


class ChainOutput(NamedTuple):
    """Everything computed for one stamp.

    Attributes:
        wheel: wheel observer output (angle, omega, omega_dot, valid; shapes (4,)).
        speed: speed observer output (filtered speed, accel, valid).
        estimates: estimator output for the stamp.
        situation: friction potential and the 12 alert records.
    """

    wheel: WheelState
    speed: SpeedState
    estimates: Estimates
    situation: Situation


class Chain(Protocol):
    """What `pipeline_node` needs of an implementation."""

    def update(
        self, t: float, wheel_angle: ArrayLike, speed: float, wheel_torque: ArrayLike
    ) -> ChainOutput:
        """Advance the chain to stamp t [s] with the sensors of that stamp."""
        ...

    def fault_report(self) -> FaultReport:
        """Faults since the previous call, per part ('wheel', 'speed', 'estimator')."""
        ...


class PythonChain:
    """The reference implementation: the pure-Python objects, fed as replay feeds them."""

    def __init__(self, settings: ChainSettings) -> None:
        """Create the observers, the estimator and the monitor from `settings`."""
        self.settings = settings
        vehicle = settings.vehicle
        self.wheels = WheelObserver(settings.observer)
        self.speed = SpeedObserver(settings.observer)
        self.estimator = Estimator(vehicle, settings.estimator)
        self.monitor = SituationMonitor(
            settings.curves,
            vehicle.static_wheel_loads[[0, 2]],
            vehicle.effective_radius,
            observer=settings.observer,
            alerts=settings.alerts,
            friction=settings.friction,
            situation=settings.situation,
        )
        self._measured = settings.estimator_speed == 'measured'

    def update(
        self, t: float, wheel_angle: ArrayLike, speed: float, wheel_torque: ArrayLike
    ) -> ChainOutput:
        """Advance to stamp t.

        Args:
            t: stamp [s].
            wheel_angle: shape (4,), [rad] unwrapped, order FL, FR, RL, RR (or speeds
                [rad/s] with ``observer.wheel_input='speed'``).
            speed: measured body speed [m/s].
            wheel_torque: shape (4,), [N m] drive minus brake torque.

        Raises:
            InputShapeError: an array input has the wrong shape.
        """
        angles = np.asarray(wheel_angle, dtype=np.float64)
        torques = np.asarray(wheel_torque, dtype=np.float64)
        wheel = self.wheels.update(t, angles)
        body = self.speed.update(t, speed)
        est = self.estimator.update(
            t,
            wheel.omega,
            wheel.omega_dot,
            speed if self._measured else body.speed,
            body.accel,
            torques,
        )
        situation = self.monitor.update(
            t, angles, speed, torques, wheel.omega, est.mu, est.mu_valid, est.fz
        )
        return ChainOutput(wheel, body, est, situation)

    def fault_report(self) -> FaultReport:
        """Faults since the previous call, per part ('wheel', 'speed', 'estimator')."""
        return merge_reports(
            {
                'wheel': self.wheels.faults.report(),
                'speed': self.speed.faults.report(),
                'estimator': self.estimator.faults.report(),
            }
        )


def make_chain(settings: ChainSettings) -> Chain:
    """The implementation `settings.kernel` names."""
    if settings.kernel == 'python':
        return PythonChain(settings)
    from vd_observer_node.kernel.chain import CompiledChain

    chain: Chain = CompiledChain(settings)
    return chain
