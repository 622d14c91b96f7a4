"""Whole observer + estimator cascade on arrays (offline; replay, report, tests).

`run_cascade` feeds the same online objects the ROS nodes use, sample by sample, so the
offline figures are those the nodes would produce on the same stamps.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vd_observer_node.errors import ConfigurationError, InputShapeError
from vd_observer_node.estimation.drivetrain import (
    TORQUE_ENGINE,
    TORQUE_MEASURED,
    Drivetrain,
    EnginePath,
    torque_source_code,
)
from vd_observer_node.estimation.estimator import Estimator, EstimatorConfig
from vd_observer_node.estimation.observer import Observer, ObserverConfig
from vd_observer_node.estimation.torque_offset import TorqueOffset
from vd_observer_node.estimation.vehicle import EstimatorVehicle

__all__ = [
    'CascadeResult',
    'CascadeState',
    'OffsetRecord',
    'checked_engine',
    'checked_record',
    'offset_result_name',
    'run_cascade',
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class CascadeResult:
    """Estimates over a whole record (N stamps; per-wheel arrays (N, 4), FL, FR, RL, RR).

    Attributes:
        t: shape (N,), [s].
        omega: shape (N, 4), [rad/s].
        omega_dot: shape (N, 4), [rad/s^2].
        speed: shape (N,), [m/s] observer-filtered speed.
        accel: shape (N,), [m/s^2].
        fx: shape (N, 4), [N].
        fz: shape (N, 4), [N].
        mu: shape (N, 4), [-] (0 where invalid).
        mu_valid: shape (N, 4), bool.
        slip: shape (N, 4), [-].
        rolling: shape (N, 4), [N].
        aero: shape (N,), [N].
        slope: shape (N,), [rad].
        slope_valid: shape (N,), bool.
        wheel_valid: shape (N, 4), bool, observer validity per wheel.
        torque_valid: shape (N,), bool, the torque source held at the stamp (False where
            the engine path's clutch slipped, and everywhere with no torque).
        torque_source: `drivetrain.TORQUE_MEASURED`, `TORQUE_ENGINE` or `TORQUE_NONE`.
        angle: shape (N, 4), [rad], the wheel observer's angle (filtered; with wheel speeds
            as input, their integral from 0 at the observer's start).
        faults: total fault counts per kind, keys 'wheel.<kind>', 'speed.<kind>' (observers)
            and 'estimator.<kind>', as the nodes report them on /diagnostics.
        mass: shape (N,), [kg] online mass estimate (`Estimates.mass`; the file's mass
            without adaptation).
        mass_std: shape (N,), [kg] its standard deviation.
        mass_converged: shape (N,), bool, the estimate is trusted and used.
        mass_used: shape (N,), [kg] the mass the stamp's Fz, mu, rolling and slope used.
        mass_excited: shape (N,), bool, the stamp updated the mass.
        radius: shape (N,), [m] online rolling radius (`Estimates.radius`; the file's
            without adaptation).
        radius_std: shape (N,), [m] its standard deviation.
        radius_converged: shape (N,), bool, the radius is trusted and used.
        radius_used: shape (N,), [m] the radius the stamp's Fx and slip used.
        radius_free_wheels: shape (N,), int, wheels that updated the radius (0: none).
        torque_offset: shape (N,), [N m] estimated offset of the engine-torque signal
            (`torque_offset.TorqueOffset.offset`; empty unless the engine path runs with
            ``torque_offset_adaptation``).
        torque_offset_std: shape (N,), [N m] its standard deviation.
        torque_offset_converged: shape (N,), bool, the offset is trusted and used.
        torque_offset_used: shape (N,), [N m] what the engine path subtracted from the signal.
        torque_offset_episodes: shape (N,), int, neutral episodes used so far.
        torque_offset_clamped: shape (N,), bool, the offset is at its bound.
    """

    t: FloatArray
    omega: FloatArray
    omega_dot: FloatArray
    speed: FloatArray
    accel: FloatArray
    fx: FloatArray
    fz: FloatArray
    mu: FloatArray
    mu_valid: BoolArray
    slip: FloatArray
    rolling: FloatArray
    aero: FloatArray
    slope: FloatArray
    slope_valid: BoolArray
    wheel_valid: BoolArray
    torque_valid: BoolArray = field(default_factory=lambda: np.ones(0, dtype=bool))
    angle: FloatArray = field(default_factory=lambda: np.zeros((0, 4)))
    torque_source: int = TORQUE_MEASURED
    faults: dict[str, int] = field(default_factory=dict)
    mass: FloatArray = field(default_factory=lambda: np.zeros(0))
    mass_std: FloatArray = field(default_factory=lambda: np.zeros(0))
    mass_converged: BoolArray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    mass_used: FloatArray = field(default_factory=lambda: np.zeros(0))
    mass_excited: BoolArray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    radius: FloatArray = field(default_factory=lambda: np.zeros(0))
    radius_std: FloatArray = field(default_factory=lambda: np.zeros(0))
    radius_converged: BoolArray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    radius_used: FloatArray = field(default_factory=lambda: np.zeros(0))
    radius_free_wheels: NDArray[np.int64] = field(
        default_factory=lambda: np.zeros(0, dtype=np.int64)
    )
    torque_offset: FloatArray = field(default_factory=lambda: np.zeros(0))
    torque_offset_std: FloatArray = field(default_factory=lambda: np.zeros(0))
    torque_offset_converged: BoolArray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    torque_offset_used: FloatArray = field(default_factory=lambda: np.zeros(0))
    torque_offset_episodes: NDArray[np.int64] = field(
        default_factory=lambda: np.zeros(0, dtype=np.int64)
    )
    torque_offset_clamped: BoolArray = field(default_factory=lambda: np.zeros(0, dtype=bool))


@dataclass
class CascadeState:
    """What one call of a cascade function hands to the next, so a record can be run in blocks.

    Pass a fresh state to the first call of `run_cascade` (or
    :func:`vd_observer_node.kernel.chain.run_cascade_compiled`) and the same one to the calls
    on the following blocks: the first call stores its observers, estimator and torque path
    here and the later ones go on from them, so the blocks give what one call on the whole
    record gives (tested). The settings of the first call hold for the later ones; a state
    belongs to one function (kernel) and one record.

    Attributes:
        parts: the function's state objects (None before the first call).
    """

    parts: tuple[Any, ...] | None = None


@dataclass(frozen=True)
class OffsetRecord:
    """The engine-torque offset estimates of a record, as `CascadeResult` carries them.

    Attributes:
        offset: shape (N,), [N m].
        std: shape (N,), [N m].
        converged: shape (N,), bool.
        used: shape (N,), [N m].
        episodes: shape (N,), int.
        clamped: shape (N,), bool.
    """

    offset: FloatArray
    std: FloatArray
    converged: BoolArray
    used: FloatArray
    episodes: NDArray[np.int64]
    clamped: BoolArray

    @classmethod
    def empty(cls, n: int) -> OffsetRecord:
        """N stamps of zeros (0: the offset is not learnt)."""
        return cls(
            np.zeros(n), np.zeros(n), np.zeros(n, dtype=bool), np.zeros(n),
            np.zeros(n, dtype=np.int64), np.zeros(n, dtype=bool),
        )  # fmt: skip

    def store(self, k: int, estimate: TorqueOffset) -> None:
        """Write stamp k's estimate (its attributes are this record's arrays)."""
        for name in TorqueOffset._fields:
            getattr(self, name)[k] = getattr(estimate, name)

    def fields(self) -> dict[str, Any]:
        """The `CascadeResult` fields (``torque_offset*``)."""
        return {offset_result_name(name): getattr(self, name) for name in TorqueOffset._fields}


def offset_result_name(attribute: str) -> str:
    """The `CascadeResult` field of a `TorqueOffset` attribute ('std' -> 'torque_offset_std',
    'offset' -> 'torque_offset')."""
    return 'torque_offset' if attribute == 'offset' else f'torque_offset_{attribute}'


def checked_record(
    t: ArrayLike,
    wheel_angle: ArrayLike,
    body_speed: ArrayLike,
    wheel_torque: ArrayLike,
    estimator_speed: str,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """The arguments of `run_cascade` as contiguous float64 arrays, checked.

    Raises:
        InputShapeError: inconsistent shapes.
        ConfigurationError: unknown estimator_speed.
    """
    if estimator_speed not in ('measured', 'observer'):
        raise ConfigurationError(
            f'estimator_speed must be measured or observer: {estimator_speed}'
        )
    stamps = np.ascontiguousarray(t, dtype=np.float64)
    angles = np.ascontiguousarray(wheel_angle, dtype=np.float64)
    speeds = np.ascontiguousarray(body_speed, dtype=np.float64)
    torques = np.ascontiguousarray(wheel_torque, dtype=np.float64)
    n = stamps.shape[0] if stamps.ndim == 1 else -1
    if angles.shape != (n, 4) or speeds.shape != (n,) or torques.shape != (n, 4):
        raise InputShapeError(
            f'expected t (N,), wheel_angle (N, 4), body_speed (N,), wheel_torque (N, 4); got '
            f'{stamps.shape}, {angles.shape}, {speeds.shape}, {torques.shape}'
        )
    return stamps, angles, speeds, torques


def checked_engine(
    n: int, torque_source: str, engine: ArrayLike | None, drivetrain: Drivetrain | None
) -> tuple[int, FloatArray]:
    """The torque source's code and the engine record (N, 3), checked.

    Raises:
        ConfigurationError: unknown source, or the engine path without engine or drivetrain.
        InputShapeError: engine is not of shape (N, 3).
    """
    code = torque_source_code(torque_source)
    if code != TORQUE_ENGINE:
        return code, np.zeros((n, 3))
    if engine is None or drivetrain is None:
        raise ConfigurationError('torque_source engine needs the engine record and a drivetrain')
    record = np.ascontiguousarray(engine, dtype=np.float64)
    if record.shape != (n, 3):
        raise InputShapeError(
            f'engine must have shape ({n}, 3) (engine torque, gear, engine speed), '
            f'got {record.shape}'
        )
    return code, record


def run_cascade(
    t: ArrayLike,
    wheel_angle: ArrayLike,
    body_speed: ArrayLike,
    wheel_torque: ArrayLike,
    vehicle: EstimatorVehicle,
    observer_config: ObserverConfig | None = None,
    estimator_config: EstimatorConfig | None = None,
    estimator_speed: str = 'measured',
    *,
    torque_source: str = 'measured',
    engine: ArrayLike | None = None,
    drivetrain: Drivetrain | None = None,
    state: CascadeState | None = None,
) -> CascadeResult:
    """Run observers and estimator over a record sampled at common stamps.

    Args:
        t: shape (N,), [s] stamps (rejected samples keep the previous estimates).
        wheel_angle: shape (N, 4), [rad] unwrapped wheel angles, or wheel speeds [rad/s]
            when ``observer_config.wheel_input`` is 'speed'.
        body_speed: shape (N,), [m/s] measured body speed.
        wheel_torque: shape (N, 4), [N m] drive minus brake torque.
        vehicle: estimator parameters.
        observer_config: observer settings (defaults if None).
        estimator_config: estimator settings (defaults if None).
        estimator_speed: 'measured' feeds the estimator the measured body speed (its slope
            low-pass does the smoothing, no observer lag), 'observer' the observer's
            filtered speed.
        torque_source: 'measured' (wheel_torque), 'engine' (wheel torques from `engine`
            with `drivetrain.engine_wheel_torques`, using the wheel observer's omega_dot for
            the engine-inertia term; invalid where `drivetrain.clutch_engaged` is False and
            for `Drivetrain.clutch_settle_time` after it was, or after a gear change) or
            'none' (wheel_torque ignored; Fx 0, mu and slope invalid).
        engine: shape (N, 3): engine torque [N m], gear (0 neutral, -1 reverse), engine speed
            [rad/s] (nan if not measured); needed by the engine path only.
        drivetrain: the vehicle's driveline; needed by the engine path only.
        state: carried from the previous block of the record (`CascadeState`); None: the
            record is whole. ``faults`` are then the totals since the first block.

    Raises:
        InputShapeError: inconsistent shapes.
        ConfigurationError: unknown estimator_speed or torque_source, or the engine path
            without engine or drivetrain.
    """
    stamps, angles, speeds, torques = checked_record(
        t, wheel_angle, body_speed, wheel_torque, estimator_speed
    )
    n = stamps.shape[0]
    source, engine_record = checked_engine(n, torque_source, engine, drivetrain)
    wheel4 = np.zeros((n, 4))
    out = {
        k: wheel4.copy()
        for k in ('angle', 'omega', 'omega_dot', 'fx', 'fz', 'mu', 'slip', 'rolling')
    }
    scalars = {
        k: np.zeros(n)
        for k in (
            'speed', 'accel', 'aero', 'slope', 'mass', 'mass_std', 'mass_used', 'radius',
            'radius_std', 'radius_used',
        )
    }  # fmt: skip
    flags = {
        k: np.zeros(n, dtype=bool) for k in ('mass_converged', 'mass_excited', 'radius_converged')
    }
    free_wheels = np.zeros(n, dtype=np.int64)
    mu_valid = np.zeros((n, 4), dtype=bool)
    wheel_valid = np.zeros((n, 4), dtype=bool)
    slope_valid = np.zeros(n, dtype=bool)
    # every array but the observer's holds the `Estimates` field of its name, stamp by stamp
    kept = {
        k: a
        for part in (out, scalars, flags)
        for k, a in part.items()
        if k not in ('angle', 'omega', 'omega_dot', 'speed', 'accel')
    }
    kept.update(mu_valid=mu_valid, slope_valid=slope_valid, radius_free_wheels=free_wheels)
    torque_valid = np.full(n, source != torque_source_code('none'))
    if state is not None and state.parts is not None:
        observer, estimator, engine_path = state.parts
    else:
        observer = Observer(observer_config or ObserverConfig())
        estimator = Estimator(vehicle, estimator_config, source)
        config = estimator_config or EstimatorConfig()
        engine_path = (
            EnginePath(
                drivetrain, config.torque_offset if config.torque_offset_adaptation else None
            )
            if drivetrain is not None and source == TORQUE_ENGINE
            else None
        )
        if state is not None:
            state.parts = (observer, estimator, engine_path)
    use_measured = estimator_speed == 'measured'
    learns = engine_path is not None and engine_path.offset_config is not None
    offset = OffsetRecord.empty(n if learns else 0)
    for k in range(n):
        tk = float(stamps[k])
        wheel = observer.wheels.update(tk, angles[k])
        body = observer.speed.update(tk, float(speeds[k]))
        speed = float(speeds[k]) if use_measured else body.speed
        torque, torque_ok = torques[k], True
        if engine_path is not None:
            torque, torque_ok = engine_path.update(
                tk, engine_record[k], wheel.omega, wheel.omega_dot
            )
            torque_valid[k] = torque_ok
            if engine_path.offset is not None:
                offset.store(k, engine_path.offset)
        est = estimator.update(
            tk, wheel.omega, wheel.omega_dot, speed, body.accel, torque, torque_ok
        )
        out['angle'][k] = wheel.angle
        out['omega'][k] = wheel.omega
        out['omega_dot'][k] = wheel.omega_dot
        wheel_valid[k] = wheel.valid
        scalars['speed'][k] = body.speed
        scalars['accel'][k] = body.accel
        for name, array in kept.items():
            array[k] = getattr(est, name)
    return CascadeResult(
        t=stamps.copy(),
        omega=out['omega'],
        omega_dot=out['omega_dot'],
        speed=scalars['speed'],
        accel=scalars['accel'],
        fx=out['fx'],
        fz=out['fz'],
        mu=out['mu'],
        mu_valid=mu_valid,
        slip=out['slip'],
        rolling=out['rolling'],
        aero=scalars['aero'],
        slope=scalars['slope'],
        slope_valid=slope_valid,
        wheel_valid=wheel_valid,
        torque_valid=torque_valid,
        torque_source=source,
        angle=out['angle'],
        faults={
            f'{part}.{kind}': n
            for part, counter in (
                ('wheel', observer.wheels.faults),
                ('speed', observer.speed.faults),
                ('estimator', estimator.faults),
            )
            for kind, n in counter.counts.items()
        }
        | (
            {'engine.torque_offset_clamped': int(engine_path.state.offset.clamped)}
            if learns and engine_path is not None
            else {}
        ),
        mass=scalars['mass'],
        mass_std=scalars['mass_std'],
        mass_converged=flags['mass_converged'],
        mass_used=scalars['mass_used'],
        mass_excited=flags['mass_excited'],
        radius=scalars['radius'],
        radius_std=scalars['radius_std'],
        radius_converged=flags['radius_converged'],
        radius_used=scalars['radius_used'],
        radius_free_wheels=free_wheels,
        **offset.fields(),
    )
