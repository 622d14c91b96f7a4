"""Compiled estimator: `estimator.Estimator` (with its `filters.LowPass` stages) in numba.

Mirrors :class:`vd_observer_node.estimation.estimator.Estimator` step for step: the wheel spin
balance, load transfer (both sources), utilised friction and its validity, slip, rolling and aero
resistance, the slope from the filtered force balance (both acceleration sources), held
inputs, resets and every fault counter. The tests run both on the same inputs and require
equal outputs (1e-9) and equal fault counts.

Array layouts:

* ``prm`` float64 (`N_PARAMS`,): see `estimator_params`;
* ``prm[27]`` is the torque source code (`drivetrain.TORQUE_*`); ``prm[28:]`` the online
  mass (`mass_grade.MassGradeEstimator`'s settings, ``prm[28]`` 1.0 where it runs);
  ``prm[47:60]`` the online rolling radius (`rolling_radius.RollingRadiusEstimator`'s
  settings, ``prm[47]`` 1.0 where it runs), ``prm[60]`` `mass_waits_for_radius`;
* ``scal`` (`N_SCAL`,): stamp of the last sample (nan before the first), slope [rad], 1.0 once
  an estimate exists, then the online mass's state (the ``_M_*`` slots: its stamp, filters,
  1/m and its variance, the last estimate), then the online radius's (the ``_R_*`` slots);
  ``held`` (14,): last finite inputs (omega,
  omega_dot, torque, v, accel);
* three low-pass filters (force (order, 5), slope (order, 1), speed (order, 1)), each
  ``stages``, ``prev`` (d,) and ``meta`` (3,): initialised, has a previous output, last dt;
* ``est`` (`EST_SIZE`,): one estimate packed (see the ``E_*`` offsets): the last one in the
  state, the output of `estimator_update`;
* ``counts`` int64 (14,): the `faults.ESTIMATOR_FAULTS` kinds in order, then rejections.

The online mass mirrors `mass_grade.MassGradeEstimator.update` (its scalar RLS is
`mass_grade.rls_step` with one parameter written out), as `Estimator` drives it; so does
the online radius `rolling_radius.RollingRadiusEstimator.update`.
"""

from __future__ import annotations

import math
from typing import Final

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vd_observer_node.errors import ConfigurationError, InputShapeError
from vd_observer_node.estimation.drivetrain import (
    TORQUE_ENGINE,
    TORQUE_MEASURED,
    TORQUE_NONE,
    TORQUE_SOURCES,
)
from vd_observer_node.estimation.estimator import (
    LOAD_TRANSFER_SOURCES,
    SLOPE_ACCEL_SOURCES,
    Estimates,
    EstimatorConfig,
)
from vd_observer_node.estimation.faults import ESTIMATOR_FAULTS, FaultCounter
from vd_observer_node.estimation.vehicle import EstimatorVehicle
from vd_observer_node.kernel._jit import jit

__all__ = [
    'EST_SIZE',
    'E_AERO',
    'E_FX',
    'E_FZ',
    'E_MASS',
    'E_MASS_CONVERGED',
    'E_MASS_EXCITED',
    'E_MASS_STD',
    'E_MASS_USED',
    'E_MU',
    'E_MU_VALID',
    'E_RADIUS',
    'E_RADIUS_CONVERGED',
    'E_RADIUS_FREE',
    'E_RADIUS_STD',
    'E_RADIUS_USED',
    'E_ROLL',
    'E_SLIP',
    'E_SLOPE',
    'E_SLOPE_VALID',
    'E_T',
    'E_TORQUE_SOURCE',
    'CompiledEstimator',
    'EstimatorState',
    'engine_torques',
    'estimates_from_packed',
    'estimator_params',
    'estimator_reset',
    'estimator_update',
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

# packed estimate
E_T: Final = 0
E_FX: Final = 1
E_FZ: Final = 5
E_MU: Final = 9
E_SLIP: Final = 13
E_ROLL: Final = 17
E_AERO: Final = 21
E_SLOPE: Final = 22
E_SLOPE_VALID: Final = 23
E_MU_VALID: Final = 24
E_TORQUE_SOURCE: Final = 28
E_MASS: Final = 29
E_MASS_STD: Final = 30
E_MASS_CONVERGED: Final = 31
E_MASS_USED: Final = 32
E_MASS_EXCITED: Final = 33
E_RADIUS: Final = 34
E_RADIUS_STD: Final = 35
E_RADIUS_CONVERGED: Final = 36
E_RADIUS_USED: Final = 37
E_RADIUS_FREE: Final = 38
EST_SIZE: Final = 39

# parameters
_MASS, _GRAVITY, _RADIUS, _J_FRONT, _J_REAR, _DRAG, _C0, _C1, _REG = range(9)
_H, _A, _B, _L, _LT_CODE, _FORCE_TAU, _SLOPE_TAU, _ACC_CODE, _ORDER = range(9, 18)
_MIN_LOAD, _MIN_EXC, _MAX_SINE, _MIN_SPEED, _SLIP_EPS, _MAX_GAP, _MAX_MU = range(18, 25)
_STATIC_FRONT, _STATIC_REAR, _TORQUE_SOURCE = 25, 26, 27
# online mass (MassGradeConfig; theta bounds 1/m; the slope bound as a sine; warm-up [s])
_M_ON, _M_TAU, _M_GRADE_TAU, _M_FILTER_TAU, _M_NOISE, _M_STD_RATIO, _M_MIN_SPEED = range(28, 35)
_M_SLOPE_MIN_SPEED, _M_MIN_ACCEL, _M_MIN_FORCE, _M_MIN_CHANGE, _M_MAX_RATE = range(35, 40)
_M_THETA_MIN, _M_THETA_MAX, _M_CONV_RATIO, _M_MIN_EXC_TIME, _M_MAX_SINE = range(40, 45)
_M_MAX_GAP, _M_WARMUP = 45, 46
# online rolling radius (RollingRadiusConfig; the bounds in [m]; the forgetting time [s])
_R_ON, _R_TAU, _R_MIN_SPEED, _R_MAX_TORQUE, _R_MAX_ACCEL, _R_ACC_TAU = range(47, 53)
_R_NOISE, _R_STD_RATIO, _R_LO, _R_HI, _R_CONV_RATIO, _R_MIN_FREE_T = range(53, 59)
_R_MAX_GAP, _M_WAITS = 59, 60
N_PARAMS: Final = 61

# online mass state in scal: its stamp (nan: none), the low-pass started (0/1) and its two
# stages of F then v, the slow low-passes of F and y (nan: none), its own slope, excited
# time, time since the (re)start, converged (0/1), 1/m (nan: fresh, set from prm at the next
# update) and its variance, has a last estimate (0/1) and that estimate's mass, std,
# converged, used, excited
_M_T, _M_LP_ON, _M_F1, _M_F2, _M_V1, _M_V2, _M_F_SLOW, _M_Y_SLOW = range(3, 11)
_M_SLOPE, _M_EXC_T, _M_RUN, _M_CONV, _M_THETA, _M_COV, _M_HAS_LAST = range(11, 18)
_M_LAST = 18  # mass, std, converged, used, excited: 5 slots
# online radius state in scal: its stamp (nan: none), the dv/dt low-pass started (0/1) and
# its two stages, R (nan: fresh, set from prm at the next update) and its variance, free
# rolling time, converged (0/1), has a last estimate (0/1) and that estimate's radius, std,
# converged, used, free wheels
_R_T, _R_LP_ON, _R_V1, _R_V2, _R_THETA, _R_COV, _R_FREE_T, _R_CONV = range(23, 31)
_R_HAS_LAST, _R_LAST = 31, 32  # _R_LAST: 5 slots
_RADIUS_PREV = 37  # the radius of the last stamp's Fx [m] (nan: none)
N_SCAL: Final = 38
assert _M_COV == _M_THETA + 1 and _R_COV == _R_THETA + 1  # _rls1_bounded's layout

# fault slots (ESTIMATOR_FAULTS order) and the rejection count
_NON_FINITE_STAMP, _NON_FINITE_VALUE, _DUPLICATE, _OUT_OF_ORDER, _GAP, _JUMP_BACK = range(6)
_NON_FINITE_OUTPUT, _WHEEL_LIFT, _MU_RANGE, _SLOPE_RANGE, _ARCSIN = range(6, 11)
_MASS_CLAMPED, _RADIUS_CLAMPED, _REJECTED = 11, 12, 13
assert ESTIMATOR_FAULTS == (
    'non_finite_stamp',
    'non_finite_value',
    'duplicate_stamp',
    'out_of_order',
    'gap',
    'time_jump_back',
    'non_finite_output',
    'wheel_lift',
    'mu_out_of_range',
    'slope_out_of_range',
    'arcsin_domain',
    'mass_clamped',
    'radius_clamped',
)
_KMH_REFERENCE: Final = 160.0  # [km/h] speed scale of paper eq. 7 (estimators.py)


def estimator_params(
    vehicle: EstimatorVehicle, config: EstimatorConfig, torque_source: int = TORQUE_MEASURED
) -> FloatArray:
    """The ``prm`` array of the estimator kernel."""
    static = vehicle.static_wheel_loads
    prm = np.zeros(N_PARAMS)
    prm[_MASS] = vehicle.mass
    prm[_GRAVITY] = vehicle.gravity
    prm[_RADIUS] = vehicle.effective_radius
    prm[_J_FRONT] = vehicle.inertia_front
    prm[_J_REAR] = vehicle.inertia_rear
    prm[_DRAG] = vehicle.drag_factor
    prm[_C0] = vehicle.rolling_c0
    prm[_C1] = vehicle.rolling_c1
    prm[_REG] = vehicle.rolling_regularisation_speed
    prm[_H] = vehicle.cg_height
    prm[_A] = vehicle.cg_to_front_axle
    prm[_B] = vehicle.cg_to_rear_axle
    prm[_L] = vehicle.wheelbase
    prm[_LT_CODE] = LOAD_TRANSFER_SOURCES.index(config.load_transfer_source)
    prm[_FORCE_TAU] = config.force_filter_tau
    prm[_SLOPE_TAU] = config.slope_filter_tau
    prm[_ACC_CODE] = SLOPE_ACCEL_SOURCES.index(config.slope_accel_source)
    prm[_ORDER] = config.filter_order
    prm[_MIN_LOAD] = config.min_load_ratio * float(np.min(static))
    prm[_MIN_EXC] = config.min_excitation_ratio
    prm[_MAX_SINE] = math.sin(config.max_slope)
    prm[_MIN_SPEED] = config.min_speed
    prm[_SLIP_EPS] = config.slip_eps
    prm[_MAX_GAP] = config.max_gap
    prm[_MAX_MU] = config.max_mu
    prm[_STATIC_FRONT] = static[0]
    prm[_STATIC_REAR] = static[2]
    prm[_TORQUE_SOURCE] = torque_source
    m = config.mass
    on = config.mass_adaptation and torque_source == TORQUE_MEASURED
    prm[_M_ON] = 1.0 if on else 0.0
    prm[_M_TAU] = m.mass_tau
    prm[_M_GRADE_TAU] = m.grade_tau
    prm[_M_FILTER_TAU] = m.filter_tau
    prm[_M_NOISE] = m.accel_noise_density
    prm[_M_STD_RATIO] = m.initial_mass_std_ratio
    prm[_M_MIN_SPEED] = m.min_speed
    prm[_M_SLOPE_MIN_SPEED] = m.slope_min_speed
    prm[_M_MIN_ACCEL] = m.min_accel
    prm[_M_MIN_FORCE] = m.min_force_ratio
    prm[_M_MIN_CHANGE] = m.min_force_change_ratio
    prm[_M_MAX_RATE] = m.max_force_rate
    prm[_M_THETA_MIN] = 1.0 / (vehicle.mass * m.mass_max_ratio)
    prm[_M_THETA_MAX] = 1.0 / (vehicle.mass * m.mass_min_ratio)
    prm[_M_CONV_RATIO] = m.converged_std_ratio
    prm[_M_MIN_EXC_TIME] = m.min_excited_time
    prm[_M_MAX_SINE] = math.sin(m.max_slope)
    prm[_M_MAX_GAP] = m.max_gap
    prm[_M_WARMUP] = 3.0 * (2.0 * m.filter_tau + m.grade_tau)  # MassGradeEstimator.warmup
    r = config.radius
    r0 = vehicle.effective_radius
    prm[_R_ON] = 1.0 if config.radius_adaptation and torque_source == TORQUE_MEASURED else 0.0
    prm[_R_TAU] = r.tau
    prm[_R_MIN_SPEED] = r.min_speed
    prm[_R_MAX_TORQUE] = r.max_wheel_torque
    prm[_R_MAX_ACCEL] = r.max_accel
    prm[_R_ACC_TAU] = r.accel_filter_tau
    prm[_R_NOISE] = r.speed_noise_density
    prm[_R_STD_RATIO] = r.initial_std_ratio
    prm[_R_LO] = r.scale_min * r0
    prm[_R_HI] = r.scale_max * r0
    prm[_R_CONV_RATIO] = r.converged_std_ratio
    prm[_R_MIN_FREE_T] = r.min_free_time
    prm[_R_MAX_GAP] = r.max_gap
    prm[_M_WAITS] = 1.0 if config.mass_waits_for_radius else 0.0
    return prm


assert LOAD_TRANSFER_SOURCES == ('tire_forces', 'acceleration')
assert SLOPE_ACCEL_SOURCES == ('speed', 'observer')


class EstimatorState:
    """The estimator kernel's state arrays (see the module docstring)."""

    def __init__(self, order: int) -> None:
        """Zeroed state for filters of `order` stages."""
        self.scal = np.zeros(N_SCAL)
        self.scal[_M_THETA] = math.nan  # the online mass is set from prm at its first update
        self.scal[_R_THETA] = math.nan  # ... and so is the online radius
        self.scal[_RADIUS_PREV] = math.nan
        self.held = np.zeros(14)
        self.f_stages = np.zeros((order, 5))
        self.f_prev = np.zeros(5)
        self.f_meta = np.zeros(3)
        self.s_stages = np.zeros((order, 1))
        self.s_prev = np.zeros(1)
        self.s_meta = np.zeros(3)
        self.v_stages = np.zeros((order, 1))
        self.v_prev = np.zeros(1)
        self.v_meta = np.zeros(3)
        self.last = np.zeros(EST_SIZE)


# -- drivetrain (drivetrain.engine_wheel_torques, clutch_engaged) ---------------------------


@jit
def engine_torques(
    dprm: FloatArray,
    engine_torque: float,
    gear_value: float,
    engine_speed: float,
    omega: FloatArray,
    omega_dot: FloatArray,
    out: FloatArray,
) -> bool:
    """`engine_wheel_torques` into ``out`` (4,); returns `clutch_engaged`.

    ``dprm`` is `Drivetrain.params_array`: [n, final, reverse, eta, J_e, max slip,
    settle time, driven (4), ratios (n)]; the gear comes as a float and goes through
    `gear_number`. The settle time is the caller's (`kernel.chain._cascade_step`).
    """
    n_gears = int(dprm[0])
    ratio = math.nan
    if math.isfinite(gear_value) and gear_value == round(gear_value) and abs(gear_value) < 2.0**31:
        gear = int(gear_value)
        if gear == 0:
            ratio = 0.0
        elif gear == -1:
            ratio = -dprm[2] * dprm[1]
        elif 1 <= gear <= n_gears:
            ratio = dprm[11 + gear - 1] * dprm[1]
    if not math.isfinite(ratio):
        out[:] = math.nan
        return False
    if ratio == 0.0:
        out[:] = 0.0
        return True
    n_driven = dprm[7] + dprm[8] + dprm[9] + dprm[10]
    carrier_accel = 0.0
    carrier_speed = 0.0
    for i in range(4):
        carrier_accel += dprm[7 + i] * omega_dot[i]
        carrier_speed += dprm[7 + i] * omega[i]
    if math.isfinite(engine_torque):
        clutch = engine_torque - dprm[4] * ratio * (carrier_accel / n_driven)
        total = ratio * clutch
        eta = dprm[3]
        total = total * eta if clutch >= 0.0 else total / eta
        for i in range(4):
            out[i] = total * dprm[7 + i] / n_driven
    else:
        out[:] = math.nan
    if not math.isfinite(engine_speed):
        return True
    return bool(abs(engine_speed - ratio * (carrier_speed / n_driven)) <= dprm[5])


# -- low-pass filter (filters.LowPass) -------------------------------------------------------


@jit
def _lp_update(
    tau: float,
    stages: FloatArray,
    prev: FloatArray,
    meta: FloatArray,
    dt: float,
    x: FloatArray,
    out: FloatArray,
) -> None:
    d = x.shape[0]
    if tau == 0.0:
        out[:] = x
        return
    if meta[0] == 0.0:
        for j in range(stages.shape[0]):
            stages[j, :] = x
        meta[0] = 1.0
        out[:] = x
        return
    alpha = -math.expm1(-max(dt, 0.0) / tau)
    prev[:] = stages[-1]
    meta[1] = 1.0
    meta[2] = dt
    for i in range(d):
        signal = x[i]
        for j in range(stages.shape[0]):
            stages[j, i] += alpha * (signal - stages[j, i])
            signal = stages[j, i]
        out[i] = signal


@jit
def _lp_derivative0(stages: FloatArray, prev: FloatArray, meta: FloatArray) -> float:
    """`LowPass.derivative` of a one-dimensional filter."""
    if meta[1] == 0.0 or meta[2] <= 0.0 or meta[0] == 0.0:
        return 0.0
    return float((stages[-1, 0] - prev[0]) / meta[2])


@jit
def _empty(prm: FloatArray, t: float, est: FloatArray) -> None:
    est[:] = 0.0
    est[E_T] = t if math.isfinite(t) else 0.0
    est[E_FZ] = prm[_STATIC_FRONT]
    est[E_FZ + 1] = prm[_STATIC_FRONT]
    est[E_FZ + 2] = prm[_STATIC_REAR]
    est[E_FZ + 3] = prm[_STATIC_REAR]
    est[E_TORQUE_SOURCE] = prm[_TORQUE_SOURCE]
    _mass_fresh_out(prm, est)
    _radius_fresh_out(prm, est)


@jit
def _mass_fresh_out(prm: FloatArray, est: FloatArray) -> None:
    """The mass fields before any update (`Estimator._fixed_mass` after a reset)."""
    m0 = prm[_MASS]
    est[E_MASS_CONVERGED] = 0.0
    est[E_MASS_USED] = m0
    est[E_MASS_EXCITED] = 0.0
    if prm[_M_ON] == 0.0:
        est[E_MASS] = m0
        est[E_MASS_STD] = 0.0
        return
    theta = 1.0 / m0
    sigma = prm[_M_STD_RATIO] / m0
    est[E_MASS] = 1.0 / theta
    est[E_MASS_STD] = math.sqrt(max(sigma * sigma, 0.0)) / (theta * theta)


@jit
def _mass_reset(prm: FloatArray, scal: FloatArray) -> None:
    """`MassGradeEstimator.reset`: nominal 1/m and prior variance, filters empty."""
    m0 = prm[_MASS]
    scal[_M_T] = math.nan
    scal[_M_LP_ON] = 0.0
    scal[_M_F_SLOW] = math.nan
    scal[_M_Y_SLOW] = math.nan
    scal[_M_SLOPE] = 0.0
    scal[_M_EXC_T] = 0.0
    scal[_M_RUN] = 0.0
    scal[_M_CONV] = 0.0
    scal[_M_THETA] = 1.0 / m0
    sigma = prm[_M_STD_RATIO] / m0
    scal[_M_COV] = sigma * sigma
    scal[_M_HAS_LAST] = 0.0


@jit
def _mass_out(prm: FloatArray, scal: FloatArray, excited: bool, est: FloatArray) -> None:
    """`MassGradeEstimator._estimate` (its mass fields) into ``est``."""
    theta = scal[_M_THETA]
    mass = 1.0 / theta
    est[E_MASS] = mass
    est[E_MASS_STD] = math.sqrt(max(scal[_M_COV], 0.0)) / (theta * theta)
    est[E_MASS_CONVERGED] = scal[_M_CONV]
    est[E_MASS_USED] = mass if scal[_M_CONV] != 0.0 else prm[_MASS]
    est[E_MASS_EXCITED] = 1.0 if excited else 0.0


@jit
def _mass_held(prm: FloatArray, scal: FloatArray, est: FloatArray) -> None:
    """`MassGradeEstimator.current`: the last estimate, or the fresh one."""
    if scal[_M_HAS_LAST] != 0.0:
        for j in range(5):
            est[E_MASS + j] = scal[_M_LAST + j]
    else:
        _mass_out(prm, scal, False, est)


@jit
def _stamp_dt(last: float, t: float, max_gap: float) -> float:
    """`faults.classify_stamp` for a finite stamp ``t`` after ``last`` (nan: none): the step
    dt [s] (0.0 at the start), nan to hold (repeated or slightly older), -1.0 to restart."""
    if math.isnan(last):
        return 0.0
    dt = t - last
    if dt == 0.0 or (dt < 0.0 and -dt <= max_gap):
        return math.nan
    if dt < 0.0 or dt > max_gap:
        return -1.0
    return dt


@jit
def _rls1_bounded(
    scal: FloatArray,
    slot: int,
    phi: float,
    y: float,
    lam: float,
    noise_var: float,
    lo: float,
    hi: float,
) -> bool:
    """`mass_grade.rls_step` with one parameter on ``scal[slot]`` (its variance in
    ``scal[slot + 1]``), every product in the reference's order, then the estimators' clamp
    to ``[lo, hi]``; a non-finite result is dropped. Returns whether the clamp acted."""
    d = 1.0 / math.sqrt(lam)
    p = scal[slot + 1] * (d * d)
    theta = scal[slot]
    p_phi = p * phi
    k = p_phi / (phi * p_phi + noise_var)
    innovation = y - phi * theta
    a = 1.0 - k * phi
    p_new = a * p * a + noise_var * (k * k)
    p_new = 0.5 * (p_new + p_new)
    theta_new = theta + k * innovation
    clamped = False
    if math.isfinite(theta_new) and math.isfinite(p_new):
        if not lo <= theta_new <= hi:
            clamped = True
            theta_new = min(max(theta_new, lo), hi)
        scal[slot], scal[slot + 1] = theta_new, p_new
    return clamped


@jit
def _mass_update(
    prm: FloatArray, scal: FloatArray, t: float, sum_fx: float, speed: float, est: FloatArray
) -> bool:
    """`MassGradeEstimator.update` (its mass fields into ``est``); returns whether the
    mass clamp acted (the caller counts 'mass_clamped'). Squares are products on both
    sides: numba's ``x ** 2`` and CPython's pow() differ in the last bit."""
    if math.isnan(scal[_M_THETA]):
        _mass_reset(prm, scal)
    if not (math.isfinite(sum_fx) and math.isfinite(speed)):
        _mass_held(prm, scal, est)
        return False
    dt = _stamp_dt(scal[_M_T], t, prm[_M_MAX_GAP])
    if math.isnan(dt):
        _mass_held(prm, scal, est)
        return False
    if dt < 0.0:
        _mass_reset(prm, scal)
        dt = 0.0
    scal[_M_T] = t
    gravity = prm[_GRAVITY]
    m0 = prm[_MASS]
    weight = m0 * gravity
    direction = 1.0 if speed >= 0.0 else -1.0
    force = sum_fx - direction * prm[_DRAG] * speed * speed
    if dt == 0.0 or scal[_M_LP_ON] == 0.0:
        scal[_M_LP_ON] = 1.0
        scal[_M_F1] = force
        scal[_M_F2] = force
        scal[_M_V1] = speed
        scal[_M_V2] = speed
        accel = 0.0
        force_rate = 0.0
    else:
        tau = prm[_M_FILTER_TAU]
        w = 1.0 if tau <= 0.0 else -math.expm1(-dt / tau)
        f1, f2, v1, v2 = scal[_M_F1], scal[_M_F2], scal[_M_V1], scal[_M_V2]
        f1 += w * (force - f1)
        f2_new = f2 + w * (f1 - f2)
        v1 += w * (speed - v1)
        v2_new = v2 + w * (v1 - v2)
        accel = (v2_new - v2) / dt
        force_rate = (f2_new - f2) / dt
        scal[_M_F1], scal[_M_F2], scal[_M_V1], scal[_M_V2] = f1, f2_new, v1, v2_new
    f_lp, v_lp = scal[_M_F2], scal[_M_V2]
    c_r = prm[_C0] * (1.0 + prm[_C1] * abs(v_lp) / _KMH_REFERENCE)
    y = accel + direction * gravity * c_r * math.cos(scal[_M_SLOPE])
    if dt == 0.0 or math.isnan(scal[_M_F_SLOW]):
        scal[_M_F_SLOW], scal[_M_Y_SLOW] = f_lp, y
    else:
        w_slow = -math.expm1(-dt / prm[_M_GRADE_TAU])
        scal[_M_F_SLOW] += w_slow * (f_lp - scal[_M_F_SLOW])
        scal[_M_Y_SLOW] += w_slow * (y - scal[_M_Y_SLOW])
    f_hp = f_lp - scal[_M_F_SLOW]
    y_hp = y - scal[_M_Y_SLOW]
    scal[_M_RUN] += dt
    excited = (
        dt > 0.0
        and scal[_M_RUN] >= prm[_M_WARMUP]
        and abs(speed) >= prm[_M_MIN_SPEED]
        and (abs(accel) >= prm[_M_MIN_ACCEL] or abs(f_lp) >= prm[_M_MIN_FORCE] * weight)
        and abs(f_hp) >= prm[_M_MIN_CHANGE] * weight
        and abs(force_rate) <= prm[_M_MAX_RATE] * weight
    )
    clamped = False
    if excited:
        tau = prm[_M_TAU]
        lam = 1.0 if math.isinf(tau) or dt <= 0.0 else math.exp(-dt / tau)
        clamped = _rls1_bounded(
            scal, _M_THETA, f_hp, y_hp, lam, prm[_M_NOISE] * prm[_M_NOISE] / dt,
            prm[_M_THETA_MIN], prm[_M_THETA_MAX],
        )  # fmt: skip
        scal[_M_EXC_T] += dt
        theta = scal[_M_THETA]
        std = math.sqrt(max(scal[_M_COV], 0.0)) / (theta * theta)
        if scal[_M_EXC_T] >= prm[_M_MIN_EXC_TIME] and std * scal[_M_THETA] <= prm[_M_CONV_RATIO]:
            scal[_M_CONV] = 1.0
    if abs(speed) >= prm[_M_SLOPE_MIN_SPEED]:
        m_used = 1.0 / scal[_M_THETA] if scal[_M_CONV] != 0.0 else m0
        sine = (f_lp / m_used - y) / gravity
        bound = prm[_M_MAX_SINE]
        scal[_M_SLOPE] = math.asin(min(max(sine, -bound), bound))
    _mass_out(prm, scal, excited, est)
    for j in range(5):
        scal[_M_LAST + j] = est[E_MASS + j]
    scal[_M_HAS_LAST] = 1.0
    return clamped


@jit
def _mass_rescale(prm: FloatArray, scal: FloatArray, ratio: float) -> bool:
    """`MassGradeEstimator.rescale_force`; returns whether the clamp acted."""
    if math.isnan(scal[_M_THETA]):
        _mass_reset(prm, scal)
    if scal[_M_EXC_T] <= 0.0:
        return False
    theta = scal[_M_THETA] / ratio
    lo, hi = prm[_M_THETA_MIN], prm[_M_THETA_MAX]
    clamped = not lo <= theta <= hi
    scal[_M_THETA] = min(max(theta, lo), hi)
    scal[_M_COV] = scal[_M_COV] / (ratio * ratio)
    if scal[_M_LP_ON] != 0.0:
        scal[_M_F1] *= ratio
        scal[_M_F2] *= ratio
    if not math.isnan(scal[_M_F_SLOW]):
        scal[_M_F_SLOW] *= ratio
    return clamped


@jit
def _radius_fresh_out(prm: FloatArray, est: FloatArray) -> None:
    """The radius fields before any update (`Estimator._fixed_radius` after a reset)."""
    r0 = prm[_RADIUS]
    est[E_RADIUS] = r0
    est[E_RADIUS_CONVERGED] = 0.0
    est[E_RADIUS_USED] = r0
    est[E_RADIUS_FREE] = 0.0
    sigma = prm[_R_STD_RATIO] * r0
    est[E_RADIUS_STD] = math.sqrt(max(sigma * sigma, 0.0)) if prm[_R_ON] != 0.0 else 0.0


@jit
def _radius_reset(prm: FloatArray, scal: FloatArray) -> None:
    """`RollingRadiusEstimator.reset`: the file's radius, prior variance, filter empty."""
    r0 = prm[_RADIUS]
    scal[_R_T] = math.nan
    scal[_R_LP_ON] = 0.0
    scal[_R_THETA] = r0
    sigma = prm[_R_STD_RATIO] * r0
    scal[_R_COV] = sigma * sigma
    scal[_R_FREE_T] = 0.0
    scal[_R_CONV] = 0.0
    scal[_R_HAS_LAST] = 0.0


@jit
def _radius_out(prm: FloatArray, scal: FloatArray, free: int, est: FloatArray) -> None:
    """`RollingRadiusEstimator._estimate` into ``est``."""
    radius = scal[_R_THETA]
    est[E_RADIUS] = radius
    est[E_RADIUS_STD] = math.sqrt(max(scal[_R_COV], 0.0))
    est[E_RADIUS_CONVERGED] = scal[_R_CONV]
    est[E_RADIUS_USED] = radius if scal[_R_CONV] != 0.0 else prm[_RADIUS]
    est[E_RADIUS_FREE] = free


@jit
def _radius_held(prm: FloatArray, scal: FloatArray, est: FloatArray) -> None:
    """`RollingRadiusEstimator.current`: the last estimate, or the fresh one."""
    if math.isnan(scal[_R_THETA]):
        _radius_reset(prm, scal)
    if scal[_R_HAS_LAST] != 0.0:
        for j in range(5):
            est[E_RADIUS + j] = scal[_R_LAST + j]
    else:
        _radius_out(prm, scal, 0, est)


@jit
def _radius_update(
    prm: FloatArray,
    scal: FloatArray,
    t: float,
    omega: FloatArray,
    torque: FloatArray,
    speed: float,
    est: FloatArray,
) -> bool:
    """`RollingRadiusEstimator.update` on finite inputs (its fields into ``est``); returns
    whether the radius clamp acted (the caller counts 'radius_clamped')."""
    if math.isnan(scal[_R_THETA]):
        _radius_reset(prm, scal)
    dt = _stamp_dt(scal[_R_T], t, prm[_R_MAX_GAP])
    if math.isnan(dt):
        _radius_held(prm, scal, est)
        return False
    if dt < 0.0:
        _radius_reset(prm, scal)
        dt = 0.0
    scal[_R_T] = t
    if dt == 0.0 or scal[_R_LP_ON] == 0.0:
        scal[_R_LP_ON] = 1.0
        scal[_R_V1] = speed
        scal[_R_V2] = speed
        accel = 0.0
    else:
        tau = prm[_R_ACC_TAU]
        a = 1.0 if tau <= 0.0 else -math.expm1(-dt / tau)
        v1, v2 = scal[_R_V1], scal[_R_V2]
        v1 += a * (speed - v1)
        v2_new = v2 + a * (v1 - v2)
        accel = (v2_new - v2) / dt
        scal[_R_V1], scal[_R_V2] = v1, v2_new
    n_free = 0
    mean_omega = 0.0
    for i in range(4):
        if abs(torque[i]) <= prm[_R_MAX_TORQUE]:
            n_free += 1
            mean_omega += omega[i]
    mean_omega /= max(n_free, 1)
    clamped = False
    if not (
        dt > 0.0
        and n_free > 0
        and abs(speed) >= prm[_R_MIN_SPEED]
        and abs(accel) <= prm[_R_MAX_ACCEL]
    ):
        n_free = 0
    else:
        tau = prm[_R_TAU]
        lam = math.exp(-dt / tau) if math.isfinite(tau) else 1.0
        clamped = _rls1_bounded(
            scal, _R_THETA, mean_omega, speed, lam, prm[_R_NOISE] * prm[_R_NOISE] / dt,
            prm[_R_LO], prm[_R_HI],
        )  # fmt: skip
        scal[_R_FREE_T] += dt
        if (
            scal[_R_FREE_T] >= prm[_R_MIN_FREE_T]
            and math.sqrt(scal[_R_COV]) <= prm[_R_CONV_RATIO] * scal[_R_THETA]
        ):
            scal[_R_CONV] = 1.0
    _radius_out(prm, scal, n_free, est)
    for j in range(5):
        scal[_R_LAST + j] = est[E_RADIUS + j]
    scal[_R_HAS_LAST] = 1.0
    return clamped


@jit
def estimator_reset(
    held: FloatArray,
    scal: FloatArray,
    f_meta: FloatArray,
    s_meta: FloatArray,
    v_meta: FloatArray,
) -> None:
    """`Estimator.reset`: slope 0, filters empty, no last estimate (fault counts stay)."""
    scal[0] = math.nan
    scal[1] = 0.0
    scal[2] = 0.0
    scal[_M_THETA] = math.nan  # the online mass starts again (from prm) at the next update
    scal[_R_THETA] = math.nan  # ... and so does the online radius
    scal[_RADIUS_PREV] = math.nan
    held[:] = 0.0
    f_meta[:] = 0.0
    s_meta[:] = 0.0
    v_meta[:] = 0.0


@jit
def _estimate(
    prm: FloatArray,
    scal: FloatArray,
    f_stages: FloatArray,
    f_prev: FloatArray,
    f_meta: FloatArray,
    s_stages: FloatArray,
    s_prev: FloatArray,
    s_meta: FloatArray,
    v_stages: FloatArray,
    v_prev: FloatArray,
    v_meta: FloatArray,
    counts: NDArray[np.int64],
    t: float,
    dt: float,
    x: FloatArray,
    wheel_ok: BoolArray,
    body_ok: bool,
    est: FloatArray,
) -> None:
    """`Estimator._estimate` into the packed estimate ``est``."""
    gravity = prm[_GRAVITY]
    v = x[12]
    accel = x[13]
    no_torque = int(prm[_TORQUE_SOURCE]) == TORQUE_NONE
    all_ok = body_ok and wheel_ok[0] and wheel_ok[1] and wheel_ok[2] and wheel_ok[3]
    # the online radius (Estimator._radius_step) first: Fx and the slip use radius_used
    if prm[_R_ON] == 0.0:
        _radius_fresh_out(prm, est)
    elif all_ok:
        if _radius_update(prm, scal, t, x[0:4], x[8:12], v, est):
            counts[_RADIUS_CLAMPED] += 1
    else:
        _radius_held(prm, scal, est)
        est[E_RADIUS_FREE] = 0.0
    radius = est[E_RADIUS_USED]
    waiting = prm[_R_ON] != 0.0 and prm[_M_WAITS] != 0.0 and est[E_RADIUS_CONVERGED] == 0.0
    # Estimator: Fx uses another radius from now on, the mass is rescaled to it
    previous = scal[_RADIUS_PREV]
    rescale = not (waiting or math.isnan(previous) or radius == previous)
    if rescale and prm[_M_ON] != 0.0 and _mass_rescale(prm, scal, previous / radius):
        counts[_MASS_CLAMPED] += 1
    scal[_RADIUS_PREV] = radius
    fx_raw = np.zeros(4)
    if not no_torque:
        for i in range(4):
            inertia = prm[_J_FRONT] if i < 2 else prm[_J_REAR]
            fx_raw[i] = (x[8 + i] - inertia * x[4 + i]) / radius
    fx_sum = fx_raw[0] + fx_raw[1] + fx_raw[2] + fx_raw[3]
    # the online mass (Estimator._mass_step) first: the rest uses mass_used
    if prm[_M_ON] != 0.0 and waiting:
        # Estimator._fixed_mass: the mass estimator's last (or fresh) estimate, not excited
        if math.isnan(scal[_M_THETA]):
            _mass_reset(prm, scal)
        _mass_held(prm, scal, est)
        est[E_MASS_EXCITED] = 0.0
    elif prm[_M_ON] != 0.0:
        if _mass_update(prm, scal, t, fx_sum if all_ok else math.nan, v, est):
            counts[_MASS_CLAMPED] += 1
        if not all_ok:
            est[E_MASS_EXCITED] = 0.0
    else:
        _mass_fresh_out(prm, est)
    mass = est[E_MASS_USED]
    reg = prm[_REG]
    direction = math.tanh(v / reg) if reg > 0.0 else (1.0 if v > 0 else (-1.0 if v < 0 else v))
    aero = prm[_DRAG] * v * v
    aero_signed = math.copysign(aero, v)
    c_roll = prm[_C0] * (1.0 + prm[_C1] * abs(v) / _KMH_REFERENCE)
    slope_prev = scal[1]
    cos_prev, sin_prev = math.cos(slope_prev), math.sin(slope_prev)
    weight = mass * gravity
    rolling_sum = c_roll * weight * cos_prev
    if int(prm[_LT_CODE]) == 0 and not no_torque:
        ground = fx_sum - direction * rolling_sum
    else:
        ground = mass * accel + weight * sin_prev + aero_signed
    force_in = np.empty(5)
    force_in[:4] = fx_raw
    force_in[4] = ground
    filtered = np.empty(5)
    _lp_update(prm[_FORCE_TAU], f_stages, f_prev, f_meta, dt, force_in, filtered)
    ground_f = filtered[4]

    # wheel_loads, clamped at 0 twice as the reference (inside and outside)
    weight_normal = mass * gravity * cos_prev
    transfer = ground_f * prm[_H]
    front = max(0.5 * (weight_normal * prm[_B] - transfer) / prm[_L], 0.0)
    rear = max(0.5 * (weight_normal * prm[_A] + transfer) / prm[_L], 0.0)
    min_load = prm[_MIN_LOAD]
    lift = False
    for i in range(4):
        fz = front if i < 2 else rear
        fx = filtered[i]
        est[E_FX + i] = fx
        est[E_FZ + i] = fz
        est[E_ROLL + i] = c_roll * fz
        valid = (fz >= min_load) and (abs(fx) >= prm[_MIN_EXC] * fz) and math.isfinite(fx)
        mu = fx / fz if valid else 0.0
        valid = valid and wheel_ok[i] and not no_torque
        if fz < min_load:
            lift = True
        est[E_MU + i] = mu
        est[E_MU_VALID + i] = 1.0 if valid else 0.0
        # vd_common.vehicle.tire.slip_ratio on the slip velocity, as the reference calls it
        sv = x[i] * radius - v
        den = max(max(abs(sv + v), abs(v)), prm[_SLIP_EPS])
        est[E_SLIP + i] = sv / den
    if lift:
        counts[_WHEEL_LIFT] += 1
    implausible = False
    for i in range(4):
        if est[E_MU_VALID + i] != 0.0 and abs(est[E_MU + i]) > prm[_MAX_MU]:
            implausible = True
            est[E_MU_VALID + i] = 0.0
    if implausible:
        counts[_MU_RANGE] += 1
    for i in range(4):
        if est[E_MU_VALID + i] == 0.0:
            est[E_MU + i] = 0.0

    forces = fx_sum - direction * rolling_sum - aero_signed
    one = np.empty(1)
    net_out = np.empty(1)
    if int(prm[_ACC_CODE]) == 0 and prm[_SLOPE_TAU] > 0.0:
        one[0] = v
        _lp_update(prm[_SLOPE_TAU], v_stages, v_prev, v_meta, dt, one, net_out)
        accel_f = _lp_derivative0(v_stages, v_prev, v_meta)
        one[0] = forces
        _lp_update(prm[_SLOPE_TAU], s_stages, s_prev, s_meta, dt, one, net_out)
        net_f = net_out[0] - mass * accel_f
    else:
        one[0] = forces - mass * accel
        _lp_update(prm[_SLOPE_TAU], s_stages, s_prev, s_meta, dt, one, net_out)
        net_f = net_out[0]
    sine = net_f / weight
    in_range = abs(sine) <= prm[_MAX_SINE]
    usable = body_ok and abs(v) >= prm[_MIN_SPEED] and not no_torque
    if usable and not in_range:
        counts[_ARCSIN if abs(sine) > 1.0 else _SLOPE_RANGE] += 1
    slope_valid = in_range and usable
    if int(prm[_TORQUE_SOURCE]) == TORQUE_ENGINE and usable and not in_range:
        for i in range(4):  # a force the engine path cannot know of (the brakes)
            est[E_MU_VALID + i] = 0.0
            est[E_MU + i] = 0.0
    if slope_valid:
        scal[1] = math.asin(sine)
    est[E_T] = t
    est[E_AERO] = aero
    est[E_SLOPE] = scal[1]
    est[E_SLOPE_VALID] = 1.0 if slope_valid else 0.0
    est[E_TORQUE_SOURCE] = prm[_TORQUE_SOURCE]


@jit
def estimator_update(
    prm: FloatArray,
    scal: FloatArray,
    held: FloatArray,
    f_stages: FloatArray,
    f_prev: FloatArray,
    f_meta: FloatArray,
    s_stages: FloatArray,
    s_prev: FloatArray,
    s_meta: FloatArray,
    v_stages: FloatArray,
    v_prev: FloatArray,
    v_meta: FloatArray,
    last: FloatArray,
    counts: NDArray[np.int64],
    t: float,
    omega: FloatArray,
    omega_dot: FloatArray,
    speed: float,
    accel: float,
    torque: FloatArray,
    torque_ok: bool,
    est: FloatArray,
) -> None:
    """Estimate everything for stamp t into ``est`` (`Estimator.update`)."""
    packed = np.empty(14)
    packed[0:4] = omega
    packed[4:8] = omega_dot
    packed[8:12] = torque
    packed[12] = speed
    packed[13] = accel
    if not math.isfinite(t):
        counts[_NON_FINITE_STAMP] += 1
        counts[_REJECTED] += 1
        if scal[2] != 0.0:
            est[:] = last
        else:
            _empty(prm, t, est)
        return
    t_last = scal[0]
    if not math.isnan(t_last):
        restart = False
        if t <= t_last:
            if t_last - t <= prm[_MAX_GAP]:
                counts[_DUPLICATE if t == t_last else _OUT_OF_ORDER] += 1
                counts[_REJECTED] += 1
                if scal[2] != 0.0:
                    est[:] = last
                else:
                    _empty(prm, t, est)
                return
            counts[_JUMP_BACK] += 1
            restart = True
        elif t - t_last > prm[_MAX_GAP]:
            counts[_GAP] += 1
            restart = True
        if restart:  # reset, keeping the held inputs
            kept = held.copy()
            estimator_reset(held, scal, f_meta, s_meta, v_meta)
            held[:] = kept
    dt = 0.0 if math.isnan(scal[0]) else t - scal[0]
    scal[0] = t
    ok = np.empty(14, dtype=np.bool_)
    all_ok = True
    for j in range(14):
        ok[j] = math.isfinite(packed[j])
        all_ok = all_ok and ok[j]
    wheel_ok = np.ones(4, dtype=np.bool_)
    body_ok = True
    if not all_ok:
        counts[_NON_FINITE_VALUE] += 1
        for j in range(14):
            if not ok[j]:
                packed[j] = held[j]
        for i in range(4):
            wheel_ok[i] = ok[i] and ok[4 + i] and ok[8 + i] and ok[12]
        body_ok = False
    held[:] = packed
    if not torque_ok:
        wheel_ok[:] = False
        body_ok = False
    _estimate(
        prm, scal, f_stages, f_prev, f_meta, s_stages, s_prev, s_meta, v_stages, v_prev, v_meta,
        counts, t, dt, packed, wheel_ok, body_ok, est,
    )  # fmt: skip
    total = 0.0
    for j in range(E_FX, E_AERO):
        total += est[j]
    if not math.isfinite(total + est[E_AERO] + est[E_SLOPE]):
        counts[_NON_FINITE_OUTPUT] += 1
        estimator_reset(held, scal, f_meta, s_meta, v_meta)
        scal[0] = t
        _empty(prm, t, est)
    last[:] = est
    scal[2] = 1.0


def estimates_from_packed(est: FloatArray) -> Estimates:
    """The `Estimates` of a packed estimate (copies)."""
    return Estimates(
        t=float(est[E_T]),
        fx=est[E_FX : E_FX + 4].copy(),
        fz=est[E_FZ : E_FZ + 4].copy(),
        mu=est[E_MU : E_MU + 4].copy(),
        slip=est[E_SLIP : E_SLIP + 4].copy(),
        mu_valid=est[E_MU_VALID : E_MU_VALID + 4] != 0.0,
        rolling=est[E_ROLL : E_ROLL + 4].copy(),
        aero=float(est[E_AERO]),
        slope=float(est[E_SLOPE]),
        slope_valid=bool(est[E_SLOPE_VALID] != 0.0),
        torque_source=int(est[E_TORQUE_SOURCE]),
        mass=float(est[E_MASS]),
        mass_std=float(est[E_MASS_STD]),
        mass_converged=bool(est[E_MASS_CONVERGED] != 0.0),
        mass_used=float(est[E_MASS_USED]),
        mass_excited=bool(est[E_MASS_EXCITED] != 0.0),
        radius=float(est[E_RADIUS]),
        radius_std=float(est[E_RADIUS_STD]),
        radius_converged=bool(est[E_RADIUS_CONVERGED] != 0.0),
        radius_used=float(est[E_RADIUS_USED]),
        radius_free_wheels=int(est[E_RADIUS_FREE]),
    )


def _wheels(name: str, value: ArrayLike) -> FloatArray:
    array = np.ascontiguousarray(value, dtype=np.float64)
    if array.shape != (4,):
        raise InputShapeError(f'{name} must have shape (4,), got {array.shape}')
    return array


class CompiledEstimator:
    """Drop-in for `estimator.Estimator` running `estimator_update` (same API)."""

    def __init__(
        self,
        vehicle: EstimatorVehicle,
        config: EstimatorConfig | None = None,
        torque_source: int = TORQUE_MEASURED,
    ) -> None:
        """Create the estimator (arguments as `Estimator`).

        Raises:
            ConfigurationError: unknown torque_source.
        """
        if torque_source not in range(len(TORQUE_SOURCES)):
            raise ConfigurationError(f'unknown torque_source {torque_source!r}')
        self.vehicle = vehicle
        self.config = config or EstimatorConfig()
        self.torque_source = int(torque_source)
        self.prm = estimator_params(vehicle, self.config, self.torque_source)
        self.s = EstimatorState(self.config.filter_order)
        self.counts = np.zeros(len(ESTIMATOR_FAULTS) + 1, dtype=np.int64)
        self._faults = FaultCounter(ESTIMATOR_FAULTS)
        self._synced = np.zeros_like(self.counts)
        self._est = np.zeros(EST_SIZE)
        self.reset()
        # compile (or load from numba's cache) now, on scratch state, not at the first sample
        scratch = EstimatorState(self.config.filter_order)
        zeros = np.zeros(4)
        estimator_update(
            self.prm, scratch.scal, scratch.held, scratch.f_stages, scratch.f_prev,
            scratch.f_meta, scratch.s_stages, scratch.s_prev, scratch.s_meta, scratch.v_stages,
            scratch.v_prev, scratch.v_meta, scratch.last, self.counts.copy(), 0.0, zeros, zeros,
            0.0, 0.0, zeros, True, self._est,
        )  # fmt: skip

    def reset(self) -> None:
        """Forget the history (slope back to 0, filters empty); fault counters stay."""
        s = self.s
        estimator_reset(s.held, s.scal, s.f_meta, s.s_meta, s.v_meta)

    @property
    def rejected_count(self) -> int:
        """Stamps rejected (non-finite, repeated or slightly older)."""
        return int(self.counts[_REJECTED])

    @property
    def last(self) -> Estimates | None:
        """The last estimate (None before the first)."""
        return estimates_from_packed(self.s.last) if self.s.scal[2] != 0.0 else None

    @property
    def faults(self) -> FaultCounter:
        """Input faults per kind, as the reference counts them (synced from the kernel)."""
        self.sync_faults()
        return self._faults

    def sync_faults(self) -> None:
        """Copy the kernel's fault counts into `faults` (call before `faults.report()`)."""
        delta = self.counts - self._synced
        for slot in np.flatnonzero(delta[: len(ESTIMATOR_FAULTS)]).tolist():
            self._faults.count(ESTIMATOR_FAULTS[slot], int(delta[slot]))
        self._synced = self.counts.copy()

    def update(
        self,
        t: float,
        omega: ArrayLike,
        omega_dot: ArrayLike,
        speed: float,
        accel: float,
        torque: ArrayLike,
        torque_ok: bool = True,
    ) -> Estimates:
        """Estimate everything for stamp t (`Estimator.update`).

        Raises:
            InputShapeError: a per-wheel input is not of shape (4,).
        """
        s = self.s
        estimator_update(
            self.prm, s.scal, s.held, s.f_stages, s.f_prev, s.f_meta, s.s_stages, s.s_prev,
            s.s_meta, s.v_stages, s.v_prev, s.v_meta, s.last, self.counts, float(t),
            _wheels('omega', omega), _wheels('omega_dot', omega_dot), float(speed), float(accel),
            _wheels('torque', torque), bool(torque_ok), self._est,
        )  # fmt: skip
        return estimates_from_packed(self._est)
