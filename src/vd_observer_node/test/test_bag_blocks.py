"""`BagReader.topic_array_blocks`: bounded blocks whose concatenation is the whole selection.

The reference is the per-message reader (`raw_messages`): the blocks, concatenated per topic,
hold the same messages in the same order, for intact, multi-file and damaged bags.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from vd_observer_node.bag import BagCorruptError, BagReader, BagWriter
from vd_observer_node.bag.cdr_batch import encode_batch
from vd_observer_node.bag.errors import BagUsageError

N = 400  # messages per topic
CHUNK = 2048  # [B] small chunks: many per block boundary


def _write(path: Path, offset_ns: int = 0) -> None:
    rng = np.random.default_rng(11)
    stamps = offset_ns + np.arange(N, dtype=np.int64) * 10_000_000
    angles = encode_batch(
        'vd_msgs/msg/WheelAngles', stamps, 'base_link', {'angle': rng.normal(size=(N, 4))}
    )
    slopes = encode_batch(
        'vd_msgs/msg/Slope',
        stamps,
        'base_link',
        {
            'angle': rng.normal(size=N),
            'valid': rng.integers(0, 2, N).astype(bool),
            'torque_source': rng.integers(0, 3, N),
            'sources': np.arange(N) % 4,
        },
    )
    with BagWriter(path, chunk_size=CHUNK) as writer:
        writer.add_topic('/a', 'vd_msgs/msg/WheelAngles')
        writer.add_topic('/s', 'vd_msgs/msg/Slope')
        writer.add_topic('/never', 'vd_msgs/msg/Slope')
        for k in range(N):
            writer.write('/a', angles[k], int(stamps[k]))
            if k % 3 == 0:  # a second topic at its own rate: blocks hold uneven shares
                writer.write('/s', slopes[k], int(stamps[k]))


def _per_topic(reader: BagReader, topics: list[str] | None) -> dict[str, list[tuple[int, bytes]]]:
    out: dict[str, list[tuple[int, bytes]]] = {}
    for m in reader.raw_messages(topics):
        out.setdefault(m.topic, []).append((m.log_time_ns, bytes(m.data)))
    return out


def _joined(
    reader: BagReader, topics: list[str] | None, block: int | None
) -> tuple[dict[str, list[tuple[int, bytes]]], list[int], dict[str, str]]:
    out: dict[str, list[tuple[int, bytes]]] = {}
    sizes: list[int] = []
    types: dict[str, str] = {}
    for arrays in reader.topic_array_blocks(topics, block_messages=block):
        sizes.append(sum(len(a.datas) for a in arrays.values()))
        for topic, a in arrays.items():
            assert a.log_time_ns.dtype == np.int64 and len(a.log_time_ns) == len(a.datas)
            types[topic] = a.msgtype
            out.setdefault(topic, []).extend(
                zip(a.log_time_ns.tolist(), [bytes(d) for d in a.datas], strict=True)
            )
    return out, sizes, types


@pytest.fixture(scope='module')
def bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp('blocks') / 'bag'
    _write(path)
    return path


@pytest.mark.parametrize('block', [1, 7, 50, 10_000, None])
@pytest.mark.parametrize('topics', [None, ['/s'], ['/a', '/s', '/missing']])
def test_blocks_concatenate_to_the_per_message_reader(
    bag: Path, block: int | None, topics: list[str] | None
) -> None:
    reader = BagReader(bag)
    expected = _per_topic(reader, topics)
    got, sizes, types = _joined(reader, topics, block)
    assert got == expected
    assert types == {t: reader.topics[t].msgtype for t in expected}
    whole = reader.topic_arrays(topics)
    assert {t: len(a.datas) for t, a in whole.items()} == {t: len(v) for t, v in got.items()}
    if block is None or block >= sum(sizes):
        assert len(sizes) == 1
    else:
        assert len(sizes) > 1
        # bounded: a block stops at the first chunk end after `block` messages (a chunk of
        # CHUNK bytes holds far fewer than 100 of these messages)
        assert max(sizes) < block + 100


def test_multi_file_bag_is_read_file_after_file(tmp_path: Path) -> None:
    first, second = tmp_path / 'one', tmp_path / 'two'
    _write(first)
    _write(second, offset_ns=N * 10_000_000)
    both = tmp_path / 'both'
    both.mkdir()
    shutil.copy(first / 'one_0.mcap', both / 'both_0.mcap')
    shutil.copy(second / 'two_0.mcap', both / 'both_1.mcap')
    reader = BagReader(both)
    assert len(reader.files) == 2
    expected = _per_topic(reader, None)
    assert len(expected['/a']) == 2 * N
    got, sizes, _ = _joined(reader, None, 37)
    assert got == expected
    assert len(sizes) > 2


def test_damaged_file_in_recover_mode_gives_the_genuine_messages(
    tmp_path: Path, bag: Path
) -> None:
    data = bytearray((bag / 'bag_0.mcap').read_bytes())
    data[len(data) // 5] ^= 0xFF  # inside a chunk: that chunk is lost, the others read
    path = tmp_path / 'bad.mcap'
    path.write_bytes(bytes(data))
    with pytest.raises(BagCorruptError):
        for _ in BagReader(path).topic_array_blocks(block_messages=20):
            pass
    reference = BagReader(path, recover=True)
    expected = _per_topic(reference, None)
    reader = BagReader(path, recover=True)
    got, _, _ = _joined(reader, None, 20)
    assert got == expected
    assert 0 < sum(len(v) for v in got.values()) < N + (N + 2) // 3
    assert reader.problems
    assert [(p.offset, p.reason) for p in reader.problems] == [
        (p.offset, p.reason) for p in reference.problems
    ]


def test_truncated_file_in_recover_mode(tmp_path: Path, bag: Path) -> None:
    data = (bag / 'bag_0.mcap').read_bytes()
    path = tmp_path / 'cut.mcap'
    path.write_bytes(data[: len(data) // 2])
    reader = BagReader(path, recover=True)
    got, _, _ = _joined(reader, None, 25)
    assert got == _per_topic(BagReader(path, recover=True), None)
    assert reader.problems


def test_block_size_must_be_positive(bag: Path) -> None:
    with pytest.raises(BagUsageError, match='block_messages'):
        next(BagReader(bag).topic_array_blocks(block_messages=0))


def test_empty_selection_gives_no_block(bag: Path) -> None:
    assert list(BagReader(bag).topic_array_blocks(['/never'], block_messages=5)) == []
    assert BagReader(bag).topic_arrays(['/never']) == {}
