"""The whole per-stamp chain in one object: observers -> estimator -> situation monitor.

What ``pipeline_node`` runs per stamp-matched set of sensor messages (wheel angles, body speed,
wheel torques, or the engine torque and gear on the engine path), ROS-free. `Chain.update` runs
the one cascade loop (`estimation.cascade_step.cascade_block`) and the one monitor loop
(`situation.monitor_step.situation_block`) on one stamp: what the offline replay runs on blocks
of stamps (`estimation.cascade.run_cascade`, then `situation.monitor.run_situation`), so the
node's outputs are the replay's on the same stamps. The torque source
(`ChainSettings.torque_source`) is the replay's: measured wheel torques, the engine path (the
monitor then gets the torques it gave the estimator, 0 where it had none) or no torque (0 to
the monitor). ``VD_JIT=0`` runs the same source as plain Python.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vd_observer_node.errors import InputShapeError
from vd_observer_node.estimation.brakes import no_brakes
from vd_observer_node.estimation.cascade import (
    CascadeParts,
    checked_speed_samples,
    empty_outputs,
    held_records,
    input_records,
)
from vd_observer_node.estimation.cascade_step import (
    ENGINE_SAMPLE,
    HELD_INPUTS,
    CascadeInputs,
    cascade_block,
)
from vd_observer_node.estimation.drivetrain import TORQUE_NONE
from vd_observer_node.estimation.estimator import (
    Estimates,
    estimates_from_record,
)
from vd_observer_node.estimation.estimator_step import SPEED_SAMPLES_MAX
from vd_observer_node.estimation.faults import FaultCounter, FaultReport, merge_reports
from vd_observer_node.estimation.imu_grade import SOURCE_FORCE
from vd_observer_node.estimation.imu_regression import bias_pitch_deg
from vd_observer_node.estimation.observer import SpeedState, WheelState
from vd_observer_node.estimation.torque_offset import TorqueOffset, offset_from_record
from vd_observer_node.estimation.vehicle import (
    EstimatorVehicle,
    load_vehicle_params,
    vehicle_tire,
)
from vd_observer_node.kernel._jit import FixedCall
from vd_observer_node.situation.chain_settings import ChainSettings
from vd_observer_node.situation.friction_potential import TyreCurves
from vd_observer_node.situation.monitor import (
    Situation,
    SituationBlock,
    SituationInputs,
    SituationMonitor,
)

__all__ = [
    'Chain',
    'ChainOutput',
    'ImuLearnt',
    'chain_faults',
    'engine_row',
    'main',
    'warm_up',
]


def engine_row(engine: ArrayLike | None) -> NDArray[np.float64]:
    """The engine argument of `Chain.update` as a (4,) float64 array (a (3,) one gets a
    turbine speed of nan).

    Raises:
        InputShapeError: missing (None on the engine path) or not of shape (3,) or (4,).
    """
    if engine is None:
        raise InputShapeError('the engine path needs engine (torque, gear, engine speed)')
    row = np.ascontiguousarray(engine, dtype=np.float64)
    if row.shape == (3,):
        row = np.append(row, np.nan)
    if row.shape != (4,):
        raise InputShapeError(f'engine must have shape (3,) or (4,), got {row.shape}')
    return row


class ImuLearnt(NamedTuple):
    """What the IMU fusion has learnt (`imu_grade`).

    Attributes:
        bias: [m/s^2] the IMU's bias of the forward specific force (a mounting pitch left
            over, ``g sin(pitch)``, and the sensor's offset); bias_std its standard deviation.
        pitch_deg: [deg] the sensor pitch (nose up) the bias amounts to
            (`imu_regression.bias_pitch_deg`).
        trusted: the bias has converged: the slope is the IMU's.
        gyro: the last stamp's grade used the angular rate (`gyro_grade`).
    """

    bias: float
    bias_std: float
    pitch_deg: float
    trusted: bool
    gyro: bool


class ChainOutput(NamedTuple):
    """Everything computed for one stamp.

    Attributes:
        wheel: wheel observer output (angle, omega, omega_dot, valid; shapes (4,)).
        speed: speed observer output (filtered speed, accel, valid).
        estimates: estimator output for the stamp.
        situation: friction potential and the 12 alert records (None without a tyre:
            `ChainSettings.curves`).
        torque_offset: the engine-torque offset estimate (engine path with
            ``torque_offset_adaptation`` only, else None).
        slope_sources: what ``estimates.slope`` is made of (`imu_grade.SOURCE_FORCE` |
            `imu_grade.SOURCE_IMU`; 0: nothing valid).
    """

    wheel: WheelState
    speed: SpeedState
    estimates: Estimates
    situation: Situation | None
    torque_offset: TorqueOffset | None = None
    slope_sources: int = 0


class Chain:
    """Observers, estimator and situation monitor on the one loop of each, one stamp a call.

    Attributes:
        settings: the chain's settings.
        parts: the cascade's parts (observers, estimator, torque path) and their records.
        monitor: the situation monitor (None without a tyre).
        engine_faults: the engine path's own faults where it learns the torque offset.
    """

    def __init__(self, settings: ChainSettings) -> None:
        """Create the parts from `settings` (compiled now, or loaded from numba's cache)."""
        self.settings = settings
        vehicle = settings.vehicle
        self.parts = CascadeParts(settings)
        self.monitor: SituationMonitor | None = None
        if settings.curves is not None:
            self.monitor = SituationMonitor(
                settings.curves,
                vehicle.static_wheel_loads[[0, 2]],
                vehicle.effective_radius,
                observer=settings.observer,
                alerts=settings.alerts,
                friction=settings.friction,
                situation=settings.situation,
            )
        self.engine_faults: FaultCounter | None = self.parts.engine_faults
        self._none = self.parts.source == TORQUE_NONE
        if settings.imu is not None:
            self.parts.grade(settings.imu)
        # one stamp's inputs and outputs: buffers filled and read at every `update`
        self._in = CascadeInputs(
            np.zeros(1), np.zeros((1, 4)), np.zeros(1), *checked_speed_samples(
                np.zeros(1), np.zeros(1), None, SPEED_SAMPLES_MAX), np.zeros((1, 4)),
            input_records(ENGINE_SAMPLE, np.zeros((1, 4))), no_brakes(1),
            **held_records(1, {}),
        )  # fmt: skip
        #: per held input, its one-row buffer and the row of a stamp without a sample
        self._held = {
            name: (getattr(self._in, name), (math.nan,) * len(dtype.names or ()))
            for name, dtype in HELD_INPUTS.items()
        }
        self._held_given = False  # a buffer holds a sample (else all are the empty row)
        self._speed_given = False  # `speed_samples` filled the next stamp's
        self._out = empty_outputs(1, self.parts.offset_on)
        #: the estimate as a plain structured array: its fields read without a recarray's
        #: Python attribute lookup (the live chain reads them every stamp)
        self._est_fields = self._out.estimates
        self._offsets = self._out.offsets.view(np.recarray)
        self._grade = self._out.grade.view(np.recarray)
        self._block = FixedCall(cascade_block, (self.parts.records(), self._in, self._out), ())
        self._situation = SituationBlock.empty(1)

    def speed_samples(self, stamps: NDArray[np.float64], values: NDArray[np.float64]) -> None:
        """The body-speed samples of the next `update`'s stamp, which the speed observer and
        the estimator take at their own stamps instead of that stamp's ``speed`` at ``t``.

        Args:
            stamps: shape (1, K), K <= `SPEED_SAMPLES_MAX`, [s] the samples stamped since
                the previous stamp, oldest first, nan after the last (as
                `alignment.SampleQueue.take_one` gives them).
            values: shape (1, K), [m/s] the samples.
        """
        inputs = self._in
        width = stamps.shape[-1]
        inputs.speed_stamp[0, :width] = stamps
        inputs.speed_sample[0, :width] = values
        if width < SPEED_SAMPLES_MAX:  # a nan where they end: the cascade reads up to it
            inputs.speed_stamp[0, width] = math.nan
        self._speed_given = True

    def _take_held(self, held: Mapping[str, Sequence[float] | None]) -> None:
        """The held inputs' samples of a stamp into their buffers (`update`)."""
        for name in held:
            if name not in self._held:
                raise InputShapeError(f'no held input {name!r}; known: {sorted(self._held)}')
        self._held_given = False
        for name, (buffer, none) in self._held.items():
            sample = held.get(name)
            buffer[0] = none if sample is None else (*sample, *none[len(sample) :])
            self._held_given = self._held_given or sample is not None

    def update(
        self,
        t: float,
        wheel_angle: ArrayLike,
        speed: float,
        wheel_torque: ArrayLike,
        engine: ArrayLike | None = None,
        brake: ArrayLike | None = None,
        held: Mapping[str, Sequence[float] | None] | None = None,
    ) -> ChainOutput:
        """Advance to stamp t.

        Args:
            t: stamp [s].
            wheel_angle: shape (4,), [rad] unwrapped, order FL, FR, RL, RR (or speeds
                [rad/s] with ``observer.wheel_input='speed'``).
            speed: measured body speed [m/s].
            wheel_torque: shape (4,), [N m] drive minus brake torque (read on the measured
                path only).
            engine: shape (3,) or (4,): engine torque [N m], gear, engine speed [rad/s] (nan
                if not measured), turbine speed [rad/s] (nan or absent if not logged); read
                on the engine path only, where it is required.
            brake: shape (4,): the brake input (`estimation.brakes.brake_torques`; nan where
                unknown); None: nothing known at this stamp (with a brake input: invalid).
            held: the held inputs' newest samples by name (`cascade_step.HELD_INPUTS`), e.g.
                ``{'imu': (stamp [s], forward specific force [m/s^2], pitch rate [rad/s])}``
                (nose down positive; read with ``settings.imu`` only): the sample's stamp and
                its first fields (the others nan); a name absent or None: none yet.

        Raises:
            InputShapeError: an array input has the wrong shape, or no engine on the engine
                path.
        """
        angles = np.ascontiguousarray(wheel_angle, dtype=np.float64)
        torques = np.ascontiguousarray(wheel_torque, dtype=np.float64)
        if angles.shape != (4,) or torques.shape != (4,):
            raise InputShapeError(
                f'wheel_angle and wheel_torque must have shape (4,), got {angles.shape}, '
                f'{torques.shape}'
            )
        parts = self.parts
        inputs = self._in
        inputs.t[0] = float(t)
        inputs.wheel_angle[0] = angles
        inputs.body_speed[0] = float(speed)
        if self._speed_given:  # given by `speed_samples` for this stamp
            self._speed_given = False
        else:  # the stamp's own speed, then a nan where the samples end (read up to it)
            inputs.speed_stamp[0, 0] = inputs.t[0]
            inputs.speed_sample[0, 0] = inputs.body_speed[0]
            inputs.speed_stamp[0, 1] = math.nan
        # the replay's without torque: no torque topic, zeros everywhere
        inputs.wheel_torque[0] = 0.0 if self._none else torques
        if parts.engine_on:
            inputs.engine[0] = tuple(engine_row(engine))
        inputs.brake[0] = math.nan if brake is None else np.reshape(brake, 4)
        if held or self._held_given:
            self._take_held(held or {})
        self._block()
        out = self._out
        stamp, speeds = inputs.t, inputs.body_speed
        torques = inputs.wheel_torque[0]
        est = out.estimates[0]
        if parts.engine_on or parts.brakes.kind != 'none':
            # the torques the engine path and brakes gave the estimator (0 where none)
            torques = np.where(np.isfinite(out.used[0]), out.used[0], 0.0)
        wheel = out.wheel[0]
        situation = None
        if self.monitor is not None:
            fields = self._est_fields
            self.monitor.run(
                stamp,
                SituationInputs(  # the buffers themselves: the monitor keeps none of them
                    inputs.wheel_angle,
                    speeds,
                    torques[None],
                    out.wheel[:, 1].copy(),
                    fields['mu'].copy(),
                    fields['mu_valid'] != 0,
                    fields['fz'].copy(),
                ),
                self._situation,
            )
            situation = self.monitor.last
            assert situation is not None  # run just set it
        offset = None
        if parts.offset_on:
            offset = offset_from_record(self._offsets[0])
            if offset.clamped and self.engine_faults is not None:
                self.engine_faults.count('torque_offset_clamped')
        estimates = estimates_from_record(est)
        sources = SOURCE_FORCE if estimates.slope_valid else 0
        if parts.imu_on:
            # the IMU fusion's slope (`imu_grade`, run in the cascade step)
            g = self._grade[0]
            estimates = replace(estimates, slope=float(g.slope), slope_valid=bool(g.slope_valid))
            sources = int(g.sources)
        return ChainOutput(
            WheelState(
                wheel[0].copy(), wheel[1].copy(), wheel[2].copy(), out.wheel_valid[0].copy()
            ),
            SpeedState(float(out.body[0, 0]), float(out.body[0, 1]), bool(out.body_valid[0])),
            estimates,
            situation,
            offset,
            sources,
        )

    @property
    def imu_trusted(self) -> bool:
        """The IMU fusion's bias has converged at the last stamp (False: not, or no IMU)."""
        return self.parts.imu_on and bool(self._grade[0].trusted)

    def imu_learnt(self) -> ImuLearnt | None:
        """What the IMU fusion has learnt up to the last stamp (None: no IMU fused)."""
        if not self.parts.imu_on:
            return None
        g = self._grade[0]
        pitch = bias_pitch_deg(float(g.bias), self.parts.imu_grade.params.gravity)
        return ImuLearnt(float(g.bias), float(g.bias_std), pitch, bool(g.trusted), bool(g.gyro))

    def fault_report(self) -> FaultReport:
        """Faults since the previous call, per part ('wheel', 'speed', 'estimator', and
        'engine' where the engine path learns the torque offset)."""
        parts = self.parts
        return chain_faults(
            parts.wheels.faults, parts.speed.faults, parts.estimator.faults, self.engine_faults
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


_warm = False


def warm_up(curves: TyreCurves) -> None:
    """Compile (or load from numba's disk cache) the chain's loops now, once per process.

    `curves` only gives the tyre arrays their types (any tyre will do); a chain of any
    settings then runs compiled code from its first stamp.
    """
    global _warm
    if _warm:
        return
    vehicle = EstimatorVehicle(
        mass=1000.0, wheelbase=2.5, cg_to_front_axle=1.0, cg_height=0.5, inertia_front=1.0,
        inertia_rear=1.0, effective_radius=0.3, drag_coefficient=0.3, frontal_area=2.0,
        air_density=1.2, rolling_c0=0.01, rolling_c1=0.0, gravity=9.81,
    )  # fmt: skip
    Chain(ChainSettings(vehicle=vehicle, curves=curves)).update(0.0, np.zeros(4), 1.0, np.zeros(4))
    _warm = True


def main() -> int:
    """``python -m vd_observer_node.chain``: compile every step function into numba's disk
    cache now (``make setup`` runs it after each build, so the first ``vd replay`` or node
    start of a fresh set-up loads machine code instead of compiling for half a minute).
    Prints one line with the time it took (about 0.5 s when the cache was already there)."""
    from vd_observer_node.kernel._jit import PACKAGE

    start = time.perf_counter()
    warm_up(TyreCurves.from_tire(vehicle_tire(load_vehicle_params())))
    print(
        f'step functions compiled into the __pycache__ folders of {PACKAGE} in '
        f'{time.perf_counter() - start:.1f} s',
        flush=True,
    )
    return 0


if __name__ == '__main__':
    sys.exit(main())
