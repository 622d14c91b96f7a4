"""What one or more drives determine of a car: the fits of ``vd calibrate`` in their order.

Each value is a vehicle-file key (``chassis.mass``) either fitted, with its standard deviation
and the samples it rests on, or not determined with the reason; the base file keeps what the
drive cannot tell. The order matters: the driven axle picks the free-rolling axle for the
radius, the radius and the final drive turn torques into forces, the force balance gives the
mass that the brake gain needs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Final

import numpy as np
import numpy.typing as npt
from scipy.optimize import least_squares
from vd_common.vehicle.estimation import EstimationVehicleParams

from vd_observer_node.estimation.formulas import rolling_speed_factor
from vd_observer_node.inputs.errors import MountingNotDeterminedError
from vd_observer_node.inputs.mounting import MountingFit, fit_mounting
from vd_observer_node.tools.calibrate.converter import (
    MIN_BIN_SAMPLES,
    MIN_PUMP_TORQUE_NM,
    binned_medians,
    fit_capacity_factor,
)
from vd_observer_node.tools.calibrate.drive import GRID_HZ, WINDOW_S, CalibrationDrive
from vd_observer_node.tools.calibrate.errors import NotDeterminedError
from vd_observer_node.tools.calibrate.force_balance import fit_force_balance
from vd_observer_node.tools.calibrate.radius import (
    FittedValue,
    fit_rolling_radius,
    parameter_covariance,
)
from vd_observer_node.tools.calibrate.ratios import (
    fit_final_drive,
    fit_gear_offset,
    fit_gear_ratios,
)

__all__ = ['MAX_RELATIVE_STD', 'Calibration', 'Fit', 'calibrate']

FloatArray = npt.NDArray[np.float64]

# Slower than this [m/s] the speed ratios are quantisation and the slip is ill-defined.
_MIN_SPEED_MPS = 3.0
# A radius fit on steady driving only: harder acceleration slips even a free axle's tyres.
_MAX_RADIUS_ACCEL_MPS2 = 1.5
# The force balance leaves out standstill and violent manoeuvres.
_MIN_FORCE_SPEED_MPS = 2.0
_MAX_FORCE_ACCEL_MPS2 = 3.0
# Share of the drive torque on the front axle above which a car is FWD (below 1 - it: RWD).
_SINGLE_AXLE_SHARE = 0.9
# The front-rear slip's dependence on engine torque must exceed this many standard deviations.
_SLIP_SIGNIFICANCE = 4.0
# Speed ratio turbine / pump above which a converter is coupled (torque ratio 1).
_COUPLED_SPEED_RATIO = 0.97
# Relative engine-to-wheel speed mismatch of a manual gearbox's engaged clutch.
_CLUTCH_SLIP = 0.02
# Residual scale of the brake gain's robust loss [N m of brake torque].
_BRAKE_F_SCALE_NM = 100.0
# The grid's samples are correlated over the averaging window: the fits' standard deviations
# (which take the samples as independent) are scaled by the root of the samples per window.
_CORRELATION = math.sqrt(GRID_HZ * WINDOW_S)
#: The largest relative standard deviation at which a fitted value is written: the accuracy
#: the estimators need of it (issue #37's targets). A fit less certain than this is not
#: determined by the drive (too little excitation: a short drive, one speed, no hill).
MAX_RELATIVE_STD: Final = {
    'wheel.effective_radius': 0.003,
    'gearbox.final_drive': 0.01,  # 1 % of the drive force: ~0.035 deg of slope at 1 kN
    'chassis.mass': 0.03,
    'rolling_resistance.c0': 0.2,
    'aero.drag_coefficient': 0.1,
}


@dataclass(frozen=True)
class Fit:
    """One vehicle-file key fitted from the drive.

    Attributes:
        key: dotted key of the vehicle file, e.g. ``chassis.mass``.
        value: the value in the file's unit (a list for a table, a string for a layout).
        std: its standard deviation (same shape; None where a choice, not an estimate).
        samples: the grid samples (``drive.GRID_HZ``) it rests on.
        how: what was fitted against what, for the file's comment and the report.
    """

    key: str
    value: float | str | tuple[float, ...]
    std: float | tuple[float, ...] | None
    samples: int
    how: str


@dataclass
class Calibration:
    """The result: fitted keys, keys not determined (with the reason) and notes.

    Attributes:
        fits: key -> its fit, in fitting order.
        not_determined: key -> why the drive does not determine it.
        notes: findings that are not vehicle-file keys (the mapping's gear offset, a wheel
            speed scale, each axle's radius).
        residuals: figure name -> (x, residual, x label, residual label) for the report.
        drive_seconds: the drives' total duration [s].
        gear_offset: added to the logged gear to give the gearbox's (fitted, else the
            mapping's).
        mounting: the IMU's mounting (for the input mapping, not the vehicle file); None
            without an IMU with three axes, or where the drive does not determine it (then
            ``not_determined`` has ``imu.mount_rpy_deg``).
    """

    fits: dict[str, Fit] = field(default_factory=dict)
    not_determined: dict[str, str] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    residuals: dict[str, tuple[FloatArray, FloatArray, str, str]] = field(default_factory=dict)
    drive_seconds: float = 0.0
    gear_offset: int = 0
    mounting: MountingFit | None = None

    def value(self, key: str, default: float) -> float:
        """A fitted number, or ``default`` where the key was not fitted."""
        fit = self.fits.get(key)
        return float(fit.value) if fit is not None and isinstance(fit.value, float) else default

    def add(self, key: str, fitted: FittedValue, how: str) -> bool:
        """Record a one-number fit (its std scaled for the grid's correlation), or say it is
        not determined where it is less certain than :data:`MAX_RELATIVE_STD` allows.

        Returns:
            True where the fit was recorded.
        """
        std = fitted.std * _CORRELATION
        limit = MAX_RELATIVE_STD.get(key)
        relative = std / abs(fitted.value) if fitted.value else math.inf
        if limit is not None and relative > limit:
            self.not_determined[key] = (
                f'{fitted.value:.5g} ± {100.0 * relative:.1f} % from {how}, less certain than '
                f'the {100.0 * limit:g} % the estimators need (too little excitation)'
            )
            return False
        self.fits[key] = Fit(key, fitted.value, std, fitted.samples, how)
        return True


def calibrate(drive: CalibrationDrive, base: EstimationVehicleParams) -> Calibration:
    """Fit what ``drive`` determines of the car ``base`` describes.

    Args:
        drive: the drive(s) on the calibration grid (`drive.concatenated` for several).
        base: the base vehicle file: the values the drive does not determine, and the
            gearbox ratios, efficiencies and inertias the fits need.

    Returns:
        The calibration (nothing is raised for a value the drive does not determine: it is
        listed in ``not_determined``).
    """
    out = Calibration(drive_seconds=drive.duration_s)
    moving = np.isfinite(drive.speed_mps) & (drive.speed_mps > _MIN_SPEED_MPS)
    layout = _driven_axle(drive, moving, out)
    if layout is None and base.driveline is not None:
        layout = base.driveline.layout
    _radius(drive, moving, layout, base, out)
    _ratios(drive, moving, layout, base, out)
    _converter(drive, base, out)
    _force_balance(drive, base, out)
    _torque_ratio(drive, base, out)
    _brake_gain(drive, base, out)
    _mounting(drive, out)
    return out


#: the mapping's mounting is called wrong where its forward axis is further than this many
#: of the fit's standard deviations (and 1 deg) from the drive's
_MOUNTING_SIGMAS = 3.0


def _mounting(drive: CalibrationDrive, out: Calibration) -> None:
    """The IMU's mounting from its three axes against the reference's acceleration."""
    if drive.imu_force_mps2 is None:
        return
    try:
        fit = fit_mounting(drive.imu_force_mps2, drive.accel_mps2)
    except MountingNotDeterminedError as error:
        out.not_determined['imu.mount_rpy_deg'] = str(error)
        return
    out.mounting = fit
    # the forward axis rests on the pitch and the yaw, the lateral one on the roll and the yaw
    spreads = (math.hypot(fit.std_deg[1], fit.std_deg[2]), math.hypot(*fit.std_deg[::2]))
    for row, axis in enumerate(drive.imu_mapped_axes):
        name = ('forward', 'lateral')[row]
        off = fit.axis_angle_deg(row, axis)
        bound = max(1.0, _MOUNTING_SIGMAS * spreads[row])
        if off > bound:
            out.notes.append(
                f"the mapping's imu.mount_rpy_deg puts the body's {name} axis {off:.1f} deg "
                f'from where the drive shows it (more than {bound:.1f} deg): use the fitted '
                'mounting'
            )


def _axle_means(drive: CalibrationDrive) -> tuple[FloatArray, FloatArray]:
    w = drive.wheel_radps
    return 0.5 * (w[:, 0] + w[:, 1]), 0.5 * (w[:, 2] + w[:, 3])


def _driven_wheel_speed(drive: CalibrationDrive, layout: str | None) -> FloatArray:
    front, rear = _axle_means(drive)
    return {'FWD': front, 'RWD': rear}.get(layout or '', 0.5 * (front + rear))


def _driven_axle(
    drive: CalibrationDrive, moving: npt.NDArray[np.bool_], out: Calibration
) -> str | None:
    """FWD, RWD or AWD (with the front share): from the measured torques' split, or from the
    front-rear slip's growth with the engine torque."""
    key = 'driveline.layout'
    usable = moving & ~drive.braking
    if drive.wheel_torque_nm is not None:
        torque = np.clip(drive.wheel_torque_nm[usable], 0.0, None)
        total = float(torque.sum())
        if total <= 0.0:
            out.not_determined[key] = 'no drive torque on the measured wheel torques'
            return None
        share = float(torque[:, :2].sum()) / total
        count = int(np.count_nonzero(usable))
        how = f'front share {share:.3f} of the measured drive torque'
        if share >= _SINGLE_AXLE_SHARE or share <= 1.0 - _SINGLE_AXLE_SHARE:
            layout = 'FWD' if share >= _SINGLE_AXLE_SHARE else 'RWD'
            out.fits[key] = Fit(key, layout, None, count, how)
            return layout
        out.fits[key] = Fit(key, 'AWD', None, count, how)
        out.fits['driveline.front_share'] = Fit(
            'driveline.front_share', share, None, count, 'measured drive torque, front / all'
        )
        return 'AWD'
    if drive.engine_torque_nm is None:
        out.not_determined[key] = 'neither measured wheel torques nor an engine torque'
        return None
    front, rear = _axle_means(drive)
    slip = (front - rear) / np.where(rear > 0.0, rear, np.nan)
    torque = drive.engine_torque_nm
    ok = usable & np.isfinite(slip) & np.isfinite(torque)
    count = int(np.count_nonzero(ok))
    if count < 50:
        out.not_determined[key] = f'{count} samples driving above 3 m/s, need 50'
        return None
    design = np.column_stack([torque[ok], np.ones(count)])
    coef, *_ = np.linalg.lstsq(design, slip[ok], rcond=None)
    residual = slip[ok] - design @ coef
    cov = parameter_covariance(design, residual)
    gain, gain_std = float(coef[0]), float(np.sqrt(cov[0, 0]))
    how = f'front-rear slip grows {gain * 1e5:+.2f} ± {gain_std * 1e5:.2f} %/kN m of engine torque'
    out.residuals['driven axle'] = (
        torque[ok],
        slip[ok] * 100.0,
        'engine torque [N m]',
        'front-rear slip [%]',
    )
    if abs(gain) < _SLIP_SIGNIFICANCE * gain_std:
        out.not_determined[key] = how + ': neither axle runs ahead with torque (AWD?)'
        return None
    layout = 'FWD' if gain > 0.0 else 'RWD'
    out.fits[key] = Fit(key, layout, None, count, how)
    return layout


def _radius(
    drive: CalibrationDrive,
    moving: npt.NDArray[np.bool_],
    layout: str | None,
    base: EstimationVehicleParams,
    out: Calibration,
) -> None:
    key = 'wheel.effective_radius'
    front, rear = _axle_means(drive)
    steady = moving & ~drive.braking & (np.abs(drive.accel_mps2) < _MAX_RADIUS_ACCEL_MPS2)
    if drive.circumferential:
        scale = float(np.median(drive.speed_mps[steady] / (0.5 * (front + rear))[steady]))
        out.not_determined[key] = (
            "the wheel speeds are logged as a circumferential speed: the ECU's own radius "
            "scales them, the base file's is kept"
        )
        radius = base.wheel.effective_radius
        out.notes.append(
            f'wheel speed scale: the reference is {100.0 * (scale / radius - 1.0):+.2f} % of '
            'the logged wheel speeds'
        )
        return
    fits: dict[str, FittedValue] = {}
    for axle, omega in (('front', front), ('rear', rear)):
        try:
            fits[axle] = fit_rolling_radius(omega[steady], drive.speed_mps[steady])
        except NotDeterminedError as error:
            out.not_determined[key] = str(error)
            return
        out.notes.append(
            f'rolling radius, {axle} axle: {fits[axle].value:.5f} ± {fits[axle].std:.5f} m'
        )
    free = {'FWD': 'rear', 'RWD': 'front'}.get(layout or '')
    if free is None:
        # no free axle: the mean of both, each slipping a little under its share of torque
        value = 0.5 * (fits['front'].value + fits['rear'].value)
        std = 0.5 * float(np.hypot(fits['front'].std, fits['rear'].std))
        fitted = FittedValue(value, std, fits['front'].samples)
        how = 'mean of both axles against the reference speed (no free-rolling axle known)'
    else:
        fitted = fits[free]
        how = f'free-rolling {free} axle against the reference speed'
    out.add(key, fitted, how)
    # the speed the radius was fitted on: the free axle's, or the mean of both
    omega = {'rear': rear, 'front': front}.get(free or '', 0.5 * (front + rear))
    residual = drive.speed_mps[steady] - fitted.value * omega[steady]
    out.residuals['rolling radius'] = (
        drive.speed_mps[steady],
        residual,
        'reference speed [m/s]',
        'v - r omega [m/s]',
    )


def _ratios(
    drive: CalibrationDrive,
    moving: npt.NDArray[np.bool_],
    layout: str | None,
    base: EstimationVehicleParams,
    out: Calibration,
) -> None:
    key = 'gearbox.final_drive'
    if drive.gear is None or drive.engine_radps is None:
        out.not_determined[key] = 'no engine input (engine speed and gear) in the bag'
        return
    # the turbine where logged: the converter slips, the turbine is locked to the wheels
    shaft = drive.turbine_radps if drive.turbine_radps is not None else drive.engine_radps
    if not np.isfinite(shaft).any():
        out.not_determined[key] = 'the mapping gives no engine (or turbine) speed element'
        return
    wheel = _driven_wheel_speed(drive, layout)
    usable = moving & (drive.gear > 0)
    try:
        overall = fit_gear_ratios(wheel[usable], shaft[usable], drive.gear[usable])
    except NotDeterminedError as error:
        out.not_determined[key] = str(error)
        return
    name = 'turbine' if drive.turbine_radps is not None else 'engine'
    for gear, fit in overall.items():
        out.notes.append(
            f'overall ratio, logged gear {gear}: {fit.value:.4f} ± {fit.std:.4f} '
            f'({fit.samples} samples, {name} against wheel speed)'
        )
    if base.driveline is None:
        out.not_determined[key] = 'the base file has no gearbox ratios to split the overall ones'
        return
    ratios = base.driveline.ratios
    gearbox = {g + 1: r for g, r in enumerate(ratios)}
    offset = fit_gear_offset(overall, gearbox)
    if offset is None:
        offset = drive.mapped_gear_offset
        offset_text = f"gear offset: not determined (one gear only), the mapping's {offset} kept"
    else:
        offset_text = f"gear offset: {offset} (the mapping's engine_torque.gear_offset)"
        if offset != drive.mapped_gear_offset:
            offset_text += f'; the mapping says {drive.mapped_gear_offset}: correct it'
    out.gear_offset = offset
    out.notes.append(offset_text)
    shifted = {g + offset: fit for g, fit in overall.items()}
    try:
        final = fit_final_drive(shifted, gearbox)
    except NotDeterminedError as error:
        out.not_determined[key] = str(error)
        return
    gears = ', '.join(str(g) for g in sorted(shifted))
    out.add(key, final, f'{name} against driven-wheel speed in gears {gears}')
    per_gear = np.array([shifted[g].value / gearbox[g] for g in sorted(shifted) if g in gearbox])
    out.residuals['final drive per gear'] = (
        np.array([float(g) for g in sorted(shifted) if g in gearbox]),
        per_gear - final.value,
        'gear',
        'overall / gearbox - final drive [-]',
    )


def _converter(drive: CalibrationDrive, base: EstimationVehicleParams, out: Calibration) -> None:
    key = 'torque_converter.capacity_factor'
    converter = base.driveline.converter if base.driveline is not None else None
    if drive.turbine_radps is None or drive.engine_torque_nm is None or drive.engine_radps is None:
        if converter is not None:
            out.not_determined[key] = 'no turbine speed logged'
        return
    if converter is None:
        out.not_determined[key] = 'the base file has no torque_converter table to fill'
        return
    assert base.driveline is not None and drive.engine_accel_radps2 is not None
    pump_torque = (
        drive.engine_torque_nm - base.driveline.engine_inertia * drive.engine_accel_radps2
    )
    try:
        fitted = fit_capacity_factor(
            converter.speed_ratio,
            drive.engine_radps,
            drive.turbine_radps,
            pump_torque,
        )
    except NotDeterminedError as error:
        out.not_determined[key] = str(error)
        return
    values = tuple(
        f.value if f is not None else float(k)
        for f, k in zip(fitted, converter.capacity_factor, strict=True)
    )
    stds = tuple(f.std * _CORRELATION if f is not None else math.nan for f in fitted)
    count = sum(f.samples for f in fitted if f is not None)
    points = ', '.join(
        f'{sr:g}' for sr, f in zip(converter.speed_ratio, fitted, strict=True) if f is not None
    )
    out.fits[key] = Fit(
        key, values, stds, count, f'engine rpm / sqrt(pump torque) at speed ratios {points}'
    )


def _spin_torque(drive: CalibrationDrive, base: EstimationVehicleParams) -> FloatArray:
    """The torque the four wheels' spin takes, sum of J_i omega_dot_i [N m], shape (N,)."""
    inertia = np.array([base.wheel.inertia_front] * 2 + [base.wheel.inertia_rear] * 2)
    return np.asarray((drive.wheel_accel_radps2 * inertia).sum(axis=1), dtype=np.float64)


def _gearbox_gear(logged: npt.NDArray[np.int64], offset: int, gears: int) -> npt.NDArray[np.int64]:
    """The gearbox's gear of each sample: the logged one plus the offset, 0 in neutral and
    where it changes (and beyond the gearbox)."""
    gear = np.where(logged > 0, logged + offset, 0)
    return np.asarray(np.where(gear <= gears, gear, 0), dtype=np.int64)


def _efficiencies(given: tuple[float, ...], gears: int) -> tuple[float, ...]:
    """The efficiency of each gear: the file's per-gear list, its one number, or 1."""
    if len(given) == gears:
        return given
    return (given[0] if given else 1.0,) * gears


def _drive_force(
    drive: CalibrationDrive, base: EstimationVehicleParams, out: Calibration
) -> tuple[FloatArray, npt.NDArray[np.bool_], str] | None:
    """The drive force at the ground [N], where the drive torque is known (braking or not:
    a brake input only says the brakes add their own), and its source."""
    radius = out.value('wheel.effective_radius', base.wheel.effective_radius)
    spin = _spin_torque(drive, base)
    if drive.wheel_torque_nm is not None and not drive.engine_path:
        force = (drive.wheel_torque_nm.sum(axis=1) - spin) / radius
        return force, np.ones(force.shape, dtype=bool), 'measured wheel torques'
    if drive.engine_torque_nm is None or drive.gear is None or drive.engine_radps is None:
        return None
    line = base.driveline
    if line is None:
        out.not_determined['chassis.mass'] = 'engine path: the base file has no gearbox'
        return None
    assert drive.engine_accel_radps2 is not None
    final = out.value('gearbox.final_drive', line.final_drive)
    gear = _gearbox_gear(drive.gear, out.gear_offset, len(line.ratios))
    ratio = np.where(gear > 0, np.asarray((0.0, *line.ratios))[gear] * final, np.nan)
    efficiency = np.asarray((1.0, *_efficiencies(line.efficiency, len(line.ratios))))[gear]
    if drive.turbine_radps is not None:
        coupled = drive.turbine_radps > _COUPLED_SPEED_RATIO * drive.engine_radps
    else:
        wheel = _driven_wheel_speed(drive, line.layout)
        coupled = np.abs(drive.engine_radps - ratio * wheel) < _CLUTCH_SLIP * drive.engine_radps
    pump = drive.engine_torque_nm - line.engine_inertia * drive.engine_accel_radps2
    force = (pump * ratio * efficiency - spin) / radius
    # in neutral the drive torque is zero, known: a coast-down
    neutral = drive.gear == 0
    force = np.where(neutral, -spin / radius, force)
    known = (((gear > 0) & coupled) | neutral) & np.isfinite(force)
    return force, known, 'engine torque through the coupled driveline'


def _force_balance(
    drive: CalibrationDrive, base: EstimationVehicleParams, out: Calibration
) -> None:
    keys = ('chassis.mass', 'rolling_resistance.c0', 'aero.drag_coefficient')
    if drive.grade_rad is None:
        for key in keys:
            out.not_determined[key] = 'no grade reference (the force balance needs the grade)'
        return
    found = _drive_force(drive, base, out)
    if found is None:
        for key in keys:
            out.not_determined.setdefault(key, 'no known drive torque (wheel or engine)')
        return
    force, known, source = found
    usable = (
        known
        & ~drive.braking
        & (drive.speed_mps > _MIN_FORCE_SPEED_MPS)
        & (np.abs(drive.accel_mps2) < _MAX_FORCE_ACCEL_MPS2)
        & np.isfinite(drive.grade_rad)
    )
    args = (force[usable], drive.speed_mps[usable], drive.accel_mps2[usable])
    settings = {
        'rolling_c1': base.rolling_resistance.c1,
        'gravity_mps2': base.environment.gravity,
        'air_density_kgpm3': base.aero.air_density,
    }
    area = base.aero.frontal_area
    try:
        fit = fit_force_balance(*args, drive.grade_rad[usable], **settings)  # type: ignore[arg-type]
        how = f'longitudinal force balance ({source}, grade from {drive.grade_source})'
        drag = fit.drag_area_m2
        drag_ok = drag is not None and out.add(
            'aero.drag_coefficient',
            FittedValue(drag.value / area, drag.std / area, drag.samples),
            how + f'; drag area {drag.value:.3f} m^2 over the frontal area {area:g} m^2',
        )
        if not drag_ok:
            if drag is None:
                out.not_determined['aero.drag_coefficient'] = '; '.join(fit.not_determined)
            # mass and c0 alone, with the base's drag: two unknowns where three were not
            base_drag = base.aero.drag_coefficient * area
            fit = fit_force_balance(
                *args,
                drive.grade_rad[usable],
                known_drag_area_m2=base_drag,
                **settings,  # type: ignore[arg-type]
            )
            how += f'; drag area of the base, {base_drag:.3f} m^2'
    except NotDeterminedError as error:
        for key in keys:
            out.not_determined[key] = str(error)
        return
    if out.add('chassis.mass', fit.mass_kg, how):
        out.add('rolling_resistance.c0', fit.rolling_c0, how)
    else:
        # c0 alone, with the base's mass (and drag where not fitted): one unknown
        grade = drive.grade_rad[usable]
        speed = args[1]
        g = base.environment.gravity
        mass = base.chassis.mass
        area_cd = out.value('aero.drag_coefficient', base.aero.drag_coefficient) * area
        rolling = (
            mass * g * np.cos(grade) * rolling_speed_factor(speed, base.rolling_resistance.c1)
        )
        rest = (
            args[0]
            - mass * (args[2] + g * np.sin(grade))
            - 0.5 * base.aero.air_density * area_cd * speed**2
        )
        c0 = float(rolling @ rest / (rolling @ rolling))
        spread = rest - c0 * rolling
        std = float(np.sqrt(parameter_covariance(rolling, spread)[0, 0]))
        out.add(
            'rolling_resistance.c0',
            FittedValue(c0, std, int(spread.size)),
            f"longitudinal force balance ({source}) with the base's mass {mass:g} kg",
        )
    out.residuals['force balance'] = (
        drive.speed_mps[usable][fit.used],
        fit.residual_n,
        'reference speed [m/s]',
        'model - drive force [N]',
    )


def _needed_force(
    drive: CalibrationDrive, base: EstimationVehicleParams, out: Calibration
) -> FloatArray:
    """The ground force the motion needs [N]: ``m (a + g sin(theta))``, rolling resistance
    and drag, with the fitted values where fitted and the base's elsewhere."""
    assert drive.grade_rad is not None
    g = base.environment.gravity
    mass = out.value('chassis.mass', base.chassis.mass)
    c0 = out.value('rolling_resistance.c0', base.rolling_resistance.c0)
    cd = out.value('aero.drag_coefficient', base.aero.drag_coefficient)
    v, theta = drive.speed_mps, drive.grade_rad
    rolling = c0 * rolling_speed_factor(v, base.rolling_resistance.c1)
    drag = 0.5 * base.aero.air_density * cd * base.aero.frontal_area * v**2
    return np.asarray(
        mass * (drive.accel_mps2 + g * (np.sin(theta) + rolling * np.cos(theta))) + drag,
        dtype=np.float64,
    )


def _torque_ratio(
    drive: CalibrationDrive, base: EstimationVehicleParams, out: Calibration
) -> None:
    """The converter's torque ratio: the turbine torque the motion needs (through the gear,
    the final drive and the efficiency) over the pump torque, where the converter slips."""
    key = 'torque_converter.torque_ratio'
    line = base.driveline
    converter = line.converter if line is not None else None
    if converter is None or line is None:
        return
    if drive.turbine_radps is None or drive.engine_torque_nm is None:
        out.not_determined[key] = 'no turbine speed logged'
        return
    if drive.grade_rad is None or drive.gear is None or drive.engine_radps is None:
        out.not_determined[key] = 'no grade reference (the motion gives the turbine torque)'
        return
    assert drive.engine_accel_radps2 is not None
    radius = out.value('wheel.effective_radius', base.wheel.effective_radius)
    final = out.value('gearbox.final_drive', line.final_drive)
    gear = _gearbox_gear(drive.gear, out.gear_offset, len(line.ratios))
    ratio = np.asarray((np.nan, *line.ratios))[gear] * final
    efficiency = np.asarray((np.nan, *_efficiencies(line.efficiency, len(line.ratios))))[gear]
    spin = _spin_torque(drive, base)
    turbine = (_needed_force(drive, base, out) * radius + spin) / (ratio * efficiency)
    pump = drive.engine_torque_nm - line.engine_inertia * drive.engine_accel_radps2
    speed_ratio = drive.turbine_radps / np.where(
        drive.engine_radps > 0.0, drive.engine_radps, np.nan
    )
    usable = (
        (gear > 0)
        & ~drive.braking
        & (drive.speed_mps > _MIN_SPEED_MPS)
        & (pump > MIN_PUMP_TORQUE_NM)
        & np.isfinite(turbine)
        & np.isfinite(speed_ratio)
    )
    # below the coupling point only: above it the ratio is 1 by construction
    coupling = converter.speed_ratio[int(np.argmax(np.asarray(converter.torque_ratio) <= 1.0))]
    below = usable & (speed_ratio < coupling)
    fits = [
        None if point >= coupling else fit
        for point, fit in zip(
            converter.speed_ratio,
            binned_medians(converter.speed_ratio, speed_ratio, turbine / pump, below),
            strict=True,
        )
    ]
    fits = [
        None if f is None else FittedValue(f.value, f.std * _CORRELATION, f.samples) for f in fits
    ]
    if all(f is None for f in fits):
        out.not_determined[key] = (
            f'no speed ratio below the coupling point ({coupling:g}) has {MIN_BIN_SAMPLES} '
            'slipping samples'
        )
        return
    points = ', '.join(
        f'{sr:g}' for sr, f in zip(converter.speed_ratio, fits, strict=True) if f is not None
    )
    out.not_determined.pop(key, None)
    out.fits[key] = Fit(
        key,
        tuple(
            f.value if f is not None else float(b)
            for f, b in zip(fits, converter.torque_ratio, strict=True)
        ),
        tuple(f.std if f is not None else math.nan for f in fits),
        sum(f.samples for f in fits if f is not None),
        f'turbine torque the motion needs over the pump torque at speed ratios {points}',
    )


def _brake_gain(drive: CalibrationDrive, base: EstimationVehicleParams, out: Calibration) -> None:
    keys = ('brakes.gain_front', 'brakes.gain_rear')
    reason = None
    if not drive.engine_path:
        reason = 'the measured wheel torques include the brakes (no gain needed)'
    elif drive.brake_bar is None:
        reason = (
            'the brake input is a switch, not a pressure'
            if drive.has_brake_input
            else 'no brake pressure logged'
        )
    elif drive.grade_rad is None:
        reason = 'no grade reference (the force balance needs the grade)'
    if reason is not None:
        if drive.has_brake_input or base.brakes is not None:
            for key in keys:
                out.not_determined[key] = reason
        return
    assert drive.brake_bar is not None and drive.grade_rad is not None
    radius = out.value('wheel.effective_radius', base.wheel.effective_radius)
    v, theta = drive.speed_mps, drive.grade_rad
    found = _drive_force(drive, base, out)
    drive_force = np.zeros(v.shape)
    if found is not None:  # engine braking where the driveline is coupled; else decoupled
        drive_force = np.where(found[1], found[0], 0.0)
    # the brakes' torque: what the motion needs beyond the drive's force
    brake_torque = (drive_force - _needed_force(drive, base, out)) * radius
    p = drive.brake_bar
    columns = np.column_stack([p[:, 0] + p[:, 1], p[:, 2] + p[:, 3]])
    usable = (
        drive.braking
        & (v > _MIN_SPEED_MPS)
        & np.isfinite(theta)
        & (columns.sum(axis=1) > 1.0)
        & np.isfinite(brake_torque)
    )
    count = int(np.count_nonzero(usable))
    if count < 50:
        for key in keys:
            out.not_determined[key] = f'{count} braking samples with pressure, need 50'
        return
    a, b = columns[usable], brake_torque[usable]
    if np.linalg.matrix_rank(a, tol=1e-6 * float(np.abs(a).max())) < 2:
        # one pressure for all wheels: only the sum of the gains is determined
        split = (
            base.brakes.gain_front / (base.brakes.gain_front + base.brakes.gain_rear)
            if base.brakes is not None
            else None
        )
        if split is None:
            for key in keys:
                out.not_determined[key] = (
                    'one pressure for all wheels: only the sum of the gains is determined, '
                    'and the base file has no split'
                )
            return
        combined = (a[:, 0] * split + a[:, 1] * (1.0 - split))[:, None]
        gain = float(_robust_linear(combined, b)[0][0])
        out.fits[keys[0]] = Fit(
            keys[0],
            gain * split,
            None,
            count,
            'pressure against deceleration (split of the base file)',
        )
        out.fits[keys[1]] = Fit(
            keys[1],
            gain * (1.0 - split),
            None,
            count,
            'pressure against deceleration (split of the base file)',
        )
        return
    gains, residual = _robust_linear(a, b)
    cov = parameter_covariance(a, residual)
    for k, key in enumerate(keys):
        out.add(
            key,
            FittedValue(float(gains[k]), float(np.sqrt(cov[k, k])), count),
            'brake pressure against the deceleration the force balance leaves',
        )


def _robust_linear(design: FloatArray, target: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``design @ x = target`` with a soft-L1 loss (a wheel locking, a bump: 100 N m scale);
    the solution and the residuals."""

    def error(x: FloatArray) -> FloatArray:
        return np.asarray(design @ x - target, dtype=np.float64)

    result = least_squares(
        error, x0=np.ones(design.shape[1]), loss='soft_l1', f_scale=_BRAKE_F_SCALE_NM
    )
    return np.asarray(result.x, dtype=np.float64), np.asarray(result.fun, dtype=np.float64)
