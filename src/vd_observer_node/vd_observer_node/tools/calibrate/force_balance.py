"""Mass, rolling resistance and drag area from the longitudinal force balance.

With the grade known from a reference, a known driving force (torque / radius; not braking,
clutch engaged) balances

    F = m * (a + g * sin(theta)) + m * g * c0 * (1 + c1 * |v| / 160) * cos(theta)
        + 0.5 * rho * CdA * v**2,

(the rolling resistance of paper eq. 7 with the base file's speed term c1), linear in
(m, m * c0, CdA), fitted with a robust loss and bounds. Without speed above 60 km/h
the drag term is not separable from c0 (both are then near-constant) and is reported as not
determined.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
from scipy.optimize import least_squares

from vd_observer_node.estimation.formulas import rolling_speed_factor
from vd_observer_node.tools.calibrate.errors import CalibrationError, NotDeterminedError
from vd_observer_node.tools.calibrate.radius import FittedValue, parameter_covariance

__all__ = ['ForceBalanceFit', 'fit_force_balance']

FloatArray = npt.NDArray[np.float64]

GRAVITY_MPS2 = 9.81
AIR_DENSITY_KGPM3 = 1.2
# Drag is 4x its 30 km/h share at 60 km/h; below this top speed drag and c0 are confounded.
_MIN_TOP_SPEED_MPS = 60.0 / 3.6
_MIN_SAMPLES = 200
# Residual scale of the robust loss, N (a gust or a bump).
_FORCE_F_SCALE = 200.0


@dataclass(frozen=True)
class ForceBalanceFit:
    """Fitted mass (kg), rolling resistance c0 (-) and drag area (m^2, None if not determined).

    Without drag, c0 absorbs the drag at the drive's speeds and is an effective value.
    ``residual_n`` (model minus force, [N]) is over the samples ``used`` marks (shape of the
    input), for the report's figures.
    """

    mass_kg: FittedValue
    rolling_c0: FittedValue
    drag_area_m2: FittedValue | None
    not_determined: tuple[str, ...]
    residual_n: FloatArray = field(default_factory=lambda: np.zeros(0))
    used: npt.NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, dtype=bool))


def fit_force_balance(
    drive_force_n: FloatArray,
    speed_mps: FloatArray,
    accel_mps2: FloatArray,
    slope_rad: FloatArray,
    rolling_c1: float = 0.0,
    gravity_mps2: float = GRAVITY_MPS2,
    air_density_kgpm3: float = AIR_DENSITY_KGPM3,
    known_drag_area_m2: float | None = None,
) -> ForceBalanceFit:
    """Fit mass, c0 and drag area from samples with a known driving force.

    Args:
        drive_force_n: Longitudinal force at the wheels, shape (n,), N.
        speed_mps: Reference speed, shape (n,), m/s.
        accel_mps2: Reference longitudinal acceleration dv/dt, shape (n,), m/s^2.
        slope_rad: Road grade from the reference, shape (n,), rad (positive uphill).
        rolling_c1: the rolling resistance's speed term c1 [km/h per m/s] (kept, not fitted).
        gravity_mps2: g [m/s^2].
        air_density_kgpm3: rho [kg/m^3].
        known_drag_area_m2: a drag area [m^2] to take as known (subtracted, not fitted):
            where the drive does not determine it, mass and c0 are then fitted alone.

    Returns:
        The fit; ``not_determined`` says why a value could not be fitted.

    Raises:
        CalibrationError: Arrays of different shapes.
        NotDeterminedError: Fewer than 200 finite samples.
    """
    force, speed, accel, slope = (
        np.asarray(a, dtype=np.float64) for a in (drive_force_n, speed_mps, accel_mps2, slope_rad)
    )
    if not (force.shape == speed.shape == accel.shape == slope.shape) or force.ndim != 1:
        raise CalibrationError('force balance: inputs differ in shape')
    usable = np.isfinite(force) & np.isfinite(speed) & np.isfinite(accel) & np.isfinite(slope)
    count = int(np.count_nonzero(usable))
    if count < _MIN_SAMPLES:
        raise NotDeterminedError(f'force balance: {count} usable samples, need {_MIN_SAMPLES}')
    force, speed, accel, slope = force[usable], speed[usable], accel[usable], slope[usable]
    with_drag = float(speed.max()) >= _MIN_TOP_SPEED_MPS and known_drag_area_m2 is None
    if known_drag_area_m2 is not None:
        force = force - 0.5 * air_density_kgpm3 * known_drag_area_m2 * speed**2
    rolling = rolling_speed_factor(speed, rolling_c1)
    columns = [accel + gravity_mps2 * np.sin(slope), gravity_mps2 * rolling * np.cos(slope)]
    if with_drag:
        columns.append(0.5 * air_density_kgpm3 * speed**2)
    design = np.column_stack(columns)
    # Unknowns: mass (kg), mass * c0 (kg), drag area (m^2).
    lower = [200.0, 0.0, 0.1][: design.shape[1]]
    upper = [10000.0, 0.05 * 10000.0, 3.0][: design.shape[1]]
    start = np.clip(np.linalg.lstsq(design, force, rcond=None)[0], lower, upper)

    def error(unknowns: FloatArray) -> FloatArray:
        return np.asarray(design @ unknowns - force, dtype=np.float64)

    result = least_squares(
        error, x0=start, bounds=(lower, upper), loss='soft_l1', f_scale=_FORCE_F_SCALE
    )
    residual = np.asarray(result.fun, dtype=np.float64)
    covariance = parameter_covariance(design, residual)
    mass = float(result.x[0])
    mass_c0 = float(result.x[1])
    c0 = mass_c0 / mass
    # c0 = (m c0) / m: first-order propagation of the joint covariance.
    gradient = np.array([-mass_c0 / mass**2, 1.0 / mass])
    c0_std = float(np.sqrt(gradient @ covariance[:2, :2] @ gradient))
    drag = None
    not_determined: tuple[str, ...] = ()
    if with_drag:
        drag = FittedValue(float(result.x[2]), float(np.sqrt(covariance[2, 2])), count)
    elif known_drag_area_m2 is None:
        not_determined = (
            f'drag area: never above {_MIN_TOP_SPEED_MPS * 3.6:.0f} km/h '
            f'(top {speed.max() * 3.6:.0f} km/h), drag not separable from rolling resistance',
        )
    return ForceBalanceFit(
        mass_kg=FittedValue(mass, float(np.sqrt(covariance[0, 0])), count),
        rolling_c0=FittedValue(c0, c0_std, count),
        drag_area_m2=drag,
        not_determined=not_determined,
        residual_n=residual,
        used=usable,
    )
