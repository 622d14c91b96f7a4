"""A sensor's mounting in the body: the rotation body <- sensor of (roll, pitch, yaw).

tf's convention, ``R = Rz(yaw) Ry(pitch) Rx(roll)``, angles [rad] of the sensor's frame in
the body frame (REP 103: x forward, y left, z up; a positive pitch turns the nose down). A
vector the sensor measures, ``v_s``, is ``R @ v_s`` in the body. The mapping's
``mount_rpy_deg`` is read with it (`mapping`), and ``vd calibrate`` states what it learnt
with its inverse (`inputs.mounting`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

__all__ = ['Rows', 'axis_angle_deg', 'forward_axis', 'lateral_axis', 'mount_rotation', 'mount_rpy']

Vector = tuple[float, float, float]
#: the rotation's three rows (the body's x, y and z axes in the sensor's frame)
Rows = tuple[Vector, Vector, Vector]


def mount_rotation(roll: float, pitch: float, yaw: float) -> Rows:
    """The rotation body <- sensor of a sensor frame at (roll, pitch, yaw) [rad], by rows."""
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    return (
        (cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr),
        (sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr),
        (-sp, cp * sr, cp * cr),
    )


def forward_axis(roll: float, pitch: float, yaw: float) -> Vector:
    """The first row of `mount_rotation`: the body's forward specific force is this row times
    the sensor's (x, y, z) vector."""
    return mount_rotation(roll, pitch, yaw)[0]


def lateral_axis(roll: float, pitch: float, yaw: float) -> Vector:
    """The second row of `mount_rotation`: the body's rate about its y axis (pitch, nose down
    positive) is this row times the sensor's angular velocity (x, y, z)."""
    return mount_rotation(roll, pitch, yaw)[1]


def mount_rpy(rows: Rows) -> Vector:
    """(roll, pitch, yaw) [rad] of a rotation body <- sensor given by its rows; the inverse of
    `mount_rotation` for pitch within (-90, 90) deg (roll and yaw within (-180, 180])."""
    (r00, _, _), (r10, _, _), (r20, r21, r22) = rows
    return (
        math.atan2(r21, r22),
        math.asin(max(-1.0, min(1.0, -r20))),
        math.atan2(r10, r00),
    )


def axis_angle_deg(u: Sequence[float], v: Sequence[float]) -> float:
    """The angle [deg] between two axes given as vectors (of any length), e.g. one row of two
    mountings: what a mounting off by that much turns into the quantity read along it."""
    dot = sum(a * b for a, b in zip(u, v, strict=True))
    norms = math.sqrt(sum(a * a for a in u) * sum(b * b for b in v))
    return math.degrees(math.acos(max(-1.0, min(1.0, dot / norms))))
