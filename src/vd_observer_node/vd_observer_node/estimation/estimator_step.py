"""The estimator's per-stamp step (compiled), over named records.

The math of `estimator.Estimator` (see its module docstring and docs/estimation.md): the
wheel spin balance, the load transfer (both sources), utilised friction and its validity,
slip, rolling and aero resistance, the slope from the filtered force balance (both
acceleration sources), held inputs, resets and every fault count, with the online radius
(`rolling_radius.radius_update`) and mass (`mass_grade_step.mass_update`) inside.

Records: `ESTIMATOR_PARAMS` (built by `estimator.estimator_params`; the online mass's and
radius's settings nested as ``p.mass`` and ``p.radius``), `ESTIMATOR_STATE` (the online mass's
and radius's states nested as ``s.mass``, ``s.radius``; the last estimate ``s.last``; the
fault counts) and `ESTIMATES`, one estimate with the fields of `estimator.Estimates`
(per-wheel fields of shape (4,)). The low-pass filters' stages, of the configured order, are
plain arrays next to them: force (order, 5), slope (order, 1), speed (order, 1).
"""

from __future__ import annotations

import math
from typing import Any, Final, NamedTuple

import numpy as np
from numpy.typing import NDArray

from vd_observer_node.estimation.axle_loads import LOAD_MODEL, axle_transfer_step
from vd_observer_node.estimation.drivetrain import TORQUE_ENGINE, TORQUE_NONE
from vd_observer_node.estimation.faults import ESTIMATOR_FAULTS
from vd_observer_node.estimation.filters import (
    LOWPASS_META,
    lowpass_bridge,
    lowpass_derivative,
    lowpass_gap,
    lowpass_input,
    lowpass_reset,
    lowpass_update,
)
from vd_observer_node.estimation.formulas import rolling_coefficient_at
from vd_observer_node.estimation.mass_grade_step import (
    MASS_GRADE_FAULTS,
    MASS_PARAMS,
    MASS_STATE,
    mass_held,
    mass_rescale,
    mass_reset,
    mass_update,
)
from vd_observer_node.estimation.rolling_radius import (
    RADIUS_PARAMS,
    RADIUS_STATE,
    ROLLING_RADIUS_FAULTS,
    radius_held,
    radius_reset,
    radius_update,
)
from vd_observer_node.kernel._jit import jit, new_record

__all__ = [
    'ESTIMATES',
    'ESTIMATOR_INPUT',
    'ESTIMATOR_PARAMS',
    'ESTIMATOR_STATE',
    'GAP_FORCE_CHANGE',
    'HELD_INPUTS',
    'REJECTED_SLOT',
    'SPEED_SAMPLES_MAX',
    'EstimatorParts',
    'estimator_reset',
    'estimator_update',
    'estimator_update_arrays',
    'new_estimator_input',
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: One estimate: the fields of `estimator.Estimates`, per-wheel ones of shape (4,)
#: (``mu_valid`` as 0/1).
ESTIMATES: Final = np.dtype(
    [
        ('t', 'f8'),
        ('fx', 'f8', (4,)),
        ('fz', 'f8', (4,)),
        ('mu', 'f8', (4,)),
        ('slip', 'f8', (4,)),
        ('mu_valid', 'u1', (4,)),  # 0/1: numba has no nested arrays of bool
        ('rolling', 'f8', (4,)),
        ('aero', 'f8'),
        ('slope', 'f8'),
        ('slope_valid', 'b1'),
        ('torque_source', 'i8'),
        ('mass', 'f8'),
        ('mass_std', 'f8'),
        ('mass_converged', 'b1'),
        ('mass_used', 'f8'),
        ('mass_excited', 'b1'),
        ('radius', 'f8'),
        ('radius_std', 'f8'),
        ('radius_converged', 'b1'),
        ('radius_used', 'f8'),
        ('radius_free_wheels', 'i8'),
    ],
    align=True,
)
#: The settings as the step uses them: the vehicle (file values), the `EstimatorConfig`
#: fields (sources as codes: the index in `LOAD_TRANSFER_SOURCES` and `SLOPE_ACCEL_SOURCES`;
#: the minimum load in [N]; the slope bound as a sine), the static wheel loads [N], the
#: torque source code, which online parts run and their settings.
ESTIMATOR_PARAMS: Final = np.dtype(
    [
        ('mass', 'f8'),
        ('gravity', 'f8'),
        ('radius', 'f8'),
        ('inertia_front', 'f8'),
        ('inertia_rear', 'f8'),
        ('drag', 'f8'),
        ('rolling_c0', 'f8'),
        ('rolling_c1', 'f8'),
        ('rolling_reg', 'f8'),
        ('cg_height', 'f8'),
        ('cg_to_front', 'f8'),
        ('cg_to_rear', 'f8'),
        ('wheelbase', 'f8'),
        ('load_transfer', 'i8'),
        ('force_tau', 'f8'),
        ('slope_tau', 'f8'),
        ('slope_accel', 'i8'),
        ('min_load', 'f8'),
        ('min_excitation', 'f8'),
        ('max_sine', 'f8'),
        ('min_speed', 'f8'),
        ('slip_eps', 'f8'),
        ('max_gap', 'f8'),
        ('max_mu', 'f8'),
        ('static_front', 'f8'),
        ('static_rear', 'f8'),
        ('torque_source', 'i8'),
        ('mass_on', 'b1'),
        ('radius_on', 'b1'),
        ('mass_waits', 'b1'),
        ('mass_p', MASS_PARAMS),
        ('radius_p', RADIUS_PARAMS),
        ('loads', LOAD_MODEL),
    ],
    align=True,
)
#: The fault counts (`ESTIMATOR_STATE.counts`): one per kind of `ESTIMATOR_FAULTS`, at its
#: place in that list, then the rejected stamps.
REJECTED_SLOT: Final = len(ESTIMATOR_FAULTS)
_NON_FINITE_STAMP: Final = ESTIMATOR_FAULTS.index('non_finite_stamp')
_NON_FINITE_VALUE: Final = ESTIMATOR_FAULTS.index('non_finite_value')
_DUPLICATE: Final = ESTIMATOR_FAULTS.index('duplicate_stamp')
_OUT_OF_ORDER: Final = ESTIMATOR_FAULTS.index('out_of_order')
_GAP: Final = ESTIMATOR_FAULTS.index('gap')
_JUMP_BACK: Final = ESTIMATOR_FAULTS.index('time_jump_back')
_NON_FINITE_OUTPUT: Final = ESTIMATOR_FAULTS.index('non_finite_output')
_WHEEL_LIFT: Final = ESTIMATOR_FAULTS.index('wheel_lift')
_MU_RANGE: Final = ESTIMATOR_FAULTS.index('mu_out_of_range')
_SLOPE_RANGE: Final = ESTIMATOR_FAULTS.index('slope_out_of_range')
_ARCSIN: Final = ESTIMATOR_FAULTS.index('arcsin_domain')
_MASS_CLAMPED: Final = ESTIMATOR_FAULTS.index('mass_clamped')
_RADIUS_CLAMPED: Final = ESTIMATOR_FAULTS.index('radius_clamped')
#: the clamp count of the online mass's and radius's own fault lists (the same place in both)
_M_CLAMPED: Final = MASS_GRADE_FAULTS.index('mass_clamped')
assert ROLLING_RADIUS_FAULTS.index('radius_clamped') == _M_CLAMPED
#: A gap the slope low-pass bridges (`filters.lowpass_gap`) after which the balance's input
#: (the forces, or forces - m*dv/dt) is further than this share of the weight [-] from the
#: trend before the gap hid a transient the bridge could only interpolate: the slope is then
#: invalid (held) until the filter has forgotten the bridge, (order + 1) * slope_filter_tau
#: after the gap.
GAP_FORCE_CHANGE: Final = 0.05

#: The most body-speed samples one stamp brings (the newest of them; more arrive only after
#: several lost wheel stamps, or with a speed much faster than the wheels).
SPEED_SAMPLES_MAX: Final = 16

#: One stamp's inputs of the estimator: omega [rad/s] and omega_dot [rad/s^2] per wheel (the
#: wheel observer's), torque [N m] per wheel (drive minus brake), speed [m/s] and accel
#: [m/s^2] of the body, torque_ok: False where the torque source cannot be trusted at the
#: stamp (the engine path while the clutch slips: mu and slope are then invalid), and the
#: measured body-speed samples stamped since the previous stamp and before this one, which the
#: slope's speed low-pass takes at their own stamps (stamps [s] and speeds [m/s], oldest
#: first, nan after the last: a sample whose wheel stamp was lost still counts).
_INPUT_FIELDS: Final = [
    ('omega', 'f8', (4,)),
    ('omega_dot', 'f8', (4,)),
    ('torque', 'f8', (4,)),
    ('speed', 'f8'),
    ('accel', 'f8'),
]
ESTIMATOR_INPUT: Final = np.dtype(
    [
        *_INPUT_FIELDS,
        ('torque_ok', 'b1'),
        ('speed_stamps', 'f8', (SPEED_SAMPLES_MAX,)),
        ('speed_samples', 'f8', (SPEED_SAMPLES_MAX,)),
    ],
    align=True,
)


def new_estimator_input() -> np.record:
    """An `ESTIMATOR_INPUT` record without speed samples (``speed_stamps`` nan: the stamp's
    own speed only), living in a 1-element array (`kernel._jit.record_array`)."""
    record = new_record(ESTIMATOR_INPUT)
    record.speed_stamps[:] = math.nan
    return record


#: The last finite inputs, held where a stamp's are not: `ESTIMATOR_INPUT` but its
#: ``torque_ok``.
HELD_INPUTS: Final = np.dtype(_INPUT_FIELDS, align=True)

#: The estimator's memory: last stamp (nan: none), slope [rad], whether ``last`` holds an
#: estimate, the radius of the last stamp's Fx (nan: none), the stamp until which the slope
#: settles after a gap (`GAP_FORCE_CHANGE`; -inf: none), the last finite inputs (omega,
#: omega_dot, torque (4 each), v, accel), the three low-passes' previous output and input and
#: bookkeeping, the stamp of the speed low-pass's last sample (nan: none), the chassis's
#: positions and rates (`axle_loads`; nan: not started), the online mass's
#: and radius's states, the fault counts, and a mass known from
#: elsewhere that replaces the file's or the online mass's (nan: none; `cascade_step` sets it
#: from the IMU's regression, `imu_grade`).
ESTIMATOR_STATE: Final = np.dtype(
    [
        ('t', 'f8'),
        ('slope', 'f8'),
        ('has_last', 'b1'),
        ('radius_prev', 'f8'),
        ('settle_until', 'f8'),
        ('held', HELD_INPUTS),
        ('force_prev', 'f8', (2, 5)),
        ('slope_prev', 'f8', (2, 1)),
        ('speed_prev', 'f8', (2, 1)),
        ('force_lp', LOWPASS_META),
        ('slope_lp', LOWPASS_META),
        ('speed_lp', LOWPASS_META),
        ('speed_t', 'f8'),
        ('axle_pos', 'f8', (4,)),
        ('axle_vel', 'f8', (4,)),
        ('mass_s', MASS_STATE),
        ('radius_s', RADIUS_STATE),
        ('last', ESTIMATES),
        ('counts', 'i8', (len(ESTIMATOR_FAULTS) + 1,)),
        ('mass_known', 'f8'),
    ],
    align=True,
)


class EstimatorParts(NamedTuple):
    """The estimator's records and arrays, as its step function takes them (records as the
    1-element arrays they live in: numba types arrays on its fast path; a NamedTuple, as the
    low-pass stages' length is a setting).

    Attributes:
        params: shape (1,), `ESTIMATOR_PARAMS`.
        state: shape (1,), `ESTIMATOR_STATE`.
        force_stages: (order, 5) the force low-pass stages.
        slope_stages: (order, 1) the slope low-pass stages.
        speed_stages: (order, 1) the speed low-pass stages.
    """

    params: NDArray[Any]
    state: NDArray[Any]
    force_stages: FloatArray
    slope_stages: FloatArray
    speed_stages: FloatArray


@jit
def estimator_reset(p: np.record, s: np.record) -> None:
    """Forget the history: slope 0, filters empty, no last estimate, no inputs to hold, the
    online mass and radius from the start (fault counts stay)."""
    _forget(p, s)
    h = s.held
    h.omega[:] = 0.0
    h.omega_dot[:] = 0.0
    h.torque[:] = 0.0
    h.speed = 0.0
    h.accel = 0.0


@jit
def _forget(p: np.record, s: np.record) -> None:
    """`estimator_reset` but for the inputs held (a restart after a gap still holds them)."""
    s.t = math.nan
    s.slope = 0.0
    s.has_last = False
    s.radius_prev = math.nan
    s.settle_until = -math.inf
    lowpass_reset(s.force_lp)
    lowpass_reset(s.slope_lp)
    lowpass_reset(s.speed_lp)
    s.speed_t = math.nan
    s.axle_pos[:] = math.nan
    s.axle_vel[:] = 0.0
    mass_reset(p.mass_p, s.mass_s)
    radius_reset(p.radius_p, s.radius_s)
    s.mass_known = math.nan


@jit
def _mass_fields(p: np.record, s: np.record, est: np.record) -> None:
    """The mass fields where nothing was estimated: the file's, or the online mass's last."""
    if p.mass_on:
        mass_held(p.mass_p, s.mass_s)
        o = s.mass_s.out
        est.mass, est.mass_std, est.mass_converged = o.mass, o.mass_std, o.converged
        est.mass_used, est.mass_excited = o.mass_used, o.excited
    else:
        est.mass, est.mass_std, est.mass_converged = p.mass, 0.0, False
        est.mass_used, est.mass_excited = p.mass, False


@jit
def _radius_fields(p: np.record, s: np.record, est: np.record) -> None:
    """The radius fields (free wheels as the online radius's last, or the file's radius)."""
    if p.radius_on:
        radius_held(p.radius_p, s.radius_s)
        o = s.radius_s.out
        est.radius, est.radius_std, est.radius_converged = o.radius, o.radius_std, o.converged
        est.radius_used, est.radius_free_wheels = o.radius_used, o.free_wheels
    else:
        est.radius, est.radius_std, est.radius_converged = p.radius, 0.0, False
        est.radius_used, est.radius_free_wheels = p.radius, 0


@jit
def _empty(p: np.record, s: np.record, t: float, est: np.record) -> None:
    """No estimate: zero forces, static loads, nothing valid; mass and radius as held."""
    est.t = t if math.isfinite(t) else 0.0
    est.fx[:] = 0.0
    for i in range(4):
        est.fz[i] = p.static_front if i < 2 else p.static_rear
    est.mu[:] = 0.0
    est.slip[:] = 0.0
    est.mu_valid[:] = 0
    est.rolling[:] = 0.0
    est.aero = 0.0
    est.slope = 0.0
    est.slope_valid = False
    est.torque_source = p.torque_source
    _mass_fields(p, s, est)
    _radius_fields(p, s, est)
    est.mass_converged = False
    est.mass_excited = False
    est.radius_converged = False
    est.radius_free_wheels = 0


@jit
def _copy(src: np.record, dst: np.record) -> None:
    """One `ESTIMATES` record into another, field by field."""
    dst.t = src.t
    dst.fx[:] = src.fx
    dst.fz[:] = src.fz
    dst.mu[:] = src.mu
    dst.slip[:] = src.slip
    dst.mu_valid[:] = src.mu_valid
    dst.rolling[:] = src.rolling
    dst.aero, dst.slope, dst.slope_valid = src.aero, src.slope, src.slope_valid
    dst.torque_source = src.torque_source
    dst.mass, dst.mass_std, dst.mass_converged = src.mass, src.mass_std, src.mass_converged
    dst.mass_used, dst.mass_excited = src.mass_used, src.mass_excited
    dst.radius, dst.radius_std = src.radius, src.radius_std
    dst.radius_converged, dst.radius_used = src.radius_converged, src.radius_used
    dst.radius_free_wheels = src.radius_free_wheels


@jit
def _online_radius(
    p: np.record, s: np.record, t: float, x: np.record, ok: bool, est: np.record
) -> None:
    """Advance the online radius (held where not every input was finite and trusted)."""
    if p.radius_on and ok:
        r = s.radius_s
        clamped = r.counts[_M_CLAMPED]
        radius_update(p.radius_p, r, t, x.omega, x.torque, x.speed)
        if r.counts[_M_CLAMPED] != clamped:
            s.counts[_RADIUS_CLAMPED] += 1
        _radius_fields(p, s, est)
    else:
        _radius_fields(p, s, est)
        est.radius_free_wheels = 0


@jit
def _online_mass(
    p: np.record, s: np.record, t: float, sum_fx: float, v: float, ok: bool, waiting: bool,
    est: np.record,
) -> None:  # fmt: skip
    """Advance the online mass; a stamp not all finite and trusted gives it a nan force (it
    holds); while it waits for the radius it is not called."""
    if p.mass_on and not waiting:
        m = s.mass_s
        if p.radius_on:
            # Fx is T/R_used: the mass carries R_used's error, the squared distance to the
            # radius estimate plus that estimate's variance (relative)
            r_used = est.radius_used
            bias = est.radius - r_used
            m.scale_var = (bias * bias + est.radius_std * est.radius_std) / (r_used * r_used)
        clamped = m.counts[_M_CLAMPED]
        mass_update(p.mass_p, m, t, sum_fx if ok else math.nan, v)
        if m.counts[_M_CLAMPED] != clamped:
            s.counts[_MASS_CLAMPED] += 1
        _mass_fields(p, s, est)
        # a held stamp (skipped) did not update the mass, whatever the last one did
        est.mass_excited = est.mass_excited and ok
    else:
        _mass_fields(p, s, est)
        est.mass_excited = False


@jit
def _bridge_speed(
    tau: float, s: np.record, v_stages: FloatArray, s_stages: FloatArray, dt: float,
    forces: float, mass: float,
) -> float:  # fmt: skip
    """Across a gap (`filters.lowpass_gap`), advance the speed low-pass with the speed the
    forces make at the slope of before the gap; return the rest of the step [s].

    The forces' low-pass bridges the gap with its input interpolated linearly to ``forces``;
    the speed's would bridge with a straight line to the new sample, whose noise then sets
    dv/dt over the whole gap. Instead the speed follows m dv/dt = F(s) - N, with F that same
    line and N the balance's force before the gap (the filtered forces minus m dv/dt): the
    slope holds across the gap, and the new sample enters over one sample period, as any.
    """
    span = lowpass_gap(tau, s.speed_lp, dt)
    if span <= 0.0:
        return dt
    level, _ = lowpass_input(tau, v_stages, s.speed_prev, s.speed_lp, 0)
    accel_f = np.zeros(1)
    lowpass_derivative(v_stages, s.speed_prev, s.speed_lp, accel_f)
    balance = s_stages[-1, 0] - mass * accel_f[0]
    f0 = s.slope_prev[1, 0]
    x0 = np.full(1, level)
    rate = np.full(1, (f0 - balance) / mass)
    curve = np.full(1, (forces - f0) / (2.0 * mass * dt))
    lowpass_bridge(tau, v_stages, s.speed_prev, span, dt - span, x0, rate, curve)
    return dt - span


@jit
def _speed_samples_before(parts: EstimatorParts, t: float, dt: float, inp: np.record) -> None:
    """Feed the slope's speed low-pass the stamp's speed samples stamped before it, each at
    its own stamp (the stamp's own speed follows in `_estimate`).

    Only between two stamps of a running filter that are not a gap (`filters.lowpass_gap`:
    over a gap the speed is bridged along the force balance, `_bridge_speed`), and only where
    the slope takes m dv/dt from the speed.
    """
    p, s = parts.params[0], parts.state[0]
    tau = p.slope_tau
    if not (p.slope_accel == 0 and tau > 0.0 and dt > 0.0 and s.speed_lp.started):
        return
    if math.isnan(s.speed_t) or lowpass_gap(tau, s.speed_lp, dt) > 0.0:
        return
    sample = np.empty(1)
    out = np.empty(1)
    for j in range(inp.speed_stamps.shape[0]):
        at = inp.speed_stamps[j]
        if not at < t:  # nan: no more; the stamp's own sample is the stamp's speed
            break
        if at <= s.speed_t or not math.isfinite(inp.speed_samples[j]):
            continue
        sample[0] = inp.speed_samples[j]
        lowpass_update(tau, parts.speed_stages, s.speed_prev, s.speed_lp, at - s.speed_t,
                       sample, out)  # fmt: skip
        s.speed_t = at


@jit
def _take(value: float, held: FloatArray, i: int) -> bool:
    """Whether ``value`` is finite; if so it is ``held[i]`` from now on."""
    if math.isfinite(value):
        held[i] = value
        return True
    return False


@jit
def _estimate(
    parts: EstimatorParts, t: float, dt: float, x: np.record, wheel_ok: BoolArray,
    body_ok: bool, torque_known: bool, est: np.record,
) -> None:  # fmt: skip
    """Every estimate of an accepted stamp from the inputs ``x`` (`HELD_INPUTS`); without
    ``torque_known`` (a torque not finite at this stamp) no Fx is computed from an old one:
    Fx 0 and the load transfer from the acceleration, as without torque."""
    p, s = parts.params[0], parts.state[0]
    f_stages, s_stages, v_stages = parts.force_stages, parts.slope_stages, parts.speed_stages
    gravity = p.gravity
    v = x.speed
    accel = x.accel
    no_torque = p.torque_source == TORQUE_NONE or not torque_known
    all_ok = body_ok and wheel_ok[0] and wheel_ok[1] and wheel_ok[2] and wheel_ok[3]
    # the online radius first: Fx and the slip use radius_used
    _online_radius(p, s, t, x, all_ok, est)
    radius = est.radius_used
    waiting = p.radius_on and p.mass_waits and not est.radius_converged
    # Fx uses another radius from now on: the mass learnt so far is rescaled to it
    previous = s.radius_prev
    rescale = not (waiting or math.isnan(previous) or radius == previous)
    if rescale and p.mass_on and mass_rescale(p.mass_p, s.mass_s, previous / radius):
        s.counts[_MASS_CLAMPED] += 1
    s.radius_prev = radius
    # the wheel spin balance; without the torque the balance has no force (not -J*omega_dot/R)
    fx_raw = np.zeros(4)
    if not no_torque:
        for i in range(4):
            inertia = p.inertia_front if i < 2 else p.inertia_rear
            fx_raw[i] = (x.torque[i] - inertia * x.omega_dot[i]) / radius
    fx_sum = fx_raw[0] + fx_raw[1] + fx_raw[2] + fx_raw[3]
    # then the online mass: the rest uses mass_used
    _online_mass(p, s, t, fx_sum, v, all_ok, waiting, est)
    if s.mass_known > 0.0:
        # a mass known from elsewhere (the IMU's regression) is the balance's
        est.mass_used = s.mass_known
    mass = est.mass_used
    # the simulator's smooth sign of the rolling resistance; drag is exactly k*v*|v|
    reg = p.rolling_reg
    direction = math.tanh(v / reg) if reg > 0.0 else (1.0 if v > 0 else (-1.0 if v < 0 else v))
    aero = p.drag * v * v
    aero_signed = math.copysign(aero, v)
    c_roll = rolling_coefficient_at(p.rolling_c0, p.rolling_c1, v)
    cos_prev, sin_prev = math.cos(s.slope), math.sin(s.slope)
    weight = mass * gravity
    # sum(Fz) = m g cos(alpha) in both load-transfer forms: the rolling sum needs no transfer
    rolling_sum = c_roll * weight * cos_prev
    if p.load_transfer == 0 and not no_torque:
        ground = fx_sum - direction * rolling_sum
    else:
        ground = mass * accel + weight * sin_prev + aero_signed
    force_in = np.empty(5)
    force_in[:4] = fx_raw
    force_in[4] = ground
    filtered = np.empty(5)
    lowpass_update(p.force_tau, f_stages, s.force_prev, s.force_lp, dt, force_in, filtered)
    ground_f = filtered[4]

    # the moment balance; a load transfer beyond the axle's load lifts the wheel: Fz = 0
    weight_normal = mass * gravity * cos_prev
    if p.loads.on:
        # through the chassis's heave and pitch on its springs (`axle_loads`); a force no wheel
        # can use (the engine path while the clutch slips) gives its settled transfer, as a
        # rigid body would, and does not swing the chassis for the next second
        if not (wheel_ok[0] or wheel_ok[1] or wheel_ok[2] or wheel_ok[3]):
            s.axle_pos[0] = math.nan
        axle = np.empty(2)
        axle_transfer_step(p.loads, s.axle_pos, s.axle_vel, dt, ground_f, axle)
        front = max(0.5 * (weight_normal * p.cg_to_rear / p.wheelbase + axle[0]), 0.0)
        rear = max(0.5 * (weight_normal * p.cg_to_front / p.wheelbase + axle[1]), 0.0)
    else:
        transfer = ground_f * p.cg_height
        front = max(0.5 * (weight_normal * p.cg_to_rear - transfer) / p.wheelbase, 0.0)
        rear = max(0.5 * (weight_normal * p.cg_to_front + transfer) / p.wheelbase, 0.0)
    min_load = p.min_load
    lift = False
    implausible = False
    for i in range(4):
        fz = front if i < 2 else rear
        fx = filtered[i]
        est.fx[i] = fx
        est.fz[i] = fz
        est.rolling[i] = c_roll * fz
        valid = (fz >= min_load) and (abs(fx) >= p.min_excitation * fz) and math.isfinite(fx)
        mu = fx / fz if valid else 0.0
        valid = valid and wheel_ok[i] and not no_torque
        lift = lift or fz < min_load
        if valid and abs(mu) > p.max_mu:
            implausible = True
            valid = False
        est.mu[i] = mu if valid else 0.0
        est.mu_valid[i] = 1 if valid else 0
        # vd_common.vehicle.tire.slip_ratio of the slip velocity
        sv = x.omega[i] * radius - v
        den = max(max(abs(sv + v), abs(v)), p.slip_eps)
        est.slip[i] = sv / den
    if lift:
        s.counts[_WHEEL_LIFT] += 1
    if implausible:
        s.counts[_MU_RANGE] += 1

    # the slope from the filtered longitudinal balance
    forces = fx_sum - direction * rolling_sum - aero_signed
    one = np.empty(1)
    net_out = np.empty(1)
    by_speed = p.slope_accel == 0 and p.slope_tau > 0.0
    one[0] = forces if by_speed else forces - mass * accel
    if lowpass_gap(p.slope_tau, s.slope_lp, dt) > 0.0:
        # the input the trend before the gap predicts (the bridge is exact for that line)
        _, trend = lowpass_input(p.slope_tau, s_stages, s.slope_prev, s.slope_lp, 0)
        if abs(one[0] - s.slope_prev[1, 0] - trend * dt) > GAP_FORCE_CHANGE * weight:
            s.settle_until = t + (s_stages.shape[0] + 1) * p.slope_tau
    if by_speed:
        # m*dv/dt as the derivative of the same low-pass applied to the speed
        # the step from the speed's last sample (`_speed_samples_before`)
        dt_speed = dt if math.isnan(s.speed_t) else t - s.speed_t
        dt_v = _bridge_speed(p.slope_tau, s, v_stages, s_stages, dt_speed, forces, mass)
        speed_in = np.full(1, v)
        lowpass_update(p.slope_tau, v_stages, s.speed_prev, s.speed_lp, dt_v, speed_in, net_out)
        s.speed_t = t
        lowpass_derivative(v_stages, s.speed_prev, s.speed_lp, net_out)
        accel_f = net_out[0]
        lowpass_update(p.slope_tau, s_stages, s.slope_prev, s.slope_lp, dt, one, net_out)
        net_f = net_out[0] - mass * accel_f
    else:
        lowpass_update(p.slope_tau, s_stages, s.slope_prev, s.slope_lp, dt, one, net_out)
        net_f = net_out[0]
    sine = net_f / weight
    in_range = abs(sine) <= p.max_sine
    usable = body_ok and abs(v) >= p.min_speed and not no_torque
    if usable and not in_range:
        # |N| > m g has no arcsin at all; below that the slope is only implausible
        s.counts[_ARCSIN if abs(sine) > 1.0 else _SLOPE_RANGE] += 1
    slope_valid = in_range and usable and t >= s.settle_until
    if p.torque_source == TORQUE_ENGINE and usable and not in_range:
        # the balance needs a force the engine path cannot know of (the brakes): the
        # torques are wrong, so is mu
        est.mu_valid[:] = 0
        est.mu[:] = 0.0
    if slope_valid:
        # an invalid stamp keeps the last valid slope (it is published as invalid)
        s.slope = math.asin(sine)
    est.t = t
    est.aero = aero
    est.slope = s.slope
    est.slope_valid = slope_valid
    est.torque_source = p.torque_source


@jit
def _reject(p: np.record, s: np.record, kind: int, t: float, est: np.record) -> None:
    s.counts[kind] += 1
    s.counts[REJECTED_SLOT] += 1
    if s.has_last:
        _copy(s.last, est)
    else:
        _empty(p, s, t, est)


@jit
def estimator_update(parts: EstimatorParts, t: float, inp: np.record, est: np.record) -> None:
    """Estimate everything for stamp t into ``est`` (`estimator.Estimator.update`).

    Args:
        parts: the estimator's records (its state advanced, its fault counts incremented).
        t: stamp [s].
        inp: `ESTIMATOR_INPUT` record.
        est: `ESTIMATES` record written.
    """
    p, s = parts.params[0], parts.state[0]
    torque_ok = inp.torque_ok
    if not math.isfinite(t):
        _reject(p, s, _NON_FINITE_STAMP, t, est)
        return
    if not math.isnan(s.t):
        restart = False
        if t <= s.t:
            if s.t - t <= p.max_gap:
                _reject(p, s, _DUPLICATE if t == s.t else _OUT_OF_ORDER, t, est)
                return
            s.counts[_JUMP_BACK] += 1
            restart = True
        elif t - s.t > p.max_gap:
            s.counts[_GAP] += 1
            restart = True
        if restart:  # reset, keeping the last finite inputs to hold
            _forget(p, s)
    dt = 0.0 if math.isnan(s.t) else t - s.t
    s.t = t
    # each input finite is taken, each other one is the last finite one (held)
    x = s.held
    speed_ok = math.isfinite(inp.speed)
    if speed_ok:
        x.speed = inp.speed
    body_ok = math.isfinite(inp.accel)
    if body_ok:
        x.accel = inp.accel
    body_ok = body_ok and speed_ok
    wheel_ok = np.ones(4, dtype=np.bool_)
    torque_known = True
    for i in range(4):
        omega_ok = _take(inp.omega[i], x.omega, i)
        omega_dot_ok = _take(inp.omega_dot[i], x.omega_dot, i)
        torque_ok_i = _take(inp.torque[i], x.torque, i)
        torque_known = torque_known and torque_ok_i
        wheel_ok[i] = omega_ok and omega_dot_ok and torque_ok_i and speed_ok
        body_ok = body_ok and wheel_ok[i]
    if not body_ok:
        s.counts[_NON_FINITE_VALUE] += 1
    if not torque_ok:
        wheel_ok[:] = False
        body_ok = False
    _speed_samples_before(parts, t, dt, inp)
    _estimate(parts, t, dt, x, wheel_ok, body_ok, torque_known, est)
    # one sum is the cheapest check: NaN/Inf anywhere makes it non-finite
    total = est.aero + est.slope
    for i in range(4):
        total += est.fx[i] + est.fz[i] + est.mu[i] + est.slip[i] + est.rolling[i]
    if not math.isfinite(total):
        # overflow from absurd (finite) input: drop the poisoned state, report nothing valid
        s.counts[_NON_FINITE_OUTPUT] += 1
        estimator_reset(p, s)
        s.t = t
        _empty(p, s, t, est)
    _copy(est, s.last)
    s.has_last = True


@jit
def estimator_update_arrays(
    parts: EstimatorParts, t: float, inp_a: np.ndarray, est_a: np.ndarray
) -> None:
    """`estimator_update` with its input and output records as the 1-element arrays they
    live in (`kernel._jit.record_array`): what `Estimator.update` calls once a stamp, as numba
    types arrays on its fast path and records not."""
    estimator_update(parts, t, inp_a[0], est_a[0])
