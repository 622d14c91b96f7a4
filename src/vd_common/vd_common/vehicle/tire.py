"""Pacejka Magic Formula (MF 5.2 style), pure longitudinal slip, with low-speed regularisation.

Equations (Pacejka, *Tire and Vehicle Dynamics*, 3rd ed., sect. 4.3.2, combined-slip and
turn-slip factors left out)::

    dfz   = (Fz - Fz0) / Fz0
    kx    = kappa + SHx,              SHx = pHx1 + pHx2 dfz
    Cx    = pCx1
    Dx    = mu_road (pDx1 + pDx2 dfz) Fz
    Ex    = (pEx1 + pEx2 dfz + pEx3 dfz^2) (1 - pEx4 sgn(kx))       (clipped to <= 1)
    Kx    = Fz (pKx1 + pKx2 dfz) exp(pKx3 dfz)                      slip stiffness [N]
    Bx    = Kx / (Cx Dx)
    Fx    = Dx sin(Cx atan(Bx kx - Ex (Bx kx - atan(Bx kx)))) + SVx,   SVx = Fz (pVx1 + pVx2 dfz)

The road friction scale ``mu_road`` multiplies the peak (it is the MF scaling factor
lambda_mux); the slip stiffness is not scaled, as on a wet or icy road the initial slope of
the curve changes much less than its peak.

Low-speed regularisation: the slip ratio uses the floored denominator::

    kappa = (omega R - v) / max(|omega R|, |v|, v_min)

Above ``v_min`` this is the textbook practical slip. Below it, the tyre force is
``Fx ~ Kx (omega R - v) / v_min``: a stiff linear damper on the slip velocity, so a wheel at
standstill carries no force and the car can start from and come to rest without a
singularity (the price is a non-physical "creep" slip velocity of order F v_min / Kx).
"""

from __future__ import annotations

import math
from typing import overload

import numpy as np
from numpy.typing import NDArray

from vd_common.vehicle.params import TireParams

__all__ = ['magic_formula_fx', 'slip_ratio', 'tire_force_from_slip_velocity']

FloatArray = NDArray[np.float64]


@overload
def slip_ratio(slip_velocity: float, ground_speed: float, v_min: float) -> float: ...
@overload
def slip_ratio(
    slip_velocity: FloatArray, ground_speed: FloatArray | float, v_min: float
) -> FloatArray: ...
def slip_ratio(
    slip_velocity: float | FloatArray, ground_speed: float | FloatArray, v_min: float
) -> float | FloatArray:
    """Practical longitudinal slip with the floored denominator.

    Args:
        slip_velocity: omega R - v, [m/s], scalar or any shape.
        ground_speed: v, [m/s], broadcastable to ``slip_velocity``.
        v_min: denominator floor, [m/s] (> 0).

    Returns:
        kappa = (omega R - v) / max(|omega R|, |v|, v_min), [-], positive when driving.
    """
    if isinstance(slip_velocity, float) and isinstance(ground_speed, float):
        wr = slip_velocity + ground_speed
        return slip_velocity / max(abs(wr), abs(ground_speed), v_min)
    sv = np.asarray(slip_velocity, dtype=float)
    gs = np.asarray(ground_speed, dtype=float)
    den = np.maximum(np.maximum(np.abs(sv + gs), np.abs(gs)), v_min)
    out: FloatArray = sv / den
    return out


@overload
def magic_formula_fx(kappa: float, fz: float, mu_road: float, tp: TireParams) -> float: ...
@overload
def magic_formula_fx(
    kappa: FloatArray, fz: FloatArray | float, mu_road: FloatArray | float, tp: TireParams
) -> FloatArray: ...
def magic_formula_fx(
    kappa: float | FloatArray,
    fz: float | FloatArray,
    mu_road: float | FloatArray,
    tp: TireParams,
) -> float | FloatArray:
    """Longitudinal tyre force, pure slip.

    Scalars take a fast ``math`` path (the integrator's hot loop); arrays are vectorised.

    Args:
        kappa: slip ratio, [-].
        fz: vertical load, [N] (values <= 0 give zero force: wheel off the ground).
        mu_road: road friction scale, [-].
        tp: tyre coefficients.

    Returns:
        Fx, [N], road on tyre, positive forward; same shape as the broadcast inputs.
    """
    if isinstance(kappa, float) and isinstance(fz, float) and isinstance(mu_road, float):
        return _fx_scalar(kappa, fz, mu_road, tp)
    k = np.asarray(kappa, dtype=float)
    z = np.maximum(np.asarray(fz, dtype=float), 0.0)
    mu = np.asarray(mu_road, dtype=float)
    dfz = (z - tp.nominal_load) / tp.nominal_load
    kx = k + (tp.pHx1 + tp.pHx2 * dfz)
    dx = mu * (tp.pDx1 + tp.pDx2 * dfz) * z
    ex = np.minimum(
        (tp.pEx1 + tp.pEx2 * dfz + tp.pEx3 * dfz * dfz) * (1.0 - tp.pEx4 * np.sign(kx)), 1.0
    )
    kk = z * (tp.pKx1 + tp.pKx2 * dfz) * np.exp(tp.pKx3 * dfz)
    # Bx = Kx / (Cx Dx); Dx -> 0 (no load or no friction) gives Fx -> 0 with finite slope,
    # so guard the division and zero the result there.
    safe_dx = np.where(dx > 0.0, dx, 1.0)
    bx = kk / (tp.pCx1 * safe_dx)
    bk = bx * kx
    fx = dx * np.sin(tp.pCx1 * np.arctan(bk - ex * (bk - np.arctan(bk))))
    out: FloatArray = np.where(dx > 0.0, fx, 0.0) + z * (tp.pVx1 + tp.pVx2 * dfz)
    return out


def _fx_scalar(kappa: float, fz: float, mu_road: float, tp: TireParams) -> float:
    if fz <= 0.0:
        return 0.0
    dfz = (fz - tp.nominal_load) / tp.nominal_load
    kx = kappa + tp.pHx1 + tp.pHx2 * dfz
    dx = mu_road * (tp.pDx1 + tp.pDx2 * dfz) * fz
    sv = fz * (tp.pVx1 + tp.pVx2 * dfz)
    if dx <= 0.0:
        return sv
    sgn = 1.0 if kx > 0.0 else (-1.0 if kx < 0.0 else 0.0)
    ex = min((tp.pEx1 + tp.pEx2 * dfz + tp.pEx3 * dfz * dfz) * (1.0 - tp.pEx4 * sgn), 1.0)
    kk = fz * (tp.pKx1 + tp.pKx2 * dfz) * math.exp(tp.pKx3 * dfz)
    bk = kk / (tp.pCx1 * dx) * kx
    return dx * math.sin(tp.pCx1 * math.atan(bk - ex * (bk - math.atan(bk)))) + sv


@overload
def tire_force_from_slip_velocity(
    slip_velocity: float, ground_speed: float, fz: float, mu_road: float, tp: TireParams
) -> float: ...
@overload
def tire_force_from_slip_velocity(
    slip_velocity: FloatArray,
    ground_speed: FloatArray | float,
    fz: FloatArray | float,
    mu_road: FloatArray | float,
    tp: TireParams,
) -> FloatArray: ...
def tire_force_from_slip_velocity(
    slip_velocity: float | FloatArray,
    ground_speed: float | FloatArray,
    fz: float | FloatArray,
    mu_road: float | FloatArray,
    tp: TireParams,
) -> float | FloatArray:
    """Tyre force as a law of the slip velocity (the modulated R of the bond graph).

    Args:
        slip_velocity: omega R - v, [m/s].
        ground_speed: v, [m/s].
        fz: vertical load, [N].
        mu_road: road friction scale, [-].
        tp: tyre coefficients (``tp.low_speed_velocity`` is the slip floor).

    Returns:
        Fx, [N], positive when the tyre drives the car.
    """
    if (
        isinstance(slip_velocity, float)
        and isinstance(ground_speed, float)
        and isinstance(fz, float)
        and isinstance(mu_road, float)
    ):
        return _fx_scalar(
            slip_ratio(slip_velocity, ground_speed, tp.low_speed_velocity), fz, mu_road, tp
        )
    kappa = slip_ratio(
        np.asarray(slip_velocity, dtype=float),
        np.asarray(ground_speed, dtype=float),
        tp.low_speed_velocity,
    )
    return magic_formula_fx(kappa, np.asarray(fz, dtype=float), mu_road, tp)
