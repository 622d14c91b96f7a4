"""The IMU fusion's regression: the mass and the IMU's bias from the force balance.

The force balance of the wheel torques and the IMU's specific force ``u = (1 + k) f + b``
(`imu_grade`'s module docstring) give

    (F - aero) / g = m' (u / g + c_r cos(alpha) (1 + k)) - m' b / g,    m' = m / (1 + k)

linear in ``theta = [m', m' b / g]`` and free of the grade: `regression_update` is one
Kalman update of that two-state filter on the filtered signals; `regression_mass`,
`regression_bias` and `regression_mass_std` read the mass and the bias out of ``theta``. The
records are `imu_grade`'s ``GRADE_PARAMS`` and ``GRADE_STATE`` (``theta``, ``cov``,
``fit_time``, ``sine``).
"""

from __future__ import annotations

import math
from typing import Final

import numpy as np

from vd_observer_node.estimation.formulas import rolling_coefficient_at
from vd_observer_node.kernel._jit import jit

__all__ = [
    'FIT_ORDER',
    'bias_pitch_deg',
    'regression_bias',
    'regression_mass',
    'regression_mass_std',
    'regression_update',
]

#: stages of the regression's low-pass on (f_x, v, F): successive stamps see the same
#: filtered error, one independent value per ``2 FIT_ORDER fit_tau``
FIT_ORDER: Final = 2


def bias_pitch_deg(bias: float, gravity: float) -> float:
    """[deg] the sensor pitch (nose up) a bias of the forward specific force [m/s^2] amounts
    to if it all were mounting: ``asin(b / g)``."""
    return math.degrees(math.asin(max(-1.0, min(1.0, bias / gravity))))


@jit
def regression_update(
    p: np.record, s: np.record, dt: float, u: float, y: float, speed: float
) -> None:
    """One Kalman update of ``theta = [m', m' b / g]`` from the filtered balance

    ``y = (F - aero) / g = m' (u / g + c_r cos(alpha) (1 + k)) - m' b / g``

    where ``F - aero = m f + c_r m g cos(alpha)`` (``f = dv/dt + g sin(alpha)``), the IMU
    reads ``u = (1 + k) f + b`` and ``m' = m / (1 + k)``, ``k = pitch_gain m``.
    """
    s.cov[0, 0] += p.mass_q * dt
    s.cov[1, 1] += p.bias_q * dt * (s.theta[0] / p.gravity) ** 2
    c_roll = rolling_coefficient_at(p.rolling_c0, p.rolling_c1, speed)
    cos_grade = math.sqrt(max(1.0 - s.sine * s.sine, 0.0))
    phi0 = u / p.gravity + c_roll * cos_grade * (1.0 + p.pitch_gain * regression_mass(p, s))
    phi1 = -1.0
    # successive stamps see the same filtered error: one independent value per 2 order tau
    inflation = max(1.0, 2.0 * FIT_ORDER * p.fit_tau / dt)
    r = (p.force_std / p.gravity) ** 2 * inflation
    c = s.cov
    pf0 = c[0, 0] * phi0 + c[0, 1] * phi1
    pf1 = c[1, 0] * phi0 + c[1, 1] * phi1
    innovation_var = phi0 * pf0 + phi1 * pf1 + r
    k0 = pf0 / innovation_var
    k1 = pf1 / innovation_var
    e = y - (phi0 * s.theta[0] + phi1 * s.theta[1])
    s.theta[0] += k0 * e
    s.theta[1] += k1 * e
    c00 = c[0, 0] - k0 * pf0
    c01 = c[0, 1] - k0 * pf1
    c11 = c[1, 1] - k1 * pf1
    c[0, 0] = c00
    c[0, 1] = c01
    c[1, 0] = c01
    c[1, 1] = c11
    s.fit_time += dt


@jit
def regression_mass(p: np.record, s: np.record) -> float:
    """The mass [kg] of the regression's m' = m / (1 + pitch_gain m)."""
    reduced = s.theta[0]
    den = 1.0 - p.pitch_gain * reduced
    return reduced / den if den > 0.0 else math.inf


@jit
def regression_bias(p: np.record, s: np.record) -> tuple[float, float]:
    """The IMU's bias b [m/s^2] of the regression's m' b / g, and its standard deviation
    (first order in both parameters)."""
    reduced = s.theta[0]
    if not reduced > 0.0:
        return 0.0, math.inf
    b = s.theta[1] * p.gravity / reduced
    # d b = g / m' d theta1 - b / m' d m'
    j0 = -b / reduced
    j1 = p.gravity / reduced
    c = s.cov
    var = j0 * j0 * c[0, 0] + 2.0 * j0 * j1 * c[0, 1] + j1 * j1 * c[1, 1]
    return b, math.sqrt(max(var, 0.0))


@jit
def regression_mass_std(p: np.record, s: np.record) -> float:
    """Standard deviation [kg] of `_mass` (its derivative times that of m')."""
    den = 1.0 - p.pitch_gain * s.theta[0]
    std = math.sqrt(max(s.cov[0, 0], 0.0))
    return std / (den * den) if den > 0.0 else math.inf
