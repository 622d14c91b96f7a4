"""The grade from an IMU's angular rate and specific force: a complementary filter.

An IMU fixed to the body turns with the road's grade and with the body's pitch on its
springs, and its gyro reads the sum's rate; its specific force, less the speed's derivative,
reads the grade itself but only as noisily as the speed is differentiated. With
``G = (1 + 3 tau s) / (1 + tau s)^3`` (``tau`` the filter's time constant) the grade is

    G [specific force's grade] + (1 - G) [pitch the gyro turned] - (1 - G) [body pitch]

The two paths add up to the grade at every frequency, so neither lags: below ``1 / tau`` the
grade is the specific force's (low-passed: the speed's noise and the vibration filtered),
above it the integrated rate's. The rate's path ``(1 - G) / s = tau^2 s (3 + tau s) /
(1 + tau s)^3`` has no gain at 0 Hz: a gyro bias does not reach the grade. The body's pitch is
a second-order model driven by the force (`_body_pitch_step`: towards its settled pitch
``k f / g`` through the vehicle file's pitch mode, `body_pitch`), so the grade keeps the
road's turning only.

Everything is read from one bank of stages of ``(f_x, v, nose-up rate, body pitch)`` (stage
``j`` follows ``j - 1`` at ``(y_(j-1) - y_j) / tau``): ``G x = 3 y2 - 2 y3``,
``(1 - G) x = x - 3 y2 + 2 y3``, ``G dv/dt = (3 y1 - 5 y2 + 2 y3) / tau`` and
``(1 - G) / s q = tau (q1 + q2 - 2 q3)``, so the filter needs no differencing (no noise from
irregular stamps) and a step of the learnt bias or mass, applied outside it, is no rate.

`gyro_advance` takes one stamp, `gyro_sine` reads the grade; `imu_grade` runs them where the
IMU gives its angular rate (`ImuGradeConfig.gyro`).
"""

from __future__ import annotations

import math
from typing import Final

import numpy as np

from vd_observer_node.estimation.filters import (
    LOWPASS_META,
    lowpass_on_ramp,
    lowpass_reset,
    lowpass_update,
    mode_step,
)
from vd_observer_node.kernel._jit import jit

__all__ = [
    'GYRO_PARAMS',
    'GYRO_STATE',
    'gyro_advance',
    'gyro_reset',
    'gyro_sine',
    'gyro_start_on_ramp',
]

_ORDER: Final = 3  # stages (the lead and the readings above are those of 3)
#: [s] the lag of the body's pitch where the vehicle file has no pitch mode (or a step is too
#: long to integrate it): the accelerometer's vibration (+-8 m/s^2 on the RAV4's rough
#: patch) is far above any suspension's pitch mode
_BODY_PITCH_TAU: Final = 0.05

#: on: the IMU's grade uses the angular rate where there is one; tau [s] the filter's time
#: constant; pitch_omega [rad/s] and pitch_zeta the body's pitch mode (`body_pitch`;
#: pitch_omega 0: none); gravity [m/s^2].
GYRO_PARAMS: Final = np.dtype(
    [('on', 'b1'), ('tau', 'f8'), ('pitch_omega', 'f8'), ('pitch_zeta', 'f8'), ('gravity', 'f8')],
    align=True,
)
#: stages (3, 4) of (f_x [m/s^2], v [m/s], nose-up rate [1/s], body pitch [rad]); body_pitch
#: [rad] (nose up) and body_pitch_rate [rad/s] the modelled body; since [s] the stamp the
#: filter started at (nan: stopped).
GYRO_STATE: Final = np.dtype(
    [
        ('stages', 'f8', (_ORDER, 4)),
        ('prev', 'f8', (2, 4)),
        ('lp', LOWPASS_META),
        ('body_pitch', 'f8'),
        ('body_pitch_rate', 'f8'),
        ('since', 'f8'),
    ],
    align=True,
)


@jit
def gyro_reset(s: np.record) -> None:
    """Stop the filter: the next `gyro_advance` starts it anew."""
    lowpass_reset(s.lp)
    s.since = math.nan


@jit
def _body_pitch_step(p: np.record, s: np.record, dt: float, settled: float) -> None:
    """Advance the modelled body pitch by ``dt`` [s] towards ``settled`` [rad]: its pitch
    mode, or a first-order lag of `_BODY_PITCH_TAU` without one (or over a long step)."""
    w: float = p.pitch_omega
    if not w > 0.0 or w * dt > 0.5:
        s.body_pitch += -math.expm1(-dt / _BODY_PITCH_TAU) * (settled - s.body_pitch)
        s.body_pitch_rate = 0.0
        return
    pitch, rate = mode_step(w, p.pitch_zeta, dt, settled, s.body_pitch, s.body_pitch_rate)
    s.body_pitch, s.body_pitch_rate = pitch, rate


@jit
def gyro_advance(
    p: np.record,
    s: np.record,
    t: float,
    dt: float,
    u: float,
    v: float,
    up_rate: float,
    settled_pitch: float,
) -> None:
    """Take one stamp.

    Args:
        p: `GYRO_PARAMS` record.
        s: `GYRO_STATE` record, advanced.
        t: stamp [s].
        dt: step [s] (<= 0: the filter holds).
        u: forward specific force [m/s^2]; v: speed [m/s].
        up_rate: the rate of the IMU's nose-up pitch [1/s] (of its sine: the pitch rate times
            the grade's cosine).
        settled_pitch: [rad] the body's pitch, nose up, that the longitudinal force would hold
            it at (``k f / g``).
    """
    if not s.lp.started:
        s.since = t
        s.body_pitch = settled_pitch
        s.body_pitch_rate = 0.0
    elif dt > 0.0:
        _body_pitch_step(p, s, dt, settled_pitch)
    else:
        return
    x = np.empty(4)
    y = np.empty(4)
    x[0], x[1], x[2], x[3] = u, v, up_rate, s.body_pitch
    lowpass_update(p.tau, s.stages, s.prev, s.lp, dt, x, y)


@jit
def gyro_start_on_ramp(p: np.record, s: np.record, v: float, accel: float) -> None:
    """Put the speed's stages on the ramp the car is on (``v`` [m/s] now, ``accel``
    [m/s^2]: stage j lags (j + 1) tau), and the pitch as if it had not turned before (stages
    at a turning body's rate would be a pitch turning for ever before: degrees that last)."""
    lowpass_on_ramp(p.tau, s.stages, 1, v, accel)
    s.stages[:, 2] = 0.0


@jit
def gyro_sine(p: np.record, s: np.record, bias: float, scale: float) -> float:
    """The grade's sine of the filter's stages (module docstring).

    Args:
        p: `GYRO_PARAMS` record; s: `GYRO_STATE` record (started).
        bias: the IMU's bias [m/s^2]; scale: 1 + k (`imu_grade`).
    """
    st, tau = s.stages, p.tau
    accel_grade = (3.0 * st[1, 0] - 2.0 * st[2, 0] - bias) / scale
    accel_grade -= (3.0 * st[0, 1] - 5.0 * st[1, 1] + 2.0 * st[2, 1]) / tau
    turned = tau * (st[0, 2] + st[1, 2] - 2.0 * st[2, 2])
    body = s.body_pitch - 3.0 * st[1, 3] + 2.0 * st[2, 3]
    return float(accel_grade / p.gravity + turned - body)
