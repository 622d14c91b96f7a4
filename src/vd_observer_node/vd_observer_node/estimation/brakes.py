"""The brakes: the brake input's torque at each wheel, or where it is unknown.

A car logs its brakes as a pressure (per wheel, per axle, or one master-cylinder pressure, in
any unit) or only as the brake-light switch. With a pressure, the brake torque of each wheel
is ``gain * p``, opposing its rotation, with the gain of its axle from the vehicle file
(``brakes.gain_front`` / ``gain_rear`` [N m per unit of the mapped pressure]); it is taken
off the drive torque (measured or the engine path's) before the estimator. With a switch only
the brake torque is unknown while the switch is on: the torques do not hold there, so the
estimator flags Fx's friction, mu and the slope invalid (never an old value held).

`brake_torques` is the compiled step (`cascade_step.cascade_step` calls it once a stamp);
:class:`Brakes` builds its parameters.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final

import numpy as np
from numpy.typing import NDArray
from vd_common.vehicle.estimation import EstimationVehicleParams

from vd_observer_node.errors import ConfigurationError
from vd_observer_node.kernel._jit import jit

__all__ = [
    'BRAKE_KINDS',
    'BRAKE_NONE',
    'BRAKE_PRESSURE',
    'BRAKE_SWITCH',
    'Brakes',
    'brake_torques',
    'no_brakes',
]

FloatArray = NDArray[np.float64]

#: the brake input's kinds (slot 0 of `Brakes.params_array`), by code
BRAKE_NONE: Final = 0
BRAKE_SWITCH: Final = 1
BRAKE_PRESSURE: Final = 2
#: their names (the mapping's ``brake.signal``), indexed by code
BRAKE_KINDS: Final = ('none', 'switch', 'pressure')
#: [rad/s] below this wheel speed a brake torque's direction is unknown (a reaction)
_STILL: Final = 0.5


@dataclass(frozen=True)
class Brakes:
    """The brake input as the cascade uses it.

    Attributes:
        kind: one of :data:`BRAKE_KINDS`.
        gain_front: [N m per unit] brake torque of a front wheel per unit of its pressure.
        gain_rear: [N m per unit] the same for a rear wheel.
    """

    kind: str = 'none'
    gain_front: float = 0.0
    gain_rear: float = 0.0

    def __post_init__(self) -> None:
        if self.kind not in BRAKE_KINDS:
            raise ConfigurationError(
                f'brake kind must be one of {", ".join(BRAKE_KINDS)}, got {self.kind!r}'
            )
        for name in ('gain_front', 'gain_rear'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ConfigurationError(f'Brakes.{name} must be >= 0, got {value}')

    @classmethod
    def from_params(cls, signal: str, params: EstimationVehicleParams, origin: str = '') -> Brakes:
        """The brake input ``signal`` ('switch' or 'pressure') with the vehicle file's gains.

        Raises:
            ConfigurationError: a pressure and no ``brakes.gain_front`` / ``gain_rear`` in
                the file (one line naming them and the file).
        """
        if signal == 'switch':
            return cls('switch')
        if params.brakes is None:
            where = f' of {origin}' if origin else ''
            raise ConfigurationError(
                f'vehicle file {params.source}: brakes.gain_front and brakes.gain_rear are '
                f'missing (the brake pressure{where} needs them, N m per unit of the mapped '
                'pressure)'
            )
        return cls('pressure', params.brakes.gain_front, params.brakes.gain_rear)

    def params_array(self) -> FloatArray:
        """shape (5,): the kind's code, then the gain of FL, FR, RL, RR."""
        f, r = self.gain_front, self.gain_rear
        return np.array([float(BRAKE_KINDS.index(self.kind)), f, f, r, r])


def no_brakes(n: int) -> FloatArray:
    """shape (n, 4) of nan: the brake record where there is no brake input."""
    return np.full((n, 4), math.nan)


@jit
def brake_torques(
    bprm: FloatArray, brake: FloatArray, omega: FloatArray, used: FloatArray
) -> bool:
    """Take the brake torques off the wheel torques ``used`` (4,) [N m], in place; returns
    whether the torques hold at this stamp.

    Args:
        bprm: shape (5,), `Brakes.params_array`.
        brake: shape (4,): each wheel's pressure (its axle's, or the one pressure), or the
            switch (0 off, else on) in ``brake[0]``; nan where not known at this stamp.
        omega: shape (4,), [rad/s] wheel speeds (the brake torque opposes the rotation).
        used: shape (4,), [N m] drive torques, written: drive minus brake torque; nan where
            the pressure is not known (the estimator then says invalid, it never holds).

    With a switch the brake torque is unknown while it is on (or unknown): not held. With a
    pressure, a braked wheel slower than 0.5 rad/s has a torque of unknown direction (at a
    standstill it is a reaction): not held.
    """
    kind = int(bprm[0])
    if kind == BRAKE_SWITCH:
        return bool(math.isfinite(brake[0]) and brake[0] == 0.0)
    if kind != BRAKE_PRESSURE:
        return True
    holds = True
    for i in range(4):
        p = brake[i]
        if not math.isfinite(p):
            used[i] = math.nan
            continue
        torque = bprm[1 + i] * p
        if torque == 0.0:
            continue
        if abs(omega[i]) < _STILL:
            holds = False
        used[i] -= math.copysign(torque, omega[i])
    return holds
