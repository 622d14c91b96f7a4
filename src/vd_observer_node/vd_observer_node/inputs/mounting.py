"""The IMU's mounting from a drive: where the body's axes point in the sensor's frame.

The sensor measures ``f_s = R^T f_b``, the body's specific force ``f_b`` seen through the
mounting ``R`` (body <- sensor, `inputs.rotation`). Along the body's x axis ``f_b`` reads the
car's acceleration plus the grade's gravity, along z gravity, along y the lateral
acceleration. Regressing the sensor's three axes on the car's acceleration ``a`` (the speed
reference's derivative, both averaged over the calibration grid's window),

    f_s = c + x a + e,

on straight road (the lateral acceleration of a bend follows the forward one where the
driver brakes into bends and accelerates out of them: the samples whose lateral specific
force, along the previous fit's y axis, is within ``STRAIGHT_MPS2`` of its median) gives the
body's forward axis as the direction of ``x``, sign included: whatever else moves
with the acceleration moves along that axis too (the grade's gravity where the car coasts
down a hill, the body's squat to first order), so it changes the gain ``|x|``, not the
direction. In the second order the squat tilts it in pitch where the drive brakes harder
than it accelerates (0.9 deg on the simulator's everyday drive 11): the pitch is the least
certain angle, and the one the IMU fusion does not need (it learns what is left of it as its
bias). The intercept ``c`` is the specific force at zero acceleration, gravity: the body's
z axis is its part orthogonal to ``x``. That gives the roll, about ``x``, where the
mean lateral acceleration and the road's crossfall tilt it a little (a roll does not change
the forward specific force the estimators read). The pitch and the yaw come from ``x``
alone, so the road's grade, which gravity at a standstill cannot tell from a pitched sensor,
does not enter them.

Uncertainty: a block jackknife over ``BLOCKS`` contiguous stretches of the drive (the grid's
samples are correlated over seconds: turns, hills), not the least-squares formula, which takes
them as independent.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

import numpy as np
import numpy.typing as npt

from vd_observer_node.inputs.errors import MountingNotDeterminedError
from vd_observer_node.inputs.rotation import Rows, axis_angle_deg, mount_rpy

__all__ = [
    'BLOCKS',
    'MAX_STD_DEG',
    'MIN_ACCEL_STD_MPS2',
    'MIN_GAIN',
    'STRAIGHT_MPS2',
    'MountingFit',
    'fit_mounting',
]

FloatArray = npt.NDArray[np.float64]

#: contiguous stretches of the drive the jackknife leaves out one at a time
BLOCKS: Final = 10
#: the acceleration's spread [m/s^2] below which the drive does not show the forward axis
MIN_ACCEL_STD_MPS2: Final = 0.2
#: on straight road [m/s^2]: the lateral specific force within this of its median (the road's
#: crossfall); a bend's lateral acceleration would go into the fit wherever it happens to
#: follow the forward one (braking into bends, accelerating out of them)
STRAIGHT_MPS2: Final = 0.5
#: the straight samples are chosen by the previous fit's lateral axis until the choice stays
#: (each pass takes out bends the last one's yaw had left in), at most this many times
_STRAIGHT_PASSES: Final = 30
#: the least specific force [m/s^2] along the forward axis per m/s^2 of the car's acceleration
#: (0.8-1.0 on the drives measured): less is a sensor that does not follow the car (another
#: topic, a unit of g read as m/s^2)
MIN_GAIN: Final = 0.5
#: the largest jackknife std of the roll and of the yaw [deg] at which the mounting is stated:
#: a yaw off by 1 deg puts 1.7 % of the lateral acceleration in the forward one (0.3 deg of
#: grade in a 3 m/s^2 bend), a roll off by 1 deg 1.7 % of the yaw rate in the pitch rate. The
#: pitch is stated with its std whatever it is: the IMU fusion learns what is left of it as
#: its bias (a constant offset of the forward specific force, asin(b / g))
MAX_STD_DEG: Final = 1.0


@dataclass(frozen=True)
class MountingFit:
    """The mounting a drive shows.

    Attributes:
        rpy_deg: (roll, pitch, yaw) [deg] of the sensor's frame in the body, as the mapping's
            ``imu.mount_rpy_deg`` takes them.
        std_deg: their jackknife standard deviations [deg].
        rows: the rotation body <- sensor by rows (its first row is the body's forward axis
            in the sensor's frame).
        gain: ``|x|``, the specific force along the forward axis per m/s^2 of the car's
            acceleration (1 on level road without squat; the grade met while coasting and the
            squat lower it).
        samples: the grid samples the fit rests on (those on straight road).
    """

    rpy_deg: tuple[float, float, float]
    std_deg: tuple[float, float, float]
    rows: Rows
    gain: float
    samples: int

    def axis_angle_deg(self, row: int, axis: tuple[float, ...]) -> float:
        """The angle [deg] between the body axis ``row`` (0 forward, 1 lateral) as this fit
        finds it and as ``axis`` gives it (the same row of another mounting, e.g. the
        mapping's): what a wrong mounting turns into the forward specific force (row 0) or
        the pitch rate (row 1)."""
        return axis_angle_deg(self.rows[row], axis)


def _rows(force: FloatArray, accel: FloatArray) -> tuple[Rows, float]:
    """The rotation's rows and the gain from one least-squares fit (module docstring)."""
    design = np.column_stack([np.ones(accel.size), accel])
    (c, x), *_ = np.linalg.lstsq(design, force, rcond=None)
    gain = float(np.linalg.norm(x))
    ex = x / gain
    up = c - np.dot(c, ex) * ex
    ez = up / np.linalg.norm(up)
    ey = np.cross(ez, ex)
    rows: Rows = (
        (float(ex[0]), float(ex[1]), float(ex[2])),
        (float(ey[0]), float(ey[1]), float(ey[2])),
        (float(ez[0]), float(ez[1]), float(ez[2])),
    )
    return rows, gain


def _wrapped_deg(angles: FloatArray, centre: float) -> FloatArray:
    """Angles [deg] taken to within 180 deg of ``centre`` (a roll near +-180 deg)."""
    wrapped: FloatArray = centre + (angles - centre + 180.0) % 360.0 - 180.0
    return wrapped


def _check_excitation(a: FloatArray, what: str) -> None:
    """Raise MountingNotDeterminedError where the acceleration ``a`` cannot show the forward
    axis."""
    spread = float(np.std(a)) if a.size else 0.0
    if a.size < 2 * BLOCKS or spread < MIN_ACCEL_STD_MPS2:
        raise MountingNotDeterminedError(
            f'the acceleration varies by {spread:.2f} m/s^2 (std) over {a.size} {what}, '
            f'less than the {MIN_ACCEL_STD_MPS2} m/s^2 that shows the forward axis'
        )


def fit_mounting(force: npt.ArrayLike, accel: npt.ArrayLike) -> MountingFit:
    """Fit the mounting from the sensor's specific force and the car's acceleration.

    Args:
        force: shape (N, 3), [m/s^2], the sensor's specific force (x, y, z) in its frame, on
            the calibration grid (rows with a nan are left out).
        accel: shape (N,), [m/s^2], the car's acceleration on the same grid.

    Returns:
        The mounting, its spread and the samples used.

    Raises:
        MountingNotDeterminedError: the acceleration varies too little on straight road, the sensor
            does not follow it (:data:`MIN_GAIN`), or the roll or the yaw is less certain than
            :data:`MAX_STD_DEG`.
    """
    f = np.asarray(force, dtype=np.float64)
    a = np.asarray(accel, dtype=np.float64)
    use = np.isfinite(f).all(axis=1) & np.isfinite(a)
    f, a = f[use], a[use]
    _check_excitation(a, 'samples')
    rows, gain = _rows(f, a)
    straight = np.ones(a.size, dtype=bool)
    for _ in range(_STRAIGHT_PASSES):
        lateral = f @ np.asarray(rows[1])
        chosen = np.abs(lateral - np.median(lateral)) < STRAIGHT_MPS2
        _check_excitation(a[chosen], 'samples on straight road')
        if np.array_equal(chosen, straight):
            break
        straight = chosen
        rows, gain = _rows(f[straight], a[straight])
    f, a = f[straight], a[straight]
    if not gain >= MIN_GAIN:  # nan too
        raise MountingNotDeterminedError(
            f"the IMU's specific force follows the car's acceleration with a gain of "
            f"{gain:.2f}, less than {MIN_GAIN} (is it the car's IMU, in the mapped unit?)"
        )
    rpy = np.degrees(mount_rpy(rows))
    blocks = np.array_split(np.arange(a.size), BLOCKS)
    leave_out = []
    for block in blocks:
        keep = np.ones(a.size, dtype=bool)
        keep[block] = False
        leave_out.append(np.degrees(mount_rpy(_rows(f[keep], a[keep])[0])))
    angles = np.array(leave_out)
    for k in range(3):
        angles[:, k] = _wrapped_deg(angles[:, k], float(rpy[k]))
    std = np.sqrt((BLOCKS - 1) / BLOCKS * ((angles - angles.mean(axis=0)) ** 2).sum(axis=0))
    fit = MountingFit(
        rpy_deg=(float(rpy[0]), float(rpy[1]), float(rpy[2])),
        std_deg=(float(std[0]), float(std[1]), float(std[2])),
        rows=rows,
        gain=gain,
        samples=int(a.size),
    )
    if max(fit.std_deg[0], fit.std_deg[2]) > MAX_STD_DEG:
        raise MountingNotDeterminedError(
            f'roll {fit.rpy_deg[0]:.1f} ± {fit.std_deg[0]:.1f} deg, yaw {fit.rpy_deg[2]:.1f} ± '
            f'{fit.std_deg[2]:.1f} deg: less certain than the {MAX_STD_DEG} deg the estimators '
            'need (too little acceleration and braking)'
        )
    return fit
