"""The torque_source field of TireForces, Friction and Slope (and Slope's sources) through the
bag CDR code, and bags written before the fields existed (their embedded definitions) read back
and upgraded."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from vd_observer_node.bag.cdr_batch import decode_batch, encode_batch, flat_fields, upgrade_batch
from vd_observer_node.bag.cdr_message import MessageCodec
from vd_observer_node.bag.reader import BagReader
from vd_observer_node.bag.typestore import (
    decoding_type,
    deserialize,
    message_class,
    message_definition,
    serialize,
)
from vd_observer_node.bag.writer import BagWriter
from vd_observer_node.estimation.drivetrain import TORQUE_ENGINE, TORQUE_MEASURED, TORQUE_NONE

TYPES = ('vd_msgs/msg/TireForces', 'vd_msgs/msg/Friction', 'vd_msgs/msg/Slope')
#: fields added after bags were written: torque_source, and Slope's sources (issue 27)
_ADDED = ('torque_source', 'sources')


def values_of(msgtype: str, n: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
    out: dict[str, np.ndarray] = {}
    for f in flat_fields(msgtype):
        shape = (n, f.count) if f.count > 1 else (n,)
        kind = np.dtype(f.dtype).kind
        if f.name in _ADDED:
            out[f.name] = rng.integers(0, 3, size=shape).astype(np.uint8)
        elif kind == 'b':
            out[f.name] = rng.integers(0, 2, size=shape).astype(bool)
        else:
            out[f.name] = rng.normal(0.0, 100.0, size=shape)
    return out


@pytest.mark.parametrize('msgtype', TYPES)
def test_field_and_constants_round_trip(msgtype: str) -> None:
    cls = message_class(msgtype)
    assert (cls.TORQUE_MEASURED, cls.TORQUE_ENGINE, cls.TORQUE_NONE) == (
        TORQUE_MEASURED,
        TORQUE_ENGINE,
        TORQUE_NONE,
    )
    names = [f.name for f in flat_fields(msgtype)]
    assert names[-1] == ('sources' if msgtype.endswith('Slope') else 'torque_source')
    assert 'torque_source' in names
    rng = np.random.default_rng(5)
    stamps = np.arange(6, dtype=np.int64) * 10_000_000
    values = values_of(msgtype, 6, rng)
    values['torque_source'] = np.array([0, 1, 2, 2, 1, 0], dtype=np.uint8)
    datas = encode_batch(msgtype, stamps, 'base_link', values)
    decoded = decode_batch(msgtype, datas)
    np.testing.assert_array_equal(decoded.values['torque_source'], values['torque_source'])
    codec = MessageCodec(msgtype, 'base_link')
    for k, data in enumerate(datas):
        flat: list[float] = []
        for f in flat_fields(msgtype):
            v = values[f.name][k]
            flat.extend(v.tolist() if f.count > 1 else [v.item()])
        assert codec.encode(int(stamps[k]), flat) == data
        assert codec.decode(data)[2][names.index('torque_source')] == values['torque_source'][k]
        msg = deserialize(data, msgtype)  # rosbags agrees on the layout
        assert msg.torque_source == values['torque_source'][k]
        assert serialize(msg, msgtype) == data


def old_definition(msgtype: str) -> str:
    """Today's definition without the torque-source (and slope-sources) lines: what older
    bags embed."""
    lines = message_definition(msgtype).splitlines()
    dropped = ('TORQUE_', 'torque_source', 'SOURCE_', 'uint8 sources')
    return '\n'.join(line for line in lines if not any(d in line for d in dropped))


@pytest.mark.parametrize('msgtype', TYPES)
def test_bags_without_the_field_read_and_upgrade(msgtype: str, tmp_path: Path) -> None:
    old = old_definition(msgtype)
    names = [f.name for f in flat_fields(msgtype)]
    alias = decoding_type(msgtype, old)
    assert alias != msgtype and alias.endswith(msgtype.split('/')[-1])
    assert decoding_type(msgtype, message_definition(msgtype)) == msgtype
    assert decoding_type(msgtype, '') == msgtype
    rng = np.random.default_rng(9)
    n = 40
    stamps = np.arange(n, dtype=np.int64) * 10_000_000
    values = {k: v for k, v in values_of(msgtype, n, rng).items() if k not in _ADDED}
    old_datas = encode_batch(alias, stamps, 'base_link', values)
    assert len(old_datas[0]) < len(
        encode_batch(
            msgtype,
            stamps[:1],
            'base_link',
            {
                **{k: v[:1] for k, v in values.items()},
                **{k: np.zeros(1, np.uint8) for k in _ADDED if k in names},
            },
        )[0]
    )
    with BagWriter(tmp_path / 'old') as writer:
        writer.add_topic('/x', msgtype, definition=old)
        writer.write_batch('/x', old_datas, stamps)
    reader = BagReader(tmp_path / 'old')
    arrays = reader.topic_arrays(['/x'])['/x']
    assert arrays.msgtype == msgtype and arrays.decoding_type == alias
    decoded = decode_batch(arrays.decoding_type, arrays.datas)
    for name, value in values.items():
        np.testing.assert_array_equal(decoded.values[name], value)
    messages = list(reader.messages(['/x']))
    assert len(messages) == n and messages[0][1] == msgtype
    assert not hasattr(messages[0][3], 'torque_source')
    upgraded = upgrade_batch(msgtype, arrays.decoding_type, arrays.datas)
    today = decode_batch(msgtype, upgraded)
    np.testing.assert_array_equal(today.stamp_ns, stamps)
    for name in (k for k in _ADDED if k in names):
        np.testing.assert_array_equal(today.values[name], np.zeros(n))
    for name, value in values.items():
        np.testing.assert_array_equal(today.values[name], value)
    assert upgrade_batch(msgtype, msgtype, upgraded) == upgraded
