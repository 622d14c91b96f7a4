"""Wheel torques from the engine torque and the engaged gear, for data without wheel torques.

Most cars report the engine torque and the gear on their CAN bus, few the torque at each
wheel. :func:`engine_wheel_torques` gives the drive torque per wheel from those two with the
drivetrain of the vehicle file (gear ratios, final drive), as the simulator's driveline
transmits it: the clutch torque times the overall ratio, split equally between the driven
wheels by an open differential::

    T_clutch = T_engine - J_engine * i * mean(omega_dot of the driven wheels)
    T_wheel  = i * T_clutch * eta / n_driven   (power to the wheels; / eta when T_clutch < 0)

with i = ratio[gear] * final_drive. The engine-inertia term is what the engine spends on
accelerating its own flywheel: in first gear J_engine * i^2 is 28 kg m^2 at the wheels, 18
times a front wheel's own inertia, so leaving it out over-states the traction torque by up
to a third in a full-throttle launch. It needs the driven wheels' omega_dot (the observer
gives it) and holds while the clutch is closed.

What the engine path cannot know:

* **brakes**: the brake torque never reaches the engine; while braking the path reports the
  drive torque only (engine drag), so Fx is too high by the brake force (docs/estimation.md
  measures it);
* **a slipping clutch** (launch, the engagement after a shift): the clutch then transmits
  less than T_engine - J_engine * i * omega_dot; gear 0 (the simulator reports 0 while the
  clutch is open in a shift) gives 0 drive torque, which is right.

Torque sources (the ``torque_source`` field of vd_msgs TireForces, Friction and Slope):
:data:`TORQUE_MEASURED` (wheel torques measured), :data:`TORQUE_ENGINE` (this module),
:data:`TORQUE_NONE` (no torque: Fx, mu and slope invalid).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Final

import numpy as np
from numpy.typing import ArrayLike, NDArray
from vd_common.errors import ParameterError
from vd_common.vehicle.estimation import EstimationConverter, EstimationVehicleParams
from vd_common.vehicle.params import VehicleParams

from vd_observer_node.errors import ConfigurationError, InputShapeError
from vd_observer_node.kernel._jit import jit, new_records

__all__ = [
    'DRIVEN_AXLES',
    'DRIVETRAIN_PARAMS',
    'MAX_CONVERTER_POINTS',
    'MAX_GEARS',
    'NO_GEAR',
    'TORQUE_ENGINE',
    'TORQUE_MEASURED',
    'TORQUE_NONE',
    'TORQUE_SOURCES',
    'Drivetrain',
    'clutch_engaged',
    'converter_speed_ratio',
    'engine_torques',
    'engine_wheel_torques',
    'gear_number',
    'torque_source_code',
]

FloatArray = NDArray[np.float64]

#: Codes of the torque source, equal to the vd_msgs constants TORQUE_MEASURED / _ENGINE / _NONE.
TORQUE_MEASURED: Final = 0
TORQUE_ENGINE: Final = 1
TORQUE_NONE: Final = 2
#: Names of the torque sources, indexed by code (CLI, mapping files, replay summary).
TORQUE_SOURCES: Final = ('measured', 'engine', 'none')
#: Which wheels the differential drives: front (FL, FR), rear (RL, RR) or all four.
DRIVEN_AXLES: Final = ('front', 'rear', 'all')


#: What `gear_number` gives for a value that is no gear at all (nan, 2.5): no box has it.
NO_GEAR: Final = -(2**31)


def gear_number(value: float) -> int:
    """A gear read as a float (a Float64MultiArray element) as an int; `NO_GEAR` for a
    non-finite or non-integral value."""
    if not math.isfinite(value) or value != round(value) or abs(value) >= 2**31:
        return NO_GEAR
    return int(value)


def torque_source_code(name: str) -> int:
    """The code of a torque source name ('measured', 'engine', 'none').

    Raises:
        ConfigurationError: unknown name.
    """
    if name not in TORQUE_SOURCES:
        raise ConfigurationError(
            f'torque source must be one of {", ".join(TORQUE_SOURCES)}, got {name!r}'
        )
    return TORQUE_SOURCES.index(name)


#: room for a gearbox's forward gears and a converter's table in `DRIVETRAIN_PARAMS`
MAX_GEARS: Final = 16
MAX_CONVERTER_POINTS: Final = 64
#: The settings of `engine_torques` (`Drivetrain.params`): the number of forward gears, the
#: final drive, the reverse gear's ratio, eta, J_e [kg m^2], the largest clutch slip [rad/s],
#: the settle time [s], which wheels are driven (1/0, FL, FR, RL, RR), the gear ratios and eta
#: per forward gear (the first ``gears`` used), each wheel's share of the torque, and the torque
#: converter (``converter`` 1/0): the first ``converter_points`` of its speed ratios, torque
#: ratios and capacity factors [rpm/sqrt(N m)].
DRIVETRAIN_PARAMS: Final = np.dtype(
    [
        ('gears', 'i8'),
        ('final_drive', 'f8'),
        ('reverse_ratio', 'f8'),
        ('efficiency', 'f8'),
        ('engine_inertia', 'f8'),
        ('max_clutch_slip', 'f8'),
        ('clutch_settle_time', 'f8'),
        ('driven', 'f8', (4,)),
        ('ratios', 'f8', (MAX_GEARS,)),
        ('gear_efficiency', 'f8', (MAX_GEARS,)),
        ('shares', 'f8', (4,)),
        ('converter', 'b1'),
        ('converter_points', 'i8'),
        ('speed_ratio', 'f8', (MAX_CONVERTER_POINTS,)),
        ('torque_ratio', 'f8', (MAX_CONVERTER_POINTS,)),
        ('capacity_factor', 'f8', (MAX_CONVERTER_POINTS,)),
    ],
    align=True,
)


@dataclass(frozen=True)
class Drivetrain:
    """The driveline between engine and wheels.

    Attributes:
        ratios: gear ratios of gears 1..n [-] (gearbox input speed / output speed).
        final_drive: final-drive ratio [-].
        reverse_ratio: ratio of the reverse gear (gear -1) [-]; the vehicle file has none,
            so :meth:`from_params` takes the first gear's (close on most manual boxes).
        efficiency: eta in (0, 1], share of the clutch power that reaches the wheels.
        driven_axle: one of :data:`DRIVEN_AXLES`.
        engine_inertia: J_engine [kg m^2] (crankshaft, flywheel, clutch disc); 0 leaves the
            engine-inertia term out.
        max_clutch_slip: [rad/s] the clutch counts as slipping (the engine path invalid)
            where the engine speed differs from i * mean(omega of the driven wheels) by more
            than this; the simulator's closed clutch slips by ~0.5 rad/s, a launch by
            hundreds.
        clutch_settle_time: [s] the engine path stays invalid this long after the clutch
            last slipped or the gear changed: the clutch reaches the slip threshold while its
            torque is still settling (the launch, the engagement after a shift), and the
            wheel torque is then off by up to a few hundred N m for ~0.2 s.
    """

    ratios: tuple[float, ...]
    final_drive: float
    reverse_ratio: float
    efficiency: float = 1.0
    driven_axle: str = 'front'
    engine_inertia: float = 0.0
    max_clutch_slip: float = 2.0
    clutch_settle_time: float = 0.3
    gear_efficiency: tuple[float, ...] = ()
    front_share: float = 0.5
    converter: EstimationConverter | None = None

    def __post_init__(self) -> None:
        numbers = {
            'final_drive': self.final_drive,
            'reverse_ratio': self.reverse_ratio,
            **{f'ratios[{k}]': r for k, r in enumerate(self.ratios)},
        }
        if not self.ratios:
            raise ConfigurationError('Drivetrain.ratios must list at least one gear')
        for name, value in numbers.items():
            if not (math.isfinite(value) and value > 0.0):
                raise ConfigurationError(f'Drivetrain.{name} must be > 0, got {value}')
        if not (math.isfinite(self.efficiency) and 0.0 < self.efficiency <= 1.0):
            raise ConfigurationError(
                f'Drivetrain.efficiency must be in (0, 1], got {self.efficiency}'
            )
        if self.driven_axle not in DRIVEN_AXLES:
            raise ConfigurationError(
                f'Drivetrain.driven_axle must be one of {", ".join(DRIVEN_AXLES)}, '
                f'got {self.driven_axle!r}'
            )
        for name in ('engine_inertia', 'max_clutch_slip', 'clutch_settle_time'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ConfigurationError(f'Drivetrain.{name} must be >= 0, got {value}')
        if self.gear_efficiency and (
            len(self.gear_efficiency) != len(self.ratios)
            or not all(math.isfinite(e) and 0.0 < e <= 1.0 for e in self.gear_efficiency)
        ):
            raise ConfigurationError(
                f'Drivetrain.gear_efficiency must list one value in (0, 1] per gear, got '
                f'{self.gear_efficiency}'
            )
        if not (math.isfinite(self.front_share) and 0.0 < self.front_share < 1.0):
            raise ConfigurationError(
                f'Drivetrain.front_share must be in (0, 1), got {self.front_share}'
            )
        if len(self.ratios) > MAX_GEARS:
            raise ConfigurationError(
                f'Drivetrain.ratios: at most {MAX_GEARS} forward gears, got {len(self.ratios)}'
            )
        points = len(self.converter.speed_ratio) if self.converter is not None else 0
        if points > MAX_CONVERTER_POINTS:
            raise ConfigurationError(
                f'Drivetrain.converter: at most {MAX_CONVERTER_POINTS} points in its table, '
                f'got {points}'
            )

    @classmethod
    def from_params(
        cls,
        params: VehicleParams | EstimationVehicleParams,
        *,
        efficiency: float | None = None,
        driven_axle: str | None = None,
    ) -> Drivetrain:
        """The drivetrain of the vehicle file (``gearbox.ratios``, ``gearbox.final_drive``
        and ``engine.inertia``; from an estimation file also ``gearbox.efficiency`` per gear,
        ``gearbox.reverse_ratio``, ``driveline.layout`` / ``front_share`` and the
        ``torque_converter``).

        Where the file says nothing (the simulator's file: a lossless front-wheel drive with
        an open differential and a clutch) the defaults are eta 1, the front axle, the
        first gear's ratio in reverse; the arguments override the file.

        Args:
            params: the parsed vehicle file (the estimators' or the simulator's).
            efficiency: eta in (0, 1] for every gear; None: the file's (else 1).
            driven_axle: one of :data:`DRIVEN_AXLES`; None: the file's layout (else front).

        Raises:
            ConfigurationError: the file has no gearbox (one line naming it).
        """
        converter = None
        gear_efficiency: tuple[float, ...] = ()
        axle, share = 'front', 0.5
        if isinstance(params, EstimationVehicleParams):
            try:
                line = params.require_driveline()
            except ParameterError as exc:
                raise ConfigurationError(str(exc)) from exc
            ratios, final, inertia = line.ratios, line.final_drive, line.engine_inertia
            reverse = line.reverse_ratio or ratios[0]
            gear_efficiency = line.efficiency
            axle = {'FWD': 'front', 'RWD': 'rear', 'AWD': 'all'}[line.layout]
            share = line.front_share if line.layout == 'AWD' else 0.5
            converter = line.converter
        else:
            ratios = tuple(params.gearbox.ratios)
            final, inertia = params.gearbox.final_drive, params.engine.inertia
            reverse = ratios[0]
        if efficiency is not None:
            gear_efficiency = ()
        return cls(
            ratios=tuple(ratios),
            final_drive=final,
            reverse_ratio=reverse,
            efficiency=1.0 if efficiency is None else efficiency,
            driven_axle=driven_axle or axle,
            engine_inertia=inertia,
            gear_efficiency=gear_efficiency,
            front_share=share,
            converter=converter,
        )

    @property
    def driven(self) -> FloatArray:
        """shape (4,), [-]: 1 on the driven wheels (FL, FR, RL, RR), else 0."""
        front = 1.0 if self.driven_axle in ('front', 'all') else 0.0
        rear = 1.0 if self.driven_axle in ('rear', 'all') else 0.0
        return np.array([front, front, rear, rear])

    def overall_ratio(self, gear: int) -> float:
        """i = gear ratio * final drive [-], signed (negative in reverse, 0 in neutral);
        nan for a gear the box does not have."""
        if gear == 0:
            return 0.0
        if gear == -1:
            return -self.reverse_ratio * self.final_drive
        if 1 <= gear <= len(self.ratios):
            return self.ratios[gear - 1] * self.final_drive
        return math.nan

    @property
    def shares(self) -> FloatArray:
        """shape (4,), [-]: each wheel's share of the drive torque (sums to 1): half an
        axle's on a driven axle; with all four driven, ``front_share`` on the front."""
        if self.driven_axle == 'front':
            return np.array([0.5, 0.5, 0.0, 0.0])
        if self.driven_axle == 'rear':
            return np.array([0.0, 0.0, 0.5, 0.5])
        f = self.front_share
        return np.array([0.5 * f, 0.5 * f, 0.5 * (1.0 - f), 0.5 * (1.0 - f)])

    def params(self) -> NDArray[Any]:
        """The settings of `engine_torques`: a `DRIVETRAIN_PARAMS` record in the 1-element
        array it lives in."""
        record: NDArray[Any] = new_records(DRIVETRAIN_PARAMS, 1)
        p = record[0]
        n = len(self.ratios)
        p['gears'] = n
        for name in ('final_drive', 'reverse_ratio', 'efficiency', 'engine_inertia',
                     'max_clutch_slip', 'clutch_settle_time'):  # fmt: skip
            p[name] = getattr(self, name)
        p['driven'] = self.driven
        p['ratios'][:n] = self.ratios
        p['gear_efficiency'][:n] = self.gear_efficiency or (self.efficiency,) * n
        p['shares'] = self.shares
        c = self.converter
        if c is not None:
            m = len(c.speed_ratio)
            p['converter'] = True
            p['converter_points'] = m
            p['speed_ratio'][:m] = c.speed_ratio
            p['torque_ratio'][:m] = c.torque_ratio
            p['capacity_factor'][:m] = c.capacity_factor
        return record


@jit
def _table(xs: FloatArray, ys: FloatArray, m: int, x: float) -> float:
    """Linear interpolation in the table ``xs[:m]`` -> ``ys[:m]``, held at both ends."""
    if x <= xs[0]:
        return float(ys[0])
    for k in range(1, m):
        if x <= xs[k]:
            w = (x - xs[k - 1]) / (xs[k] - xs[k - 1])
            return float(ys[k - 1] + w * (ys[k] - ys[k - 1]))
    return float(ys[m - 1])


@jit
def converter_speed_ratio(p: np.record, pump_torque: float, turbine_speed: float) -> float:
    """The speed ratio turbine/pump at which the converter of ``p`` (`DRIVETRAIN_PARAMS`)
    absorbs ``pump_torque`` [N m] with the turbine at ``turbine_speed`` [rad/s]: the root of
    ``turbine_rpm / SR = K(SR) * sqrt(pump_torque)`` by bisection; 1 where even SR -> 1
    needs less torque (coupling, overrun) or the torque is not positive."""
    m = p.converter_points
    if not (pump_torque > 0.0 and turbine_speed > 0.0):
        return 1.0
    rpm = turbine_speed * 30.0 / math.pi
    root = math.sqrt(pump_torque)
    hi = p.speed_ratio[m - 1]  # the table's last speed ratio: from there on, coupling
    if rpm / hi - _table(p.speed_ratio, p.capacity_factor, m, hi) * root >= 0.0:
        return 1.0
    lo = 1e-3
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        if rpm / mid - _table(p.speed_ratio, p.capacity_factor, m, mid) * root > 0.0:
            lo = mid
        else:
            hi = mid
    return float(0.5 * (lo + hi))


@jit
def engine_torques(
    p: np.record,
    engine_torque: float,
    gear_value: float,
    engine_speed: float,
    turbine_speed: float,
    omega: FloatArray,
    omega_dot: FloatArray,
    out: FloatArray,
) -> bool:
    """Wheel torques from the engine torque into ``out`` (4,) [N m]; returns whether the
    path holds (the compiled step of `engine_wheel_torques` and `clutch_engaged`).

    With a clutch (no converter in ``p``) the path holds where the engine turns at i
    times the driven wheels (the clutch is closed). With a torque converter the pump
    torque ``T_e - J_e * omega_dot_e`` is multiplied by the converter's torque ratio at
    the speed ratio turbine/engine: the turbine speed logged, else i times the driven
    wheels; the engine speed logged, else the one at which the converter absorbs the
    torque (its capacity factor K). The path then holds where the logged turbine speed is
    i times the driven wheels (the gear is engaged, not shifting).

    Args:
        p: `DRIVETRAIN_PARAMS` record (`Drivetrain.params`).
        engine_torque: net engine torque [N m].
        gear_value: the gear as a float (`gear_number` rules: no gear gives nan torques).
        engine_speed: [rad/s], nan if not measured (then only the gear is checked).
        turbine_speed: [rad/s] the converter's turbine (gearbox input), nan if not logged.
        omega: shape (4,), [rad/s] wheel speeds.
        omega_dot: shape (4,), [rad/s^2] wheel accelerations (the engine-inertia term).
        out: shape (4,), written.
    """
    n_gears = p.gears
    ratio = math.nan
    eta = p.efficiency
    if math.isfinite(gear_value) and gear_value == round(gear_value) and abs(gear_value) < 2.0**31:
        gear = int(gear_value)
        if gear == 0:
            ratio = 0.0
        elif gear == -1:
            ratio = -p.reverse_ratio * p.final_drive
            eta = p.gear_efficiency[0]
        elif 1 <= gear <= n_gears:
            ratio = p.ratios[gear - 1] * p.final_drive
            eta = p.gear_efficiency[gear - 1]
    if not math.isfinite(ratio):
        out[:] = math.nan
        return False
    if ratio == 0.0:
        out[:] = 0.0  # neutral: nothing reaches the wheels, whatever the engine does
        return True
    driven = p.driven
    n_driven = driven[0] + driven[1] + driven[2] + driven[3]
    carrier_accel = 0.0
    carrier_speed = 0.0
    for i in range(4):
        carrier_accel += driven[i] * omega_dot[i]
        carrier_speed += driven[i] * omega[i]
    carrier_accel /= n_driven
    carrier_speed /= n_driven
    gearbox_in = ratio * carrier_speed  # the turbine's (clutch's) speed the wheels give
    torque_ratio = 1.0
    speed_ratio = 1.0
    if p.converter:
        turbine = turbine_speed if math.isfinite(turbine_speed) else gearbox_in
        if math.isfinite(engine_speed) and engine_speed > 0.0:
            speed_ratio = turbine / engine_speed
        elif math.isfinite(engine_torque):
            speed_ratio = converter_speed_ratio(p, engine_torque, abs(turbine))
        m = p.converter_points
        if speed_ratio < p.speed_ratio[m - 1]:  # overrun and coupling: 1
            torque_ratio = _table(p.speed_ratio, p.torque_ratio, m, speed_ratio)
    if math.isfinite(engine_torque):
        # the engine's own acceleration: i * the driven wheels' over the speed ratio (a
        # steady converter slip; exact with the clutch or a locked converter)
        spin = ratio * carrier_accel / max(speed_ratio, 0.5)
        pump = engine_torque - p.engine_inertia * spin
        total = ratio * torque_ratio * pump
        # The engine turns forward in every gear: a positive pump torque sends power to
        # the wheels (losses take eta of it), a negative one (engine braking) draws it.
        total = total * eta if pump >= 0.0 else total / eta
        for i in range(4):
            out[i] = total * p.shares[i]
    else:
        out[:] = math.nan
    if p.converter:
        if not math.isfinite(turbine_speed):
            return True
        return bool(abs(turbine_speed - gearbox_in) <= p.max_clutch_slip)
    if not math.isfinite(engine_speed):
        return True
    return bool(abs(engine_speed - gearbox_in) <= p.max_clutch_slip)


def engine_wheel_torques(
    engine_torque: float,
    gear: int,
    drivetrain: Drivetrain,
    wheel_omega_dot: ArrayLike | None = None,
) -> FloatArray:
    """Drive torque per wheel from the engine torque and the engaged gear (`engine_torques`).

    Args:
        engine_torque: net engine torque at the crankshaft [N m] (combustion minus drag, as
            vd_msgs/WheelTorques.engine_torque carries it).
        gear: engaged gear: 0 neutral (or clutch open), 1..n forward, -1 reverse.
        drivetrain: the vehicle's driveline.
        wheel_omega_dot: shape (4,), [rad/s^2] wheel accelerations (the observer's), for the
            engine-inertia term; None leaves it out.

    Returns:
        shape (4,), [N m], order FL, FR, RL, RR, positive driving forward; 0 on undriven
        wheels and in neutral. All nan for a non-finite engine torque in gear, or a gear the
        box does not have: the estimator then counts a non-finite input and clears the validity
        flags, as for any unusable sample.

    Raises:
        InputShapeError: wheel_omega_dot is not of shape (4,).
    """
    accel = np.zeros(4)
    if wheel_omega_dot is not None:
        accel = np.ascontiguousarray(wheel_omega_dot, dtype=np.float64)
        if accel.shape != (4,):
            raise InputShapeError(f'wheel_omega_dot must have shape (4,), got {accel.shape}')
    out = np.empty(4)
    engine_torques(
        drivetrain.params()[0], float(engine_torque), float(gear), math.nan, math.nan,
        np.zeros(4), accel, out,
    )  # fmt: skip
    return out


def clutch_engaged(
    engine_speed: float, gear: int, wheel_omega: ArrayLike, drivetrain: Drivetrain
) -> bool:
    """Whether the engine path holds at this sample: the clutch is closed (not slipping).

    Args:
        engine_speed: [rad/s] crankshaft speed; nan when not measured (then only the gear
            is checked).
        gear: engaged gear (0 neutral, -1 reverse).
        wheel_omega: shape (4,), [rad/s] wheel speeds (the observer's).
        drivetrain: the vehicle's driveline.

    Returns:
        False for a gear the box does not have, and where the engine speed differs from
        i * mean(omega of the driven wheels) by more than ``max_clutch_slip`` (a launch,
        the engagement after a shift); True in neutral (0 drive torque is then right).

    Raises:
        InputShapeError: wheel_omega is not of shape (4,).
    """
    omega = np.ascontiguousarray(wheel_omega, dtype=np.float64)
    if omega.shape != (4,):
        raise InputShapeError(f'wheel_omega must have shape (4,), got {omega.shape}')
    engaged = engine_torques(
        drivetrain.params()[0], 0.0, float(gear), float(engine_speed), math.nan, omega,
        np.zeros(4), np.empty(4),
    )  # fmt: skip
    return bool(engaged)
