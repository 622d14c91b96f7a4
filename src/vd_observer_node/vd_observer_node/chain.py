"""The whole per-stamp chain in one object: observers -> estimator -> situation monitor.

What ``pipeline_node`` runs per stamp-matched set of sensor messages (wheel angles, body speed,
wheel torques, or the engine torque and gear on the engine path), ROS-free. It computes exactly
what offline replay computes on the same stamps
(:func:`vd_observer_node.estimation.cascade.run_cascade` followed by
:func:`vd_observer_node.situation.monitor.run_situation`): the wheel and speed observers, the
estimator fed the measured (or the observer's) speed, and the situation monitor fed the sensors and
the cascade's omega, mu and Fz. The torque source (`ChainSettings.torque_source`) is the replay's:
measured wheel torques, the engine path (`drivetrain.EnginePath`; the monitor then gets the
torques it gave the estimator, 0 where it had none) or no torque (0 to the monitor).

Two implementations behind one interface, chosen by `ChainSettings.kernel`:

* ``'python'``: the reference objects (`Observer`, `Estimator`, `SituationMonitor`);
* ``'compiled'``: the numba kernel (:mod:`vd_observer_node.kernel`), tested equal to the
  reference.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Final, NamedTuple, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vd_observer_node.errors import ConfigurationError, InputShapeError
from vd_observer_node.estimation.drivetrain import (
    TORQUE_ENGINE,
    TORQUE_NONE,
    Drivetrain,
    EnginePath,
    torque_source_code,
)
from vd_observer_node.estimation.estimator import Estimates, Estimator, EstimatorConfig
from vd_observer_node.estimation.faults import (
    ENGINE_FAULTS,
    FaultCounter,
    FaultReport,
    merge_reports,
)
from vd_observer_node.estimation.observer import (
    ObserverConfig,
    SpeedObserver,
    SpeedState,
    WheelObserver,
    WheelState,
)
from vd_observer_node.estimation.torque_offset import TorqueOffset
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
    'chain_faults',
    'engine_row',
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
        torque_source: 'measured' (the wheel torques), 'engine' (from the engine torque and
            gear through `drivetrain`) or 'none' (no torque: Fx 0, mu and slope invalid), as
            `cascade.run_cascade` takes it.
        drivetrain: the vehicle's driveline; needed by the engine path only.
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
    torque_source: str = 'measured'
    drivetrain: Drivetrain | None = None

    def __post_init__(self) -> None:
        if self.estimator_speed not in ESTIMATOR_SPEEDS:
            raise ConfigurationError(
                f'estimator_speed must be one of {ESTIMATOR_SPEEDS}, got {self.estimator_speed!r}'
            )
        if self.kernel not in KERNELS:
            raise ConfigurationError(f'kernel must be one of {KERNELS}, got {self.kernel!r}')
        if self.source == TORQUE_ENGINE and self.drivetrain is None:
            raise ConfigurationError('torque_source engine needs a drivetrain')

    @property
    def source(self) -> int:
        """The torque source's code (`drivetrain.TORQUE_SOURCES`).

        Raises:
            ConfigurationError: unknown torque source.
        """
        return torque_source_code(self.torque_source)


def engine_row(engine: ArrayLike | None) -> NDArray[np.float64]:
    """The engine argument of `Chain.update` as a (3,) float64 array.

    Raises:
        InputShapeError: missing (None on the engine path) or not of shape (3,).
    """
    if engine is None:
        raise InputShapeError('the engine path needs engine (torque, gear, engine speed)')
    row = np.ascontiguousarray(engine, dtype=np.float64)
    if row.shape != (3,):
        raise InputShapeError(f'engine must have shape (3,), got {row.shape}')
    return row


class ChainOutput(NamedTuple):
    """Everything computed for one stamp.

    Attributes:
        wheel: wheel observer output (angle, omega, omega_dot, valid; shapes (4,)).
        speed: speed observer output (filtered speed, accel, valid).
        estimates: estimator output for the stamp.
        situation: friction potential and the 12 alert records.
        torque_offset: the engine-torque offset estimate (engine path with
            ``torque_offset_adaptation`` only, else None).
    """

    wheel: WheelState
    speed: SpeedState
    estimates: Estimates
    situation: Situation
    torque_offset: TorqueOffset | None = None


class Chain(Protocol):
    """What `pipeline_node` needs of an implementation."""

    def update(
        self,
        t: float,
        wheel_angle: ArrayLike,
        speed: float,
        wheel_torque: ArrayLike,
        engine: ArrayLike | None = None,
    ) -> ChainOutput:
        """Advance the chain to stamp t [s] with the sensors of that stamp (`engine`: the
        engine path's (3,) engine torque [N m], gear, engine speed [rad/s])."""
        ...

    def fault_report(self) -> FaultReport:
        """Faults since the previous call, per part ('wheel', 'speed', 'estimator', and
        'engine' where the engine path learns the torque offset)."""
        ...


class PythonChain:
    """The reference implementation: the pure-Python objects, fed as replay feeds them."""

    def __init__(self, settings: ChainSettings) -> None:
        """Create the observers, the estimator and the monitor from `settings`."""
        self.settings = settings
        vehicle = settings.vehicle
        self.wheels = WheelObserver(settings.observer)
        self.speed = SpeedObserver(settings.observer)
        self.estimator = Estimator(vehicle, settings.estimator, settings.source)
        est = settings.estimator
        self.engine = (
            EnginePath(
                settings.drivetrain, est.torque_offset if est.torque_offset_adaptation else None
            )
            if settings.drivetrain is not None and settings.source == TORQUE_ENGINE
            else None
        )
        self._none = settings.source == TORQUE_NONE
        # the engine path's own fault (a clamped torque offset), where it learns the offset
        self.engine_faults = (
            FaultCounter(ENGINE_FAULTS)
            if self.engine is not None and self.engine.offset_config is not None
            else None
        )
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
        self,
        t: float,
        wheel_angle: ArrayLike,
        speed: float,
        wheel_torque: ArrayLike,
        engine: ArrayLike | None = None,
    ) -> ChainOutput:
        """Advance to stamp t.

        Args:
            t: stamp [s].
            wheel_angle: shape (4,), [rad] unwrapped, order FL, FR, RL, RR (or speeds
                [rad/s] with ``observer.wheel_input='speed'``).
            speed: measured body speed [m/s].
            wheel_torque: shape (4,), [N m] drive minus brake torque (read on the measured
                path only).
            engine: shape (3,): engine torque [N m], gear, engine speed [rad/s] (nan if not
                measured); read on the engine path only, where it is required.

        Raises:
            InputShapeError: an array input has the wrong shape, or no engine on the engine
                path.
        """
        angles = np.asarray(wheel_angle, dtype=np.float64)
        torques = np.asarray(wheel_torque, dtype=np.float64)
        row = engine_row(engine) if self.engine is not None else None
        if self._none:
            torques = np.zeros(4)  # the replay's: no torque topic, zeros everywhere
        wheel = self.wheels.update(t, angles)
        body = self.speed.update(t, speed)
        torque_ok = True
        if self.engine is not None and row is not None:
            torques, torque_ok = self.engine.update(t, row, wheel.omega, wheel.omega_dot)
        est = self.estimator.update(
            t,
            wheel.omega,
            wheel.omega_dot,
            speed if self._measured else body.speed,
            body.accel,
            torques,
            torque_ok,
        )
        if self.engine is not None:
            # the monitor gets the torques the engine path gave the estimator (0 where it
            # had none: a gear the box lacks), as the replay feeds it
            torques = np.where(np.isfinite(torques), torques, 0.0)
        situation = self.monitor.update(
            t, angles, speed, torques, wheel.omega, est.mu, est.mu_valid, est.fz
        )
        offset = self.engine.offset if self.engine is not None else None
        if offset is not None and offset.clamped and self.engine_faults is not None:
            self.engine_faults.count('torque_offset_clamped')
        return ChainOutput(wheel, body, est, situation, offset)

    def fault_report(self) -> FaultReport:
        """Faults since the previous call, per part ('wheel', 'speed', 'estimator', and
        'engine' where the engine path learns the torque offset)."""
        return chain_faults(
            self.wheels.faults, self.speed.faults, self.estimator.faults, self.engine_faults
        )


def chain_faults(
    wheel: FaultCounter,
    speed: FaultCounter,
    estimator: FaultCounter,
    engine: FaultCounter | None,
) -> FaultReport:
    """The chain's fault report from its parts' counters (both implementations)."""
    parts = {'wheel': wheel.report(), 'speed': speed.report(), 'estimator': estimator.report()}
    if engine is not None:
        parts['engine'] = engine.report()
    return merge_reports(parts)


def make_chain(settings: ChainSettings) -> Chain:
    """The implementation `settings.kernel` names."""
    if settings.kernel == 'python':
        return PythonChain(settings)
    from vd_observer_node.kernel.chain import CompiledChain

    chain: Chain = CompiledChain(settings)
    return chain
