"""Per-message CDR coding (the live raw path) against the batch coder and rosbags."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from vd_observer_node.bag import BagFormatError, BagUsageError, UnknownMessageTypeError
from vd_observer_node.bag.alerts_cdr import encode_alerts
from vd_observer_node.bag.cdr_batch import decode_batch, encode_batch, flat_fields
from vd_observer_node.bag.cdr_message import AlertsCodec, MessageCodec
from vd_observer_node.bag.typestore import VD_MSG_TYPES, deserialize, serialize

FIXED_TYPES = tuple(
    t
    for t in (*VD_MSG_TYPES, 'geometry_msgs/msg/TwistStamped', 'geometry_msgs/msg/AccelStamped')
    if t != 'vd_msgs/msg/Alerts' and t != 'vd_msgs/msg/Alert'
)


def _flat(values: dict[str, np.ndarray], msgtype: str) -> list[float | int | bool]:
    out: list[float | int | bool] = []
    for f in flat_fields(msgtype):
        v = values[f.name][0]
        out.extend(np.atleast_1d(v).tolist())
    return out


@settings(max_examples=60, deadline=None)
@given(
    msgtype=st.sampled_from(FIXED_TYPES),
    frame=st.text(alphabet='abz_/09', max_size=12),
    seed=st.integers(0, 2**32 - 1),
)
def test_message_coding_equals_batch_coding_and_rosbags(
    msgtype: str, frame: str, seed: int
) -> None:
    rng = np.random.default_rng(seed)
    stamp = int(rng.integers(-(2**31) * 10**9, (2**31 - 1) * 10**9))
    values: dict[str, np.ndarray] = {}
    for f in flat_fields(msgtype):
        shape = (1, f.count) if f.count > 1 else (1,)
        kind = np.dtype(f.dtype).kind
        if kind == 'f':
            values[f.name] = rng.normal(0.0, 1e3, size=shape)
        elif kind == 'b':
            values[f.name] = rng.integers(0, 2, size=shape).astype(bool)
        else:
            info = np.iinfo(np.dtype(f.dtype))
            values[f.name] = rng.integers(info.min, info.max, size=shape, endpoint=True)
    codec = MessageCodec(msgtype, frame)
    data = codec.encode(stamp, _flat(values, msgtype))
    assert data == encode_batch(msgtype, np.array([stamp]), frame, values)[0]
    assert serialize(deserialize(data, msgtype), msgtype) == data  # rosbags reads it back
    got_stamp, got_frame, got = codec.decode(data)
    assert got_stamp == stamp
    assert got_frame == frame.encode()
    batch = decode_batch(msgtype, [data])
    for name, value in zip(codec.fields, got, strict=True):
        np.testing.assert_array_equal(np.asarray(value), batch.values[name][0])
    # a codec with another frame_id decodes it too (the sender's frame_id is not ours)
    other = MessageCodec(msgtype, 'base_link_other')
    assert other.decode(data)[0] == stamp


def test_codec_refuses_what_it_cannot_code() -> None:
    codec = MessageCodec('vd_msgs/msg/Slope', 'f')
    with pytest.raises(BagUsageError, match='cannot encode'):
        codec.encode(0, [0.5])
    with pytest.raises(BagUsageError, match='int32'):
        codec.encode(2**31 * 10**9, [0.5, True, 1, 3])
    good = codec.encode(1, [0.5, True, 1, 3])
    with pytest.raises(BagFormatError, match='little-endian'):
        codec.decode(b'\x00\x00' + good[2:])
    with pytest.raises(BagFormatError):
        codec.decode(good[:-5])
    with pytest.raises(UnknownMessageTypeError):
        MessageCodec('vd_msgs/msg/Alerts')


@settings(max_examples=30, deadline=None)
@given(frame=st.text(alphabet='abz_/09', max_size=9), seed=st.integers(0, 2**32 - 1))
def test_alerts_codec_equals_the_batch_encoder(frame: str, seed: int) -> None:
    rng = np.random.default_rng(seed)
    stamp = int(rng.integers(0, 2**31 * 10**9))
    level = rng.integers(0, 3, size=12)
    onset = np.where(level > 0, rng.integers(0, 2**31 * 10**9, size=12), 0)
    detected = np.where(level > 0, rng.integers(0, 2**31 * 10**9, size=12), 0)
    data = AlertsCodec(frame).encode(stamp, level.tolist(), onset.tolist(), detected.tolist())
    batch = encode_alerts(
        np.array([stamp]),
        frame,
        {
            'level': level.reshape(1, 3, 4),
            'onset_ns': onset.reshape(1, 3, 4),
            'detected_ns': detected.reshape(1, 3, 4),
        },
    )
    assert data == batch[0]
    msg = deserialize(data, 'vd_msgs/msg/Alerts')
    assert [a.level for a in msg.alerts] == level.tolist()
    with pytest.raises(BagUsageError, match='12 channels'):
        AlertsCodec(frame).encode(stamp, [0], [0], [0])
