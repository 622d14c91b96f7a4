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
from typing import Any, Final, NamedTuple

import numpy as np
from numpy.typing import NDArray
from vd_common.vehicle.estimation import EstimationVehicleParams

from vd_observer_node.errors import ConfigurationError
from vd_observer_node.kernel._jit import jit, new_records

__all__ = [
    'BRAKE_KINDS',
    'BRAKE_NONE',
    'BRAKE_PARAMS',
    'BRAKE_PRESSURE',
    'BRAKE_STATE',
    'BRAKE_SWITCH',
    'BrakeParts',
    'Brakes',
    'brake_gain_update',
    'brake_gains',
    'brake_torques',
    'new_brake_state',
    'no_brakes',
]

FloatArray = NDArray[np.float64]

#: the brake input's kinds (`BRAKE_PARAMS.kind`), by code
BRAKE_NONE: Final = 0
BRAKE_SWITCH: Final = 1
BRAKE_PRESSURE: Final = 2
#: their names (the mapping's ``brake.signal``), indexed by code
BRAKE_KINDS: Final = ('none', 'switch', 'pressure')
#: [rad/s] below this wheel speed a brake torque's direction is unknown (a reaction)
_STILL: Final = 0.5
#: The brake input's settings (`Brakes.params`): kind (`BRAKE_KINDS` code), gain [N m per
#: unit] of each wheel FL, FR, RL, RR, learn (one gain learnt online), then the learnt gain's
#: memory [s], force_noise [N], min_braking_time [s], converged_std_ratio [-] and
#: filter_tau [s] (`Brakes`).
BRAKE_PARAMS: Final = np.dtype(
    [
        ('kind', 'i8'),
        ('gain', 'f8', (4,)),
        ('learn', 'b1'),
        ('memory', 'f8'),
        ('force_noise', 'f8'),
        ('min_braking_time', 'f8'),
        ('converged_std_ratio', 'f8'),
        ('filter_tau', 'f8'),
    ],
    align=True,
)
#: The learnt gain's state (`new_brake_state`): gain [N m per unit] and its variance, the
#: braking time used [s], converged, theta [rad] the slope before the braking (nan: none), t
#: [s] the last stamp, the two first-order stages of the balance's force [N], the speed
#: [m/s] and the regressor (pressure sum / R), and speed_before [m/s] the filtered speed of
#: the stamp before (force_stages[0] nan: the filters have not started).
BRAKE_STATE: Final = np.dtype(
    [
        ('gain', 'f8'),
        ('variance', 'f8'),
        ('excited_time', 'f8'),
        ('converged', 'b1'),
        ('theta', 'f8'),
        ('t', 'f8'),
        ('force_stages', 'f8', (2,)),
        ('speed_stages', 'f8', (2,)),
        ('regressor_stages', 'f8', (2,)),
        ('speed_before', 'f8'),
    ],
    align=True,
)


class BrakeParts(NamedTuple):
    """The brake input's records, each as the 1-element array it lives in.

    Attributes:
        params: `BRAKE_PARAMS` (kind `BRAKE_NONE`: no brake input).
        state: `BRAKE_STATE`.
    """

    params: NDArray[Any]
    state: NDArray[Any]


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

    def params(self) -> NDArray[Any]:
        """The settings as a `BRAKE_PARAMS` record in the 1-element array it lives in."""
        record: NDArray[Any] = new_records(BRAKE_PARAMS, 1)
        record['kind'] = BRAKE_KINDS.index(self.kind)
        record['gain'] = (self.gain_front, self.gain_front, self.gain_rear, self.gain_rear)
        learning = ('learn', 'memory', 'force_noise', 'min_braking_time',
                    'converged_std_ratio', 'filter_tau')  # fmt: skip
        for name in learning:  # the fields of the same name
            record[name] = getattr(self, name)
        return record

    def parts(self) -> BrakeParts:
        """Its settings and a learnt gain's state before any braking."""
        return BrakeParts(self.params(), new_brake_state())


def new_brake_state() -> NDArray[Any]:
    """A learnt gain's state before any braking: a `BRAKE_STATE` record in the 1-element
    array it lives in (gain 0 of infinite variance, nothing filtered)."""
    state: NDArray[Any] = new_records(BRAKE_STATE, 1)
    unseen = ('theta', 't', 'force_stages', 'speed_stages', 'regressor_stages', 'speed_before')
    for name in unseen:
        state[name] = math.nan
    state['variance'] = math.inf
    return state


def no_brakes(n: int) -> FloatArray:
    """shape (n, 4) of nan: the brake record where there is no brake input."""
    return np.full((n, 4), math.nan)


@jit
def brake_gains(p: np.record, s: np.record, gains: FloatArray) -> None:
    """The gain of each wheel into ``gains`` (4,) from the `BRAKE_PARAMS` and `BRAKE_STATE`
    records: the file's, or the learnt one once converged (nan before: the brake torque is
    then unknown)."""
    if p.learn:
        gains[:] = s.gain if s.converged else math.nan
    else:
        gains[:] = p.gain


@jit
def brake_torques(
    p: np.record, gains: FloatArray, brake: FloatArray, omega: FloatArray, used: FloatArray
) -> bool:
    """Take the brake torques off the wheel torques ``used`` (4,) [N m], in place; returns
    whether the torques hold at this stamp.

    Args:
        p: `BRAKE_PARAMS` record.
        gains: shape (4,), [N m per unit] (`brake_gains`; nan: not known yet).
        brake: shape (4,): each wheel's pressure (its axle's, or the one pressure), or its
            switch (0 off, else on; the one switch on every wheel, `inputs.decode.brake_row`);
            nan where not known at this stamp.
        omega: shape (4,), [rad/s] wheel speeds (the brake torque opposes the rotation).
        used: shape (4,), [N m] drive torques, written: drive minus brake torque; nan where
            the pressure is not known (the estimator then says invalid, it never holds).

    With a switch the brake torque is unknown while it is on (or unknown): not held. With a
    pressure, a braked wheel slower than 0.5 rad/s has a torque of unknown direction (at a
    standstill it is a reaction), and a gain not learnt yet gives no torque: not held.
    """
    kind = p.kind
    if kind == BRAKE_SWITCH:  # holds while no wheel's switch is on (or unknown)
        off = True
        for i in range(4):
            off = off and math.isfinite(brake[i]) and brake[i] == 0.0
        return off
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
    brakes: BrakeParts, t: float, brake: FloatArray, drive: FloatArray, ep: np.record,
    einp: np.record, path_ok: bool, est: np.record,
) -> None:  # fmt: skip
    """One stamp of the learnt gain (module docstring), after the estimator's.

    Args:
        brakes: the records (learn on); the state is advanced.
        t: stamp [s].
        brake: shape (4,), the pressures.
        drive: shape (4,), [N m] the drive torques before the brakes.
        ep: the estimator's `estimator_step.ESTIMATOR_PARAMS` (wheel inertias, gravity).
        einp: the estimator's `estimator_step.ESTIMATOR_INPUT` of this stamp (the wheel
            observer's omega, the estimator's body speed).
        path_ok: the drive torques held (engine path engaged and settled).
        est: the estimator's `estimator_step.ESTIMATES` of this stamp (its radius, mass,
            resistances, and its slope: valid before the braking).
    """
    p, bs = brakes.params[0], brakes.state[0]
    omega, speed = einp.omega, einp.speed
    dt = 0.0 if math.isnan(bs.t) else t - bs.t
    bs.t = t
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
        bs.theta = est.slope  # the grade the next braking starts on (the last valid one)
    usable = known and forward and path_ok and math.isfinite(bs.theta) and 0.0 <= dt < 0.5
    if not usable:
        bs.force_stages[0] = math.nan  # the filters start again at the next usable stamp
        return
    # the balance without the brakes and the acceleration, on the grade before the braking
    radius = est.radius_used
    inertia = 2.0 * (ep.inertia_front + ep.inertia_rear)
    force = -est.aero - est.mass_used * ep.gravity * math.sin(bs.theta)
    for i in range(4):
        force += drive[i] / radius - est.rolling[i]
    phi_raw = total / radius
    if math.isnan(bs.force_stages[0]) or dt == 0.0:
        bs.force_stages[0], bs.force_stages[1] = force, force
        bs.speed_stages[0], bs.speed_stages[1], bs.speed_before = speed, speed, speed
        bs.regressor_stages[0], bs.regressor_stages[1] = phi_raw, phi_raw
        return
    w = -math.expm1(-dt / p.filter_tau)
    bs.force_stages[0] += w * (force - bs.force_stages[0])
    bs.force_stages[1] += w * (bs.force_stages[0] - bs.force_stages[1])
    bs.speed_stages[0] += w * (speed - bs.speed_stages[0])
    bs.speed_stages[1] += w * (bs.speed_stages[0] - bs.speed_stages[1])
    bs.regressor_stages[0] += w * (phi_raw - bs.regressor_stages[0])
    bs.regressor_stages[1] += w * (bs.regressor_stages[0] - bs.regressor_stages[1])
    accel_f = (bs.speed_stages[1] - bs.speed_before) / dt
    bs.speed_before = bs.speed_stages[1]
    if not braking or bs.regressor_stages[1] <= 0.0:
        return
    # the wheels' spin inertia moves with the body: (m + sum(J) / R^2) dv/dt
    y = bs.force_stages[1] - (est.mass_used + inertia / (radius * radius)) * accel_f
    phi = bs.regressor_stages[1]
    lam = math.exp(-dt / p.memory)
    var = bs.variance / lam
    noise = p.force_noise * p.force_noise
    if math.isinf(var):
        gain, var = y / phi, noise / (phi * phi)  # the first sample alone
    else:
        k = var * phi / (phi * phi * var + noise)
        gain = bs.gain + k * (y - phi * bs.gain)
        var = (1.0 - k * phi) * var
    if not (math.isfinite(gain) and math.isfinite(var)):
        return
    bs.gain, bs.variance = max(gain, 0.0), var
    bs.excited_time += dt
    if (
        bs.excited_time >= p.min_braking_time
        and bs.gain > 0.0
        and math.sqrt(var) <= p.converged_std_ratio * bs.gain
    ):
        bs.converged = True
