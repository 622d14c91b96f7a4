"""True road-friction potential of the simulated tyre: Magic-Formula peak μ and slip.

The alerts and the friction-potential estimator of ``vd_observer_node`` are judged against
this truth (docs/alerts.md section 4.1): the peak of the simulator's own Magic Formula at the
true wheel load and road friction scale ``road_mu``, looked up in the tyre's peak table
(``vd_common.vehicle.friction``, which also explains why a table at ``road_mu`` = 1 is
enough: the peak μ and its slip both scale with ``road_mu``).

ROS-free. Wheel order FL=0, FR=1, RL=2, RR=3; axles 0 front (FL, FR), 1 rear (RL, RR).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from vd_common.vehicle.friction import FrictionTable, axle_mean, unit_peak

__all__ = [
    'FrictionTruth',
    'true_friction_potential',
]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class FrictionTruth:
    """True friction potential per wheel and per axle.

    Attributes:
        mu_max: shape (..., 4), [-] peak μ of each wheel at its load and the road's μ, on
            the side given by the sign of its Fx (Fx >= 0: driving side).
        slip_peak: shape (..., 4), [-] slip magnitude at that peak.
        axle_mu_max: shape (..., 2), [-] mean of the axle's two wheels (front, rear).
        axle_slip_peak: shape (..., 2), [-] mean of the axle's two wheels.
    """

    mu_max: FloatArray
    slip_peak: FloatArray
    axle_mu_max: FloatArray
    axle_slip_peak: FloatArray


def true_friction_potential(
    table: FrictionTable, fz: ArrayLike, fx: ArrayLike, road_mu: ArrayLike
) -> FrictionTruth:
    """Peak μ and slip of every wheel at its true load and the road's μ (vectorised).

    Args:
        table: from :func:`~vd_common.vehicle.friction.friction_table` for the
            simulated tyre.
        fz: shape (N, 4) (or (4,)), [N] wheel loads; clipped to the table's load range.
        fx: same shape, [N] tyre forces; their sign picks the side (>= 0: driving).
        road_mu: shape (N,) (or scalar), [-] road friction scale (>= 0).

    Returns:
        Per-wheel (N, 4) and per-axle (N, 2) peaks, see :class:`FrictionTruth`.
    """
    r = np.asarray(road_mu, dtype=np.float64)[..., None]
    mu, slip = unit_peak(table, fz, np.asarray(fx, dtype=np.float64) >= 0.0)
    mu_max = r * mu
    slip_peak = r * slip
    return FrictionTruth(mu_max, slip_peak, axle_mean(mu_max), axle_mean(slip_peak))
