"""The live nodes' raw CDR codec writes and reads exactly what rclpy serializes."""

from __future__ import annotations

import numpy as np
import pytest
from geometry_msgs.msg import AccelStamped, TwistStamped
from rclpy.serialization import deserialize_message, serialize_message
from vd_observer_node.bag.cdr_message import MessageCodec

from vd_msgs.msg import (
    Friction,
    FrictionPotential,
    Resistances,
    Slope,
    TireForces,
    WheelAngles,
    WheelStates,
    WheelTorques,
)

RNG_SEED = 20261124


def _fill(msg: object, codec: MessageCodec, rng: np.random.Generator) -> list[object]:
    """Set every field of `msg` to random values; return them flattened in CDR order."""
    flat: list[object] = []
    for name in codec.fields:
        *path, leaf = name.split('.')
        target = msg
        for part in path:
            target = getattr(target, part)
        current = getattr(target, leaf)
        if isinstance(current, bool):
            value: object = bool(rng.integers(0, 2))
            flat.append(value)
        elif isinstance(current, float):
            value = float(rng.normal(0.0, 100.0))
            flat.append(value)
        elif isinstance(current, int):
            value = int(rng.integers(0, 5))
            flat.append(value)
        else:  # fixed array: numpy array or list
            sample = np.asarray(current)
            if sample.dtype == bool:
                values = [bool(v) for v in rng.integers(0, 2, size=sample.size)]
            elif sample.dtype.kind in 'ui':
                values = [int(v) for v in rng.integers(0, 5, size=sample.size)]
            else:
                values = [float(v) for v in rng.normal(0.0, 100.0, size=sample.size)]
            value = values
            flat.extend(values)
        setattr(target, leaf, value)
    return flat


@pytest.mark.parametrize(
    ('cls', 'msgtype'),
    [
        (WheelAngles, 'vd_msgs/msg/WheelAngles'),
        (WheelStates, 'vd_msgs/msg/WheelStates'),
        (WheelTorques, 'vd_msgs/msg/WheelTorques'),
        (TireForces, 'vd_msgs/msg/TireForces'),
        (Friction, 'vd_msgs/msg/Friction'),
        (Resistances, 'vd_msgs/msg/Resistances'),
        (Slope, 'vd_msgs/msg/Slope'),
        (FrictionPotential, 'vd_msgs/msg/FrictionPotential'),
        (TwistStamped, 'geometry_msgs/msg/TwistStamped'),
        (AccelStamped, 'geometry_msgs/msg/AccelStamped'),
    ],
)
@pytest.mark.parametrize('frame', ['', 'base_link', 'odom'])
def test_codec_matches_rclpy_serialization(cls: type, msgtype: str, frame: str) -> None:
    rng = np.random.default_rng(RNG_SEED)
    codec = MessageCodec(msgtype, frame)
    msg = cls()
    msg.header.frame_id = frame
    msg.header.stamp.sec = 1234
    msg.header.stamp.nanosec = 567_890_123
    flat = _fill(msg, codec, rng)
    data = codec.encode(1234 * 10**9 + 567_890_123, flat)  # type: ignore[arg-type]
    # Not byte for byte: rmw leaves its alignment padding uninitialised (we write zeros).
    assert len(data) == len(serialize_message(msg))
    assert deserialize_message(data, cls) == msg
    stamp, got_frame, values = codec.decode(serialize_message(msg))
    assert stamp == 1234 * 10**9 + 567_890_123
    assert got_frame == frame.encode()
    decoded: list[object] = []
    for value in values:
        decoded.extend(value if isinstance(value, tuple) else (value,))
    assert decoded == flat
