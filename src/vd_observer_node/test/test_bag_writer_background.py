"""BagWriter(background=True): the same file as the plain writer, and errors still surface."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from full_disk import fill_disk_after
from vd_common.topics import ESTIMATES_SLOPE, SENSORS_BODY_VELOCITY, SENSORS_WHEEL_ANGLES
from vd_observer_node.bag import BagDiskFullError, BagReader, BagUsageError, BagWriter
from vd_observer_node.bag.cdr_batch import encode_batch
from vd_observer_node.bag.repair import repair_bag

ANGLES = 'vd_msgs/msg/WheelAngles'


def _angles(rng: np.random.Generator, start: int, n: int) -> tuple[np.ndarray, list[bytes]]:
    stamps = (start + np.arange(n, dtype=np.int64)) * 1_000_000
    return stamps, encode_batch(ANGLES, stamps, 'base_link', {'angle': rng.normal(size=(n, 4))})


def _write(path: Path, background: bool) -> None:
    # interleaved blocks, topics declared between them and single messages, as the replay
    # and the tools mix them
    rng = np.random.default_rng(7)
    with BagWriter(path, chunk_size=8192, background=background) as writer:
        writer.add_topic(SENSORS_WHEEL_ANGLES, ANGLES)
        for block in range(6):
            stamps, datas = _angles(rng, 1000 * block, 1000)
            which = np.zeros(len(datas), dtype=np.int64)
            topics = [SENSORS_WHEEL_ANGLES]
            if block >= 2:
                writer.add_topic(SENSORS_BODY_VELOCITY, 'geometry_msgs/msg/TwistStamped')
                topics = [SENSORS_WHEEL_ANGLES, SENSORS_BODY_VELOCITY]
                which = (rng.random(len(datas)) < 0.3).astype(np.int64)
            writer.write_interleaved(topics, which, datas, stamps)
            if block == 3:
                writer.add_topic(ESTIMATES_SLOPE, 'vd_msgs/msg/Slope')
            writer.write(SENSORS_WHEEL_ANGLES, datas[0], int(stamps[-1]) + 1)


def test_the_background_writer_writes_the_same_bytes(tmp_path: Path) -> None:
    # one folder name: the metadata record names the file
    _write(tmp_path / 'plain' / 'bag', background=False)
    _write(tmp_path / 'background' / 'bag', background=True)
    plain = (tmp_path / 'plain' / 'bag' / 'bag_0.mcap').read_bytes()
    background = (tmp_path / 'background' / 'bag' / 'bag_0.mcap').read_bytes()
    assert len(plain) > 100_000  # many chunks, so the queue really held some
    assert background == plain
    reader = BagReader(tmp_path / 'background' / 'bag')
    assert reader.topics[SENSORS_WHEEL_ANGLES].message_count == sum(
        1 for m in reader.raw_messages() if m.topic == SENSORS_WHEEL_ANGLES
    )


def test_a_full_disk_in_the_background_is_raised_and_keeps_complete_chunks(
    tmp_path: Path, monkeypatch: Any
) -> None:
    rng = np.random.default_rng(3)
    writer = BagWriter(tmp_path / 'full', chunk_size=4096, background=True)
    writer.add_topic(SENSORS_WHEEL_ANGLES, ANGLES)
    fill_disk_after(writer, 30_000, monkeypatch)
    written: list[bytes] = []
    with pytest.raises(BagDiskFullError, match='disk full'):
        # raised by a later call or at the latest by close, never lost
        for block in range(20):
            stamps, datas = _angles(rng, 500 * block, 500)
            writer.write_interleaved(
                [SENSORS_WHEEL_ANGLES], np.zeros(len(datas), dtype=np.int64), datas, stamps
            )
            written += datas
        writer.close()
    with pytest.raises(BagUsageError, match=r'failed earlier|closed'):
        writer.write(SENSORS_WHEEL_ANGLES, written[0], 0)
    writer.close()  # idempotent after the failure, no hang
    report = repair_bag(tmp_path / 'full')
    assert report.messages_recovered > 0
    got = [m.data for m in BagReader(tmp_path / 'full').raw_messages()]
    assert got == written[: len(got)]
