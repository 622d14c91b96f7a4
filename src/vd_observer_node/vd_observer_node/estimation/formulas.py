"""Physical estimator formulas (pure, vectorized; see docs/estimation.md for derivations).

Conventions (shared with the simulator): wheel order FL, FR, RL, RR; Fx road -> tire,
positive forward; slope alpha positive uphill; rolling resistance and aero drag act on the
body, opposing the motion, with a smoothly regularised direction near v = 0.

Every function accepts leading batch dimensions: per-wheel arrays have shape (..., 4) and
scalars per stamp shape (...).
"""

from __future__ import annotations

import math
from typing import Final

import numpy as np
from numpy.typing import ArrayLike, NDArray
from vd_common.vehicle.tire import slip_ratio as tire_slip_ratio

from vd_observer_node.estimation.vehicle import EstimatorVehicle
from vd_observer_node.kernel._jit import jit

__all__ = [
    'KMH_REFERENCE',
    'aero_drag',
    'motion_direction',
    'rolling_coefficient',
    'rolling_coefficient_at',
    'rolling_resistance',
    'rolling_speed_factor',
    'slip_ratio',
    'slope_from_forces',
    'tire_longitudinal_force',
    'utilised_friction',
    'wheel_loads',
]

FloatArray = NDArray[np.float64]

#: [km/h] speed scale of paper eq. 7's rolling coefficient
KMH_REFERENCE: Final = 160.0


@jit
def rolling_coefficient_at(c0: float, c1: float, speed: float) -> float:
    """c0 * (1 + c1 * |v| / 160) of paper eq. 7 at one speed [m/s] (the compiled steps')."""
    return c0 * (1.0 + c1 * abs(speed) / KMH_REFERENCE)


def tire_longitudinal_force(
    torque: ArrayLike,
    omega_dot: ArrayLike,
    vehicle: EstimatorVehicle,
    radius: float | None = None,
) -> FloatArray:
    """Fx_i = (T_i - J_i * omega_dot_i) / R_eff, from the wheel spin balance.

    Args:
        torque: shape (..., 4), [N m], drive minus brake torque per wheel.
        omega_dot: shape (..., 4), [rad/s^2], wheel angular acceleration.
        vehicle: parameters (J per wheel, R_eff).
        radius: R_eff [m] if not the vehicle's (the online estimate).

    Returns:
        shape (..., 4), [N], road -> tire longitudinal force, positive forward.
    """
    t = np.asarray(torque, dtype=np.float64)
    wd = np.asarray(omega_dot, dtype=np.float64)
    r = vehicle.effective_radius if radius is None else radius
    return (t - vehicle.wheel_inertia * wd) / r


def motion_direction(speed: ArrayLike, speed_scale: float) -> FloatArray:
    """Regularised sign of the speed, tanh(v / v_s), in [-1, 1].

    Args:
        speed: shape (...), [m/s].
        speed_scale: v_s [m/s]; 0 gives the plain sign.
    """
    v = np.asarray(speed, dtype=np.float64)
    if speed_scale <= 0.0:
        return np.sign(v)
    return np.tanh(v / speed_scale)


def aero_drag(speed: ArrayLike, vehicle: EstimatorVehicle) -> FloatArray:
    """Aerodynamic drag magnitude 0.5 * rho * Cx * A * v^2.

    Args:
        speed: shape (...), [m/s].

    Returns:
        shape (...), [N], >= 0 (it opposes the motion).
    """
    v = np.asarray(speed, dtype=np.float64)
    return vehicle.drag_factor * v * v


def rolling_coefficient(speed: ArrayLike, vehicle: EstimatorVehicle) -> FloatArray:
    """c0 * (1 + c1 * |v| / 160) of paper eq. 7 (c1 converts m/s to km/h).

    Args:
        speed: shape (...), [m/s].

    Returns:
        shape (...), [-].
    """
    return vehicle.rolling_c0 * rolling_speed_factor(speed, vehicle.rolling_c1)


def rolling_speed_factor(speed: ArrayLike, c1: float) -> FloatArray:
    """1 + c1 * |v| / 160 of paper eq. 7: the rolling coefficient per unit of c0.

    Args:
        speed: shape (...), [m/s].
        c1: [km/h per m/s].

    Returns:
        shape (...), [-].
    """
    v = np.abs(np.asarray(speed, dtype=np.float64))
    return np.asarray(1.0 + c1 * v / KMH_REFERENCE, dtype=np.float64)


def rolling_resistance(speed: ArrayLike, fz: ArrayLike, vehicle: EstimatorVehicle) -> FloatArray:
    """Rolling resistance magnitude per wheel, paper eq. 7: c0 * (1 + c1 * v / 160) * Fz_i.

    Args:
        speed: shape (...), [m/s].
        fz: shape (..., 4), [N], wheel normal loads.

    Returns:
        shape (..., 4), [N], >= 0 for fz >= 0.
    """
    c = rolling_coefficient(speed, vehicle)
    return np.asarray(c)[..., np.newaxis] * np.asarray(fz, dtype=np.float64)


def wheel_loads(
    ground_force: ArrayLike,
    cos_slope: ArrayLike,
    vehicle: EstimatorVehicle,
    mass: float | None = None,
) -> FloatArray:
    """Quasi-static wheel loads with longitudinal load transfer (whole-vehicle moment balance).

    Fz_front_axle = (m*g*cos(alpha)*b - G*h) / L,  Fz_rear_axle = (m*g*cos(alpha)*a + G*h) / L,
    with G = m*v_dot + m*g*sin(alpha) + F_aero_signed = sum(Fx) - sum(F_r_signed): the
    longitudinal force the ground exerts on the vehicle net of rolling resistance. Each wheel
    carries half its axle load (no roll model). Loads are clamped at 0 (wheel lift).

    Args:
        ground_force: shape (...), G [N].
        cos_slope: shape (...), cos(alpha) [-].
        mass: m [kg] if not the vehicle's (the online estimate); the CG stays the file's.

    Returns:
        shape (..., 4), [N], order FL, FR, RL, RR.
    """
    g_force = np.asarray(ground_force, dtype=np.float64)
    m = vehicle.mass if mass is None else mass
    weight_normal = m * vehicle.gravity * np.asarray(cos_slope, dtype=np.float64)
    transfer = g_force * vehicle.cg_height
    front = 0.5 * (weight_normal * vehicle.cg_to_rear_axle - transfer) / vehicle.wheelbase
    rear = 0.5 * (weight_normal * vehicle.cg_to_front_axle + transfer) / vehicle.wheelbase
    loads: FloatArray = np.stack(np.broadcast_arrays(front, front, rear, rear), axis=-1)
    return np.maximum(loads, 0.0)


def utilised_friction(
    fx: ArrayLike, fz: ArrayLike, min_load: float, min_excitation_ratio: float
) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Utilised friction mu_i = Fx_i / Fz_i with a validity flag.

    mu is only meaningful where the wheel is loaded (Fz >= min_load) and excited
    (|Fx| >= min_excitation_ratio * Fz): near Fx = 0 the ratio is dominated by the force
    estimation error. Where invalid, mu is reported as 0 (the Friction message convention).

    Args:
        fx: shape (..., 4), [N].
        fz: shape (..., 4), [N].
        min_load: [N].
        min_excitation_ratio: [-].

    Returns:
        (mu, valid): shape (..., 4) each, [-] and bool.
    """
    x = np.asarray(fx, dtype=np.float64)
    z = np.asarray(fz, dtype=np.float64)
    valid = (z >= min_load) & (np.abs(x) >= min_excitation_ratio * z) & np.isfinite(x)
    mu = np.where(valid, x / np.where(valid, z, 1.0), 0.0)
    return mu, valid


def slip_ratio(
    omega: ArrayLike,
    speed: ArrayLike,
    vehicle: EstimatorVehicle,
    eps: float = 0.1,
    radius: float | None = None,
) -> FloatArray:
    """Longitudinal slip s_i = (omega_i*R - v) / max(|omega_i*R|, |v|, eps).

    Args:
        omega: shape (..., 4), [rad/s].
        speed: shape (...), [m/s].
        eps: floor of the denominator [m/s], keeps s finite at standstill.
        radius: R_eff [m] if not the vehicle's (the online estimate).

    Returns:
        shape (..., 4), [-], positive when driving.
    """
    r = vehicle.effective_radius if radius is None else radius
    wheel_speed = np.asarray(omega, dtype=np.float64) * r
    v = np.asarray(speed, dtype=np.float64)[..., np.newaxis]
    # The tyre model's own definition, so estimate and simulation mean the same slip.
    return tire_slip_ratio(wheel_speed - v, v, eps)


def slope_from_forces(
    net_force: ArrayLike,
    vehicle: EstimatorVehicle,
    max_slope: float,
    mass: float | None = None,
) -> tuple[FloatArray, NDArray[np.bool_]]:
    """alpha = arcsin(N / (m*g)), N = sum(Fx) - sum(F_r_signed) - F_aero_signed - m*v_dot.

    N is the part of the longitudinal force balance left to gravity, m*g*sin(alpha).

    Args:
        net_force: shape (...), N [N].
        max_slope: |alpha| bound [rad]; beyond it the estimate is clamped and invalid.
        mass: m [kg] if not the vehicle's (the online estimate).

    Returns:
        (alpha [rad], valid): shape (...) each.
    """
    n = np.asarray(net_force, dtype=np.float64)
    sine = n / ((vehicle.mass if mass is None else mass) * vehicle.gravity)
    bound = math.sin(max_slope)
    valid = np.isfinite(sine) & (np.abs(sine) <= bound)
    clipped = np.clip(np.nan_to_num(sine, nan=0.0), -bound, bound)
    # libm's asin, not numpy's SIMD loop (which differs in the last bit on some CPUs): the
    # compiled kernel calls libm, and the two must agree bit for bit.
    alpha = np.array([math.asin(s) for s in clipped.ravel().tolist()]).reshape(clipped.shape)
    return alpha, valid
