"""Analytic vehicle trajectories obeying the estimator conventions (tests and benchmarks).

The trajectory is built backwards from smooth closed-form motion so that every quantity
and its derivatives are exact: body position x(t), speed v = x', acceleration v' ; wheel
angles theta_i = (x + delta_i) / R_eff with a small periodic slip displacement delta_i;
slope alpha(t). Loads are the quasi-static whole-vehicle moment balance, the tire forces
close the longitudinal balance m*v' = sum(Fx) - sum(F_r) - F_aero - m*g*sin(alpha)
(split between axles by `front_share`), and the wheel torques follow from the spin balance
T_i = J_i * omega_dot_i + R_eff * Fx_i.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vd_observer_node.estimation import formulas as phys
from vd_observer_node.estimation.vehicle import EstimatorVehicle

__all__ = ['SyntheticTrajectory', 'TrajectoryShape', 'synthetic_trajectory']

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class SyntheticTrajectory:
    """Exact signals on the stamps t (per-wheel arrays shape (N, 4), FL, FR, RL, RR).

    Attributes:
        t: shape (N,), [s].
        angle: shape (N, 4), [rad].
        omega: shape (N, 4), [rad/s].
        omega_dot: shape (N, 4), [rad/s^2].
        speed: shape (N,), [m/s].
        accel: shape (N,), [m/s^2].
        slope: shape (N,), [rad].
        fx: shape (N, 4), [N].
        fz: shape (N, 4), [N].
        torque: shape (N, 4), [N m].
        rolling: shape (N, 4), [N].
        aero: shape (N,), [N].
    """

    t: FloatArray
    angle: FloatArray
    omega: FloatArray
    omega_dot: FloatArray
    speed: FloatArray
    accel: FloatArray
    slope: FloatArray
    fx: FloatArray
    fz: FloatArray
    torque: FloatArray
    rolling: FloatArray
    aero: FloatArray


@dataclass(frozen=True)
class TrajectoryShape:
    """The shape of the analytic trajectory (`synthetic_trajectory`).

    Attributes:
        v0: mean speed [m/s].
        accel_amplitude: amplitude of v' [m/s^2] (sinusoidal speed oscillation).
        accel_frequency: frequency of the speed oscillation [Hz].
        slope_mean: [rad].
        slope_amplitude: [rad].
        slope_frequency: [Hz].
        slip_amplitude: amplitude of the wheel slip displacement delta_i [m].
        slip_frequency: [Hz].
        front_share: fraction of sum(Fx) carried by the front axle [-].
    """

    v0: float = 15.0
    accel_amplitude: float = 1.5
    accel_frequency: float = 0.3
    slope_mean: float = 0.03
    slope_amplitude: float = 0.02
    slope_frequency: float = 0.1
    slip_amplitude: float = 0.01
    slip_frequency: float = 1.0
    front_share: float = 0.9


def synthetic_trajectory(
    t: ArrayLike, vehicle: EstimatorVehicle, shape: TrajectoryShape = TrajectoryShape()
) -> SyntheticTrajectory:
    """Sample the analytic trajectory at stamps t (may be irregular).

    Args:
        t: shape (N,), [s].
        vehicle: parameters.
        shape: speed, slope and slip oscillations, the front axle's share of the force.
    """
    v0, accel_amplitude, accel_frequency = shape.v0, shape.accel_amplitude, shape.accel_frequency
    slope_mean, slope_amplitude = shape.slope_mean, shape.slope_amplitude
    slope_frequency, front_share = shape.slope_frequency, shape.front_share
    slip_amplitude, slip_frequency = shape.slip_amplitude, shape.slip_frequency
    ts = np.asarray(t, dtype=np.float64)
    w = 2.0 * np.pi * accel_frequency
    speed_amp = accel_amplitude / w
    x = v0 * ts + speed_amp / w * (1.0 - np.cos(w * ts))
    v = v0 + speed_amp * np.sin(w * ts)
    a = accel_amplitude * np.cos(w * ts)
    ws = 2.0 * np.pi * slip_frequency
    # Different phases per wheel so the four channels are not identical.
    phase = np.array([0.0, 0.7, 1.9, 2.8])
    arg = ws * ts[:, None] + phase
    delta = slip_amplitude * np.sin(arg)
    delta_d = slip_amplitude * ws * np.cos(arg)
    delta_dd = -slip_amplitude * ws**2 * np.sin(arg)
    r = vehicle.effective_radius
    angle = (x[:, None] + delta) / r
    omega = (v[:, None] + delta_d) / r
    omega_dot = (a[:, None] + delta_dd) / r
    alpha = slope_mean + slope_amplitude * np.sin(2.0 * np.pi * slope_frequency * ts)
    m, g = vehicle.mass, vehicle.gravity
    aero = phys.aero_drag(v, vehicle)
    ground = m * a + m * g * np.sin(alpha) + aero
    fz = phys.wheel_loads(ground, np.cos(alpha), vehicle)
    rolling = phys.rolling_resistance(v, fz, vehicle)
    total_fx = ground + rolling.sum(axis=1)
    split = np.array([front_share, front_share, 1.0 - front_share, 1.0 - front_share]) / 2.0
    fx = total_fx[:, None] * split
    torque = vehicle.wheel_inertia * omega_dot + r * fx
    return SyntheticTrajectory(
        t=ts,
        angle=angle,
        omega=omega,
        omega_dot=omega_dot,
        speed=v,
        accel=a,
        slope=alpha,
        fx=fx,
        fz=fz,
        torque=torque,
        rolling=rolling,
        aero=aero,
    )
