"""Driving resistances: rolling resistance (paper eq. 7) and aerodynamic drag."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from vd_common.vehicle.params import AeroParams, RollingResistanceParams

__all__ = ['aero_drag', 'rolling_resistance']

FloatArray = NDArray[np.float64]
Scalar = float | FloatArray


def rolling_resistance(v: Scalar, fz: Scalar, rp: RollingResistanceParams) -> Scalar:
    """Rolling resistance force of one wheel or axle, paper eq. 7.

    ``F_r = c0 (1 + c1 |v| / 160) Fz tanh(v / v_r)``: the tanh replaces sign(v) so the force
    vanishes smoothly at standstill (a stopped car on the flat carries no force).

    Args:
        v: ground speed, [m/s].
        fz: vertical load, [N].
        rp: rolling-resistance parameters.

    Returns:
        Force opposing motion, [N] (same sign as v).
    """
    if isinstance(v, float) and isinstance(fz, float):
        return rp.c0 * (1.0 + rp.c1 * abs(v) / 160.0) * fz * math.tanh(v / rp.regularisation_speed)
    va = np.asarray(v, dtype=float)
    out: FloatArray = (
        rp.c0
        * (1.0 + rp.c1 * np.abs(va) / 160.0)
        * np.asarray(fz, dtype=float)
        * np.tanh(va / rp.regularisation_speed)
    )
    return out


def aero_drag(v: Scalar, ap: AeroParams) -> Scalar:
    """Aerodynamic drag ``0.5 rho Cx A v |v|``.

    Args:
        v: speed through still air, [m/s].
        ap: aero parameters.

    Returns:
        Force opposing motion, [N].
    """
    k = 0.5 * ap.air_density * ap.drag_coefficient * ap.frontal_area
    if isinstance(v, float):
        return k * v * abs(v)
    va = np.asarray(v, dtype=float)
    out: FloatArray = k * va * np.abs(va)
    return out
