"""The brakes: the brake input's torque at each wheel, or where it is unknown.

A car logs its brakes as a pressure (per wheel, per axle, or one master-cylinder pressure, in
any unit) or only as the brake-light switch. With a pressure, the brake torque of each wheel
is ``gain * p``, opposing its rotation, with the gain of its axle from the vehicle file
(``brakes.gain_front`` / ``gain_rear`` [N m per unit of the mapped pressure]); it is taken
off the drive torque (measured or the engine path's) before the estimator. With a switch only
the brake torque is unknown while the switch is on: the torques do not hold there, so the
estimator flags Fx's friction, mu and the slope invalid (never an old value held).

**A gain learnt online** (a pressure and no gain in the vehicle file): one gain for every
wheel, by scalar recursive least squares on the decelerations, as the mass is learnt
(`mass_grade_step`). While the pressure is on and the car rolls forward, the longitudinal
balance gives the brake force::

    G * sum(p_i) / R = sum(T_drive,i - J_i omega_dot_i) / R - F_roll - F_aero
                       - m (dv/dt + g sin(theta_before))

with theta_before the slope estimated (valid) just before the pressure came on: the grade
is taken as constant through a braking, which is what makes G observable without a grade
sensor. A changing grade while braking, a wrong mass or a wrong drive torque go into G
alike. Until it has converged (`BrakeLearning`: enough braking time and a relative standard
deviation below a bound) the brake torque is unknown, as with a switch; once converged, G
is used like a file's gain. Honest limits: one gain for all wheels (the sum of the brake
forces is right, each wheel's share only if the real gains are alike, so per-wheel mu is
not), and a bias of 1 % of g in the grade gives ~1 % of m g of brake force error.

`brake_torques` and `brake_gain_update` are the compiled steps (`cascade_step.cascade_step`
calls them once a stamp); :class:`Brakes` builds their parameters.
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
    'BRAKE_GAIN_SLOTS',
    'BRAKE_KINDS',
    'BRAKE_NONE',
    'BRAKE_PRESSURE',
    'BRAKE_SWITCH',
    'Brakes',
    'brake_gain_update',
    'brake_gains',
    'brake_torques',
    'new_brake_state',
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
#: the learnt gain's state (`new_brake_state`): gain [N m per unit], its variance, braking
#: time used [s], converged (0/1), the slope before the braking [rad] (nan: none), last stamp
#: [s], then the two first-order stages of the force, the speed and the regressor, and the
#: filtered speed of the stamp before (nan: filters not started)
BRAKE_GAIN_SLOTS: Final = (
    'gain', 'variance', 'excited_time', 'converged', 'theta', 't',
    'f1', 'f2', 'v1', 'v2', 'p1', 'p2', 'v_prev',
)  # fmt: skip
_G, _VAR, _TIME, _CONV, _THETA, _T, _F1, _F2, _V1, _V2, _P1, _P2, _VP = range(13)


@dataclass(frozen=True)
class Brakes:
    """The brake input as the cascade uses it.

    Attributes:
        kind: one of :data:`BRAKE_KINDS`.
        gain_front: [N m per unit] brake torque of a front wheel per unit of its pressure.
        gain_rear: [N m per unit] the same for a rear wheel.
        learn: learn one gain for every wheel online (module docstring); the gains above
            are then not used.
        filter_tau: [s] time constant of the two first-order stages applied alike to the
            balance's force, the speed (whose derivative is then taken) and the pressure:
            the observers' acceleration lags a braking's onset, the filtered balance not.
        memory: [s] forgetting time of the learnt gain (over braking time).
        force_noise: [N] standard deviation of the balance's force per stamp (GNSS-free
            drives: observer accel noise, engine-torque error).
        min_braking_time: [s] braking time before the learnt gain may be trusted.
        converged_std_ratio: [-] the learnt gain is trusted once its standard deviation is
            below this share of it.
    """

    kind: str = 'none'
    gain_front: float = 0.0
    gain_rear: float = 0.0
    learn: bool = False
    filter_tau: float = 0.2
    memory: float = 120.0
    force_noise: float = 300.0
    min_braking_time: float = 1.0
    converged_std_ratio: float = 0.1

    def __post_init__(self) -> None:
        if self.kind not in BRAKE_KINDS:
            raise ConfigurationError(
                f'brake kind must be one of {", ".join(BRAKE_KINDS)}, got {self.kind!r}'
            )
        for name in ('gain_front', 'gain_rear', 'min_braking_time'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ConfigurationError(f'Brakes.{name} must be >= 0, got {value}')
        for name in ('filter_tau', 'memory', 'force_noise', 'converged_std_ratio'):
            value = getattr(self, name)
            if not value > 0.0:
                raise ConfigurationError(f'Brakes.{name} must be > 0, got {value}')

    @classmethod
    def from_params(cls, signal: str, params: EstimationVehicleParams, origin: str = '') -> Brakes:
        """The brake input ``signal`` ('switch' or 'pressure') with the vehicle file's gains.

        A pressure without ``brakes.gain_front`` / ``gain_rear`` in the file learns its
        gain online (``learn``).

        Raises:
            ConfigurationError: an unknown signal.
        """
        del origin  # named in refusals of the mapping, none left here
        if signal == 'switch':
            return cls('switch')
        if signal != 'pressure':
            raise ConfigurationError(f'brake signal must be switch or pressure, got {signal!r}')
        if params.brakes is None:
            return cls('pressure', learn=True)
        return cls('pressure', params.brakes.gain_front, params.brakes.gain_rear)

    def params_array(self) -> FloatArray:
        """shape (11,): the kind's code, the gain of FL, FR, RL, RR, learn (0/1), memory,
        force noise, minimum braking time, converged standard-deviation ratio, filter tau."""
        f, r = self.gain_front, self.gain_rear
        return np.array(
            [float(BRAKE_KINDS.index(self.kind)), f, f, r, r, float(self.learn), self.memory,
             self.force_noise, self.min_braking_time, self.converged_std_ratio,
             self.filter_tau]
        )  # fmt: skip


def new_brake_state() -> FloatArray:
    """shape (13,): a learnt gain's state before any braking (`BRAKE_GAIN_SLOTS`)."""
    state = np.full(len(BRAKE_GAIN_SLOTS), math.nan)
    state[:4] = [0.0, math.inf, 0.0, 0.0]
    return state


def no_brakes(n: int) -> FloatArray:
    """shape (n, 4) of nan: the brake record where there is no brake input."""
    return np.full((n, 4), math.nan)


@jit
def brake_gains(bprm: FloatArray, bst: FloatArray, gains: FloatArray) -> None:
    """The gain of each wheel into ``gains`` (4,): the file's, or the learnt one once
    converged (nan before: the brake torque is then unknown)."""
    if bprm[5] > 0.0:
        gains[:] = bst[_G] if bst[_CONV] > 0.0 else math.nan
    else:
        gains[:] = bprm[1:5]


@jit
def brake_torques(
    bprm: FloatArray, gains: FloatArray, brake: FloatArray, omega: FloatArray, used: FloatArray
) -> bool:
    """Take the brake torques off the wheel torques ``used`` (4,) [N m], in place; returns
    whether the torques hold at this stamp.

    Args:
        bprm: shape (10,), `Brakes.params_array`.
        gains: shape (4,), [N m per unit] (`brake_gains`; nan: not known yet).
        brake: shape (4,): each wheel's pressure (its axle's, or the one pressure), or the
            switch (0 off, else on) in ``brake[0]``; nan where not known at this stamp.
        omega: shape (4,), [rad/s] wheel speeds (the brake torque opposes the rotation).
        used: shape (4,), [N m] drive torques, written: drive minus brake torque; nan where
            the pressure is not known (the estimator then says invalid, it never holds).

    With a switch the brake torque is unknown while it is on (or unknown): not held. With a
    pressure, a braked wheel slower than 0.5 rad/s has a torque of unknown direction (at a
    standstill it is a reaction), and a gain not learnt yet gives no torque: not held.
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
        if p == 0.0:
            continue
        if not math.isfinite(gains[i]):
            holds = False
            continue
        torque = gains[i] * p
        if abs(omega[i]) < _STILL:
            holds = False
        used[i] -= math.copysign(torque, omega[i])
    return holds


@jit
def brake_gain_update(
    bprm: FloatArray, bst: FloatArray, t: float, brake: FloatArray, omega: FloatArray,
    drive: FloatArray, ep: np.record, speed: float, path_ok: bool, est: np.record,
) -> None:  # fmt: skip
    """One stamp of the learnt gain (module docstring), after the estimator's.

    Args:
        bprm: `Brakes.params_array` (learn on).
        bst: shape (13,), the state (`new_brake_state`), advanced.
        t: stamp [s].
        brake: shape (4,), the pressures.
        omega: shape (4,), [rad/s] the wheel observer's.
        drive: shape (4,), [N m] the drive torques before the brakes.
        ep: the estimator's `estimator_step.ESTIMATOR_PARAMS` (wheel inertias, gravity).
        speed: [m/s] the estimator's body speed.
        path_ok: the drive torques held (engine path engaged and settled).
        est: the estimator's `estimator_step.ESTIMATES` of this stamp (its radius, mass,
            resistances, and its slope: valid before the braking).
    """
    dt = 0.0 if math.isnan(bst[_T]) else t - bst[_T]
    bst[_T] = t
    total = 0.0
    known = True
    for i in range(4):
        if not math.isfinite(brake[i]):
            known = False
        else:
            total += brake[i]
    braking = total > 0.0
    forward = speed > 1.0
    for i in range(4):
        forward = forward and omega[i] > _STILL
    if not braking and est.slope_valid:
        bst[_THETA] = est.slope  # the grade the next braking starts on (the last valid one)
    usable = known and forward and path_ok and math.isfinite(bst[_THETA]) and 0.0 <= dt < 0.5
    if not usable:
        bst[_F1] = math.nan  # the filters start again at the next usable stamp
        return
    # the balance without the brakes and the acceleration, on the grade before the braking
    radius = est.radius_used
    inertia = 2.0 * (ep.inertia_front + ep.inertia_rear)
    force = -est.aero - est.mass_used * ep.gravity * math.sin(bst[_THETA])
    for i in range(4):
        force += drive[i] / radius - est.rolling[i]
    phi_raw = total / radius
    if math.isnan(bst[_F1]) or dt == 0.0:
        bst[_F1], bst[_F2] = force, force
        bst[_V1], bst[_V2], bst[_VP] = speed, speed, speed
        bst[_P1], bst[_P2] = phi_raw, phi_raw
        return
    w = -math.expm1(-dt / bprm[10])
    bst[_F1] += w * (force - bst[_F1])
    bst[_F2] += w * (bst[_F1] - bst[_F2])
    bst[_V1] += w * (speed - bst[_V1])
    bst[_V2] += w * (bst[_V1] - bst[_V2])
    bst[_P1] += w * (phi_raw - bst[_P1])
    bst[_P2] += w * (bst[_P1] - bst[_P2])
    accel_f = (bst[_V2] - bst[_VP]) / dt
    bst[_VP] = bst[_V2]
    if not braking or bst[_P2] <= 0.0:
        return
    # the wheels' spin inertia moves with the body: (m + sum(J) / R^2) dv/dt
    y = bst[_F2] - (est.mass_used + inertia / (radius * radius)) * accel_f
    phi = bst[_P2]
    lam = math.exp(-dt / bprm[6])
    var = bst[_VAR] / lam
    noise = bprm[7] * bprm[7]
    if math.isinf(var):
        gain, var = y / phi, noise / (phi * phi)  # the first sample alone
    else:
        k = var * phi / (phi * phi * var + noise)
        gain = bst[_G] + k * (y - phi * bst[_G])
        var = (1.0 - k * phi) * var
    if not (math.isfinite(gain) and math.isfinite(var)):
        return
    bst[_G], bst[_VAR] = max(gain, 0.0), var
    bst[_TIME] += dt
    if bst[_TIME] >= bprm[8] and bst[_G] > 0.0 and math.sqrt(var) <= bprm[9] * bst[_G]:
        bst[_CONV] = 1.0
