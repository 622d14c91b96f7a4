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

__all__ = ['FittedValue', 'fit_proportional', 'fit_rolling_radius', 'parameter_covariance']

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
        Reference speeds are in m/s.
    """
    return fit_proportional(
        wheel_speed_radps,
        reference_speed_mps,
        'rolling radius',
        bounds_m,
        min_response=_MIN_SPEED_MPS,
    )


def fit_proportional(
    regressor: FloatArray,
    response: FloatArray,
    name: str,
    bounds: tuple[float, float],
    min_response: float,
    f_scale: float = 0.1,
) -> FittedValue:
    """Fit ``response = k * regressor`` robustly (soft-L1 loss) within bounds.

    Args:
        regressor: Shape (n,), e.g. wheel speed in rad/s.
        response: Shape (n,), e.g. reference speed in m/s or engine speed in rad/s.
        name: What is fitted, for the error messages.
        bounds: Physical bounds of k.
        min_response: Samples with a smaller response are left out (quantisation, standstill).
        f_scale: Residual size (response unit) above which the loss turns linear.

    Returns:
        k with its standard deviation and the number of samples used.

    Raises:
        CalibrationError: Arrays of different shapes.
        NotDeterminedError: Fewer than 50 usable samples.
    """
    x = np.asarray(regressor, dtype=np.float64)
    y = np.asarray(response, dtype=np.float64)
    if x.shape != y.shape or x.ndim != 1:
        raise CalibrationError(f'{name}: inputs of shapes {x.shape} and {y.shape} differ in shape')
    usable = np.isfinite(x) & np.isfinite(y) & (y > min_response) & (x > 0.0)
    count = int(np.count_nonzero(usable))
    if count < _MIN_SAMPLES:
        raise NotDeterminedError(
            f'{name}: {count} samples above {min_response:g}, need {_MIN_SAMPLES}'
        )
    x_used = x[usable]
    y_used = y[usable]
    start = float(np.clip(np.median(y_used / x_used), *bounds))

    def error(k: FloatArray) -> FloatArray:
        return float(k[0]) * x_used - y_used

    result = least_squares(
        error, x0=[start], bounds=([bounds[0]], [bounds[1]]), loss='soft_l1', f_scale=f_scale
    )
    residual = np.asarray(result.fun, dtype=np.float64)
    jacobian = np.asarray(result.jac, dtype=np.float64)[:, 0]
    dof = max(count - 1, 1)
    variance = float(residual @ residual) / dof / float(jacobian @ jacobian)
    return FittedValue(value=float(result.x[0]), std=float(np.sqrt(variance)), samples=count)


def parameter_covariance(design: FloatArray, residual: FloatArray) -> FloatArray:
    """Covariance of a linear least-squares fit's unknowns: ``inv(A^T A)`` times the residual
    variance (the residuals' sum of squares over the degrees of freedom).

    Args:
        design: shape (n, k), the regressors A.
        residual: shape (n,), the fit's residuals.

    Returns:
        shape (k, k).
    """
    a = np.asarray(design, dtype=np.float64).reshape(len(residual), -1)
    dof = max(a.shape[0] - a.shape[1], 1)
    return np.asarray(np.linalg.inv(a.T @ a) * float(residual @ residual) / dof, dtype=np.float64)
