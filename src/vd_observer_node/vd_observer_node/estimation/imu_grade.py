"""Road grade from an IMU's specific force, fused with the force balance (issue 27).

An accelerometer fixed to the body reads the specific force along the car (its mounting
rotated out by the input mapping, `inputs.decode`)::

    u = (1 + k) f + b,    f = dv/dt + g sin(alpha)

with ``b`` its bias (sensor offset, a mounting pitch left over: ``g sin(delta)``) and ``k`` the
body's pitch under the longitudinal force (squat and dive: the body, and the sensor on it,
pitch by ``pitch_compliance * m f``, so ``k = g m pitch_compliance``, 6 % on the Clio). So
``sin(alpha) = ((u - b) / (1 + k) - dv/dt) / g`` needs neither the mass nor the torque, but
``b`` (and ``k``'s mass). The force balance of the wheel torques gives what is missing::

    F - aero = m f + c_r m g cos(alpha)   =>   (F - aero) / g = m' (u / g + c_r cos(alpha)
               (1 + k)) - m' b / g,         m' = m / (1 + k)

linear in ``theta = [m', m' b / g]``: a two-state Kalman filter (`_regression`) learns the
mass and the bias from every stamp where the torques hold and the car moves, whatever the
grade (it is not in the equation): ordinary drives excite it through their accelerations and
their grades alike (Vahidi et al. 2005 fuse the same two sensors). ``u``, the speed and
``F - aero`` go through the same low-pass (``tau``, 2 stages: the vibration), ``dv/dt`` is the
filtered speed's derivative, so every term carries the same lag.

The fused slope: the force balance's slope until the filter has run ``settle`` seconds; then
the two slopes weighted by their variances (the IMU's is its bias's, the force balance's
``force_slope_std``) until the bias's standard deviation is below ``bias_tol``; from then on
(latched) the IMU's grade (``sources = SOURCE_FORCE | SOURCE_IMU``: the IMU's grade with a bias
learnt from the force balance). Without a valid force slope (no torque, standstill) the IMU's
grade with the bias known so far (``SOURCE_IMU``; valid once the bias's standard deviation is
below ``alone_bias_std``). Where the IMU drops out (no sample newer than ``max_age``),
saturates (``|f_x| >= saturation``) or gives a non-finite value, the force balance's slope is
passed on as it is (``SOURCE_FORCE``) and the IMU's filters restart when it comes back (the
regression is kept).

`imu_grade_step` is the one per-stamp function (compiled, `kernel._jit`); the cascade's stamp
(`cascade_step.cascade_step`) runs it after the estimator, on the estimator's outputs, and
feeds the regression's mass back once it has converged (``mass_feedback``: the estimator's
force balance, slope and tyre loads use it from the next stamp on). `ImuGrade` holds the
records.

Where the IMU gives its angular rate (``GRADE_INPUT.pitch_rate`` finite, ``gyro`` on) the
grade is `gyro_grade`'s complementary filter of the rate and the specific force instead of
the low-pass with its lead and step switch above; the regression (`imu_regression`), the bias
and the weighting are the same either way.
"""

from __future__ import annotations

import math
from typing import Final

import numpy as np
from numpy.typing import NDArray

from vd_observer_node.estimation.filters import (
    LOWPASS_META,
    lowpass_derivative,
    lowpass_on_ramp,
    lowpass_reset,
    lowpass_update,
)
from vd_observer_node.estimation.gyro_grade import (
    GYRO_PARAMS,
    GYRO_STATE,
    gyro_advance,
    gyro_reset,
    gyro_sine,
    gyro_start_on_ramp,
)
from vd_observer_node.estimation.imu_regression import (
    FIT_ORDER,
    regression_bias,
    regression_mass,
    regression_mass_std,
    regression_update,
)
from vd_observer_node.estimation.imu_settings import ImuGradeConfig
from vd_observer_node.kernel._jit import jit, new_record

__all__ = [
    'GRADE_INPUT',
    'GRADE_OUT',
    'GRADE_PARAMS',
    'GRADE_STATE',
    'LEVER_TAU',
    'SOURCE_FORCE',
    'SOURCE_IMU',
    'ImuGrade',
    'imu_grade_step',
]

FloatArray = NDArray[np.float64]

#: bit of ``sources``: the force balance (wheel torques, mass) contributed
SOURCE_FORCE: Final = 1
#: bit of ``sources``: the IMU's specific force contributed
SOURCE_IMU: Final = 2
_ORDER: Final = 3  # stages of the grade's low-pass on (f_x, v) (the lead reads 3)
#: One stamp's inputs of the fusion: imu_stamp [s] the stamp of the newest IMU sample (nan:
#: none yet) and f_x [m/s^2] its longitudinal specific force in body axes; speed [m/s] the
#: body's; slope_force [rad] the force balance's slope (`estimator_step`) and force_valid;
#: force [N] the longitudinal force balance without gravity and rolling, sum(Fx) - aero
#: (signed), and force_ok: the wheel torques held at the stamp (the regression may use it);
#: mass_used [kg] the mass the force balance's slope used (`Estimates.mass_used`);
#: pitch_rate [rad/s] the body's pitch rate of the same IMU sample (REP 103: nose down
#: positive; nan: the sensor gives none).
GRADE_INPUT: Final = np.dtype(
    [
        ('imu_stamp', 'f8'),
        ('f_x', 'f8'),
        ('pitch_rate', 'f8'),
        ('speed', 'f8'),
        ('slope_force', 'f8'),
        ('force_valid', 'b1'),
        ('force', 'f8'),
        ('force_ok', 'b1'),
        ('mass_used', 'f8'),
    ],
    align=True,
)

#: [s] the low-pass of the pitch acceleration of the lever-arm term
#: (`ImuGradeConfig.lever_arm_z`): two samples of a 100 Hz sensor. Its lag is the term's
#: error (at 2.5 Hz, 0.05 s lags 38 deg); on the RAV4's windscreen 0.01 and 0.02 s give the
#: same slope, 0.05 s 0.004 deg more, 0.1 s 0.01 deg more (chosen on that drive)
LEVER_TAU: Final = 0.02
GRADE_PARAMS: Final = np.dtype(
    [
        ('gravity', 'f8'),
        ('tau', 'f8'),
        ('lead', 'f8'),
        ('fit_tau', 'f8'),
        ('fit_delay', 'f8'),
        ('step_tau', 'f8'),
        ('step_sine', 'f8'),
        ('warmup', 'f8'),
        ('bias_settle', 'f8'),
        ('max_age', 'f8'),
        ('saturation', 'f8'),
        ('max_sine', 'f8'),
        ('min_speed', 'f8'),
        ('mass0', 'f8'),
        ('mass0_std', 'f8'),
        ('bias0_std', 'f8'),
        ('pitch_gain', 'f8'),
        ('force_std', 'f8'),
        ('mass_q', 'f8'),
        ('bias_q', 'f8'),
        ('mass_tol', 'f8'),
        ('bias_tol', 'f8'),
        ('alone_bias_std', 'f8'),
        ('force_slope_var', 'f8'),
        ('rolling_c0', 'f8'),
        ('rolling_c1', 'f8'),
        ('feedback', 'b1'),
        ('lever_z', 'f8'),
        ('gyro', GYRO_PARAMS),
    ],
    align=True,
)
GRADE_STATE: Final = np.dtype(
    [
        ('stages', 'f8', (_ORDER, 2)),  # the grade's low-pass of (f_x, v)
        ('prev', 'f8', (2, 2)),  # filters.lowpass_update: last output and last input
        ('lp', LOWPASS_META),
        ('fit_stages', 'f8', (FIT_ORDER, 3)),  # the regression's low-pass of (f_x, v, F)
        ('fit_prev', 'f8', (2, 3)),
        ('fit_lp', LOWPASS_META),
        ('step_stages', 'f8', (_ORDER, 2)),  # the short low-pass of (f_x, v), no lead
        ('step_prev', 'f8', (2, 2)),
        ('step_lp', LOWPASS_META),
        ('step_accel', 'f8'),  # [m/s^2] its last dv/dt
        ('accel', 'f8'),  # [m/s^2] the grade's filter's last dv/dt
        ('last_t', 'f8'),
        ('since', 'f8'),  # [s] the IMU's filters have run since this stamp (nan: stopped)
        ('bias', 'f8'),  # [-] learnt bias of the IMU's sine (b / g)
        ('bias_time', 'f8'),  # [s] of trusted stamps in the bias
        ('sine', 'f8'),  # last fused sine
        ('start', 'f8', (6,)),  # start-up sums: n, t, t^2, v, t v, f_x (see _collect)
        ('dropouts', 'i8'),
        ('saturated', 'i8'),
        ('theta', 'f8', (2,)),  # the regression's [m', m' b / g] (see _regression)
        ('cov', 'f8', (2, 2)),
        ('fit_time', 'f8'),  # [s] of stamps in the regression
        ('fitted', 'b1'),  # the regression's mass has converged (latched until a reset)
        ('trusted', 'b1'),  # the regression's bias has converged (latched until a reset)
        ('stepping', 'b1'),  # the grade is the short low-pass's (a step, `step_tau`)
        ('rate_stamp', 'f8'),  # [s] the last IMU sample's stamp with a pitch rate (nan: none)
        ('rate_last', 'f8'),  # [rad/s] its pitch rate
        ('rate_dot', 'f8'),  # [rad/s^2] the pitch acceleration (`_pitch_acceleration`)
        ('gyro', GYRO_STATE),  # the angular rate's grade (`gyro_grade`)
    ],
    align=True,
)
#: One stamp's fusion: the fused slope [rad] and whether it is valid, the sources it used
#: (`SOURCE_FORCE` | `SOURCE_IMU`), the IMU's own bias-corrected slope [rad] (nan where it
#: has none), the learnt bias of the longitudinal specific force [m/s^2], the filtered
#: acceleration dv/dt [m/s^2], the mass [kg] the regression found and its standard deviation,
#: whether it has converged, the bias's standard deviation [m/s^2], whether it is trusted,
#: and whether the IMU's grade used the angular rate (`ImuGradeConfig.gyro`).
GRADE_OUT: Final = np.dtype(
    [
        ('slope', 'f8'),
        ('slope_valid', 'b1'),
        ('sources', 'u1'),
        ('slope_imu', 'f8'),
        ('bias', 'f8'),
        ('accel', 'f8'),
        ('mass', 'f8'),
        ('mass_std', 'f8'),
        ('fitted', 'b1'),
        ('bias_std', 'f8'),
        ('trusted', 'b1'),
        ('gyro', 'b1'),
    ],
    align=True,
)


def grade_params(
    config: ImuGradeConfig, gravity: float, mass: float, rolling_c0: float, rolling_c1: float
) -> np.record:
    """The `GRADE_PARAMS` record of `config` with the vehicle file's gravity [m/s^2], mass
    [kg] and rolling-resistance coefficients (paper eq. 7)."""
    p = new_record(GRADE_PARAMS)
    p.gravity = gravity
    p.tau = config.tau_in_use
    p.warmup = config.warmup
    p.fit_tau = config.fit_tau
    p.fit_delay = config.fit_delay
    p.step_tau = config.step_tau_in_use
    p.step_sine = math.sin(config.step_slope)
    p.lead = _ORDER * config.tau_in_use if config.lag_compensation else 0.0
    p.bias_settle = config.settle
    p.max_age = config.max_age
    p.saturation = config.saturation
    p.max_sine = math.sin(config.max_slope)
    p.min_speed = config.min_speed
    p.mass0 = mass
    p.mass0_std = config.mass_std
    p.bias0_std = config.bias_std
    p.pitch_gain = gravity * config.pitch_compliance
    p.force_std = config.force_std
    p.mass_q = config.mass_drift**2
    p.bias_q = config.bias_drift**2
    p.mass_tol = config.mass_tol
    p.bias_tol = config.bias_tol
    p.alone_bias_std = config.alone_bias_std
    p.force_slope_var = config.force_slope_std**2
    p.rolling_c0 = rolling_c0
    p.rolling_c1 = rolling_c1
    p.feedback = config.mass_feedback
    p.lever_z = config.lever_arm_z
    p.gyro.on = config.gyro
    p.gyro.tau = config.gyro_tau
    p.gyro.pitch_omega = 2.0 * math.pi * config.pitch_frequency
    p.gyro.pitch_zeta = config.pitch_damping
    p.gyro.gravity = gravity
    return p


@jit
def imu_grade_reset(p: np.record, s: np.record) -> None:
    """Forget everything: filters, regression (back to its prior), counts."""
    lowpass_reset(s.lp)
    lowpass_reset(s.fit_lp)
    lowpass_reset(s.step_lp)
    gyro_reset(s.gyro)
    s.last_t = math.nan
    s.since = math.nan
    s.bias = 0.0
    s.bias_time = 0.0
    s.sine = 0.0
    s.stepping = False
    s.dropouts = 0
    s.saturated = 0
    s.theta[0] = p.mass0 / (1.0 + p.pitch_gain * p.mass0)
    s.theta[1] = 0.0
    s.cov[:, :] = 0.0
    s.cov[0, 0] = p.mass0_std**2
    s.cov[1, 1] = (p.mass0 * p.bias0_std / p.gravity) ** 2
    s.fit_time = 0.0
    s.fitted = False
    s.trusted = False
    s.rate_stamp = math.nan
    s.rate_last = 0.0
    s.rate_dot = 0.0


@jit
def _pitch_acceleration(p: np.record, s: np.record, stamp: float, rate: float) -> float:
    """The body's pitch acceleration [rad/s^2] at the IMU sample of `stamp` [s] with pitch
    rate `rate` [rad/s]: the rate's difference from the previous sample over their time,
    low-passed with `LEVER_TAU` (a new sample only; 0 without a rate, from the first sample
    and after a dropout longer than ``max_age``)."""
    if not (math.isfinite(stamp) and math.isfinite(rate)):
        s.rate_stamp = math.nan
        s.rate_dot = 0.0
        return 0.0
    gap = stamp - s.rate_stamp
    if math.isnan(s.rate_stamp) or gap < 0.0 or gap > p.max_age:
        s.rate_dot = 0.0
    elif gap > 0.0:
        share = gap / (LEVER_TAU + gap)
        s.rate_dot += share * ((rate - s.rate_last) / gap - s.rate_dot)
    if gap != 0.0:  # a new sample (or the first): the next difference starts here
        s.rate_stamp = stamp
        s.rate_last = rate
    return float(s.rate_dot)


@jit
def _collect(sums: FloatArray, t: float, v: float, u: float) -> None:
    """Add a start-up stamp (``t`` [s] since the start, speed ``v``, specific force ``u``)."""
    sums[0] += 1.0
    sums[1] += t
    sums[2] += t * t
    sums[3] += v
    sums[4] += t * v
    sums[5] += u


@jit
def _line(sums: FloatArray, t: float, v: float, u: float) -> tuple[float, float, float]:
    """The start-up's least-squares line through the speed, at ``t`` [s] since the start
    (speed [m/s] and rate [m/s^2]), and the mean specific force [m/s^2] (with the stamp
    ``t``, ``v``, ``u`` added)."""
    _collect(sums, t, v, u)
    n = sums[0]
    t_mean = sums[1] / n
    var = sums[2] / n - t_mean * t_mean
    v_mean = sums[3] / n
    rate = (sums[4] / n - t_mean * v_mean) / var if n >= 3.0 and var > 0.0 else 0.0
    return v_mean + rate * (t - t_mean), rate, sums[5] / n


@jit
def _force_only(out: np.record, slope_force: float, force_valid: bool) -> None:
    out.slope = slope_force
    out.slope_valid = force_valid
    out.sources = SOURCE_FORCE if force_valid else 0
    out.slope_imu = math.nan


@jit
def _accel_sine(
    p: np.record,
    s: np.record,
    y: FloatArray,
    v_dot: float,
    ys: FloatArray,
    dys: FloatArray,
    bias: float,
    scale: float,
) -> float:
    """The grade's sine from the specific force alone: the low-passed ``(f_x, v)`` (``y``,
    ``v_dot``; the short low-pass's ``ys``, ``dys``) with the lead and the step switch of
    `ImuGradeConfig` (``bias`` [m/s^2], ``scale`` = 1 + k)."""
    lagged = y[0] / scale - v_dot
    # the lead: a ramp through the stages lags by order tau; adding that times the rate
    # makes the grade's filter (1 + order tau s) / (1 + tau s)^order, without lag on ramps.
    # The rate from the stages (each stage's rate is its input minus itself over tau), not
    # by differencing the output: no noise from irregular stamps (a real log's 0.2 ms after
    # 20 ms), and a step of the learnt bias or mass is no rate.
    st = s.stages
    rate = (st[1, 0] - st[2, 0]) / scale - (st[0, 1] - 2.0 * st[1, 1] + st[2, 1]) / p.tau
    rate /= p.tau
    sine = (lagged + p.lead * rate - bias / scale) / p.gravity
    # a step of the grade: the lead overshoots it for a few tau, the short low-pass
    # (`step_tau`, no lead) has followed it; from where they differ by more than the short
    # one's noise until they agree again (a quarter of that), the short one's
    if p.step_tau > 0.0:
        fast = ((ys[0] - bias) / scale - dys[1]) / p.gravity
        apart = abs(fast - sine)
        s.stepping = apart > (0.25 * p.step_sine if s.stepping else p.step_sine)
        if s.stepping:
            sine = fast
    return float(sine)


@jit
def imu_grade_step(p: np.record, s: np.record, t: float, inp: np.record, out: np.record) -> None:
    """One stamp of the fusion.

    Args:
        p: `GRADE_PARAMS` record.
        s: `GRADE_STATE` record, advanced.
        t: stamp [s].
        inp: `GRADE_INPUT` record.
        out: `GRADE_OUT` record, written.
    """
    imu_stamp, f_x, speed = inp.imu_stamp, inp.f_x, inp.speed
    if p.lever_z != 0.0:
        # a sensor above the pitch centre also reads the body's pitch acceleration
        f_x = f_x - p.lever_z * _pitch_acceleration(p, s, imu_stamp, inp.pitch_rate)
    slope_force, force_valid = inp.slope_force, inp.force_valid
    force, force_ok, mass_used = inp.force, inp.force_ok, inp.mass_used
    dt = 0.0 if math.isnan(s.last_t) else t - s.last_t
    if dt < 0.0:  # a stamp out of order: the estimator rejected it too
        dt = 0.0
    s.last_t = t
    fresh = not math.isnan(imu_stamp) and t - imu_stamp <= p.max_age
    saturated = abs(f_x) >= p.saturation
    ok = fresh and not saturated and math.isfinite(f_x) and math.isfinite(speed)
    m = regression_mass(p, s)
    out.mass = m
    out.mass_std = regression_mass_std(p, s)
    out.fitted = s.fitted
    out.trusted = s.trusted
    out.bias, out.bias_std = regression_bias(p, s)
    out.accel = math.nan
    out.gyro = False
    if not ok:
        if not math.isnan(s.since):
            s.dropouts += 1
        if saturated and math.isfinite(f_x):
            s.saturated += 1
        lowpass_reset(s.lp)
        lowpass_reset(s.fit_lp)
        lowpass_reset(s.step_lp)
        gyro_reset(s.gyro)
        s.since = math.nan
        s.stepping = False
        _force_only(out, slope_force, force_valid)
        return
    if math.isnan(s.since):
        s.since = t
        s.start[:] = 0.0
    usable = force_ok and math.isfinite(force)
    if t - s.since < p.warmup:
        # the start-up: a line through the speed and the mean specific force, so that the
        # filters start on the ramp the car is on (a steady start would see no acceleration)
        _collect(s.start, t - s.since, speed, f_x)
        _force_only(out, slope_force, force_valid)
        return
    # two filter banks: (f_x, v) for the grade (`tau`, `_ORDER` stages, with a lead) and
    # (f_x, v, F) for the regression (`fit_tau`, `FIT_ORDER` stages: faster, its lag does
    # not matter as long as the three carry the same)
    x = np.empty(2)
    y = np.empty(2)
    dy = np.empty(2)
    xf = np.empty(3)
    yf = np.empty(3)
    dyf = np.empty(3)
    ys = np.empty(2)
    dys = np.empty(2)
    u_in, v_in = f_x, speed
    if not s.lp.started:
        v_now, v_rate, u_mean = _line(s.start, t - s.since, speed, f_x)
        u_in, v_in = u_mean, v_now
        xf[0] = x[0] = u_mean
        xf[1] = x[1] = v_now
        xf[2] = force if usable else 0.0
        lowpass_update(p.tau, s.stages, s.prev, s.lp, dt, x, y)
        lowpass_update(p.fit_tau, s.fit_stages, s.fit_prev, s.fit_lp, dt, xf, yf)
        lowpass_update(p.step_tau, s.step_stages, s.step_prev, s.step_lp, dt, x, ys)
        # on the ramp the car is on: the speed's stages lag it
        lowpass_on_ramp(p.tau, s.stages, 1, v_now, v_rate)
        lowpass_on_ramp(p.step_tau, s.step_stages, 1, v_now, v_rate)
        lowpass_on_ramp(p.fit_tau, s.fit_stages, 1, v_now, v_rate)
        dy[1] = dyf[1] = dys[1] = v_rate
    elif dt <= 0.0:
        # a repeated stamp: no time has passed, the filters hold (a derivative over no time
        # would be 0, and the lead would take the step back as a rate)
        y[:] = s.stages[-1]
        yf[:] = s.fit_stages[-1]
        ys[:] = s.step_stages[-1]
        dy[1] = s.accel
        dys[1] = s.step_accel
    else:
        xf[0] = x[0] = f_x
        xf[1] = x[1] = speed
        # the force balance is filtered with the others; where it has none, its last value
        xf[2] = force if usable else s.fit_stages[-1, 2]
        lowpass_update(p.tau, s.stages, s.prev, s.lp, dt, x, y)
        lowpass_derivative(s.stages, s.prev, s.lp, dy)
        lowpass_update(p.fit_tau, s.fit_stages, s.fit_prev, s.fit_lp, dt, xf, yf)
        lowpass_derivative(s.fit_stages, s.fit_prev, s.fit_lp, dyf)
        lowpass_update(p.step_tau, s.step_stages, s.step_prev, s.step_lp, dt, x, ys)
        lowpass_derivative(s.step_stages, s.step_prev, s.step_lp, dys)
    v_dot = dy[1]
    s.step_accel = dys[1]
    s.accel = v_dot
    out.accel = v_dot
    # forward only: the rolling resistance's sign is the speed's (and reversing is rare);
    # not before the filters have forgotten the force balance's value at their start
    settled = t - s.since >= p.warmup + p.fit_delay
    if usable and settled and speed >= p.min_speed and dt > 0.0:
        regression_update(p, s, dt, yf[0], yf[2] / p.gravity, speed)
        m = regression_mass(p, s)
        out.mass = m
        out.mass_std = regression_mass_std(p, s)
        out.bias, out.bias_std = regression_bias(p, s)
        if s.fit_time >= p.bias_settle:
            s.fitted = s.fitted or out.mass_std <= p.mass_tol * m
            s.trusted = s.trusted or out.bias_std <= p.bias_tol
        out.fitted = s.fitted
        out.trusted = s.trusted
    bias = out.bias
    scale = 1.0 + p.pitch_gain * m
    if p.gyro.on and math.isfinite(inp.pitch_rate):
        g = s.gyro
        starting = not g.lp.started
        # the sine's rate of a nose-up pitch (REP 103's pitch rate is nose down)
        up_rate = -inp.pitch_rate * math.sqrt(max(1.0 - s.sine * s.sine, 0.0))
        settled = (scale - 1.0) * (u_in - bias) / (scale * p.gravity)
        gyro_advance(p.gyro, g, t, dt, u_in, v_in, up_rate, settled)
        if starting:
            gyro_start_on_ramp(p.gyro, g, v_in, v_dot)
        sine = gyro_sine(p.gyro, g, bias, scale)
        # its start: the filter holds the pitch the body had then as the one it keeps (a
        # body still settling on its springs is a step the rate's path passes for a few
        # tau); fade from the specific force's grade to it over that time
        fade = math.exp(-(t - g.since) / p.gyro.tau)
        if fade > 1e-6:
            sine += fade * (_accel_sine(p, s, y, v_dot, ys, dys, bias, scale) - sine)
        out.gyro = True
    else:
        gyro_reset(s.gyro)
        sine = _accel_sine(p, s, y, v_dot, ys, dys, bias, scale)
    valid = abs(sine) <= p.max_sine
    slope_imu = math.asin(max(-1.0, min(1.0, sine)))
    s.sine = sine
    out.slope_imu = slope_imu
    if s.trusted:
        out.slope = slope_imu
        out.slope_valid = valid
        out.sources = SOURCE_IMU | SOURCE_FORCE
    elif not force_valid:
        # no force balance to lean on: the IMU's grade with the bias known so far, valid
        # only once that is known well enough (an unmeasured mounting pitch is degrees)
        out.slope = slope_imu
        out.slope_valid = valid and out.bias_std <= p.alone_bias_std
        out.sources = SOURCE_IMU
    else:
        # both, weighted by their variances: the IMU's is its bias's (while it is learnt),
        # the force balance's grows with the mass error the regression sees in it (its
        # slope is off by (m / m_used - 1) f / g) and the regression's own uncertainty
        imu_var = (out.bias_std / p.gravity) ** 2
        load = y[0] / p.gravity
        mass_error = (m - mass_used) / mass_used if mass_used > 0.0 else 0.0
        force_var = p.force_slope_var + (mass_error * load) ** 2
        force_var += (out.mass_std / m * load) ** 2 if m > 0.0 else 0.0
        weight = force_var / (force_var + imu_var)
        out.slope = weight * slope_imu + (1.0 - weight) * slope_force
        out.slope_valid = True
        out.sources = (SOURCE_IMU if weight > 0.01 else 0) | (SOURCE_FORCE if weight < 0.99 else 0)


class ImuGrade:
    """The fusion's records: settings and state (`cascade_step` steps them).

    Attributes:
        config: the settings.
        params: `GRADE_PARAMS` record.
        state: `GRADE_STATE` record.
    """

    def __init__(
        self,
        config: ImuGradeConfig | None,
        gravity: float,
        mass: float,
        rolling_c0: float,
        rolling_c1: float,
    ) -> None:
        """Create the records (a fresh state) with the vehicle file's values (see
        `grade_params`)."""
        self.config = config or ImuGradeConfig()
        self.params = grade_params(self.config, gravity, mass, rolling_c0, rolling_c1)
        self.state = new_record(GRADE_STATE)
        imu_grade_reset(self.params, self.state)

    def follow_rate(self, rate_hz: float) -> dict[str, float]:
        """Fix the settings left to the inputs' rate, now that it is known (from the stamp
        the estimator's follow it, `Estimator.follow_rate`); the filters keep their state
        (their stages hold signals, not coefficients).

        Args:
            rate_hz: [Hz] rate of the slower of the wheel and body-speed inputs.

        Returns:
            The settings fixed here, by name, with their values (empty: none was left
            unset, or they were fixed before).
        """
        self.config, fixed = self.config.at_rate(rate_hz)
        if fixed:
            self.params.tau = self.config.tau_in_use
            self.params.step_tau = self.config.step_tau_in_use
            self.params.lead = _ORDER * self.params.tau if self.config.lag_compensation else 0.0
        return fixed
