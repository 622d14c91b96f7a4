"""Packed message sequences: the same messages as a list of bytes, moved without one.

PackedMessages / PackedParts stand in for ``list[bytes]`` on the replay's hot path (reader,
batch coders, writer). Every operation must give exactly what the list would, for any mix of
message lengths (zero included), and the writer must write byte-identical files whichever
form it is given.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from vd_observer_node.bag import BagReader, BagWriter
from vd_observer_node.bag.alerts_cdr import decode_alerts, encode_alerts, encode_alerts_packed
from vd_observer_node.bag.cdr_batch import decode_batch, encode_batch, encode_packed
from vd_observer_node.bag.packed import PackedMessages, PackedParts

messages = st.lists(st.binary(max_size=40), max_size=30)


@given(datas=messages, data=st.data())
def test_packed_messages_behave_as_the_list(datas: list[bytes], data: st.DataObject) -> None:
    packed = PackedMessages.from_list(datas)
    assert len(packed) == len(datas)
    assert list(packed) == datas and packed == datas and datas == packed
    assert [packed[k] for k in range(len(datas))] == datas
    index = np.array(
        data.draw(st.lists(st.integers(0, max(len(datas) - 1, 0)), max_size=20)) if datas else [],
        dtype=np.int64,
    )
    picked = [datas[k] for k in index.tolist()]
    taken = packed.take(index)
    assert taken == picked
    compact = taken.compact()
    assert compact == picked and compact.data == b''.join(picked)
    assert compact.compact() is compact
    assert PackedMessages.concat([taken, packed, taken]) == picked + datas + picked
    assert packed[1:4] == datas[1:4]


@given(groups=st.lists(messages, max_size=5), data=st.data())
def test_packed_parts_behave_as_the_concatenated_list(
    groups: list[list[bytes]], data: st.DataObject
) -> None:
    parts = [PackedMessages.from_list(g) for g in groups]
    flat = [m for g in groups for m in g]
    joined = PackedParts.join(parts)
    assert joined == flat and list(joined) == flat
    assert joined.lengths.tolist() == [len(m) for m in flat]
    index = np.array(data.draw(st.permutations(range(len(flat)))) if flat else [], dtype=np.int64)
    picked = [flat[k] for k in index.tolist()]
    taken = joined.take(index)
    assert taken == picked
    assert taken.compact() == picked and taken.compact().data == b''.join(picked)
    # copied into place: what the writer does with the messages of a chunk
    at = np.concatenate([[0], np.cumsum(taken.lengths)[:-1]]).astype(np.int64)
    out = np.zeros(int(taken.lengths.sum()), dtype=np.uint8)
    taken.scatter_into(out, at)
    assert out.tobytes() == b''.join(picked)


def test_packed_is_no_bytes_or_string() -> None:
    packed = PackedMessages.from_list([b'ab'])
    assert packed != b'ab' and packed != 'ab' and packed == [b'ab'] and packed != [b'a']


def _stream(n: int) -> tuple[list[str], np.ndarray, list[bytes], np.ndarray]:
    rng = np.random.default_rng(3)
    stamps = np.arange(n, dtype=np.int64) * 1000
    angles = encode_batch(
        'vd_msgs/msg/WheelAngles', stamps, 'x', {'angle': rng.normal(size=(n, 4))}
    )
    slopes = encode_batch(
        'vd_msgs/msg/Slope',
        stamps,
        'yy',
        {
            'angle': rng.normal(size=n),
            'valid': np.ones(n),
            'torque_source': np.ones(n),
            'sources': np.ones(n),
        },
    )
    which = rng.integers(0, 2, size=n)
    datas = [angles[k] if which[k] == 0 else slopes[k] for k in range(n)]
    datas[7] += b'\x00\x00\x00'  # a third length
    return ['/a', '/s'], which, datas, stamps


@pytest.mark.parametrize('form', ['list', 'packed', 'parts'])
def test_write_interleaved_writes_the_same_file_from_any_form(tmp_path: Path, form: str) -> None:
    topics, which, datas, stamps = _stream(5000)
    given_as: list[bytes] | PackedMessages | PackedParts = datas
    if form == 'packed':
        given_as = PackedMessages.from_list(datas).take(np.arange(len(datas)))
    elif form == 'parts':
        # per-topic buffers, interleaved by index only: how the replay hands them over
        per_topic = [
            PackedMessages.from_list([d for d, w in zip(datas, which, strict=True) if w == k])
            for k in (0, 1)
        ]
        rows = np.zeros(len(datas), dtype=np.int64)
        for k in (0, 1):
            rows[which == k] = np.arange(int(np.count_nonzero(which == k)))
        given_as = PackedParts(per_topic, which, rows)
        assert given_as == datas
    files = []
    for name, messages_ in (('ref', datas), (form, given_as)):
        folder = tmp_path / name / 'bag'
        with BagWriter(folder, chunk_size=8192) as writer:
            for topic, msgtype in zip(
                topics, ('vd_msgs/msg/WheelAngles', 'vd_msgs/msg/Slope'), strict=True
            ):
                writer.add_topic(topic, msgtype)
            writer.write_interleaved(topics, which, messages_, stamps)
        files.append((folder / 'bag_0.mcap').read_bytes())
    assert files[0] == files[1]
    got = [(m.topic, m.data) for m in BagReader(tmp_path / form / 'bag').raw_messages()]
    assert got == [(topics[w], d) for w, d in zip(which.tolist(), datas, strict=True)]


def test_reader_gives_packed_arrays_equal_to_the_raw_messages(tmp_path: Path) -> None:
    topics, which, datas, stamps = _stream(3000)
    with BagWriter(tmp_path / 'bag', chunk_size=4096) as writer:
        writer.add_topic('/a', 'vd_msgs/msg/WheelAngles')
        writer.add_topic('/s', 'vd_msgs/msg/Slope')
        writer.write_interleaved(topics, which, datas, stamps)
    reader = BagReader(tmp_path / 'bag')
    arrays = reader.topic_arrays()
    for k, topic in enumerate(topics):
        expected = [d for d, w in zip(datas, which.tolist(), strict=True) if w == k]
        assert isinstance(arrays[topic].datas, PackedMessages)
        assert arrays[topic].datas == expected
    blocks = list(reader.topic_array_blocks(['/s'], block_messages=100))
    assert [m for b in blocks for m in b['/s'].datas] == arrays['/s'].datas


def test_batch_coders_take_packed_and_list_alike() -> None:
    rng = np.random.default_rng(5)
    n = 200
    stamps = np.arange(n, dtype=np.int64) * 7
    values = {'angle': rng.normal(size=(n, 4))}
    packed = encode_packed('vd_msgs/msg/WheelAngles', stamps, 'base', values)
    listed = encode_batch('vd_msgs/msg/WheelAngles', stamps, 'base', values)
    assert packed == listed
    pick = rng.permutation(n)[:150]
    a = decode_batch('vd_msgs/msg/WheelAngles', packed.take(pick))  # not compact
    b = decode_batch('vd_msgs/msg/WheelAngles', [listed[k] for k in pick.tolist()])
    assert np.array_equal(a.stamp_ns, b.stamp_ns) and np.array_equal(a.stamp_ns, stamps[pick])
    assert np.array_equal(a.values['angle'], b.values['angle'])
    level = rng.integers(0, 3, size=(n, 3, 4))
    alerts = encode_alerts_packed(stamps, 'base', {'level': level})
    assert alerts == encode_alerts(stamps, 'base', {'level': level})
    assert np.array_equal(decode_alerts(alerts.take(pick)).values['level'], level[pick])


@given(st.lists(st.binary(min_size=0, max_size=40), min_size=0, max_size=60), st.randoms())
def test_the_compiled_copy_places_every_range_as_slicing_does(
    datas: list[bytes], random: object
) -> None:
    """copy_ranges (compiled, and its Python source as VD_JIT=0 runs it) against the oracle
    of plain slicing, for messages of mixed lengths in a shuffled order."""
    from vd_observer_node.bag.copy_kernel import copy_ranges

    packed = PackedMessages.from_list(datas)
    order = list(range(len(datas)))
    random.shuffle(order)  # type: ignore[attr-defined]
    lengths = packed.lengths[order]
    at = np.zeros(len(order), dtype=np.int64)
    np.cumsum(lengths[:-1] + 3, out=at[1:])  # 3-byte gaps that must stay untouched
    size = int(at[-1] + lengths[-1]) if order else 0
    expected = bytearray(b'\xee' * size)
    for k, j in enumerate(order):
        expected[at[k] : at[k] + len(datas[j])] = datas[j]
    for copy in (copy_ranges, getattr(copy_ranges, 'py_func', copy_ranges)):
        out = np.full(size, 0xEE, dtype=np.uint8)
        copy(out, at, packed.array, packed.starts[order], lengths)
        assert out.tobytes() == bytes(expected)
