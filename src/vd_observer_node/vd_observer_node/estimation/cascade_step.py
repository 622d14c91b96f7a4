"""The cascade's stamp, compiled: wheel and speed observers, the torque path, the estimator.

`cascade_block` is the one loop that runs the cascade, over N >= 1 stamps: the offline
replay, the fleet and the evaluation call it on blocks of a record (`cascade.run_cascade`),
the pipeline node on one stamp at a time (`chain.Chain`). Every part is the step function of
its own module (`levant_step.levant_update`, `torque_offset.torque_offset_step`,
`drivetrain.engine_torques`, `estimator_step.estimator_update`, and with an IMU
`imu_grade.imu_grade_step`) on that part's records; with ``VD_JIT=0`` the same source runs as
plain Python.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from vd_observer_node.estimation.brakes import (
    BRAKE_NONE,
    brake_gain_update,
    brake_gains,
    brake_torques,
)
from vd_observer_node.estimation.drivetrain import TORQUE_NONE, engine_torques
from vd_observer_node.estimation.estimator_step import estimator_update
from vd_observer_node.estimation.imu_grade import imu_grade_step
from vd_observer_node.estimation.levant_step import levant_update
from vd_observer_node.estimation.torque_offset import torque_offset_step
from vd_observer_node.kernel._jit import jit

__all__ = ['CLUTCH_SETTLE', 'ENGINE_INERTIA', 'cascade_block', 'cascade_step']

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: slots of `Drivetrain.params_array` the torque path reads here
ENGINE_INERTIA = 4
CLUTCH_SETTLE = 6


@jit
def cascade_step(
    wp: np.record, wlip: FloatArray, ws: np.record, wch: np.recarray,
    sp: np.record, slip_: FloatArray, ss: np.record, sch: np.recarray,
    ep: np.record, es: np.record, fst: FloatArray, sst: FloatArray, vst: FloatArray,
    measured: bool, engine_on: bool, dprm: FloatArray, escl: FloatArray, offset_on: bool,
    op: np.record, os_: np.record, oout: np.record, bprm: FloatArray, bst: FloatArray,
    imu_on: bool, gp: np.record, gs: np.record,
    t: float, angle: FloatArray, speed: float, torque: FloatArray, engine: FloatArray,
    brake: FloatArray, imu: FloatArray, wheel: FloatArray, wheel_valid: BoolArray,
    body: FloatArray, body_valid: BoolArray, used: FloatArray, est: np.record,
    grade: np.record,
) -> bool:  # fmt: skip
    """One stamp: wheel and speed observers, the torque path, the estimator, then the IMU.

    Args:
        wp, wlip, ws, wch: the wheel differentiator (`LevantDifferentiator.kernel_args`).
        sp, slip_, ss, sch: the speed differentiator (one channel).
        ep, es, fst, sst, vst: the estimator (`Estimator.params`, `EstimatorState.args`).
        measured: the estimator gets the measured speed (else the observer's).
        engine_on: the torque path is the engine's (`dprm`, `escl`, and with ``offset_on``
            the offset estimator `op`, `os_`, `oout`); else `torque` is used as it is.
        dprm: `Drivetrain.params_array` (empty off the engine path).
        escl: shape (2,), the engine path's state: the stamp the clutch last slipped or the
            gear changed (-inf before), the last gear (nan before).
        offset_on: the engine path learns the engine-torque offset and subtracts it.
        op, os_, oout: the offset estimator's settings, state and estimate records.
        bprm: shape (11,), the brake input (`brakes.Brakes.params_array`; kind
            `BRAKE_NONE`: none).
        bst: shape (13,), the learnt brake gain's state (`brakes.new_brake_state`).
        imu_on: the IMU fusion runs (`gp`, `gs`: `imu_grade.GRADE_PARAMS`, `GRADE_STATE`):
            its regression's mass, once fitted, is the estimator's from the next stamp on
            (with ``gp.feedback``), and the mass fields of `est` are the regression's once
            it has data.
        t: stamp [s].
        angle: shape (4,), [rad] wheel angles (or speeds [rad/s], as the observer takes).
        speed: [m/s] measured body speed.
        torque: shape (4,), [N m] measured wheel torques (read off the engine path only).
        engine: shape (4,), engine torque [N m], gear, engine speed [rad/s], turbine speed
            [rad/s] (engine path; the speeds nan where not logged).
        brake: shape (4,), the brake input (`brake_torques`).
        imu: shape (2,): stamp [s] of the newest IMU sample (nan: none) and its forward
            specific force [m/s^2] (read with ``imu_on``).
        wheel: shape (3, 4), written: angle, omega, omega_dot.
        wheel_valid: shape (4,), written.
        body: shape (3, 1), written: speed, accel, jerk of the speed observer.
        body_valid: shape (1,), written.
        used: shape (4,), written: the wheel torques the estimator got [N m].
        est: `estimator_step.ESTIMATES` record, written.
        grade: `imu_grade.GRADE_OUT` record, written with ``imu_on``: the fused slope.

    Returns:
        Whether the torque path held (the engine path: clutch engaged, gear known, settled;
        the brakes: not braking with a switch only, the pressure's torque known).
    """
    levant_update(wp, wlip, ws, wch, t, angle, wheel, wheel_valid)
    sample = np.empty(1)
    sample[0] = speed
    levant_update(sp, slip_, ss, sch, t, sample, body, body_valid)
    v_est = speed if measured else body[0, 0]
    torque_ok = True
    if engine_on:
        engine_torque = engine[0]
        if offset_on:
            torque_offset_step(
                op, dprm[ENGINE_INERTIA], os_, t, engine[0], engine[1], engine[2], oout
            )
            engine_torque = engine_torque - oout.used
        engaged = engine_torques(
            dprm, engine_torque, engine[1], engine[2], engine[3], wheel[1], wheel[2], used
        )
        if not engaged or engine[1] != escl[1]:
            escl[0] = t
        escl[1] = engine[1]
        torque_ok = engaged and t - escl[0] >= dprm[CLUTCH_SETTLE]
    else:
        used[:] = torque
    braked = bprm[0] != BRAKE_NONE
    learn = braked and bprm[5] > 0.0
    path_ok = torque_ok
    drive = used.copy() if learn else used
    if braked:
        gains = np.empty(4)
        brake_gains(bprm, bst, gains)
        torque_ok = brake_torques(bprm, gains, brake, wheel[1], used) and torque_ok
    estimator_update(
        ep, es, fst, sst, vst, t, wheel[1], wheel[2], v_est, body[1, 0], used, torque_ok, est
    )
    if learn:
        brake_gain_update(bprm, bst, t, brake, wheel[1], drive, ep, v_est, path_ok, est)
    if imu_on:
        _imu_step(ep, es, gp, gs, t, imu, speed, torque_ok, est, grade)
    return torque_ok


@jit
def _imu_step(
    ep: np.record, es: np.record, gp: np.record, gs: np.record, t: float, imu: FloatArray,
    speed: float, torque_ok: bool, est: np.record, grade: np.record,
) -> None:  # fmt: skip
    """The IMU fusion on the estimator's outputs, and its mass fed back (see `cascade_step`)."""
    # the longitudinal balance without gravity and rolling: what the regression explains
    force = est.fx[0] + est.fx[1] + est.fx[2] + est.fx[3] - math.copysign(est.aero, speed)
    ok = torque_ok and ep.torque_source != TORQUE_NONE and math.isfinite(force)
    imu_grade_step(
        gp, gs, t, imu[0], imu[1], speed, est.slope, est.slope_valid, force, ok,
        est.mass_used, grade,
    )  # fmt: skip
    if gs.fit_time > 0.0:
        # the mass published is the regression's once it has data (an IMU that never
        # delivers leaves the estimator's)
        est.mass = grade.mass
        est.mass_std = grade.mass_std
        est.mass_converged = grade.fitted
    if gp.feedback:
        es.mass_known = grade.mass if grade.fitted else math.nan


@jit
def cascade_block(
    wp_: np.ndarray, wlip: FloatArray, ws_: np.ndarray, wch: np.recarray,
    sp_: np.ndarray, slip_: FloatArray, ss_: np.ndarray, sch: np.recarray,
    ep_: np.ndarray, es_: np.ndarray, fst: FloatArray, sst: FloatArray, vst: FloatArray,
    measured: bool, engine_on: bool, dprm: FloatArray, escl: FloatArray, offset_on: bool,
    op_: np.ndarray, os__: np.ndarray, oout_: np.ndarray, bprm: FloatArray, bst: FloatArray,
    imu_on: bool, gp_: np.ndarray, gs_: np.ndarray,
    t: FloatArray, angles: FloatArray, speeds: FloatArray, torques: FloatArray,
    engine: FloatArray, brakes: FloatArray, imu: FloatArray, wheel: FloatArray,
    wheel_valid: BoolArray, body: FloatArray,
    body_valid: BoolArray, used: FloatArray, est: np.ndarray, torque_valid: BoolArray,
    offsets: np.ndarray, grade: np.ndarray,
) -> None:  # fmt: skip
    """`cascade_step` over N stamps (the parts' records carry on from block to block).

    Args:
        (parts): as `cascade_step`, each record as the 1-element array it lives in
            (`kernel._jit.record_array`: numba types arrays on its fast path, records not).
        t: shape (N,), [s].
        angles: shape (N, 4); speeds (N,); torques (N, 4); engine (N, 4); brakes (N, 4);
            imu (N, 2) (as `cascade_step`).
        wheel: shape (N, 3, 4), written; wheel_valid (N, 4); body (N, 3); body_valid (N,).
        used: shape (N, 4), written: the wheel torques the estimator got.
        est: shape (N,) `estimator_step.ESTIMATES` records, written.
        torque_valid: shape (N,), written.
        offsets: shape (N,) `torque_offset.OFFSET_ESTIMATE_DTYPE` records written where the
            offset is learnt, else shape (0,).
        grade: shape (N,) `imu_grade.GRADE_OUT` records written with ``imu_on``.
    """
    wp, ws, sp, ss, ep, es = wp_[0], ws_[0], sp_[0], ss_[0], ep_[0], es_[0]
    op, os_, oout = op_[0], os__[0], oout_[0]
    gp, gs = gp_[0], gs_[0]
    body1 = np.empty((3, 1))
    valid1 = np.empty(1, dtype=np.bool_)
    for k in range(t.shape[0]):
        torque_valid[k] = cascade_step(
            wp, wlip, ws, wch, sp, slip_, ss, sch, ep, es, fst, sst, vst, measured, engine_on,
            dprm, escl, offset_on, op, os_, oout, bprm, bst, imu_on, gp, gs, t[k], angles[k],
            speeds[k], torques[k], engine[k], brakes[k], imu[k], wheel[k], wheel_valid[k],
            body1, valid1, used[k], est[k], grade[k],
        )  # fmt: skip
        if offsets.shape[0] > 0:
            offsets[k] = oout
        body[k, 0] = body1[0, 0]
        body[k, 1] = body1[1, 0]
        body[k, 2] = body1[2, 0]
        body_valid[k] = valid1[0]
