"""Input mapping: which topics of a user's data feed vd, with which types, fields and units.

One mapping describes one car's data. It names, for each input of the cascade, the topic, its
ROS type, where the four wheels are in the message (joint names or array indices), the unit
and the sign of each wheel, and how samples of different topics are put together. Without a
mapping, vd reads its own topics (:func:`default_mapping`: ``/vd/sensors/*`` with vd_msgs
types).

The wheels come from ``wheel_angles`` or from ``wheel_speeds`` (ABS sensors; the observer then
runs the first-order differentiator on them), never both.

YAML form (every key of an input but ``topic`` and ``type`` is optional where the type does
not need it)::

    wheel_angles:
      topic: /joint_states
      type: sensor_msgs/msg/JointState
      joints: [wheel_fl_joint, wheel_fr_joint, wheel_rl_joint, wheel_rr_joint]
      unit: rad               # rad | deg | rev
      sign: [1, -1, 1, -1]    # per wheel: +1 where the joint turns forward when rolling
    body_speed:
      topic: /odom
      type: nav_msgs/msg/Odometry
      unit: m/s               # m/s | km/h
    wheel_torques:
      topic: /wheel_torques
      type: std_msgs/msg/Float64MultiArray
      indices: [0, 1, 2, 3]   # element of each wheel, order FL, FR, RL, RR
      unit: N m               # N m | kN m
    alignment: latest         # latest (default) | exact

``alignment``: ``latest`` (the default, for vd's own topics too) runs the cascade on the
wheel sensor's stamps with the newest body speed and torque sample not later than each
(sample and hold, as a live system sees them; a wheel stamp is dropped while an input is
missing or older than ``max_age`` [s], default 0.5); ``exact`` runs it only on the stamps
that every input has, and holds a headerless input (Float64MultiArray, stamped on receipt)
at its latest value: it is the default where an input is headerless. On a lossless stream
of vd's own sensors, stamped together, the two give the same estimates; when messages are
lost, ``exact`` loses every stamp that misses
any input (30 % random loss per topic: half the wheel stamps estimated, slope RMS 1.47x the
lossless one), ``latest`` estimates them all (1.03x; scripts/eval_loss.py).

``torque_source`` (``vd replay``, ``vd report`` and ``pipeline_node``; the other live nodes
read measured torques; a mapping file's key, not a node parameter): where the wheel
torques are not measured, ``engine`` derives them from the engine torque and the gear (the
``engine_torque`` input; the drivetrain of the vehicle file,
:mod:`vd_observer_node.estimation.drivetrain`) and ``none`` runs without torque (Fx, mu and
slope invalid); ``wheel_torques`` is then not read::

    torque_source: engine
    engine_torque:
      topic: /can/engine
      type: std_msgs/msg/Float64MultiArray
      indices: [0, 1, 2]      # engine torque, gear, engine speed (optional 3rd)
      unit: N m               # of the torque: N m | kN m
      speed_unit: rpm         # of the engine speed: rad/s | rpm

``imu`` (optional): the longitudinal specific force of an accelerometer fixed to the body, fused
with the force balance's slope (`estimation.imu_grade`, docs/estimation.md). From
``sensor_msgs/msg/Imu`` (``linear_acceleration``), ``geometry_msgs/msg/AccelStamped``
(``accel.linear``) or ``std_msgs/msg/Float64MultiArray`` (``indices``: the x, y, z elements,
or one element that is already the body's forward specific force). ``mount_rpy_deg`` is the
sensor frame's fixed orientation in the body frame (REP 103: x forward, y left, z up; roll,
pitch, yaw in degrees, applied as tf does, yaw then pitch then roll; positive pitch is nose
down); the body's forward specific force is the first row of that rotation times the
sensor's vector. Without it, a sensor with three axes has its mounting learnt online
(`mount_learner`) and is fused from then on::

    imu:
      topic: /imu
      type: sensor_msgs/msg/Imu
      mount_rpy_deg: [0, -2.5, 0]   # the sensor looks 2.5 deg nose up
      unit: m/s^2                   # m/s^2 | g

``engine_torque`` from ``vd_msgs/msg/WheelTorques`` reads its ``engine_torque``, ``gear`` and
``engine_speed`` (the default: vd's own ``/vd/sensors/wheel_torques``). A fourth element of
``indices`` is an automatic gearbox's turbine speed (``speed_unit`` too); ``gear_offset``
(an integer, default 0) is added to the logged gear where the bus counts its gears otherwise
than the vehicle file's ``gearbox.ratios`` (the RAV4's SFTOUT: 2 in third gear).

``brake`` (optional; on the measured and engine paths): the brakes as a pressure or a switch
(:mod:`vd_observer_node.estimation.brakes`)::

    brake:
      topic: /can/brake
      type: std_msgs/msg/Float64MultiArray
      signal: pressure        # pressure | switch
      indices: [0, 1]         # pressure: 1 (one for all wheels), 2 (front, rear) or 4
      unit: bar               # bar | kPa | MPa | Pa | psi | '-' (uncalibrated); per unit of
                              # this the vehicle file's brakes.gain_front / gain_rear [N m]

With ``signal: switch`` (one index; 0 is off, anything else on) the brake torque is unknown
while braking: Fx, mu and slope are flagged invalid there.

``reference`` (optional; ``vd calibrate`` only, the cascade does not read it): a speed that
does not slip (``speed``, typed as ``body_speed``) and the road grade (``grade``:
``vd_msgs/msg/Slope``, one element of a Float64MultiArray with ``unit`` rad or deg, or a
``sensor_msgs/msg/NavSatFix`` whose altitude is differenced over 40 m of the speed's
distance), where the bag has no ``/vd/truth/body_velocity`` and ``/vd/truth/slope``
(docs/calibrate.md)::

    reference:
      speed: {topic: /pose/odom, type: nav_msgs/msg/Odometry}
      grade: {topic: /vd/truth/slope, type: vd_msgs/msg/Slope}


Supported types per input (:data:`SUPPORTED_TYPES`): wheel angles from
``vd_msgs/msg/WheelAngles``, ``sensor_msgs/msg/JointState`` (position) or
``std_msgs/msg/Float64MultiArray``; wheel speeds from ``sensor_msgs/msg/JointState``
(velocity) or ``std_msgs/msg/Float64MultiArray``, in rad/s, rpm, deg/s, or as the wheel's
circumferential speed in m/s or km/h (divided by the vehicle's effective rolling radius);
body speed from ``geometry_msgs/msg/TwistStamped``
(``twist.linear.x``), ``nav_msgs/msg/Odometry`` (``twist.twist.linear.x``) or
``std_msgs/msg/Float64MultiArray``; wheel torques from ``vd_msgs/msg/WheelTorques``,
``sensor_msgs/msg/JointState`` (effort) or ``std_msgs/msg/Float64MultiArray``.
Float64MultiArray has no header: its samples are stamped with their log time.
Units (``unit``, ``speed_unit``) are read regardless of case: ``RPM`` is ``rpm``.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any, Final

import yaml
from vd_common.topics import (
    SENSORS,
    SENSORS_BODY_VELOCITY,
    SENSORS_WHEEL_ANGLES,
    SENSORS_WHEEL_TORQUES,
    TRUTH,
    TRUTH_SLOPE,
)

from vd_observer_node.estimation.alignment import ALIGNMENTS
from vd_observer_node.estimation.drivetrain import TORQUE_SOURCES
from vd_observer_node.estimation.imu_settings import VEHICLE_FIELDS, ImuGradeConfig
from vd_observer_node.inputs.errors import MappingError
from vd_observer_node.inputs.rotation import forward_axis, lateral_axis

__all__ = [
    'ALIGNMENTS',
    'BRAKE_INPUT',
    'BRAKE_SIGNALS',
    'ENGINE_INPUT',
    'FUSION_KEY',
    'HELD_KEYS',
    'IMU_INPUT',
    'IMU_KEYS',
    'INPUTS',
    'INPUT_KEYS',
    'PER_RADIUS_UNITS',
    'REFERENCE_KEY',
    'SETTINGS',
    'SPEED_UNITS',
    'SUPPORTED_TYPES',
    'TORQUE_SOURCE_KEY',
    'UNITS',
    'InputMapping',
    'InputSpec',
    'ReferenceMapping',
    'default_mapping',
    'forward_axis',
    'lateral_axis',
    'load_input_mapping',
    'mapping_from_dict',
    'mapping_from_params',
]

#: The cascade's inputs, in the order of a mapping file (wheel angles OR wheel speeds).
INPUTS: Final = ('wheel_angles', 'wheel_speeds', 'body_speed', 'wheel_torques')
#: Top-level keys that are settings of the whole mapping, not inputs.
SETTINGS: Final = ('alignment', 'max_age')
#: Optional input of the engine path: engine torque, gear and (optionally) engine speed.
ENGINE_INPUT: Final = 'engine_torque'
#: Optional input: an accelerometer's longitudinal specific force (the grade fusion).
IMU_INPUT: Final = 'imu'
#: Optional input of the brakes: a pressure (per wheel, per axle or one) or a switch.
BRAKE_INPUT: Final = 'brake'
#: What the brake input is (its ``signal`` key).
BRAKE_SIGNALS: Final = ('pressure', 'switch')
#: Where the wheel torques come from (`drivetrain.TORQUE_SOURCES`): a top-level key of the
#: file (replay, report and pipeline_node; not a node parameter of its own).
TORQUE_SOURCE_KEY: Final = 'torque_source'
#: The calibration's reference (``vd calibrate``; the cascade does not read it): a speed
#: (``reference.speed``, typed as ``body_speed``) and a road grade (``reference.grade``).
REFERENCE_KEY: Final = 'reference'
#: The reference's grade, an input of its own name (types and units below).
GRADE_INPUT: Final = 'grade'

# vd's own sensor types, as the topic contract gives them
WHEEL_ANGLES_TYPE: Final = SENSORS[SENSORS_WHEEL_ANGLES]
WHEEL_TORQUES_TYPE: Final = SENSORS[SENSORS_WHEEL_TORQUES]
JOINT_STATE: Final = 'sensor_msgs/msg/JointState'
FLOAT64_ARRAY: Final = 'std_msgs/msg/Float64MultiArray'
TWIST_STAMPED: Final = SENSORS[SENSORS_BODY_VELOCITY]
ODOMETRY: Final = 'nav_msgs/msg/Odometry'
IMU_TYPE: Final = 'sensor_msgs/msg/Imu'
ACCEL_STAMPED: Final = 'geometry_msgs/msg/AccelStamped'
SLOPE_TYPE: Final = TRUTH[TRUTH_SLOPE]
NAVSATFIX: Final = 'sensor_msgs/msg/NavSatFix'

SUPPORTED_TYPES: Final[dict[str, tuple[str, ...]]] = {
    'wheel_angles': (WHEEL_ANGLES_TYPE, JOINT_STATE, FLOAT64_ARRAY),
    'wheel_speeds': (JOINT_STATE, FLOAT64_ARRAY),
    'body_speed': (TWIST_STAMPED, ODOMETRY, FLOAT64_ARRAY),
    'wheel_torques': (WHEEL_TORQUES_TYPE, JOINT_STATE, FLOAT64_ARRAY),
    ENGINE_INPUT: (WHEEL_TORQUES_TYPE, FLOAT64_ARRAY),
    IMU_INPUT: (IMU_TYPE, ACCEL_STAMPED, FLOAT64_ARRAY),
    BRAKE_INPUT: (FLOAT64_ARRAY,),
    GRADE_INPUT: (SLOPE_TYPE, FLOAT64_ARRAY, NAVSATFIX),
}

#: Factor to the SI unit of each input, by unit name; the first is the SI unit (the default).
UNITS: Final[dict[str, dict[str, float]]] = {
    'wheel_angles': {'rad': 1.0, 'deg': math.pi / 180.0, 'rev': 2.0 * math.pi},
    'wheel_speeds': {
        'rad/s': 1.0,
        'rpm': 2.0 * math.pi / 60.0,
        'deg/s': math.pi / 180.0,
        'm/s': 1.0,
        'km/h': 1.0 / 3.6,
    },
    'body_speed': {'m/s': 1.0, 'km/h': 1.0 / 3.6},
    'wheel_torques': {'N m': 1.0, 'kN m': 1000.0},
    ENGINE_INPUT: {'N m': 1.0, 'kN m': 1000.0},
    IMU_INPUT: {'m/s^2': 1.0, 'g': 9.80665},
    GRADE_INPUT: {'rad': 1.0, 'deg': math.pi / 180.0},
    # to bar; '-' an uncalibrated pressure, taken as it is (the gain is then per its unit)
    BRAKE_INPUT: {
        'bar': 1.0,
        'kPa': 0.01,
        'MPa': 10.0,
        'Pa': 1e-5,
        'psi': 0.0689475729,
        '-': 1.0,
    },
}
#: Units of the engine speed (``speed_unit`` of ``engine_torque``) and their factor to rad/s.
SPEED_UNITS: Final = {'rad/s': 1.0, 'rpm': math.pi / 30.0}
#: Wheel-speed units of the circumferential speed: divided by the effective rolling radius.
PER_RADIUS_UNITS: Final = frozenset({'m/s', 'km/h'})
#: Inputs with one value per wheel (the others are one scalar).
_PER_WHEEL: Final = frozenset({'wheel_angles', 'wheel_speeds', 'wheel_torques'})
#: The settings of one input, in the order of a mapping file.
INPUT_KEYS: Final = ('topic', 'type', 'joints', 'indices', 'unit', 'scale', 'sign')
#: The key of the IMU fusion's settings (``imu.fusion``, `ImuGradeConfig` fields).
FUSION_KEY: Final = 'fusion'
#: The settings of the IMU besides its fusion's (node parameters ``inputs.imu.<key>``).
IMU_KEYS: Final = ('topic', 'type', 'indices', 'unit', 'scale', 'mount_rpy_deg')
#: The optional held inputs (`InputMapping.held_specs`) and their settings, which the nodes
#: declare as parameters ``inputs.<name>.<key>``.
HELD_KEYS: Final = {IMU_INPUT: IMU_KEYS}
# speed_unit and gear_offset: engine_torque only; signal: brake only; mount_rpy_deg and
# fusion: imu only
_KEYS: Final = frozenset(
    (*INPUT_KEYS, 'speed_unit', 'gear_offset', 'signal', 'mount_rpy_deg', 'fusion')
)


@dataclass(frozen=True)
class InputSpec:
    """Where one input of the cascade comes from.

    Attributes:
        name: the input, one of :data:`INPUTS`.
        topic: ROS topic name.
        msgtype: ROS type, 'pkg/msg/Type', one of ``SUPPORTED_TYPES[name]``.
        joints: JointState only: the joint name of FL, FR, RL, RR (per-wheel inputs).
        indices: Float64MultiArray only: the element of FL, FR, RL, RR, or of the scalar.
        factor: multiplies the raw value to give SI units (unit factor times ``scale``).
        sign: shape (4,) per-wheel sign (+1 or -1) for per-wheel inputs, (1,) for a scalar.
        per_radius: wheel speeds given as a circumferential speed: the value times ``factor``
            is in m/s and is divided by the effective rolling radius [m] to give rad/s.
        speed_factor: ``engine_torque`` only: multiplies the engine speed to give rad/s.
        axis: ``imu`` only: shape (3,), the body's forward axis in the sensor's frame (the
            first row of the mounting rotation): f_x = axis . (f_sx, f_sy, f_sz); () for a
            Float64MultiArray with one element (already the forward specific force).
        pitch_axis: ``imu`` only: shape (3,), the body's lateral (y, REP 103) axis in the
            sensor's frame (the second row of the mounting rotation): the body's pitch rate
            (nose down positive) is pitch_axis . (w_sx, w_sy, w_sz) of an Imu's
            ``angular_velocity``; () where the type carries no angular rate.
        mount_stated: ``imu`` only: the mapping states ``mount_rpy_deg`` (else, with three
            axes, it is learnt online: `learns_mounting`).
        gear_offset: ``engine_torque`` only: added to the logged gear.
        signal: ``brake`` only: 'pressure' or 'switch'.
        fusion: ``imu`` only: settings of the IMU fusion for this sensor (field of
            `estimation.imu_settings.ImuGradeConfig`, value), e.g. a vibrating phone-class
            sensor's ``lag_compensation: false``.
    """

    name: str
    topic: str
    msgtype: str
    joints: tuple[str, ...] = ()
    indices: tuple[int, ...] = ()
    factor: float = 1.0
    sign: tuple[float, ...] = (1.0, 1.0, 1.0, 1.0)
    per_radius: bool = False
    speed_factor: float = 1.0
    axis: tuple[float, ...] = ()
    pitch_axis: tuple[float, ...] = ()
    mount_stated: bool = False
    gear_offset: int = 0
    signal: str = ''
    fusion: tuple[tuple[str, float], ...] = ()

    @property
    def three_axes(self) -> bool:
        """``imu``: it gives the three axes of its specific force (an Imu, an AccelStamped, or
        a Float64MultiArray with the indices of x, y and z)."""
        return self.msgtype != FLOAT64_ARRAY or len(self.indices) == 3

    @property
    def learns_mounting(self) -> bool:
        """``imu`` with three axes and no ``mount_rpy_deg``: the mounting is learnt online
        (`mount_learner`)."""
        return self.name == IMU_INPUT and not self.mount_stated and self.three_axes

    @property
    def width(self) -> int:
        """Values per sample: 4 for the per-wheel inputs and the brake (its value of each
        wheel, or the switch), 1 for the body speed, 2 for the IMU (its forward specific
        force and the body's pitch rate, nan where the sensor gives none; 6 where it
        `learns_mounting`: the sensor's specific force and angular rate), 4 for the engine
        (torque, gear, engine speed, turbine speed)."""
        if self.name == ENGINE_INPUT:
            return 4
        if self.name == IMU_INPUT:
            return 6 if self.learns_mounting else 2
        return 4 if self.name in _PER_WHEEL or self.name == BRAKE_INPUT else 1


@dataclass(frozen=True)
class ReferenceMapping:
    """The calibration's reference (``reference`` of a mapping file; ``vd calibrate`` only).

    Attributes:
        speed: the longitudinal speed [m/s after conversion] of a reference that does not
            slip (GNSS, a pose's odometry), typed as ``body_speed``; None: not mapped.
        grade: the road grade [rad after conversion], positive uphill, from a
            ``vd_msgs/msg/Slope`` (its ``valid`` flag honoured) or one element of a
            Float64MultiArray; None: not mapped.
    """

    speed: InputSpec | None = None
    grade: InputSpec | None = None


@dataclass(frozen=True)
class InputMapping:
    """The three inputs of the cascade (see the module docstring for the YAML form).

    Attributes:
        wheels: the wheel sensors, FL, FR, RL, RR: the ``wheel_angles`` input (unwrapped
            angles, [rad] after conversion) or the ``wheel_speeds`` one ([rad/s]).
        body_speed: longitudinal body speed [m/s after conversion].
        wheel_torques: drive minus brake torque per wheel [N m after conversion].
        source: where the mapping was read from ('' for the default).
        alignment: one of :data:`ALIGNMENTS`.
        max_age: with 'latest' alignment, the oldest a held sample may be [s].
        engine_torque: engine torque [N m], gear and engine speed [rad/s], read with
            ``torque_source`` engine only (default: vd's WheelTorques topic).
        torque_source: 'measured' (``wheel_torques``), 'engine' (``engine_torque`` through
            the drivetrain) or 'none' (no torque).
        imu: the accelerometer (forward specific force [m/s^2] after conversion), or None.
        brake: the brake input (None: none).
        reference: the calibration's speed and grade reference (None: none mapped).
    """

    wheels: InputSpec
    body_speed: InputSpec
    wheel_torques: InputSpec
    source: str = ''
    alignment: str = 'latest'
    max_age: float = 0.5
    engine_torque: InputSpec | None = None
    torque_source: str = 'measured'
    imu: InputSpec | None = None
    brake: InputSpec | None = None
    reference: ReferenceMapping | None = None

    @property
    def engine(self) -> InputSpec:
        """The engine input (vd's own WheelTorques topic unless mapped)."""
        return self.engine_torque or _default_engine()

    @property
    def used_specs(self) -> tuple[InputSpec, ...]:
        """The inputs the torque source reads: wheel angles, body speed, and the wheel
        torques (measured), the engine input (engine) or nothing more (none); then the
        brake input where mapped (not with none)."""
        if self.torque_source == 'none':
            return (self.wheels, self.body_speed)
        torque = self.engine if self.torque_source == 'engine' else self.wheel_torques
        brake = (self.brake,) if self.brake is not None else ()
        return (self.wheels, self.body_speed, torque, *brake)

    @property
    def specs(self) -> tuple[InputSpec, InputSpec, InputSpec]:
        """The inputs: wheels, body speed, wheel torques."""
        return (self.wheels, self.body_speed, self.wheel_torques)

    @property
    def wheel_input(self) -> str:
        """What the wheel sensors are, as `ObserverConfig.wheel_input`: 'angle' or 'speed'."""
        return 'speed' if self.wheels.name == 'wheel_speeds' else 'angle'

    @property
    def brake_signal(self) -> str:
        """The brake input's signal ('switch' or 'pressure'), '' without one."""
        return self.brake.signal if self.brake is not None else ''

    @property
    def imu_fusion(self) -> tuple[tuple[str, float], ...] | None:
        """The IMU fusion's settings of this sensor (``imu.fusion``), None without an IMU."""
        return self.imu.fusion if self.imu is not None else None

    @property
    def held_specs(self) -> tuple[InputSpec, ...]:
        """The held inputs mapped (each stamp takes the newest sample not later than it;
        ``spec.name`` is their `estimation.cascade_step.HELD_INPUTS` name): the IMU."""
        return tuple(spec for spec in (self.imu,) if spec is not None)

    @property
    def topics(self) -> tuple[str, ...]:
        """The distinct input topics, in input order (two inputs may share a JointState)."""
        return tuple(dict.fromkeys(s.topic for s in self.specs))

    @property
    def is_default(self) -> bool:
        """True when it reads vd's own sensor topics with vd's types, unchanged."""
        default = default_mapping()
        return (
            self.specs == default.specs
            and self.alignment == default.alignment
            and self.torque_source == 'measured'
            and self.engine_torque is None
            and self.imu is None
            and self.brake is None
        )


def default_mapping() -> InputMapping:
    """vd's own sensor topics (``/vd/sensors/*``) with vd_msgs types, SI units."""
    return InputMapping(
        wheels=InputSpec('wheel_angles', SENSORS_WHEEL_ANGLES, WHEEL_ANGLES_TYPE),
        body_speed=InputSpec('body_speed', SENSORS_BODY_VELOCITY, TWIST_STAMPED, sign=(1.0,)),
        wheel_torques=InputSpec('wheel_torques', SENSORS_WHEEL_TORQUES, WHEEL_TORQUES_TYPE),
    )


def _default_engine() -> InputSpec:
    return InputSpec(ENGINE_INPUT, SENSORS_WHEEL_TORQUES, WHEEL_TORQUES_TYPE, sign=(1.0,))


def _number(where: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise MappingError(f'{where} must be a finite number, got {value!r}')
    return float(value)


def _unit_name(raw: Any, units: Mapping[str, float]) -> Any:
    """The unit ``raw`` as spelt in ``units`` when it matches one regardless of case (``RPM``
    is ``rpm``; no two units of one input differ by case alone); else ``raw`` unchanged."""
    if isinstance(raw, str):
        by_case = {u.casefold(): u for u in units}
        return by_case.get(raw.strip().casefold(), raw)
    return raw


def _spec(name: str, data: Any, where: str) -> InputSpec:
    if not isinstance(data, Mapping):
        raise MappingError(f'{where} must be a mapping with topic and type')
    unknown = sorted(set(data) - _KEYS)
    if unknown:
        raise MappingError(
            f'{where}.{unknown[0]}: unknown key (known: {", ".join(sorted(_KEYS))})'
        )
    for key in ('topic', 'type'):
        if not isinstance(data.get(key), str) or not data[key]:
            raise MappingError(f'{where}.{key} is missing (a string)')
    topic, msgtype = str(data['topic']), str(data['type'])
    if not topic.startswith('/'):
        raise MappingError(f'{where}.topic must be an absolute name (/...), got {topic!r}')
    if msgtype not in SUPPORTED_TYPES[name]:
        allowed = ', '.join(SUPPORTED_TYPES[name])
        raise MappingError(f'{where}.type {msgtype!r} is not supported (use one of {allowed})')
    width = 4 if name in _PER_WHEEL else 1
    speed_factor = 1.0
    gear_offset = 0
    signal = ''
    if name == BRAKE_INPUT:
        signal = data.get('signal', '')
        if signal not in BRAKE_SIGNALS:
            raise MappingError(
                f'{where}.signal {signal!r} is unknown (use one of {", ".join(BRAKE_SIGNALS)})'
            )
        if signal == 'switch' and ('unit' in data or 'scale' in data):
            raise MappingError(f'{where}.unit and scale are for a pressure, not a switch')
    elif 'signal' in data:
        raise MappingError(f'{where}.signal is for {BRAKE_INPUT} only')
    if name == ENGINE_INPUT:
        raw_offset = data.get('gear_offset', 0)
        if isinstance(raw_offset, bool) or not isinstance(raw_offset, int):
            raise MappingError(f'{where}.gear_offset must be an integer, got {raw_offset!r}')
        gear_offset = raw_offset
    elif 'gear_offset' in data:
        raise MappingError(f'{where}.gear_offset is for {ENGINE_INPUT} only')
    if name == ENGINE_INPUT:
        speed_unit = _unit_name(data.get('speed_unit', 'rad/s'), SPEED_UNITS)
        if speed_unit not in SPEED_UNITS:
            raise MappingError(
                f'{where}.speed_unit {speed_unit!r} is unknown (use one of '
                f'{", ".join(SPEED_UNITS)})'
            )
        speed_factor = SPEED_UNITS[speed_unit]
    elif 'speed_unit' in data:
        raise MappingError(f'{where}.speed_unit is for {ENGINE_INPUT} only')
    if 'mount_rpy_deg' in data and name != IMU_INPUT:
        raise MappingError(f'{where}.mount_rpy_deg is for {IMU_INPUT} only')
    if 'fusion' in data and name != IMU_INPUT:
        raise MappingError(f'{where}.fusion is for {IMU_INPUT} only')
    joints: tuple[str, ...] = ()
    indices: tuple[int, ...] = ()
    if msgtype == JOINT_STATE:
        raw = data.get('joints')
        if (
            not isinstance(raw, list)
            or len(raw) != width
            or not all(isinstance(j, str) and j for j in raw)
            or len(set(raw)) != width
        ):
            raise MappingError(f'{where}.joints must list {width} distinct joint names')
        joints = tuple(raw)
    elif 'joints' in data:
        raise MappingError(f'{where}.joints is for sensor_msgs/msg/JointState only')
    if msgtype == FLOAT64_ARRAY:
        # the engine input: torque and gear, and the engine and turbine speeds if logged;
        # the brake: one pressure (or the switch), one per axle, or one per wheel; the IMU:
        # x, y, z, or one element already the forward specific force
        sizes = {
            ENGINE_INPUT: (2, 3, 4),
            BRAKE_INPUT: (1,) if signal == 'switch' else (1, 2, 4),
            IMU_INPUT: (1, 3),
        }
        sizes_here = sizes.get(name, (width,))
        default = {ENGINE_INPUT: 3, BRAKE_INPUT: 1}.get(name, width)
        raw = data.get('indices', list(range(default)))
        if (
            not isinstance(raw, list)
            or len(raw) not in sizes_here
            or not all(isinstance(i, int) and not isinstance(i, bool) and i >= 0 for i in raw)
        ):
            count = ' or '.join(str(k) for k in sizes_here)
            raise MappingError(f'{where}.indices must list {count} element indices >= 0')
        indices = tuple(raw)
    elif 'indices' in data:
        raise MappingError(f'{where}.indices is for std_msgs/msg/Float64MultiArray only')
    unit = _unit_name(data.get('unit', next(iter(UNITS[name]))), UNITS[name])
    if unit not in UNITS[name]:
        raise MappingError(
            f'{where}.unit {unit!r} is unknown (use one of {", ".join(UNITS[name])})'
        )
    scale = _number(f'{where}.scale', data.get('scale', 1.0))
    if scale == 0.0:
        raise MappingError(f'{where}.scale must not be 0')
    raw_sign = data.get('sign', [1] * width)
    if not isinstance(raw_sign, list) or len(raw_sign) != width:
        raise MappingError(f'{where}.sign must list {width} values of +1 or -1')
    sign = tuple(_number(f'{where}.sign', s) for s in raw_sign)
    if any(s not in (1.0, -1.0) for s in sign):
        raise MappingError(f'{where}.sign must list {width} values of +1 or -1')
    axis: tuple[float, ...] = ()
    pitch_axis: tuple[float, ...] = ()
    if name == IMU_INPUT:
        rpy = data.get('mount_rpy_deg', [0.0, 0.0, 0.0])
        if not isinstance(rpy, list) or len(rpy) != 3:
            raise MappingError(f'{where}.mount_rpy_deg must list roll, pitch, yaw [deg]')
        angles = [math.radians(_number(f'{where}.mount_rpy_deg', a)) for a in rpy]
        one_element = msgtype == FLOAT64_ARRAY and len(indices) == 1
        if one_element and any(a != 0.0 for a in angles):
            raise MappingError(
                f'{where}.mount_rpy_deg needs the 3 axes (indices of x, y, z), not one element'
            )
        axis = () if one_element else forward_axis(*angles)
        pitch_axis = lateral_axis(*angles) if msgtype == IMU_TYPE else ()
    fusion = _fusion(where, data.get('fusion', {}))
    return InputSpec(
        name=name,
        topic=topic,
        msgtype=msgtype,
        joints=joints,
        indices=indices,
        factor=UNITS[name][unit] * scale,
        sign=sign,
        per_radius=name == 'wheel_speeds' and unit in PER_RADIUS_UNITS,
        speed_factor=speed_factor,
        axis=axis,
        pitch_axis=pitch_axis,
        mount_stated='mount_rpy_deg' in data,
        gear_offset=gear_offset,
        signal=signal,
        fusion=fusion,
    )


def _fusion(where: str, raw: Any) -> tuple[tuple[str, float], ...]:
    """The ``imu.fusion`` settings: a mapping of `ImuGradeConfig` fields to numbers or
    booleans (checked by the config when it is made)."""
    if not isinstance(raw, dict):
        raise MappingError(f'{where}.fusion must map settings to values')
    known = {f.name for f in fields(ImuGradeConfig)} - set(VEHICLE_FIELDS)
    items = []
    for key, value in raw.items():
        if key not in known:
            raise MappingError(f'{where}.fusion.{key} is not a setting: {sorted(known)}')
        if isinstance(value, bool):
            items.append((str(key), float(value)))
        else:
            items.append((str(key), _number(f'{where}.fusion.{key}', value)))
    return tuple(items)


def mapping_from_dict(data: Any, source: str = 'mapping') -> InputMapping:
    """Build a mapping from its YAML content; absent inputs keep vd's own topics.

    Args:
        data: a mapping of input name (:data:`INPUTS`) to its settings.
        source: named in every error (the file).

    Raises:
        MappingError: one line naming the key and what is allowed.
    """
    if data is None:
        data = {}
    if not isinstance(data, Mapping):
        raise MappingError(f'{source}: expected a mapping of {", ".join(INPUTS)}')
    keys = (
        *INPUTS,
        *SETTINGS,
        ENGINE_INPUT,
        BRAKE_INPUT,
        IMU_INPUT,
        TORQUE_SOURCE_KEY,
        REFERENCE_KEY,
    )
    unknown = sorted(set(data) - set(keys))
    if unknown:
        raise MappingError(f'{source}: {unknown[0]}: unknown input (use {", ".join(keys)})')
    torque_source = data.get(TORQUE_SOURCE_KEY, 'measured')
    if torque_source not in TORQUE_SOURCES:
        raise MappingError(
            f'{source}: {TORQUE_SOURCE_KEY} {torque_source!r} is unknown (use one of '
            f'{", ".join(TORQUE_SOURCES)})'
        )
    if 'wheel_angles' in data and 'wheel_speeds' in data:
        raise MappingError(f'{source}: wheel_speeds: give wheel_angles or wheel_speeds, not both')
    default = default_mapping()
    wheel_name = 'wheel_speeds' if 'wheel_speeds' in data else 'wheel_angles'
    specs = [
        _spec(name, data[name], f'{source}: {name}') if name in data else spec
        for name, spec in zip(
            (wheel_name, 'body_speed', 'wheel_torques'), default.specs, strict=True
        )
    ]
    types: dict[str, str] = {}

    def one_type(spec: InputSpec) -> None:
        if types.setdefault(spec.topic, spec.msgtype) != spec.msgtype:
            raise MappingError(
                f'{source}: {spec.name}.type: {spec.topic} is also mapped as '
                f'{types[spec.topic]} (one topic has one type)'
            )

    def optional(name: str) -> InputSpec | None:
        if name not in data:
            return None
        spec = _spec(name, data[name], f'{source}: {name}')
        one_type(spec)
        return spec

    for spec in specs:
        one_type(spec)
    engine = optional(ENGINE_INPUT)
    imu = optional(IMU_INPUT)
    brake = optional(BRAKE_INPUT)
    # 'latest' rides through lost messages; a headerless input (stamped on receipt) can only be
    # held at its latest value, which 'exact' does (the inputs the torque source reads, the
    # brake included)
    read = [*specs[:2]]
    if torque_source == 'measured':
        read.append(specs[2])
    elif torque_source == 'engine' and engine is not None:
        read.append(engine)
    if brake is not None and torque_source != 'none':
        read.append(brake)
    headerless = any(spec.msgtype == FLOAT64_ARRAY for spec in read)
    alignment = data.get('alignment', 'exact' if headerless else default.alignment)
    if alignment not in ALIGNMENTS:
        raise MappingError(
            f'{source}: alignment {alignment!r} is unknown (use one of {", ".join(ALIGNMENTS)})'
        )
    max_age = _number(f'{source}: max_age', data.get('max_age', default.max_age))
    if max_age <= 0.0:
        raise MappingError(f'{source}: max_age must be > 0 s, got {max_age}')
    wheels, body_speed, wheel_torques = specs
    return InputMapping(
        wheels,
        body_speed,
        wheel_torques,
        source=source,
        alignment=alignment,
        max_age=max_age,
        engine_torque=engine,
        torque_source=torque_source,
        imu=imu,
        brake=brake,
        reference=_reference(data.get(REFERENCE_KEY), f'{source}: {REFERENCE_KEY}'),
    )


def _reference(data: Any, where: str) -> ReferenceMapping | None:
    """The ``reference`` section: ``speed`` (as ``body_speed``) and ``grade``."""
    if data is None:
        return None
    if not isinstance(data, Mapping):
        raise MappingError(f'{where} must be a mapping with speed and/or grade')
    unknown = sorted(set(data) - {'speed', GRADE_INPUT})
    if unknown:
        raise MappingError(f'{where}.{unknown[0]}: unknown key (use speed, {GRADE_INPUT})')
    speed = _spec('body_speed', data['speed'], f'{where}.speed') if 'speed' in data else None
    grade = (
        _spec(GRADE_INPUT, data[GRADE_INPUT], f'{where}.{GRADE_INPUT}')
        if GRADE_INPUT in data
        else None
    )
    return ReferenceMapping(speed=speed, grade=grade)


def mapping_from_params(
    values: Mapping[str, Any], prefix: str = 'inputs.', source: str = 'parameters'
) -> InputMapping:
    """Build a mapping from flat node parameters ``<prefix><input>.<key>`` (the params form).

    The parameters are regrouped into the file's form and read by :func:`mapping_from_dict`,
    so a ROS params file and a mapping file are checked by one parser. An input none of
    whose parameters is set keeps vd's own topic.

    Args:
        values: parameter name -> value, None where a parameter is not set; names without
            `prefix` are ignored. ROS gives arrays as lists or ``array.array``.
        prefix: the parameters' common prefix.
        source: named in every error.

    Raises:
        MappingError: one line naming the input and key.
    """
    data: dict[str, dict[str, Any]] = {}
    source = f'{source} {prefix}*'
    for name, value in values.items():
        if value is None or not name.startswith(prefix):
            continue
        parts = name[len(prefix) :].split('.')
        if not isinstance(value, str | bytes | int | float | bool):
            value = list(value)  # ROS arrays (array.array, tuples) in the YAML form
        if len(parts) == 1 and parts[0] in SETTINGS:
            data[parts[0]] = value
            continue
        if len(parts) == 3 and parts[:2] == [IMU_INPUT, FUSION_KEY]:
            # inputs.imu.fusion.<setting>: the file's ``imu: {fusion: {...}}``
            data.setdefault(IMU_INPUT, {}).setdefault(FUSION_KEY, {})[parts[2]] = value
            continue
        if len(parts) != 2:
            raise MappingError(f'{source}: {name}: expected {prefix}<input>.<key>')
        data.setdefault(parts[0], {})[parts[1]] = value
    return mapping_from_dict(data, source=source)


def load_input_mapping(path: str | os.PathLike[str]) -> InputMapping:
    """Read a mapping file (YAML, see the module docstring).

    Raises:
        MappingError: unreadable file, malformed YAML or a refused key (one line).
    """
    try:
        text = Path(path).read_text(encoding='utf-8')
    except (OSError, UnicodeDecodeError) as exc:
        raise MappingError(f'cannot read input mapping {path}: {exc}') from exc
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        detail = ' '.join(str(exc).split())
        raise MappingError(f'input mapping {path} is not valid YAML: {detail}') from exc
    return mapping_from_dict(data, source=f'input mapping {path}')
