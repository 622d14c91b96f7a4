"""Overall ratio per gear and the final drive from engine (or turbine) speed against wheel speed.

With the clutch engaged (or the converter locked) ``engine = ratio(gear) * wheel``; each gear's
ratio is a one-parameter robust fit. The final drive follows from the overall ratios and the
gearbox ratios of the base file, as the inverse-variance mean of ``overall / gearbox`` over gears.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import numpy.typing as npt

from vd_observer_node.tools.calibrate.errors import NotDeterminedError
from vd_observer_node.tools.calibrate.radius import FittedValue, fit_proportional

__all__ = ['fit_final_drive', 'fit_gear_offset', 'fit_gear_ratios']

FloatArray = npt.NDArray[np.float64]

# Engine speeds below this (rad/s, ~570 rpm) are idle or stall, not a coupled driveline.
_MIN_ENGINE_RADPS = 60.0
# Overall ratios of road cars lie in this range (top gear x short final drive .. first x long).
_RATIO_BOUNDS = (1.0, 30.0)
# Residual scale of the robust loss, rad/s of engine speed (~10 rpm of slip or quantisation).
_ENGINE_F_SCALE = 1.0


def fit_gear_ratios(
    wheel_speed_radps: FloatArray,
    engine_speed_radps: FloatArray,
    gear: npt.NDArray[np.int64],
) -> dict[int, FittedValue]:
    """Fit the overall (gearbox x final drive) ratio of every gear with enough samples.

    Args:
        wheel_speed_radps: Mean driven-axle wheel speed, shape (n,), rad/s.
        engine_speed_radps: Engine or turbine speed, shape (n,), rad/s.
        gear: Engaged gear number per sample, shape (n,); values <= 0 (neutral, reverse,
            unknown) are left out.

    Returns:
        Gear number -> fitted overall ratio (dimensionless). Gears with fewer than 50 usable
        samples are absent.

    Raises:
        NotDeterminedError: No gear has enough samples.
    """
    gears = np.asarray(gear)
    wheel = np.asarray(wheel_speed_radps, dtype=np.float64)
    engine = np.asarray(engine_speed_radps, dtype=np.float64)
    fitted: dict[int, FittedValue] = {}
    reasons: list[str] = []
    for number in sorted(int(g) for g in np.unique(gears) if g > 0):
        in_gear = gears == number
        try:
            fitted[number] = fit_proportional(
                wheel[in_gear],
                engine[in_gear],
                f'ratio of gear {number}',
                _RATIO_BOUNDS,
                min_response=_MIN_ENGINE_RADPS,
                f_scale=_ENGINE_F_SCALE,
            )
        except NotDeterminedError as error:
            reasons.append(str(error))
    if not fitted:
        raise NotDeterminedError(
            'gear ratios: no gear with enough samples (' + '; '.join(reasons) + ')'
        )
    return fitted


def fit_final_drive(
    overall_ratios: Mapping[int, FittedValue], gearbox_ratios: Mapping[int, float]
) -> FittedValue:
    """The final drive from fitted overall ratios and the base file's gearbox ratios.

    Args:
        overall_ratios: Gear -> fitted overall ratio.
        gearbox_ratios: Gear -> gearbox ratio (dimensionless) from the base vehicle file.

    Returns:
        The inverse-variance weighted final drive, its standard deviation and the total
        number of samples.

    Raises:
        NotDeterminedError: No fitted gear has a gearbox ratio.
    """
    common = [g for g in overall_ratios if g in gearbox_ratios and gearbox_ratios[g] > 0.0]
    if not common:
        raise NotDeterminedError(
            'final drive: no fitted gear has a gearbox ratio in the base file'
        )
    values = np.array([overall_ratios[g].value / gearbox_ratios[g] for g in common])
    stds = np.array([max(overall_ratios[g].std, 1e-12) / gearbox_ratios[g] for g in common])
    weights = 1.0 / stds**2
    value = float(weights @ values / weights.sum())
    std = float(np.sqrt(1.0 / weights.sum()))
    return FittedValue(
        value=value, std=std, samples=sum(overall_ratios[g].samples for g in common)
    )


def fit_gear_offset(
    overall_ratios: Mapping[int, FittedValue], gearbox_ratios: Mapping[int, float]
) -> int | None:
    """The number to add to the logged gear to get the gearbox's (a bus that counts otherwise).

    The final drive is one number: the right offset makes ``overall(logged) / gearbox(logged
    + offset)`` the same in every gear. Each admissible offset (every shifted gear in the
    gearbox) is scored by the relative spread of those quotients; the least wins.

    Args:
        overall_ratios: logged gear -> fitted overall ratio.
        gearbox_ratios: gear -> gearbox ratio of the base file.

    Returns:
        The offset, or None when fewer than two gears were fitted (any offset fits one).
    """
    logged = sorted(overall_ratios)
    if len(logged) < 2 or not gearbox_ratios:
        return None
    spreads: dict[int, float] = {}
    for offset in range(min(gearbox_ratios) - logged[0], max(gearbox_ratios) - logged[-1] + 1):
        if not all(g + offset in gearbox_ratios for g in logged):
            continue
        quotients = np.array(
            [overall_ratios[g].value / gearbox_ratios[g + offset] for g in logged]
        )
        spreads[offset] = float(np.std(quotients) / np.mean(quotients))
    if not spreads:
        return None
    return min(spreads, key=spreads.__getitem__)
