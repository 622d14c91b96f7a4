"""Decode one mapped input topic to stamped SI arrays.

vd's own fixed-layout types (WheelAngles, WheelTorques, TwistStamped) are batch-decoded with
numpy (:func:`vd_observer_node.bag.cdr_batch.decode_batch`); the standard types with
variable-length fields (JointState, Odometry, Float64MultiArray) are deserialized message by
message with rosbags (about 10 µs of CPU each for JointState and Odometry, 4 µs for
Float64MultiArray: 1.5 s per 150 s of a 1 kHz JointState topic).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vd_observer_node.bag.cdr_batch import decode_batch
from vd_observer_node.bag.reader import TopicArrays
from vd_observer_node.bag.typestore import deserialize
from vd_observer_node.inputs.errors import MappingError
from vd_observer_node.inputs.mapping import (
    ENGINE_INPUT,
    FLOAT64_ARRAY,
    JOINT_STATE,
    ODOMETRY,
    TWIST_STAMPED,
    WHEEL_ANGLES_TYPE,
    WHEEL_TORQUES_TYPE,
    InputSpec,
)

__all__ = ['InputSeries', 'decode_engine', 'decode_input']

_NS = 1_000_000_000
#: the field of vd's batch-decodable types that holds the input
_BATCH_FIELD = {
    WHEEL_ANGLES_TYPE: 'angle',
    WHEEL_TORQUES_TYPE: 'torque',
    TWIST_STAMPED: 'twist.linear.x',
}
#: the JointState array of each per-wheel input
_JOINT_FIELD = {'wheel_angles': 'position', 'wheel_torques': 'effort'}


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


def decode_input(spec: InputSpec, arrays: TopicArrays) -> InputSeries:
    """Decode the messages of ``spec.topic`` to the input's SI values.

    Args:
        spec: the input's mapping.
        arrays: the topic's raw messages (`BagReader.topic_arrays`), of type ``spec.msgtype``.

    Returns:
        The series in message order (not sorted; the replay aligns by stamp).

    Raises:
        MappingError: a mapped joint or element is absent from the messages.
        BagFormatError: a message cannot be decoded.
    """
    if spec.msgtype in _BATCH_FIELD:
        fields = decode_batch(spec.msgtype, arrays.datas)
        raw = fields.values[_BATCH_FIELD[spec.msgtype]].reshape(len(arrays.datas), spec.width)
        stamps, values, frames = fields.stamp_ns, raw.astype(np.float64), fields.frame_id
    elif spec.msgtype == JOINT_STATE:
        stamps, values, frames = _per_message(spec, arrays, _joint_state(spec))
    elif spec.msgtype == FLOAT64_ARRAY:
        stamps, values, frames = _per_message(spec, arrays, _float64_array(spec))
    elif spec.msgtype == ODOMETRY:
        stamps, values, frames = _per_message(spec, arrays, _odometry)
    else:  # the mapping refuses every other type
        raise MappingError(f'{spec.name}: no decoder for {spec.msgtype}')
    if spec.factor != 1.0 or any(s != 1.0 for s in spec.sign):
        # only then: the default mapping's values pass bit for bit
        values = values * (spec.factor * np.asarray(spec.sign))
    return InputSeries(stamps.astype(np.int64), values, frames)


def decode_engine(spec: InputSpec, arrays: TopicArrays) -> InputSeries:
    """Decode the engine input (``engine_torque`` of the mapping) to stamped SI values.

    Args:
        spec: the engine input's mapping.
        arrays: the topic's raw messages, of type ``spec.msgtype``.

    Returns:
        values of shape (N, 3): engine torque [N m] (unit, scale and sign applied), gear
        (as a float, 0 neutral, -1 reverse) and engine speed [rad/s] (nan when the mapping
        has no element for it).

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
                fields.values['engine_torque'].astype(np.float64),
                fields.values['gear'].astype(np.float64),
                fields.values['engine_speed'].astype(np.float64),
            ],
            axis=1,
        ).reshape(n, 3)
        stamps, frames = fields.stamp_ns, fields.frame_id
    elif spec.msgtype == FLOAT64_ARRAY:
        stamps, values, frames = _per_message(spec, arrays, _engine_array(spec))
    else:  # the mapping refuses every other type
        raise MappingError(f'{spec.name}: no decoder for {spec.msgtype}')
    values = values.copy()
    values[:, 0] *= spec.factor * spec.sign[0]
    values[:, 2] *= spec.speed_factor
    return InputSeries(stamps.astype(np.int64), values, frames)


def _engine_array(spec: InputSpec) -> Callable[[Any, int], tuple[int, Sequence[float], bytes]]:
    def extract(msg: Any, log: int) -> tuple[int, Sequence[float], bytes]:
        data = msg.data
        if max(spec.indices) >= len(data):
            raise MappingError(
                f'{spec.name}.indices: element {max(spec.indices)} is beyond the '
                f'{len(data)} values of the messages on {spec.topic}'
            )
        row = [float(data[i]) for i in spec.indices]
        return log, row if len(row) == 3 else [*row, float('nan')], b''

    return extract
