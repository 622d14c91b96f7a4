"""Road-friction potential of the Magic Formula tyre: its peak μ and slip per load, road classes.

The friction-potential estimator of ``vd_observer_node`` fits the road's friction scale on
this peak, and the simulator's truth (``vd_sim_node.vehicle.friction_truth``, docs/alerts.md
section 4.1) is the same peak at the true wheel load and road friction scale ``road_mu``.

Why a table at ``road_mu`` = 1 is enough: the Magic Formula (:mod:`.tire`) scales only the
peak factor ``Dx`` with ``road_mu`` and leaves the slip stiffness ``Kx`` unchanged, so
``Bx = Kx/(Cx Dx)`` scales with ``1/road_mu`` and (with ``SHx = SVx = 0``, as for the Clio's
tyre)

    Fx(kappa; r) = r Fx(kappa / r; 1).

The peak μ **and** the slip at the peak therefore both scale with ``r``: μ 1.05 at slip 0.148
on dry asphalt at 2500 N, 0.315 at 0.044 at ``road_mu`` 0.3. The table holds, per load, the
peak μ and its slip on the driving side (slip > 0) and the braking side (slip < 0, the
curvature ``Ex`` is slightly asymmetric); a lookup is one ``np.interp`` per side.

The road classes (ice, snow, wet, dry) of a μ_max are codes of vd_msgs/msg/FrictionPotential.

ROS-free. Wheel order FL=0, FR=1, RL=2, RR=3; axles 0 front (FL, FR), 1 rear (RL, RR).
"""

from __future__ import annotations

import bisect
import functools
import math
from dataclasses import dataclass
from typing import Final

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vd_common.errors import ParameterError
from vd_common.vehicle.params import TireParams
from vd_common.vehicle.tire import magic_formula_fx

__all__ = [
    'ROAD_CLASS_BOUNDS',
    'ROAD_DRY',
    'ROAD_ICE',
    'ROAD_SNOW',
    'ROAD_UNKNOWN',
    'ROAD_WET',
    'FrictionTable',
    'axle_mean',
    'friction_table',
    'road_class',
    'road_class_of',
    'unit_peak',
    'vehicle_road_class',
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: Road class codes, as in vd_msgs/msg/FrictionPotential.
ROAD_UNKNOWN: Final = 0
ROAD_ICE: Final = 1
ROAD_SNOW: Final = 2
ROAD_WET: Final = 3
ROAD_DRY: Final = 4
#: [-] μ_max bounds of the classes: ice < 0.2 <= snow < 0.45 <= wet < 0.75 <= dry (the
#: estimator's default ``class_bounds`` are the same).
ROAD_CLASS_BOUNDS: Final = (0.2, 0.45, 0.75)


@dataclass(frozen=True)
class FrictionTable:
    """MF peak per load at ``road_mu`` = 1. All arrays shape (L,).

    Attributes:
        load: [N] wheel loads, increasing; lookups clip to its range.
        mu_drive: [-] peak μ on the driving side (slip > 0).
        slip_drive: [-] slip at that peak (> 0).
        mu_brake: [-] peak |μ| on the braking side (slip < 0).
        slip_brake: [-] |slip| at that peak (> 0).
    """

    load: FloatArray
    mu_drive: FloatArray
    slip_drive: FloatArray
    mu_brake: FloatArray
    slip_brake: FloatArray


def friction_table(
    tire: TireParams,
    *,
    load_min: float = 200.0,
    load_max: float = 6000.0,
    loads: int = 59,
    slip_max: float = 0.6,
    slips: int = 6001,
) -> FrictionTable:
    """Tabulate the tyre's MF peak at ``road_mu`` = 1 against the load (cached per tyre).

    Args:
        tire: Magic Formula coefficients (must have ``pHx* = pVx* = 0`` for the road scaling
            to hold exactly; otherwise the table is the peak at ``road_mu`` = 1 only).
        load_min: [N] lowest tabulated load (> 0).
        load_max: [N] highest tabulated load.
        loads: number of loads (>= 2), evenly spaced.
        slip_max: [-] largest slip searched for the peak (the peak is at ~0.15 at road_mu 1).
        slips: number of slip samples in [0, slip_max]; the peak slip resolution is
            ``slip_max / (slips - 1)`` (1e-4 by default).

    Raises:
        ParameterError: invalid grid.
    """
    if not (0.0 < load_min < load_max) or loads < 2 or not slip_max > 0.0 or slips < 3:
        raise ParameterError(
            f'friction table grid: need 0 < load_min < load_max, loads >= 2, slip_max > 0, '
            f'slips >= 3; got {load_min}, {load_max}, {loads}, {slip_max}, {slips}'
        )
    return _cached_table(tire, load_min, load_max, loads, slip_max, slips)


@functools.lru_cache(maxsize=8)
def _cached_table(
    tire: TireParams, load_min: float, load_max: float, loads: int, slip_max: float, slips: int
) -> FrictionTable:
    load = np.linspace(load_min, load_max, loads)
    kappa = np.linspace(0.0, slip_max, slips)
    fz = load[:, None]
    drive = magic_formula_fx(kappa[None, :], fz, 1.0, tire) / fz
    brake = -magic_formula_fx(-kappa[None, :], fz, 1.0, tire) / fz
    i_drive = np.argmax(drive, axis=1)
    i_brake = np.argmax(brake, axis=1)
    rows = np.arange(loads)
    table = FrictionTable(
        load=load,
        mu_drive=drive[rows, i_drive],
        slip_drive=kappa[i_drive],
        mu_brake=brake[rows, i_brake],
        slip_brake=kappa[i_brake],
    )
    for a in (table.load, table.mu_drive, table.slip_drive, table.mu_brake, table.slip_brake):
        a.flags.writeable = False  # shared by the cache
    return table


def axle_mean(wheel: ArrayLike) -> FloatArray:
    """Per-axle mean of a per-wheel array: shape (..., 4) -> (..., 2) (front, rear)."""
    w = np.asarray(wheel, dtype=np.float64)
    out: FloatArray = 0.5 * (w[..., 0::2] + w[..., 1::2])
    return out


def unit_peak(
    table: FrictionTable, load: ArrayLike, driving: ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """Peak μ and the slip magnitude there at ``road_mu`` = 1.

    Args:
        table: from :func:`friction_table`.
        load: [N], any shape; clipped to the table's range.
        driving: same shape, bool; True for the driving side (slip > 0).

    Returns:
        (peak μ [-], slip at the peak [-]), the shape of ``load``.
    """
    z = np.clip(np.asarray(load, dtype=np.float64), table.load[0], table.load[-1])
    side = np.asarray(driving, dtype=bool)
    mu: FloatArray = np.where(
        side, np.interp(z, table.load, table.mu_drive), np.interp(z, table.load, table.mu_brake)
    )
    slip: FloatArray = np.where(
        side,
        np.interp(z, table.load, table.slip_drive),
        np.interp(z, table.load, table.slip_brake),
    )
    return mu, slip


def road_class(
    mu_max: ArrayLike, bounds: tuple[float, float, float] = ROAD_CLASS_BOUNDS
) -> IntArray:
    """Road class code of μ_max values, without hysteresis (as the truth is classified).

    Args:
        mu_max: any shape, [-].
        bounds: increasing class bounds (ice/snow, snow/wet, wet/dry).

    Returns:
        Same shape, int64: ROAD_ICE .. ROAD_DRY; ROAD_UNKNOWN where μ_max is not finite.
    """
    m = np.asarray(mu_max, dtype=np.float64)
    codes = ROAD_ICE + np.searchsorted(np.asarray(bounds, dtype=np.float64), m, side='right')
    out: IntArray = np.where(np.isfinite(m), codes, ROAD_UNKNOWN).astype(np.int64)
    return out


def road_class_of(mu_max: float, bounds: tuple[float, float, float] = ROAD_CLASS_BOUNDS) -> int:
    """:func:`road_class` of one value, without numpy (the simulator node's per-sample path).

    Args:
        mu_max: [-].
        bounds: increasing class bounds.
    """
    if not math.isfinite(mu_max):
        return ROAD_UNKNOWN
    return ROAD_ICE + bisect.bisect_right(bounds, mu_max)


def vehicle_road_class(axle_mu_max: ArrayLike) -> IntArray:
    """Class of the vehicle's road: that of the axle with the lower μ_max.

    Every axle of the truth is fully confident, so the estimator's rule (most confident axle)
    does not decide; the lower one is the road that limits the car.

    Args:
        axle_mu_max: shape (..., 2), [-].

    Returns:
        Shape (...), int64 road class code.
    """
    return road_class(np.min(np.asarray(axle_mu_max, dtype=np.float64), axis=-1))
