"""The torque converter's capacity factor K from the pump (engine) and turbine speeds.

A converter's pump absorbs ``T_pump = (n_pump / K(SR))**2`` at the speed ratio
``SR = n_turbine / n_pump`` (n in rpm, K in rpm / sqrt(N m)): where the engine torque and both
speeds are logged, each sample gives ``K = n_pump / sqrt(T_pump)`` at its SR. K is taken as a
robust mean (median, with the median absolute deviation for its spread) of the samples near
each speed ratio of the base file's table, so the fitted table keeps the base's grid. The
torque ratio needs the turbine's torque, which buses do not log: it stays the base's.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from vd_observer_node.tools.calibrate.errors import NotDeterminedError
from vd_observer_node.tools.calibrate.radius import FittedValue

__all__ = [
    'MIN_BIN_SAMPLES',
    'MIN_PUMP_TORQUE_NM',
    'SPEED_RATIO_HALF_BIN',
    'binned_medians',
    'fit_capacity_factor',
]

FloatArray = npt.NDArray[np.float64]

_RPM_PER_RADPS = 30.0 / math.pi
#: Below this pump torque [N m] the root is dominated by the torque signal's offset.
MIN_PUMP_TORQUE_NM = 30.0
# Below this pump speed [rad/s] the engine is at or under idle.
_MIN_PUMP_RADPS = 60.0
#: Samples within this speed ratio of a grid point count for it.
SPEED_RATIO_HALF_BIN = 0.05
#: A grid point needs this many samples.
MIN_BIN_SAMPLES = 50
# The median absolute deviation of a normal sample is this times its standard deviation.
_MAD_TO_STD = 1.4826


def fit_capacity_factor(
    speed_ratio_grid: Sequence[float],
    pump_radps: FloatArray,
    turbine_radps: FloatArray,
    pump_torque_nm: FloatArray,
) -> list[FittedValue | None]:
    """K at each speed ratio of the grid that the drive covers.

    Args:
        speed_ratio_grid: the base table's speed ratios [-], increasing.
        pump_radps: shape (n,), engine (pump) speed [rad/s].
        turbine_radps: shape (n,), turbine speed [rad/s].
        pump_torque_nm: shape (n,), engine torque less the engine's inertia torque [N m].

    Returns:
        Per grid point: K [rpm / sqrt(N m)] with its standard deviation and sample count, or
        None where fewer than 50 samples lie within 0.05 of that speed ratio.

    Raises:
        NotDeterminedError: no grid point has enough samples.
    """
    pump = np.asarray(pump_radps, dtype=np.float64)
    torque = np.asarray(pump_torque_nm, dtype=np.float64)
    ratio = np.asarray(turbine_radps, dtype=np.float64) / np.where(pump > 0.0, pump, np.nan)
    usable = (
        np.isfinite(ratio)
        & np.isfinite(torque)
        & (torque > MIN_PUMP_TORQUE_NM)
        & (pump > _MIN_PUMP_RADPS)
    )
    k = np.full(pump.shape, np.nan)
    k[usable] = pump[usable] * _RPM_PER_RADPS / np.sqrt(torque[usable])
    out = binned_medians(speed_ratio_grid, ratio, k, usable)
    if all(f is None for f in out):
        raise NotDeterminedError(
            f'capacity factor: no speed ratio of the table has {MIN_BIN_SAMPLES} samples with '
            f'the pump torque above {MIN_PUMP_TORQUE_NM:g} N m'
        )
    return out


def binned_medians(
    grid: Sequence[float],
    speed_ratio: FloatArray,
    values: FloatArray,
    usable: npt.NDArray[np.bool_],
) -> list[FittedValue | None]:
    """A robust mean of ``values`` near each speed ratio of ``grid``: the median of the usable
    samples within `SPEED_RATIO_HALF_BIN`, its spread the median absolute deviation over the
    root of their count; None where fewer than `MIN_BIN_SAMPLES`."""
    out: list[FittedValue | None] = []
    for point in grid:
        near = usable & (np.abs(speed_ratio - point) <= SPEED_RATIO_HALF_BIN)
        count = int(np.count_nonzero(near))
        if count < MIN_BIN_SAMPLES:
            out.append(None)
            continue
        chosen = values[near]
        median = float(np.median(chosen))
        spread = _MAD_TO_STD * float(np.median(np.abs(chosen - median)))
        out.append(FittedValue(median, spread / math.sqrt(count), count))
    return out
