"""The body's pitch on its springs, from a full vehicle file (the IMU fusion's ``k``).

The longitudinal ground force ``F`` acts ``cg_height`` below the centre of gravity: the body
squats and dives by `pitch_compliance` times ``F`` once settled, and gets there as its pitch
mode (`pitch_mode`: the springs' pitch stiffness against the body's pitch inertia, damped by
the dampers) lets it (the axle loads take the whole chassis, `axle_loads`). An IMU on the
body turns with it: `imu_grade` reads its specific force as ``(1 + k) f`` (``k = g m
compliance``), and the angular rate's grade (`gyro_grade`) takes the modelled pitch out of
the rate it integrates. An estimation-only vehicle file has no springs: a rigid body
(compliance 0).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

from vd_common.vehicle.params import VehicleParams, load_vehicle_if_full

__all__ = ['BodyPitch', 'body_pitch_of', 'pitch_compliance', 'pitch_mode', 'vehicle_body_pitch']


@dataclass(frozen=True)
class BodyPitch:
    """How the body pitches on its springs under the longitudinal ground force.

    Attributes:
        compliance: settled pitch per newton of ground force, [rad/N] (nose up under a
            forward force; 0: a rigid body).
        frequency: undamped frequency of the pitch mode, [Hz] (0: settles at once).
        damping: damping ratio of the pitch mode, [-].
    """

    compliance: float = 0.0
    frequency: float = 0.0
    damping: float = 0.5


def _corner_pair(suspension: float, tyre: float) -> float:
    """[N/m] one axle's two corners, each its spring in series with its tyre."""
    return 1.0 / (0.5 / suspension + 0.5 / tyre)


def pitch_compliance(
    wheelbase: float,
    cg_height: float,
    front_stiffness: float,
    rear_stiffness: float,
    tyre_stiffness: float,
) -> float:
    """Body pitch per newton of longitudinal ground force [rad/N] of a car on its springs.

    The ground force ``F`` acts ``cg_height`` below the CG: a moment ``h F`` taken up by the
    axles as ``+-h F / L``; each axle's corner springs (two per axle, the suspension in series
    with the tyre) deflect by that over their stiffness, and the body pitches by the
    difference over the wheelbase: ``h (1/k_f + 1/k_r) / L^2``.

    Args:
        wheelbase: L [m].
        cg_height: h [m].
        front_stiffness, rear_stiffness: one corner's suspension spring [N/m].
        tyre_stiffness: one tyre's vertical stiffness [N/m].
    """
    front = _corner_pair(front_stiffness, tyre_stiffness)
    rear = _corner_pair(rear_stiffness, tyre_stiffness)
    return cg_height * (1.0 / front + 1.0 / rear) / wheelbase**2


def pitch_mode(
    front_arm: float,
    rear_arm: float,
    front_pair: tuple[float, float],
    rear_pair: tuple[float, float],
    pitch_inertia: float,
) -> tuple[float, float]:
    """Undamped frequency [Hz] and damping ratio [-] of the body's pitch about its CG.

    Pitch stiffness ``K = k_f a^2 + k_r b^2`` and damping ``C = c_f a^2 + c_r b^2`` of the
    axles (``k``: both corners, each spring in series with its tyre; ``c``: both dampers)
    against the pitch inertia ``I``: ``f = sqrt(K / I) / (2 pi)``, ``zeta = C / (2 sqrt(K I))``
    (the body's heave neglected).

    Args:
        front_arm, rear_arm: a, b, the CG's distance to each axle [m].
        front_pair, rear_pair: (k, c) of one axle: stiffness [N/m], damping [N s/m].
        pitch_inertia: I [kg m^2].
    """
    stiffness = front_pair[0] * front_arm**2 + rear_pair[0] * rear_arm**2
    damping = front_pair[1] * front_arm**2 + rear_pair[1] * rear_arm**2
    frequency = math.sqrt(stiffness / pitch_inertia) / (2.0 * math.pi)
    return frequency, damping / (2.0 * math.sqrt(stiffness * pitch_inertia))


def vehicle_body_pitch(path: str | os.PathLike[str] | None) -> BodyPitch:
    """`BodyPitch` of a full vehicle file's suspension and tyres; a rigid body for a file
    that has none (an estimation-only file); None: the shipped Clio."""
    return body_pitch_of(load_vehicle_if_full(path))


def body_pitch_of(vp: VehicleParams | None) -> BodyPitch:
    """`BodyPitch` of a full vehicle's suspension and tyres (None: a rigid body)."""
    if vp is None:
        return BodyPitch()
    c, s, tyre = vp.chassis, vp.suspension, vp.wheel.tyre_vertical_stiffness
    front = (_corner_pair(s.stiffness_front, tyre), 2.0 * s.damping_front)
    rear = (_corner_pair(s.stiffness_rear, tyre), 2.0 * s.damping_rear)
    arm = c.cg_to_front_axle
    frequency, damping = pitch_mode(arm, c.wheelbase - arm, front, rear, c.pitch_inertia)
    compliance = pitch_compliance(
        c.wheelbase, c.cg_height, s.stiffness_front, s.stiffness_rear, tyre
    )
    return BodyPitch(compliance, frequency, damping)
