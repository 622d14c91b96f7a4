"""The observer + estimator cascade over a record of stamps (replay, fleet, report, tests).

`run_cascade` runs `cascade_step.cascade_block`, the one loop of the cascade, on the parts'
records (`CascadeParts`): the same step functions the live pipeline node runs one stamp at a
time, so the offline figures are those the nodes produce on the same stamps. A record can be
run in blocks with a carried `CascadeState` (what the streamed replay does).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any, Final

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vd_observer_node.errors import ConfigurationError, InputShapeError
from vd_observer_node.estimation.brakes import Brakes, no_brakes
from vd_observer_node.estimation.cascade_step import (
    CASCADE_SWITCHES,
    ENGINE_SAMPLE,
    ENGINE_STATE,
    HELD_INPUTS,
    CascadeInputs,
    CascadeOutputs,
    CascadeRecords,
    EnginePathParts,
    ImuParts,
    cascade_block,
)
from vd_observer_node.estimation.differentiator import LevantDifferentiator
from vd_observer_node.estimation.drivetrain import (
    DRIVETRAIN_PARAMS,
    TORQUE_ENGINE,
    TORQUE_MEASURED,
    TORQUE_NONE,
    Drivetrain,
    torque_source_code,
)
from vd_observer_node.estimation.estimator import Estimator, EstimatorConfig
from vd_observer_node.estimation.estimator_step import (
    ESTIMATES,
    SPEED_SAMPLES_MAX,
    new_estimator_input,
)
from vd_observer_node.estimation.faults import ENGINE_FAULTS, FaultCounter
from vd_observer_node.estimation.imu_grade import GRADE_INPUT, GRADE_OUT, SOURCE_FORCE, ImuGrade
from vd_observer_node.estimation.imu_settings import ImuGradeConfig
from vd_observer_node.estimation.observer import WHEEL_INPUTS, ObserverConfig
from vd_observer_node.estimation.torque_offset import (
    OFFSET_ESTIMATE_DTYPE,
    TorqueOffset,
    new_offset_estimate,
    new_offset_state,
    offset_params,
)
from vd_observer_node.estimation.vehicle import EstimatorVehicle
from vd_observer_node.kernel._jit import new_records, record_array

__all__ = [
    'ESTIMATOR_SPEEDS',
    'CascadeParts',
    'CascadeResult',
    'CascadeSeries',
    'CascadeSettings',
    'CascadeState',
    'OffsetRecord',
    'cascade_result',
    'checked_brake',
    'checked_engine',
    'checked_record',
    'checked_speed_samples',
    'empty_outputs',
    'held_records',
    'input_records',
    'offset_result_name',
    'run_cascade',
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: Speed fed to the estimator: the measured body speed, or the observer's filtered one.
ESTIMATOR_SPEEDS: Final = ('measured', 'observer')


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
        wheel_torque_used: shape (N, 4), [N m] the wheel torques the estimator got (the
            measured ones, the engine path's (nan where it had none), or zeros without
            torque).
        slope_sources: shape (N,), uint8: what the slope used, `imu_grade.SOURCE_FORCE`
            | `imu_grade.SOURCE_IMU` (0: nothing valid).
        slope_force: shape (N,), [rad] the force balance's own slope (= slope without IMU).
        slope_imu: shape (N,), [rad] the IMU's bias-corrected grade (nan where it has none;
            empty without IMU).
        imu_bias: shape (N,), [m/s^2] the learnt bias of the IMU's specific force (empty
            without IMU).
        imu_mass: shape (N,), [kg] the mass the IMU regression found (`imu_grade`; empty
            without IMU); imu_mass_std its standard deviation.
        imu_fitted: shape (N,), bool, the regression's mass has converged.
        imu_trusted: shape (N,), bool, its bias has converged: the slope is the IMU's.
        imu_gyro: shape (N,), bool, the IMU's grade used its angular rate (`gyro_grade`).
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
    wheel_torque_used: FloatArray = field(default_factory=lambda: np.zeros((0, 4)))
    slope_sources: NDArray[np.uint8] = field(default_factory=lambda: np.zeros(0, dtype=np.uint8))
    slope_force: FloatArray = field(default_factory=lambda: np.zeros(0))
    slope_imu: FloatArray = field(default_factory=lambda: np.zeros(0))
    imu_bias: FloatArray = field(default_factory=lambda: np.zeros(0))
    imu_mass: FloatArray = field(default_factory=lambda: np.zeros(0))
    imu_mass_std: FloatArray = field(default_factory=lambda: np.zeros(0))
    imu_fitted: BoolArray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    imu_trusted: BoolArray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    imu_gyro: BoolArray = field(default_factory=lambda: np.zeros(0, dtype=bool))


@dataclass(frozen=True)
class CascadeSettings:
    """Everything the cascade (observers, estimator, torque path, IMU fusion) is set with.

    `situation.chain_settings.ChainSettings` extends it with the situation monitor's; both
    are built from node parameters, a settings file or the CLI by
    `situation.chain_settings.chain_settings`.

    Attributes:
        vehicle: estimator vehicle parameters.
        observer: observer settings.
        estimator: estimator settings.
        estimator_speed: one of `ESTIMATOR_SPEEDS`: 'measured' feeds the estimator the
            measured body speed (its slope low-pass does the smoothing, no observer lag),
            'observer' the observer's filtered speed.
        torque_source: 'measured' (the wheel torques), 'engine' (wheel torques from the
            engine torque and gear through `drivetrain` (`drivetrain.engine_torques`), using
            the wheel observer's omega_dot for the engine-inertia term; invalid where the
            clutch is not engaged and for `Drivetrain.clutch_settle_time` after it was, or
            after a gear change) or 'none' (no torque: Fx 0, mu and slope invalid).
        drivetrain: the vehicle's driveline; needed by the engine path only.
        imu: the IMU fusion's settings (`imu_grade`); None: its defaults where a record has
            an IMU, and without one the force balance's slope as it is.
        brakes: the brake input's kind and gains (`brakes.Brakes`); None: none.
    """

    vehicle: EstimatorVehicle
    observer: ObserverConfig = field(default_factory=ObserverConfig)
    estimator: EstimatorConfig = field(default_factory=EstimatorConfig)
    estimator_speed: str = 'measured'
    torque_source: str = 'measured'
    drivetrain: Drivetrain | None = None
    imu: ImuGradeConfig | None = None
    brakes: Brakes | None = None

    def __post_init__(self) -> None:
        if self.estimator_speed not in ESTIMATOR_SPEEDS:
            raise ConfigurationError(
                f'estimator_speed must be one of {ESTIMATOR_SPEEDS}, got {self.estimator_speed!r}'
            )
        if self.source == TORQUE_ENGINE and self.drivetrain is None:
            raise ConfigurationError('torque_source engine needs a drivetrain')

    @property
    def source(self) -> int:
        """The torque source's code (`drivetrain.TORQUE_SOURCES`).

        Raises:
            ConfigurationError: unknown torque source.
        """
        return torque_source_code(self.torque_source)


@dataclass(frozen=True)
class CascadeSeries:
    """A record of the cascade's inputs at common stamps (N stamps; order FL, FR, RL, RR).

    Attributes:
        t: shape (N,), [s] stamps (rejected samples keep the previous estimates).
        wheel_angle: shape (N, 4), [rad] unwrapped wheel angles, or wheel speeds [rad/s]
            when the observer's ``wheel_input`` is 'speed'.
        body_speed: shape (N,), [m/s] measured body speed.
        wheel_torque: shape (N, 4), [N m] drive minus brake torque (ignored unless the torque
            source is 'measured').
        engine: shape (N, 3) or (N, 4): engine torque [N m], gear (0 neutral, -1 reverse),
            engine speed [rad/s] (nan if not measured), turbine speed [rad/s] (an automatic
            gearbox's; nan or absent if not logged); needed by the engine path only.
        brake: shape (N, 4): the brake input per wheel (`brakes.brake_torques`: pressures,
            or the switch on every wheel; nan where unknown); None: no brake input.
        imu: shape (N, 3) or (N, 2): stamp [s] of the newest IMU sample at each stamp (nan:
            none), its longitudinal specific force in body axes [m/s^2] and the body's pitch
            rate [rad/s] (REP 103, nose down positive; nan or absent: no angular rate); the
            slope is then the fusion of `imu_grade` (None: the force balance's slope, as
            without an IMU).
        speed_samples: the body-speed samples each stamp feeds the speed observer at their
            own stamps (`alignment.samples_between`): their stamps [s] and values [m/s],
            shape (N, K) each, K <= `estimator_step.SPEED_SAMPLES_MAX`, oldest first, nan after
            the last; None: each stamp's ``body_speed`` at the stamp.
        held: the held inputs by name (`cascade_step.HELD_INPUTS`; ``imu`` above is one of
            them), each shape (N, C): the newest sample's stamp [s] at each stamp (nan: none)
            and its first C - 1 fields (the record's fields after them nan).
    """

    t: ArrayLike
    wheel_angle: ArrayLike
    body_speed: ArrayLike
    wheel_torque: ArrayLike
    engine: ArrayLike | None = None
    brake: ArrayLike | None = None
    imu: ArrayLike | None = None
    speed_samples: tuple[ArrayLike, ArrayLike] | None = None
    held: Mapping[str, ArrayLike] | None = None


@dataclass
class CascadeState:
    """What one call of a cascade function hands to the next, so a record can be run in blocks.

    Pass a fresh state to the first call of `run_cascade` and the same one to the calls on
    the following blocks: the first call stores its parts here and the later ones go on from
    them, so the blocks give what one call on the whole record gives (tested). The settings
    of the first call hold for the later ones; a state belongs to one record.

    Attributes:
        parts: the cascade's parts (None before the first call).
    """

    parts: CascadeParts | None = None


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

    def fields(self) -> dict[str, Any]:
        """The `CascadeResult` fields (``torque_offset*``)."""
        return {offset_result_name(name): getattr(self, name) for name in TorqueOffset._fields}


def offset_result_name(attribute: str) -> str:
    """The `CascadeResult` field of a `TorqueOffset` attribute ('std' -> 'torque_offset_std',
    'offset' -> 'torque_offset')."""
    return 'torque_offset' if attribute == 'offset' else f'torque_offset_{attribute}'


def checked_record(
    series: CascadeSeries,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """The stamps, wheel angles, body speeds and wheel torques of a record as contiguous
    float64 arrays, checked.

    Raises:
        InputShapeError: inconsistent shapes.
    """
    stamps = np.ascontiguousarray(series.t, dtype=np.float64)
    angles = np.ascontiguousarray(series.wheel_angle, dtype=np.float64)
    speeds = np.ascontiguousarray(series.body_speed, dtype=np.float64)
    torques = np.ascontiguousarray(series.wheel_torque, dtype=np.float64)
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
    """The torque source's code and the engine record (N, 4), checked.

    Args:
        engine: shape (N, 3) or (N, 4): engine torque, gear, engine speed and (if logged)
            turbine speed; a record of 3 columns gets a turbine speed of nan.

    Raises:
        ConfigurationError: unknown source, or the engine path without engine or drivetrain.
        InputShapeError: engine is not of shape (N, 3) or (N, 4).
    """
    code = torque_source_code(torque_source)
    if code != TORQUE_ENGINE:
        return code, np.zeros((n, 4))
    if engine is None or drivetrain is None:
        raise ConfigurationError('torque_source engine needs the engine record and a drivetrain')
    record = np.ascontiguousarray(engine, dtype=np.float64)
    if record.ndim == 2 and record.shape == (n, 3):
        record = np.concatenate([record, np.full((n, 1), np.nan)], axis=1)
    if record.shape != (n, 4):
        raise InputShapeError(
            f'engine must have shape ({n}, 3) or ({n}, 4) (engine torque, gear, engine speed, '
            f'turbine speed), got {record.shape}'
        )
    return code, record


def checked_speed_samples(
    stamps: FloatArray,
    speeds: FloatArray,
    given: tuple[ArrayLike, ArrayLike] | None,
    width: int | None = None,
) -> tuple[FloatArray, FloatArray]:
    """The speed samples per stamp (`CascadeInputs.speed_stamp`, ``speed_sample``).

    Args:
        stamps: shape (N,), [s] the stamps.
        speeds: shape (N,), [m/s] the body speed at each (used where `given` is None).
        given: `CascadeSeries.speed_samples`.
        width: the arrays' columns (the live chain's buffer: `SPEED_SAMPLES_MAX`); None:
            those given (1 without).

    Raises:
        InputShapeError: `given` is not two arrays of shape (N, K), K <= SPEED_SAMPLES_MAX.
    """
    n = stamps.shape[0]
    if given is None:
        stamp = np.full((n, width or 1), np.nan)
        sample = np.full((n, width or 1), np.nan)
        stamp[:, 0], sample[:, 0] = stamps, speeds
        return stamp, sample
    at, values = (np.asarray(a, dtype=np.float64) for a in given)
    if at.ndim != 2 or at.shape != values.shape or at.shape[0] != n:
        raise InputShapeError(
            f'speed_samples must be two arrays of shape ({n}, K), got {at.shape}, {values.shape}'
        )
    if at.shape[1] > SPEED_SAMPLES_MAX:
        raise InputShapeError(
            f'speed_samples hold at most {SPEED_SAMPLES_MAX} samples a stamp, got {at.shape[1]}'
        )
    stamp = np.full((n, width or at.shape[1]), np.nan)
    sample = np.full((n, width or at.shape[1]), np.nan)
    stamp[:, : at.shape[1]], sample[:, : at.shape[1]] = at, values
    return stamp, sample


def checked_brake(n: int, brake: ArrayLike | None) -> FloatArray:
    """The brake record (N, 4) (`brakes.brake_torques`), nan without one.

    Raises:
        InputShapeError: brake is not of shape (N, 4).
    """
    if brake is None:
        return no_brakes(n)
    record = np.ascontiguousarray(brake, dtype=np.float64)
    if record.shape != (n, 4):
        raise InputShapeError(f'brake must have shape ({n}, 4), got {record.shape}')
    return record


class CascadeParts:
    """The cascade's parts and their records: what `cascade_step.cascade_block` advances.

    Attributes:
        wheels: the wheel observer's differentiator (4 channels).
        speed: the speed observer's differentiator (1 channel).
        estimator: the estimator.
        source: the torque source's code (`drivetrain.TORQUE_SOURCES`).
        measured: the estimator gets the measured speed (else the observer's).
        drivetrain: `Drivetrain.params` on the engine path, else zeros (unread).
        engine_state: the engine path's state (`cascade_step.ENGINE_STATE`).
        offset_on: the engine path learns the engine-torque offset.
        offset_params, offset_state, offset_estimate: the offset estimator's records.
        engine_faults: the engine path's own fault counter where it learns the offset.
        brakes: the brake input (`brakes.Brakes`; kind 'none' without one).
        brake_parts: its records (`brakes.BrakeParts`: settings, the learnt gain's state).
    """

    def __init__(self, settings: CascadeSettings) -> None:
        """Create the parts (compiled, or loaded from numba's cache, by their wrappers).

        Raises:
            ConfigurationError: unknown torque source.
        """
        config = settings.observer
        estimator_config = settings.estimator
        vehicle = settings.vehicle
        drivetrain = settings.drivetrain
        self.source = settings.source

        wheel_input = WHEEL_INPUTS.index(config.wheel_input)
        self.wheels = LevantDifferentiator(
            config.wheel_lipschitz, n_channels=4, settings=config.differentiator(wheels=True),
            input_derivative=wheel_input,
        )  # fmt: skip
        self.speed = LevantDifferentiator(
            config.speed_lipschitz, n_channels=1, settings=config.differentiator()
        )
        self.estimator = Estimator(vehicle, estimator_config, self.source)
        self.measured = settings.estimator_speed == 'measured'
        engine_on = self.source == TORQUE_ENGINE and drivetrain is not None
        self.engine_on = engine_on
        self.drivetrain = (
            drivetrain.params() if engine_on and drivetrain else new_records(DRIVETRAIN_PARAMS, 1)
        )
        self.engine_state = new_records(ENGINE_STATE, 1)
        self.engine_state['changed_at'] = -np.inf
        self.engine_state['gear'] = np.nan
        self.offset_on = engine_on and estimator_config.torque_offset_adaptation
        self.offset_params = offset_params(estimator_config.torque_offset)
        self.offset_state = new_offset_state()
        self.offset_estimate = new_offset_estimate()
        self.engine_faults = FaultCounter(ENGINE_FAULTS) if self.offset_on else None
        #: the IMU fusion (`imu_grade`): its records, on from the first block with an IMU
        self.imu_on = False
        self.imu_grade = ImuGrade(None, vehicle.gravity, vehicle.mass, vehicle.rolling_c0,
                                  vehicle.rolling_c1)  # fmt: skip
        self._vehicle = vehicle
        # without torque there is nothing to take a brake torque from
        brakes = settings.brakes
        self.brakes = brakes if brakes is not None and self.source != TORQUE_NONE else Brakes()
        #: the brake input's records (`brakes.BRAKE_PARAMS`, `brakes.BRAKE_STATE`)
        self.brake_parts = self.brakes.parts()
        self._records: CascadeRecords | None = None

    def grade(self, config: ImuGradeConfig | None) -> ImuGrade:
        """Turn the IMU fusion on (on the first call, with `config`; defaults if None) and
        return its records."""
        if not self.imu_on:
            v = self._vehicle
            self.imu_grade = ImuGrade(config, v.gravity, v.mass, v.rolling_c0, v.rolling_c1)
            self.imu_on = True
            self._records = None
        return self.imu_grade

    def records(self) -> CascadeRecords:
        """Every part's records as `cascade_step.cascade_block` takes them (views of the live
        records, which are never replaced: every reset works in place; built once, and again
        when the IMU fusion is turned on)."""
        if self._records is not None:
            return self._records
        a = record_array
        switches = new_records(CASCADE_SWITCHES, 1)
        switches['measured_speed'] = self.measured
        switches['engine_path'] = self.engine_on
        switches['offset_learnt'] = self.offset_on
        switches['imu_fused'] = self.imu_on
        self._records = CascadeRecords(
            switches, self.wheels.parts(), self.speed.parts(), self.estimator.parts,
            record_array(new_estimator_input()),
            EnginePathParts(
                self.drivetrain, self.engine_state, a(self.offset_params), a(self.offset_state),
                a(self.offset_estimate),
            ),
            self.brake_parts,
            ImuParts(
                a(self.imu_grade.params), a(self.imu_grade.state), new_records(GRADE_INPUT, 1)
            ),
        )  # fmt: skip
        return self._records

    def faults(self) -> dict[str, int]:
        """Total fault counts per kind ('wheel.<kind>', 'speed.<kind>', 'estimator.<kind>',
        and 'engine.torque_offset_clamped' where the offset is learnt)."""
        counts = {
            f'{part}.{kind}': n
            for part, counter in (
                ('wheel', self.wheels.faults),
                ('speed', self.speed.faults),
                ('estimator', self.estimator.faults),
            )
            for kind, n in counter.counts.items()
        }
        if self.offset_on:
            counts['engine.torque_offset_clamped'] = int(self.offset_state.clamped)
        return counts


def empty_outputs(n: int, offsets: bool) -> CascadeOutputs:
    """`cascade_block`'s output buffers for N stamps (``offsets``: the offset is learnt)."""
    return CascadeOutputs(
        np.zeros((n, 3, 4)), np.zeros((n, 4), dtype=np.bool_), np.zeros((n, 3)),
        np.zeros(n, dtype=np.bool_), np.zeros((n, 4)), new_records(ESTIMATES, n),
        np.zeros(n, dtype=np.bool_), new_records(OFFSET_ESTIMATE_DTYPE, n if offsets else 0),
        new_records(GRADE_OUT, n),
    )  # fmt: skip


def run_cascade(
    series: CascadeSeries, settings: CascadeSettings, state: CascadeState | None = None
) -> CascadeResult:
    """Run observers and estimator over a record sampled at common stamps.

    Args:
        series: the inputs at each stamp.
        settings: the cascade's settings (`situation.chain_settings` builds them from node
            parameters, a settings file or the CLI; a `ChainSettings` is one).
        state: carried from the previous block of the record (`CascadeState`); None: the
            record is whole. ``faults`` are then the totals since the first block.

    Raises:
        InputShapeError: inconsistent shapes.
        ConfigurationError: the engine path without its engine record.
    """
    stamps, angles, speeds, torques = checked_record(series)
    n = stamps.shape[0]
    source, engine_record = checked_engine(
        n, settings.torque_source, series.engine, settings.drivetrain
    )
    brake_record = checked_brake(n, series.brake)
    if source == TORQUE_NONE:
        torques = np.zeros((n, 4))  # no torque topic: zeros everywhere
    if state is not None and state.parts is not None:
        parts = state.parts
    else:
        parts = CascadeParts(settings)
        if state is not None:
            state.parts = parts
    held = dict(series.held or {})
    if series.imu is not None:
        held['imu'] = series.imu
    if 'imu' in held:  # an IMU turns its fusion on
        parts.grade(settings.imu)
    out = empty_outputs(n, parts.offset_on)
    speed_stamp, speed_sample = checked_speed_samples(stamps, speeds, series.speed_samples)
    inputs = CascadeInputs(
        t=stamps, wheel_angle=angles, body_speed=speeds, speed_stamp=speed_stamp,
        speed_sample=speed_sample, wheel_torque=torques,
        engine=input_records(ENGINE_SAMPLE, engine_record), brake=brake_record,
        **held_records(n, held),
    )  # fmt: skip
    cascade_block(parts.records(), inputs, out)
    if source == TORQUE_NONE:
        out.torque_valid[:] = False
    return cascade_result(stamps, source, parts, out)


def held_records(n: int, held: Mapping[str, ArrayLike]) -> dict[str, NDArray[Any]]:
    """Every held input's records over N stamps (`cascade_step.HELD_INPUTS`), nan where not
    given.

    Args:
        held: by name, shape (N, C) each: the sample's stamp [s] and its first C - 1 fields
            (`CascadeSeries.held`).

    Raises:
        InputShapeError: an unknown name, or columns of another shape.
    """
    unknown = sorted(set(held) - set(HELD_INPUTS))
    if unknown:
        raise InputShapeError(f'no held input {unknown}; known: {sorted(HELD_INPUTS)}')
    out = {}
    for name, dtype in HELD_INPUTS.items():
        given = held.get(name)
        columns = np.zeros((n, 0)) if given is None else np.asarray(given, dtype=np.float64)
        fields = dtype.names or ()
        if given is not None and (
            columns.ndim != 2 or columns.shape[0] != n or not 2 <= columns.shape[1] <= len(fields)
        ):
            raise InputShapeError(
                f'{name} must have shape ({n}, C), 2 <= C <= {len(fields)} '
                f'({", ".join(fields)}), got {columns.shape}'
            )
        out[name] = input_records(dtype, columns)
    return out


def input_records(dtype: np.dtype[Any], columns: FloatArray) -> NDArray[Any]:
    """The records of an input given as columns (the API's (N, C) arrays, in the order of
    the record's fields; the fields after the C given are nan): shape (N,)."""
    records: NDArray[Any] = new_records(dtype, columns.shape[0])
    names = dtype.names or ()
    for i, name in enumerate(names):
        records[name] = columns[:, i] if i < columns.shape[1] else np.nan
    return records


def cascade_result(
    stamps: FloatArray, source: int, parts: CascadeParts, out: CascadeOutputs
) -> CascadeResult:
    """The `CascadeResult` of a block's outputs (copies of its arrays)."""
    est = out.estimates.view(np.recarray)
    offsets = out.offsets.view(np.recarray)
    learnt = OffsetRecord(
        offsets.offset.copy(), offsets.offset_std.copy(), offsets.converged.copy(),
        offsets.used.copy(), offsets.episodes.copy(), offsets.clamped.copy(),
    )  # fmt: skip
    result = CascadeResult(
        t=stamps.copy(),
        omega=out.wheel[:, 1, :].copy(),
        omega_dot=out.wheel[:, 2, :].copy(),
        speed=out.body[:, 0].copy(),
        accel=out.body[:, 1].copy(),
        fx=est.fx.copy(),
        fz=est.fz.copy(),
        mu=est.mu.copy(),
        mu_valid=est.mu_valid != 0,
        slip=est.slip.copy(),
        rolling=est.rolling.copy(),
        aero=est.aero.copy(),
        slope=est.slope.copy(),
        slope_valid=est.slope_valid.copy(),
        wheel_valid=out.wheel_valid.copy(),
        torque_valid=out.torque_valid.copy(),
        torque_source=source,
        angle=out.wheel[:, 0, :].copy(),
        faults=parts.faults(),
        mass=est.mass.copy(),
        mass_std=est.mass_std.copy(),
        mass_converged=est.mass_converged.copy(),
        mass_used=est.mass_used.copy(),
        mass_excited=est.mass_excited.copy(),
        radius=est.radius.copy(),
        radius_std=est.radius_std.copy(),
        radius_converged=est.radius_converged.copy(),
        radius_used=est.radius_used.copy(),
        radius_free_wheels=est.radius_free_wheels.astype(np.int64),
        **learnt.fields(),
        wheel_torque_used=out.used.copy(),
        slope_sources=np.where(est.slope_valid, SOURCE_FORCE, 0).astype(np.uint8),
        slope_force=est.slope.copy(),
    )
    return replace(result, **_imu_fields(out.grade.view(np.recarray))) if parts.imu_on else result


def _imu_fields(grade: np.recarray) -> dict[str, Any]:
    """The `CascadeResult` fields of the IMU fusion's outputs (copies)."""
    return {
        'slope': grade.slope.copy(),
        'slope_valid': grade.slope_valid.copy(),
        'slope_sources': grade.sources.copy(),
        'slope_imu': grade.slope_imu.copy(),
        'imu_bias': grade.bias.copy(),
        'imu_mass': grade.mass.copy(),
        'imu_mass_std': grade.mass_std.copy(),
        'imu_fitted': grade.fitted.copy(),
        'imu_trusted': grade.trusted.copy(),
        'imu_gyro': grade.gyro.copy(),
    }
