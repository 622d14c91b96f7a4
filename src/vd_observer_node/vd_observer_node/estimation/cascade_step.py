"""The cascade's stamp, compiled: wheel and speed observers, the torque path, the estimator.

`cascade_block` is the one loop that runs the cascade, over N >= 1 stamps: the offline
replay, the fleet and the evaluation call it on blocks of a record (`cascade.run_cascade`),
the pipeline node on one stamp at a time (`chain.Chain`). Every part is the step function of
its own module (`levant_step.levant_update`, `torque_offset.torque_offset_step`,
`drivetrain.engine_torques`, `estimator_step.estimator_update`, and with an IMU
`imu_grade.imu_grade_step`) on that part's records; with ``VD_JIT=0`` the same source runs as
plain Python.

The loop takes three groups, each a NamedTuple of named arrays (numba types NamedTuples and
reads their fields by name; records live in 1-element arrays, as numba types arrays on its
fast path): the parts (`CascadeRecords`: every part's parameters and state, owned by
`cascade.CascadeParts`), the inputs (`CascadeInputs`: one row per stamp) and the outputs
(`CascadeOutputs`: one row per stamp).
The speed observer and the estimator's speed low-pass (with the measured speed) take every
body-speed sample at its own stamp: a stamp's samples are those stamped after the previous
stamp and not after its own (`alignment.samples_between`), so a sample whose wheel stamp was
lost still counts, and a held sample is not fed to the observer twice.
A new input is a field of `CascadeInputs`, filled where the inputs are built
(`cascade.cascade_inputs`, `chain.Chain`) and read by the part that uses it here.
"""

from __future__ import annotations

import math
from typing import Any, Final, NamedTuple

import numpy as np
from numpy.typing import NDArray

from vd_observer_node.estimation.brakes import (
    BRAKE_NONE,
    BrakeParts,
    brake_gain_update,
    brake_gains,
    brake_torques,
)
from vd_observer_node.estimation.drivetrain import TORQUE_NONE, engine_torques
from vd_observer_node.estimation.estimator_step import (
    EstimatorParts,
    estimator_update,
)
from vd_observer_node.estimation.imu_grade import imu_grade_step
from vd_observer_node.estimation.levant_step import LevantParts, levant_held, levant_update
from vd_observer_node.estimation.torque_offset import torque_offset_step
from vd_observer_node.kernel._jit import jit, jit_inlined

__all__ = [
    'CASCADE_SWITCHES',
    'ENGINE_SAMPLE',
    'ENGINE_STATE',
    'HELD_INPUTS',
    'IMU_SAMPLE',
    'CascadeInputs',
    'CascadeOutputs',
    'CascadeRecords',
    'EnginePathParts',
    'ImuParts',
    'cascade_block',
    'cascade_step',
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: The engine path's memory: the stamp [s] the clutch last slipped or the gear changed (-inf
#: before), and the last gear (nan before).
ENGINE_STATE: Final = np.dtype([('changed_at', 'f8'), ('gear', 'f8')], align=True)

#: One stamp's engine-path input: engine torque [N m], gear (0 neutral, -1 reverse), engine
#: speed [rad/s] and an automatic gearbox's turbine speed [rad/s] (the speeds nan where not
#: logged).
ENGINE_SAMPLE: Final = np.dtype(
    [('torque', 'f8'), ('gear', 'f8'), ('speed', 'f8'), ('turbine_speed', 'f8')], align=True
)

#: One stamp's IMU input: the stamp [s] of the newest IMU sample (nan: none), its forward
#: specific force [m/s^2] and the body's pitch rate [rad/s] (nose down positive; nan: none).
IMU_SAMPLE: Final = np.dtype([('stamp', 'f8'), ('f_x', 'f8'), ('pitch_rate', 'f8')], align=True)

#: The held inputs, by their field of `CascadeInputs`: each stamp takes the newest sample not
#: later than it (sample and hold, as a live node sees it), a record whose first field is the
#: sample's stamp [s] (nan: none yet; the part that reads it judges its age). The replay, the
#: live chain and the pipeline node carry every one of them alike (`cascade.held_records`,
#: `chain.Chain.update`, ``InputMapping.held_specs``): a new held input is its record here, its
#: field of `CascadeInputs`, its key in the input mapping, and the part that reads it.
HELD_INPUTS: Final = {'imu': IMU_SAMPLE}  # by the input mapping's names

#: Which parts run: measured_speed (the estimator gets the measured speed, else the speed
#: observer's), engine_path (the wheel torques come from the engine torque and gear),
#: offset_learnt (the engine path learns the engine-torque offset and subtracts it),
#: imu_fused (the IMU fusion runs).
CASCADE_SWITCHES: Final = np.dtype(
    [
        ('measured_speed', 'b1'),
        ('engine_path', 'b1'),
        ('offset_learnt', 'b1'),
        ('imu_fused', 'b1'),
    ],
    align=True,
)


class EnginePathParts(NamedTuple):
    """The engine path's records (empty and unused off it).

    Attributes:
        drivetrain: shape (1,), `drivetrain.DRIVETRAIN_PARAMS` (`Drivetrain.params`; zeros
            off the engine path).
        engine_state: shape (1,), `ENGINE_STATE`.
        offset_params: shape (1,), the offset estimator's settings (`torque_offset`).
        offset_state: shape (1,), its state.
        offset_estimate: shape (1,), its estimate of the stamp.
    """

    drivetrain: NDArray[Any]
    engine_state: NDArray[Any]
    offset_params: NDArray[Any]
    offset_state: NDArray[Any]
    offset_estimate: NDArray[Any]


class ImuParts(NamedTuple):
    """The IMU fusion's records (`imu_grade`), each as the 1-element array it lives in.

    Attributes:
        params: `imu_grade.GRADE_PARAMS`.
        state: `imu_grade.GRADE_STATE`.
        input: `imu_grade.GRADE_INPUT`, the stamp's (a buffer).
    """

    params: NDArray[Any]
    state: NDArray[Any]
    input: NDArray[Any]


class CascadeRecords(NamedTuple):
    """Every part of the cascade, advanced in place by `cascade_block`.

    Attributes:
        switches: shape (1,), `CASCADE_SWITCHES`.
        wheel: the wheel observer (4 channels).
        speed: the speed observer (1 channel).
        estimator: the estimator (`estimator_step.EstimatorParts`).
        estimator_input: shape (1,), `estimator_step.ESTIMATOR_INPUT` (a buffer).
        engine: the engine path.
        brakes: the brake input.
        imu: the IMU fusion.
    """

    switches: NDArray[Any]
    wheel: LevantParts
    speed: LevantParts
    estimator: EstimatorParts
    estimator_input: NDArray[Any]
    engine: EnginePathParts
    brakes: BrakeParts
    imu: ImuParts


class CascadeInputs(NamedTuple):
    """The cascade's inputs over N stamps (contiguous float64 arrays).

    Attributes:
        t: shape (N,), [s] stamps.
        wheel_angle: shape (N, 4), [rad] wheel angles (or speeds [rad/s], as the observer
            takes them), order FL, FR, RL, RR.
        body_speed: shape (N,), [m/s] measured body speed (the newest sample not later than
            the stamp).
        speed_stamp: shape (N, K), K <= `SPEED_SAMPLES_MAX`, [s] the stamps of the body-speed
            samples the stamp feeds the speed observer and the estimator, oldest first (nan:
            no more).
        speed_sample: shape (N, K), [m/s] those samples.
        wheel_torque: shape (N, 4), [N m] measured wheel torques (read off the engine path
            only).
        engine: shape (N,), `ENGINE_SAMPLE` records (read on the engine path).
        brake: shape (N, 4), the brake input (`brakes.brake_torques`; nan: none).
        imu: shape (N,), `IMU_SAMPLE` records (held; read with the IMU fusion on).
    """

    t: FloatArray
    wheel_angle: FloatArray
    body_speed: FloatArray
    speed_stamp: FloatArray
    speed_sample: FloatArray
    wheel_torque: FloatArray
    engine: NDArray[Any]
    brake: FloatArray
    imu: NDArray[Any]


class CascadeOutputs(NamedTuple):
    """The cascade's outputs over N stamps, written by `cascade_block` (row k after stamp k).

    Attributes:
        wheel: shape (N, 3, 4): the wheel observer's angle, omega, omega_dot.
        wheel_valid: shape (N, 4).
        body: shape (N, 3): the speed observer's speed, accel, jerk.
        body_valid: shape (N,).
        used: shape (N, 4), [N m] the wheel torques the estimator got.
        estimates: shape (N,) `estimator_step.ESTIMATES` records.
        torque_valid: shape (N,): the torque path held (the engine path: clutch engaged,
            gear known, settled; the brakes: not braking with a switch only, the pressure's
            torque known).
        offsets: shape (N,) `torque_offset.OFFSET_ESTIMATE_DTYPE` records where the offset
            is learnt, else shape (0,).
        grade: shape (N,) `imu_grade.GRADE_OUT` records, written with the IMU fusion on.
    """

    wheel: FloatArray
    wheel_valid: BoolArray
    body: FloatArray
    body_valid: BoolArray
    used: FloatArray
    estimates: NDArray[Any]
    torque_valid: BoolArray
    offsets: NDArray[Any]
    grade: NDArray[Any]


@jit_inlined
def cascade_step(
    parts: CascadeRecords, inputs: CascadeInputs, k: int, out: CascadeOutputs, body: FloatArray
) -> None:
    """Stamp k: wheel and speed observers, the torque path, the estimator, then the IMU.

    With the IMU fusion on, its regression's mass, once fitted, is the estimator's from the
    next stamp on (with ``feedback``), and the mass fields of the estimate are the
    regression's once it has data.

    Args:
        parts: every part, advanced in place.
        inputs: the inputs; row k is the stamp's.
        k: the stamp's row.
        out: the outputs; row k is written.
        body: shape (3, 1), a buffer for the speed observer's output (allocated once a block:
            the observer writes channel-major).
    """
    switches = parts.switches[0]
    t = inputs.t[k]
    speed = inputs.body_speed[k]
    wheel = out.wheel[k]
    w, s = parts.wheel, parts.speed
    levant_update(
        w.params[0], w.lipschitz, w.state[0], w.channels, t, inputs.wheel_angle[k], wheel,
        out.wheel_valid[k],
    )  # fmt: skip
    body_valid = out.body_valid[k : k + 1]
    fed = False
    for j in range(inputs.speed_stamp.shape[1]):
        stamp = inputs.speed_stamp[k, j]
        if math.isnan(stamp):
            break
        levant_update(
            s.params[0], s.lipschitz, s.state[0], s.channels, stamp,
            inputs.speed_sample[k, j : j + 1], body, body_valid,
        )  # fmt: skip
        fed = True
    if not fed:  # no new sample: the estimate of the newest one
        levant_held(s.channels, body, body_valid)
    out.body[k, 0] = body[0, 0]
    out.body[k, 1] = body[1, 0]
    out.body[k, 2] = body[2, 0]
    v_est = speed if switches.measured_speed else body[0, 0]
    used = out.used[k]
    torque_ok = True
    if switches.engine_path:
        engine = inputs.engine[k]
        e = parts.engine
        line, memory = e.drivetrain[0], e.engine_state[0]
        engine_torque = engine.torque
        if switches.offset_learnt:
            oout = e.offset_estimate[0]
            torque_offset_step(
                e.offset_params[0], line.engine_inertia, e.offset_state[0], t, engine.torque,
                engine.gear, engine.speed, oout,
            )  # fmt: skip
            engine_torque = engine_torque - oout.used
            out.offsets[k] = oout
        engaged = engine_torques(
            line, engine_torque, engine.gear, engine.speed, engine.turbine_speed, wheel[1],
            wheel[2], used,
        )  # fmt: skip
        if not engaged or engine.gear != memory.gear:
            memory.changed_at = t
        memory.gear = engine.gear
        torque_ok = engaged and t - memory.changed_at >= line.clutch_settle_time
    else:
        used[:] = inputs.wheel_torque[k]
    brake_params = parts.brakes.params[0]
    brake = inputs.brake[k]
    braked = brake_params.kind != BRAKE_NONE
    learn = braked and brake_params.learn
    path_ok = torque_ok
    drive = used.copy() if learn else used
    if braked:
        gains = np.empty(4)
        brake_gains(brake_params, parts.brakes.state[0], gains)
        torque_ok = brake_torques(brake_params, gains, brake, wheel[1], used) and torque_ok
    inp = parts.estimator_input[0]
    inp.omega[:] = wheel[1]
    inp.omega_dot[:] = wheel[2]
    inp.torque[:] = used
    inp.speed = v_est
    if switches.measured_speed:  # the slope's speed low-pass takes them at their own stamps
        _speed_samples_in(inputs.speed_stamp[k], inputs.speed_sample[k], inp)
    else:
        inp.speed_stamps[0] = math.nan
    inp.accel = body[1, 0]
    inp.torque_ok = torque_ok
    est = out.estimates[k]
    estimator_update(parts.estimator, t, inp, est)
    if learn:
        brake_gain_update(
            parts.brakes, t, brake, drive, parts.estimator.params[0], inp, path_ok, est
        )
    if switches.imu_fused:
        _imu_step(parts, inputs, k, torque_ok, est, out.grade[k])
    out.torque_valid[k] = torque_ok


@jit
def _speed_samples_in(stamps: FloatArray, samples: FloatArray, inp: Any) -> None:
    """The stamp's speed samples into the estimator's input, up to the first nan (the
    estimator reads up to there; a stamp brings one or two)."""
    taken = 0
    for j in range(stamps.shape[0]):
        if math.isnan(stamps[j]):
            break
        inp.speed_stamps[j] = stamps[j]
        inp.speed_samples[j] = samples[j]
        taken += 1
    if taken < inp.speed_stamps.shape[0]:
        inp.speed_stamps[taken] = math.nan


@jit
def _imu_step(
    parts: CascadeRecords, inputs: CascadeInputs, k: int, torque_ok: bool, est: Any, grade: Any
) -> None:
    """The IMU fusion on the estimator's outputs, and its mass fed back (see `cascade_step`)."""
    ep, es = parts.estimator.params[0], parts.estimator.state[0]
    gp, gs, inp = parts.imu.params[0], parts.imu.state[0], parts.imu.input[0]
    speed = inputs.body_speed[k]
    # the longitudinal balance without gravity and rolling: what the regression explains
    force = est.fx[0] + est.fx[1] + est.fx[2] + est.fx[3] - math.copysign(est.aero, speed)
    imu = inputs.imu[k]
    inp.imu_stamp = imu.stamp
    inp.f_x = imu.f_x
    inp.pitch_rate = imu.pitch_rate
    inp.speed = speed
    inp.slope_force = est.slope
    inp.force_valid = est.slope_valid
    inp.force = force
    inp.force_ok = torque_ok and ep.torque_source != TORQUE_NONE and math.isfinite(force)
    inp.mass_used = est.mass_used
    imu_grade_step(gp, gs, inputs.t[k], inp, grade)
    if gs.fit_time > 0.0:
        # the mass published is the regression's once it has data (an IMU that never
        # delivers leaves the estimator's)
        est.mass = grade.mass
        est.mass_std = grade.mass_std
        est.mass_converged = grade.fitted
    if gp.feedback:
        es.mass_known = grade.mass if grade.fitted else math.nan


@jit
def cascade_block(parts: CascadeRecords, inputs: CascadeInputs, out: CascadeOutputs) -> None:
    """`cascade_step` over the N stamps of `inputs` (the parts carry on from block to block).

    Args:
        parts: every part, advanced in place.
        inputs: N stamps.
        out: N rows, written.
    """
    body = np.empty((3, 1))
    for k in range(inputs.t.shape[0]):
        cascade_step(parts, inputs, k, out, body)
