"""Decode one mapped input topic to stamped SI arrays.

vd's own fixed-layout types (WheelAngles, WheelTorques, TwistStamped) are batch-decoded with
numpy (:func:`vd_observer_node.bag.cdr_batch.decode_batch`); the standard types with
variable-length fields (JointState, Odometry, Float64MultiArray) are deserialized message by
message with rosbags (about 10 µs of CPU each for JointState and Odometry, 4 µs for
Float64MultiArray: 1.5 s per 150 s of a 1 kHz JointState topic).

:class:`InputDecoder` is the live nodes' per-message form of the same decoding: the raw CDR
bytes of one subscription -> stamp, frame_id and SI values, with the same per-message
extractors (JointState, Odometry, Float64MultiArray) and the same factor and signs as a
replay, so a mapping means one thing offline and live.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vd_observer_node.bag.cdr_batch import decode_batch
from vd_observer_node.bag.cdr_message import MessageCodec
from vd_observer_node.bag.reader import TopicArrays
from vd_observer_node.bag.typestore import deserialize
from vd_observer_node.inputs.errors import MappingError
from vd_observer_node.inputs.health import StreamHealth
from vd_observer_node.inputs.mapping import (
    ACCEL_STAMPED,
    BRAKE_INPUT,
    ENGINE_INPUT,
    FLOAT64_ARRAY,
    IMU_INPUT,
    IMU_TYPE,
    JOINT_STATE,
    ODOMETRY,
    TWIST_STAMPED,
    WHEEL_ANGLES_TYPE,
    WHEEL_TORQUES_TYPE,
    InputSpec,
)

__all__ = [
    'InputDecoder',
    'InputSeries',
    'InputStats',
    'brake_row',
    'decode_brake',
    'decode_engine',
    'decode_imu_vectors',
    'decode_input',
    'has_header',
    'input_stats',
]

_NS = 1_000_000_000
#: the field of vd's batch-decodable types that holds the input
_BATCH_FIELD = {
    WHEEL_ANGLES_TYPE: 'angle',
    WHEEL_TORQUES_TYPE: 'torque',
    TWIST_STAMPED: 'twist.linear.x',
}
#: the WheelTorques fields of the engine input, in its order (torque, gear, engine speed)
_ENGINE_FIELDS = ('engine_torque', 'gear', 'engine_speed')
#: the JointState array of each per-wheel input
_JOINT_FIELD = {'wheel_angles': 'position', 'wheel_speeds': 'velocity', 'wheel_torques': 'effort'}


@dataclass(frozen=True)
class InputSeries:
    """One input over a recording, in SI units with the mapping's signs applied.

    Attributes:
        stamp_ns: shape (N,), int64 [ns]: header stamps (log times for Float64MultiArray).
        values: shape (N, W), float64: W = 4 (FL, FR, RL, RR) or 1 (body speed).
        frame_ids: shape (N,), bytes: header.frame_id of each message (b'' without header).
    """

    stamp_ns: NDArray[np.int64]
    values: NDArray[np.float64]
    frame_ids: NDArray[np.bytes_]


def _stamp(header: Any) -> int:
    return int(header.stamp.sec) * _NS + int(header.stamp.nanosec)


def _per_message(
    spec: InputSpec,
    arrays: TopicArrays,
    extract: Callable[[Any, int], tuple[int, Sequence[float], bytes]],
) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.bytes_]]:
    """Deserialize each message and ``extract`` its row (``spec.width`` values)."""
    n = len(arrays.datas)
    stamps = np.empty(n, dtype=np.int64)
    values = np.empty((n, spec.width), dtype=np.float64)
    frames: list[bytes] = []
    for k, data in enumerate(arrays.datas):
        msg = deserialize(data, spec.msgtype)
        stamp, row, frame = extract(msg, int(arrays.log_time_ns[k]))
        stamps[k] = stamp
        values[k] = row
        frames.append(frame)
    return stamps, values, np.array(frames, dtype=np.bytes_).reshape(n)


def _joint_state(spec: InputSpec) -> Callable[[Any, int], tuple[int, Sequence[float], bytes]]:
    field = _JOINT_FIELD[spec.name]
    where: dict[tuple[str, ...], list[int]] = {}  # joint order of a message -> our indices

    def extract(msg: Any, _log: int) -> tuple[int, Sequence[float], bytes]:
        names = tuple(msg.name)
        index = where.get(names)
        if index is None:
            missing = [j for j in spec.joints if j not in names]
            if missing:
                raise MappingError(
                    f'{spec.name}.joints: {missing[0]!r} is not among the joints of '
                    f'{spec.topic} ({", ".join(names) or "none"})'
                )
            index = where[names] = [names.index(j) for j in spec.joints]
        column = getattr(msg, field)
        if len(column) != len(names):
            raise MappingError(
                f'{spec.name}: the JointState messages on {spec.topic} carry no {field} '
                f'for their joints ({len(column)} values for {len(names)} joints)'
            )
        return _stamp(msg.header), [float(column[i]) for i in index], msg.header.frame_id.encode()

    return extract


def _float64_array(spec: InputSpec) -> Callable[[Any, int], tuple[int, Sequence[float], bytes]]:
    def extract(msg: Any, log: int) -> tuple[int, Sequence[float], bytes]:
        data = msg.data
        if max(spec.indices) >= len(data):
            raise MappingError(
                f'{spec.name}.indices: element {max(spec.indices)} is beyond the '
                f'{len(data)} values of the messages on {spec.topic}'
            )
        return log, [float(data[i]) for i in spec.indices], b''

    return extract


def _odometry(msg: Any, _log: int) -> tuple[int, Sequence[float], bytes]:
    return _stamp(msg.header), [float(msg.twist.twist.linear.x)], msg.header.frame_id.encode()


def _factor(spec: InputSpec, radius: float | None) -> float:
    """The input's factor to SI units, divided by the rolling radius for m/s or km/h speeds.

    Raises:
        MappingError: a wheel speed in m/s or km/h and no radius.
    """
    if not spec.per_radius:
        return spec.factor
    if radius is None or not radius > 0.0:
        raise MappingError(f'{spec.name}: a unit of m/s or km/h needs the rolling radius')
    return spec.factor / radius


def has_header(spec: InputSpec) -> bool:
    """True when the input's messages carry a header stamp (all types but Float64MultiArray)."""
    return spec.msgtype != FLOAT64_ARRAY


def _imu(spec: InputSpec) -> Callable[[Any, int], tuple[int, Sequence[float], bytes]]:
    """The IMU's forward specific force (the mounting's first row times the sensor's vector:
    Imu.linear_acceleration, AccelStamped.accel.linear, or a Float64MultiArray's x, y, z; one
    element of an array is already the forward specific force) and the body's pitch rate
    [rad/s] (the mounting's second row times Imu.angular_velocity; nan for the other types
    and for an Imu that marks its angular velocity unknown, REP 145's covariance -1)."""
    ax, ay, az = spec.axis if spec.axis else (1.0, 0.0, 0.0)
    rx, ry, rz = spec.pitch_axis if spec.pitch_axis else (0.0, 1.0, 0.0)

    def imu(msg: Any, _log: int) -> tuple[int, Sequence[float], bytes]:
        a, w = msg.linear_acceleration, msg.angular_velocity
        rate = math.nan
        if msg.angular_velocity_covariance[0] != -1.0:
            rate = rx * float(w.x) + ry * float(w.y) + rz * float(w.z)
        row = [ax * float(a.x) + ay * float(a.y) + az * float(a.z), rate]
        return _stamp(msg.header), row, msg.header.frame_id.encode()

    def accel(msg: Any, _log: int) -> tuple[int, Sequence[float], bytes]:
        a = msg.accel.linear
        row = [ax * float(a.x) + ay * float(a.y) + az * float(a.z), math.nan]
        return _stamp(msg.header), row, msg.header.frame_id.encode()

    if spec.msgtype == IMU_TYPE:
        return imu
    if spec.msgtype == ACCEL_STAMPED:
        return accel
    array = _float64_array(spec)

    def mounted(msg: Any, log: int) -> tuple[int, Sequence[float], bytes]:
        stamp, values, frame = array(msg, log)
        if not spec.axis:
            return stamp, [values[0], math.nan], frame
        x, y, z = values
        return stamp, [ax * x + ay * y + az * z, math.nan], frame

    return mounted


def _imu_vectors(spec: InputSpec) -> Callable[[Any, int], tuple[int, Sequence[float], bytes]]:
    """The sensor's own specific force (x, y, z) and angular rate (x, y, z), no mounting
    applied (`decode_imu_vectors`); the rate nan where the type has none or the Imu marks it
    unknown."""
    array = _float64_array(spec)
    unknown = [math.nan] * 3

    def extract(msg: Any, log: int) -> tuple[int, Sequence[float], bytes]:
        if spec.msgtype == FLOAT64_ARRAY:
            stamp, xyz, frame = array(msg, log)
            return stamp, [*xyz, *unknown], frame
        a = msg.accel.linear if spec.msgtype == ACCEL_STAMPED else msg.linear_acceleration
        rate = unknown
        if spec.msgtype == IMU_TYPE and msg.angular_velocity_covariance[0] != -1.0:
            w = msg.angular_velocity
            rate = [float(w.x), float(w.y), float(w.z)]
        row = [float(a.x), float(a.y), float(a.z), *rate]
        return _stamp(msg.header), row, msg.header.frame_id.encode()

    return extract


def decode_imu_vectors(spec: InputSpec, arrays: TopicArrays) -> InputSeries:
    """Decode the IMU topic's messages to the sensor's own vectors, no mounting applied.

    Learning the mounting (``vd calibrate``, `inputs.mounting`) needs what the sensor
    itself measured, where `decode_input` gives the body's forward specific force and pitch
    rate through the mapping's mounting.

    Args:
        spec: the mapping's ``imu`` input (its unit, scale and sign are applied to the
            specific force).
        arrays: the topic's raw messages, of type ``spec.msgtype``.

    Returns:
        values of shape (N, 6): the specific force (x, y, z) [m/s^2] and the angular rate
        (x, y, z) [rad/s] in the sensor's frame, the rate nan where the type has none or the
        Imu marks it unknown (REP 145: ``angular_velocity_covariance[0]`` = -1); stamps as
        the replay takes them (header stamps; log times for a Float64MultiArray).

    Raises:
        MappingError: a Float64MultiArray with one element (already the forward specific
            force: it has no axes to learn), or an index beyond the message.
        BagFormatError: a message cannot be decoded.
    """
    if not spec.three_axes:
        raise MappingError(
            f'{spec.name}: one element of {spec.topic} is already the forward specific force; '
            'its mounting needs the 3 axes (indices of x, y, z)'
        )
    # the input as it is decoded where the mapping states no mounting (`learns_mounting`)
    return decode_input(replace(spec, mount_stated=False), arrays)


def _gain(spec: InputSpec, radius: float | None) -> tuple[float, ...] | None:
    """Each value's factor to SI units (unit, scale and sign); None where every one is 1
    (the default mapping's values pass bit for bit, without a multiplication). The IMU's
    unit and scale are its specific force's: its angular rate is in rad/s (REP 103)."""
    factor = _factor(spec, radius)
    if factor == 1.0 and all(s == 1.0 for s in spec.sign):
        return None
    gain = tuple((factor * np.asarray(spec.sign, dtype=np.float64)).tolist())
    if spec.name == IMU_INPUT:  # the mounting is learnt from the vectors (`learns_mounting`)
        return (gain[0],) * 3 + (1.0,) * 3 if spec.learns_mounting else (gain[0], 1.0)
    return gain


def _extractor(spec: InputSpec) -> Callable[[Any, int], tuple[int, Sequence[float], bytes]]:
    """The per-message extractor of a standard type with variable-length fields."""
    if spec.name == IMU_INPUT:
        return _imu_vectors(spec) if spec.learns_mounting else _imu(spec)
    if spec.msgtype == JOINT_STATE:
        return _joint_state(spec)
    if spec.msgtype == FLOAT64_ARRAY:
        return _float64_array(spec)
    if spec.msgtype == ODOMETRY:
        return _odometry
    raise MappingError(f'{spec.name}: no decoder for {spec.msgtype}')


def _engine_gain(spec: InputSpec) -> tuple[float, float, float, float]:
    """The engine input's factors to SI: the torque's unit, scale and sign, 1 for the gear,
    the engine and turbine speeds' unit."""
    return (spec.factor * spec.sign[0], 1.0, spec.speed_factor, spec.speed_factor)


def brake_row(spec: InputSpec, values: Sequence[float]) -> tuple[float, float, float, float]:
    """The brake input's value of each wheel (FL, FR, RL, RR) from its mapped elements: one
    (every wheel; a switch), two (front, rear) or four; a pressure in the mapping's unit,
    scale and sign (to bar, or as it is for '-')."""
    gain = 1.0 if spec.signal == 'switch' else spec.factor * spec.sign[0]
    v = [float(x) * gain for x in values]
    if len(v) == 1:
        return (v[0], v[0], v[0], v[0])
    if len(v) == 2:
        return (v[0], v[0], v[1], v[1])
    return (v[0], v[1], v[2], v[3])


class InputDecoder:
    """One mapped input, one message at a time: raw CDR bytes -> stamp, frame and SI values.

    vd's fixed-layout types are unpacked with ``struct`` (:class:`MessageCodec`, a few µs);
    the standard types are deserialized with rosbags and read by the extractors
    :func:`decode_input` uses for a bag. A Float64MultiArray has no header: it takes the
    ``receive_ns`` the caller gives (the live node's clock at reception). The engine input
    (``engine_torque``) gives what :func:`decode_engine` gives for a bag: engine torque
    [N m], gear, engine speed [rad/s] (nan when not mapped), with the same extractor and
    factors.

    Attributes:
        spec: the input's mapping.
    """

    def __init__(self, spec: InputSpec, radius: float | None = None) -> None:
        """Prepare the decoder of ``spec.msgtype``.

        Args:
            spec: the input's mapping.
            radius: effective rolling radius [m], for wheel speeds in m/s or km/h.

        Raises:
            MappingError: the type has no decoder (the mapping refuses such types first), or
                a wheel speed in m/s or km/h comes without a radius.
        """
        self.spec = spec
        self._codec: MessageCodec | None = None
        self._extract: Callable[[Any, int], tuple[int, Sequence[float], bytes]] | None = None
        self._engine: tuple[int, ...] = ()  # the engine fields' places in the codec's
        if spec.name == BRAKE_INPUT:
            self._extract = _brake_array(spec)
            self._gain: tuple[float, ...] | None = None
            return
        if spec.name == ENGINE_INPUT:
            if spec.msgtype == WHEEL_TORQUES_TYPE:
                self._codec = MessageCodec(spec.msgtype)
                self._engine = tuple(self._codec.fields.index(f) for f in _ENGINE_FIELDS)
            elif spec.msgtype == FLOAT64_ARRAY:
                self._extract = _engine_array(spec)
            else:  # the mapping refuses every other type
                raise MappingError(f'{spec.name}: no decoder for {spec.msgtype}')
            self._gain = _engine_gain(spec)
            return
        if spec.msgtype in _BATCH_FIELD:
            self._codec = MessageCodec(spec.msgtype)
            self._field = self._codec.fields.index(_BATCH_FIELD[spec.msgtype])
        else:
            self._extract = _extractor(spec)
        self._gain = _gain(spec, radius)

    def decode(self, data: bytes, receive_ns: int = 0) -> tuple[int, bytes, tuple[float, ...]]:
        """Stamp [ns], header.frame_id and the ``spec.width`` SI values of one message.

        Args:
            data: the message's CDR bytes (a raw subscription's callback argument).
            receive_ns: [ns] the stamp of a message without header (Float64MultiArray).

        Raises:
            BagFormatError: the bytes are not a message of ``spec.msgtype``.
            MappingError: a mapped joint or element is absent from the message.
        """
        if self._codec is not None:
            stamp, frame, fields = self._codec.decode(data)
            row: tuple[float, ...]
            if self._engine:
                row = (*(float(fields[i]) for i in self._engine), float('nan'))
            else:
                raw = fields[self._field]
                row = tuple(raw) if isinstance(raw, tuple) else (raw,)
        else:
            assert self._extract is not None  # set in __init__ when there is no codec
            msg = deserialize(data, self.spec.msgtype)
            stamp, values, frame = self._extract(msg, receive_ns)
            row = tuple(values)
        if self._gain is not None:
            row = tuple(v * g for v, g in zip(row, self._gain, strict=True))
        if self.spec.gear_offset and math.isfinite(row[1]):
            row = (row[0], row[1] + self.spec.gear_offset, *row[2:])
        return stamp, frame, row


def decode_input(spec: InputSpec, arrays: TopicArrays, radius: float | None = None) -> InputSeries:
    """Decode the messages of ``spec.topic`` to the input's SI values.

    Args:
        spec: the input's mapping.
        arrays: the topic's raw messages (`BagReader.topic_arrays`), of type ``spec.msgtype``.
        radius: effective rolling radius [m], for wheel speeds given in m/s or km/h.

    Returns:
        The series in message order (not sorted; the replay aligns by stamp).

    Raises:
        MappingError: a mapped joint or element is absent from the messages, or a wheel
            speed in m/s or km/h comes without a radius.
        BagFormatError: a message cannot be decoded.
    """
    if spec.msgtype in _BATCH_FIELD:
        fields = decode_batch(spec.msgtype, arrays.datas)
        raw = fields.values[_BATCH_FIELD[spec.msgtype]].reshape(len(arrays.datas), spec.width)
        stamps, values, frames = fields.stamp_ns, raw.astype(np.float64), fields.frame_id
    else:  # _extractor refuses a type without decoder (the mapping refuses it first)
        stamps, values, frames = _per_message(spec, arrays, _extractor(spec))
    gain = _gain(spec, radius)
    if gain is not None:
        values = values * np.asarray(gain)
    return InputSeries(stamps.astype(np.int64), values, frames)


def decode_engine(spec: InputSpec, arrays: TopicArrays) -> InputSeries:
    """Decode the engine input (``engine_torque`` of the mapping) to stamped SI values.

    Args:
        spec: the engine input's mapping.
        arrays: the topic's raw messages, of type ``spec.msgtype``.

    Returns:
        values of shape (N, 4): engine torque [N m] (unit, scale and sign applied), gear
        (as a float, 0 neutral, -1 reverse; the mapping's ``gear_offset`` added), engine
        speed and turbine speed [rad/s] (nan when the mapping has no element for them).

    Raises:
        MappingError: a mapped element is absent from the messages.
        BagFormatError: a message cannot be decoded.
    """
    if spec.name != ENGINE_INPUT:
        raise MappingError(f'{spec.name}: not the {ENGINE_INPUT} input')
    n = len(arrays.datas)
    if spec.msgtype == WHEEL_TORQUES_TYPE:
        fields = decode_batch(spec.msgtype, arrays.datas)
        values = np.stack(
            [
                *(fields.values[f].astype(np.float64) for f in _ENGINE_FIELDS),
                np.full(n, np.nan),
            ],
            axis=1,
        ).reshape(n, 4)
        stamps, frames = fields.stamp_ns, fields.frame_id
    elif spec.msgtype == FLOAT64_ARRAY:
        stamps, values, frames = _per_message(spec, arrays, _engine_array(spec))
    else:  # the mapping refuses every other type
        raise MappingError(f'{spec.name}: no decoder for {spec.msgtype}')
    values = values * np.asarray(_engine_gain(spec))  # InputDecoder's factors, live
    if spec.gear_offset:
        values[:, 1] += spec.gear_offset
    return InputSeries(stamps.astype(np.int64), values, frames)


def decode_brake(spec: InputSpec, arrays: TopicArrays) -> InputSeries:
    """Decode the brake input (``brake`` of the mapping) to stamped values per wheel.

    Returns:
        values of shape (N, 4): each wheel's pressure (bar, or the raw unit for '-') or the
        switch (on every wheel), as `brake_row` gives them.

    Raises:
        MappingError: a mapped element is absent from the messages.
        BagFormatError: a message cannot be decoded.
    """
    if spec.name != BRAKE_INPUT:
        raise MappingError(f'{spec.name}: not the {BRAKE_INPUT} input')
    stamps, values, frames = _per_message(spec, arrays, _brake_array(spec))
    return InputSeries(stamps.astype(np.int64), values, frames)


def _brake_array(spec: InputSpec) -> Callable[[Any, int], tuple[int, Sequence[float], bytes]]:
    elements = _float64_array(spec)

    def extract(msg: Any, log: int) -> tuple[int, Sequence[float], bytes]:
        stamp, values, frame = elements(msg, log)
        return stamp, brake_row(spec, values), frame

    return extract


def _engine_array(spec: InputSpec) -> Callable[[Any, int], tuple[int, Sequence[float], bytes]]:
    def extract(msg: Any, log: int) -> tuple[int, Sequence[float], bytes]:
        data = msg.data
        if max(spec.indices) >= len(data):
            raise MappingError(
                f'{spec.name}.indices: element {max(spec.indices)} is beyond the '
                f'{len(data)} values of the messages on {spec.topic}'
            )
        row = [float(data[i]) for i in spec.indices]
        return log, [*row, *([float('nan')] * (4 - len(row)))], b''

    return extract


@dataclass(frozen=True)
class InputStats:
    """How regularly one input arrived over a recording (the replay and report summaries).

    Attributes:
        name: the input (:data:`~vd_observer_node.inputs.mapping.INPUTS`).
        topic: its topic.
        messages: messages on the topic.
        longest_gap_s: [s] longest interval between consecutive stamps (0 with < 2 messages).
        long_gaps: intervals longer than `max_gap_s`: there the observers restart.
        max_gap_s: [s] the observers' ``max_gap`` the gaps were counted against.
        expected: stamps expected between the first and the last at the input's nominal
            period (`health.StreamHealth`); None for an input without header, whose losses
            its log times cannot tell.
        lost: of those, the ones that are not in the recording (None without header).
    """

    name: str
    topic: str
    messages: int
    longest_gap_s: float
    long_gaps: int
    max_gap_s: float
    expected: int | None = None
    lost: int | None = None

    def text(self) -> str:
        """One line, e.g. 'wheel_torques (/can/wheel_torques): 900 messages, longest gap
        0.010 s, 0 gaps > 0.5 s'."""
        line = (
            f'{self.name} ({self.topic}): {self.messages} messages, longest gap '
            f'{self.longest_gap_s:.3f} s, {self.long_gaps} gaps > {self.max_gap_s:g} s'
        )
        if self.lost and self.expected:
            line += (
                f', {self.lost} of {self.expected} expected stamps lost '
                f'({100.0 * self.lost / self.expected:.1f} %)'
            )
        return line


def input_stats(spec: InputSpec, series: InputSeries, max_gap_s: float) -> InputStats:
    """Messages, longest gap, gaps longer than `max_gap_s` [s] and stamps lost of one decoded
    input."""
    stamps = np.sort(series.stamp_ns)
    gaps = np.diff(stamps)
    expected = lost = None
    if has_header(spec):
        health = StreamHealth()
        health.add_many(stamps)
        window = health.window()
        expected, lost = window.expected, window.expected - window.received
    return InputStats(
        name=spec.name,
        topic=spec.topic,
        messages=len(stamps),
        longest_gap_s=float(gaps.max()) * 1e-9 if gaps.size else 0.0,
        long_gaps=int(np.count_nonzero(gaps > round(max_gap_s * 1e9))),
        max_gap_s=max_gap_s,
        expected=expected,
        lost=lost,
    )
