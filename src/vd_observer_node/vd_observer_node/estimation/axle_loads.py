"""The axle loads of a car on its springs: the load transfer through the chassis's vertical
dynamics, from a full vehicle file.

The longitudinal ground force ``G`` acts ``h`` (the whole vehicle's CG height) below the CG.
Settled, the axles carry its moment as ``-+ h G / L`` (`formulas.wheel_loads`). Until then
the body heaves and pitches on its springs, the wheels on their tyres, and the axle loads
swing: a braking that starts at once unloads the rear axle by about a third more than the
settled transfer, 0.15-0.2 s later, and that is where the friction potential reads the tyre.

The model is the simulator's chassis, linearised about rest (the bond graph of
`vd_sim_node.vehicle.model`: a sprung mass with heave and pitch inertia, each axle's two
springs and dampers to its unsprung mass, each axle's tyres to the road), driven by the
pitch moment ``h G`` about the sprung CG. Four positions (sprung heave ``z`` [m], pitch
``theta`` [rad] nose up, front and rear unsprung heave [m]) and their rates; the outputs are
the tyre forces' deviations from rest, the axle loads' transfer [N]. Settled it is exactly
``-+ h G / L``, so the quasi-static loads are its steady state. A vehicle file without a
suspension (an estimation-only file) describes a rigid body: the settled transfer at once.

The estimator steps it by semi-implicit Euler in sub-steps of at most `MAX_SUB_STEP` (the
wheel hop is at 11-13 Hz on the Clio: stable and within a per cent of the exact response at
1 ms) and restarts it settled after a step longer than `MAX_STEP` (a gap: whatever swung
has settled).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Final

import numpy as np
from numpy.typing import NDArray
from vd_common.vehicle.params import VehicleParams

from vd_observer_node.kernel._jit import jit, new_record

__all__ = [
    'LOAD_MODEL',
    'MAX_STEP',
    'MAX_SUB_STEP',
    'VerticalModel',
    'axle_transfer_step',
    'load_model_params',
]

FloatArray = NDArray[np.float64]

#: [s] the longest sub-step of the integration.
MAX_SUB_STEP: Final = 1e-3
#: [s] a longer step restarts the model settled.
MAX_STEP: Final = 0.05

#: The model as the step takes it: on (False: rigid, the settled transfer at once); the
#: accelerations of the four positions as ``kp @ pos + kv @ vel + b * G``; the axle load
#: transfers (front, rear) [N] as ``cp @ pos + cv @ vel``; settle: the positions at rest per
#: newton of ``G``.
LOAD_MODEL: Final = np.dtype(
    [
        ('on', 'b1'),
        ('kp', 'f8', (4, 4)),
        ('kv', 'f8', (4, 4)),
        ('b', 'f8', (4,)),
        ('cp', 'f8', (2, 4)),
        ('cv', 'f8', (2, 4)),
        ('settle', 'f8', (4,)),
    ],
    align=True,
)


@dataclass(frozen=True)
class VerticalModel:
    """The chassis's vertical dynamics (SI units; per axle: both corners together).

    Attributes:
        sprung_mass: [kg].
        pitch_inertia: the sprung mass's about its CG [kg m^2].
        sprung_cg_to_front: the sprung CG to the front axle [m].
        wheelbase: [m].
        cg_height: the whole vehicle's CG height [m] (the arm of the ground force).
        unsprung: (front, rear) [kg].
        spring: (front, rear) suspension stiffness [N/m].
        damper: (front, rear) suspension damping [N s/m].
        tyre: (stiffness [N/m], damping [N s/m]) of one axle's two tyres.
    """

    sprung_mass: float
    pitch_inertia: float
    sprung_cg_to_front: float
    wheelbase: float
    cg_height: float
    unsprung: tuple[float, float]
    spring: tuple[float, float]
    damper: tuple[float, float]
    tyre: tuple[float, float]

    @classmethod
    def from_params(cls, vp: VehicleParams) -> VerticalModel:
        """The model of a full vehicle file."""
        c, s, w = vp.chassis, vp.suspension, vp.wheel
        unsprung = (2.0 * c.unsprung_mass_front, 2.0 * c.unsprung_mass_rear)
        return cls(
            sprung_mass=c.mass - unsprung[0] - unsprung[1],
            pitch_inertia=c.pitch_inertia,
            sprung_cg_to_front=c.sprung_cg_to_front_axle,
            wheelbase=c.wheelbase,
            cg_height=c.cg_height,
            unsprung=unsprung,
            spring=(2.0 * s.stiffness_front, 2.0 * s.stiffness_rear),
            damper=(2.0 * s.damping_front, 2.0 * s.damping_rear),
            tyre=(2.0 * w.tyre_vertical_stiffness, 2.0 * w.tyre_vertical_damping),
        )

    def forces(self, pos: FloatArray, vel: FloatArray) -> tuple[FloatArray, FloatArray]:
        """The suspension forces on the body and the tyre forces on the axles [N], up, each
        (front, rear), at positions and rates (deviations from rest)."""
        a = self.sprung_cg_to_front
        b = self.wheelbase - a
        lever = np.array([a, -b])
        deflection = pos[0] + lever * pos[1] - pos[2:]
        rate = vel[0] + lever * vel[1] - vel[2:]
        suspension = -np.asarray(self.spring) * deflection - np.asarray(self.damper) * rate
        tyre = -self.tyre[0] * pos[2:] - self.tyre[1] * vel[2:]
        return suspension, tyre

    def accelerations(self, pos: FloatArray, vel: FloatArray, ground: float) -> FloatArray:
        """d(vel)/dt [m/s^2, rad/s^2] under the ground force ``ground`` [N]."""
        a = self.sprung_cg_to_front
        b = self.wheelbase - a
        susp, tyre = self.forces(pos, vel)
        return np.array(
            [
                (susp[0] + susp[1]) / self.sprung_mass,
                (self.cg_height * ground + a * susp[0] - b * susp[1]) / self.pitch_inertia,
                (tyre[0] - susp[0]) / self.unsprung[0],
                (tyre[1] - susp[1]) / self.unsprung[1],
            ]
        )


def load_model_params(model: VerticalModel | None) -> Any:
    """The `LOAD_MODEL` record of a model (None: rigid, ``on`` False)."""
    p = new_record(LOAD_MODEL)
    if model is None:
        return p
    zero = np.zeros(4)
    unit = np.eye(4)
    p.on = True
    p.kp[:] = np.column_stack([model.accelerations(e, zero, 0.0) for e in unit])
    p.kv[:] = np.column_stack([model.accelerations(zero, e, 0.0) for e in unit])
    p.b[:] = model.accelerations(zero, zero, 1.0)
    p.cp[:] = np.column_stack([model.forces(e, zero)[1] for e in unit])
    p.cv[:] = np.column_stack([model.forces(zero, e)[1] for e in unit])
    p.settle[:] = np.linalg.solve(p.kp, -p.b)
    return p


@jit
def axle_transfer_step(
    p: Any, pos: FloatArray, vel: FloatArray, dt: float, ground: float, out: FloatArray
) -> None:
    """Advance the model by ``dt`` under the ground force and write the axle load transfers.

    Args:
        p: `LOAD_MODEL` record (``on`` False: the settled transfer, the state untouched).
        pos: shape (4,), the positions, advanced in place (nan: not started: starts settled).
        vel: shape (4,), their rates, advanced in place.
        dt: [s] since the last step (<= 0 or > `MAX_STEP`: restart settled at ``ground``).
        ground: G [N], held over the step.
        out: shape (2,), [N] written: the front and rear axle loads' transfer (both wheels).
    """
    if not p.on:
        return
    if math.isnan(pos[0]) or not dt > 0.0 or dt > MAX_STEP:
        for i in range(4):
            pos[i] = p.settle[i] * ground
            vel[i] = 0.0
    else:
        steps = max(math.ceil(dt / MAX_SUB_STEP - 1e-9), 1)
        h = dt / steps
        acc = np.empty(4)
        for _ in range(steps):
            for i in range(4):
                total = p.b[i] * ground
                for j in range(4):
                    total += p.kp[i, j] * pos[j] + p.kv[i, j] * vel[j]
                acc[i] = total
            for i in range(4):
                vel[i] += h * acc[i]
                pos[i] += h * vel[i]
    for k in range(2):
        total = 0.0
        for j in range(4):
            total += p.cp[k, j] * pos[j] + p.cv[k, j] * vel[j]
        out[k] = total
