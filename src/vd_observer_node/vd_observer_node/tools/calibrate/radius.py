"""Effective rolling radius of one axle against a speed reference.

On a free-rolling (or lightly loaded) axle the wheel's circumferential speed equals the body's
longitudinal speed, ``v = r * omega``; the fit is this one-parameter model over the low-slip
samples, with a robust loss so that wheel-spin or braking samples that pass the filter weigh
little.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.optimize import least_squares

from vd_observer_node.tools.calibrate.errors import CalibrationError, NotDeterminedError

__all__ = ['FittedValue', 'fit_rolling_radius']

FloatArray = npt.NDArray[np.float64]

# Below this speed the encoder quantisation dominates the speed ratio.
_MIN_SPEED_MPS = 3.0
# Fewer samples than this do not give a standard deviation worth writing.
_MIN_SAMPLES = 50


@dataclass(frozen=True)
class FittedValue:
    """One fitted value.

    Attributes:
        value: The estimate (unit of the quantity, here m).
        std: Its standard deviation from the fit's Jacobian and residual scale (same unit).
        samples: Number of samples the fit rests on.
    """

    value: float
    std: float
    samples: int


def fit_rolling_radius(
    wheel_speed_radps: FloatArray,
    reference_speed_mps: FloatArray,
    bounds_m: tuple[float, float] = (0.15, 0.6),
) -> FittedValue:
    """Fit the effective rolling radius of one axle.

    Args:
        wheel_speed_radps: Mean wheel angular speed of the axle, shape (n,), rad/s.
        reference_speed_mps: Longitudinal body speed from the reference, shape (n,), m/s,
            sampled at the same stamps.
        bounds_m: Physical bounds of the radius, m.

    Returns:
        The radius (m) with its standard deviation and sample count.

    Raises:
        CalibrationError: Arrays of different shapes.
        NotDeterminedError: Fewer than 50 finite samples above 3 m/s.
    """
    omega = np.asarray(wheel_speed_radps, dtype=np.float64)
    speed = np.asarray(reference_speed_mps, dtype=np.float64)
    if omega.shape != speed.shape or omega.ndim != 1:
        raise CalibrationError(
            f'wheel speed {omega.shape} and reference speed {speed.shape} differ in shape'
        )
    usable = np.isfinite(omega) & np.isfinite(speed) & (speed > _MIN_SPEED_MPS) & (omega > 0.0)
    count = int(np.count_nonzero(usable))
    if count < _MIN_SAMPLES:
        raise NotDeterminedError(
            f'rolling radius: {count} samples above {_MIN_SPEED_MPS} m/s, need {_MIN_SAMPLES}'
        )
    omega_used = omega[usable]
    speed_used = speed[usable]
    start = float(np.clip(np.median(speed_used / omega_used), *bounds_m))

    def speed_error(radius: FloatArray) -> FloatArray:
        return float(radius[0]) * omega_used - speed_used

    result = least_squares(
        speed_error,
        x0=[start],
        bounds=([bounds_m[0]], [bounds_m[1]]),
        loss='soft_l1',
        f_scale=0.1,
    )
    residual = np.asarray(result.fun, dtype=np.float64)
    jacobian = np.asarray(result.jac, dtype=np.float64)[:, 0]
    dof = max(count - 1, 1)
    variance = float(residual @ residual) / dof / float(jacobian @ jacobian)
    return FittedValue(value=float(result.x[0]), std=float(np.sqrt(variance)), samples=count)
