"""Repair of bags whose writer died: SIGKILL of a writing process, truncation, disk full."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from full_disk import fill_disk_after
from vd_common.topics import SENSORS_WHEEL_ANGLES
from vd_observer_node.bag import (
    BagDiskFullError,
    BagExistsError,
    BagPathError,
    BagReader,
    BagUsageError,
    BagWriter,
)
from vd_observer_node.bag.cdr_batch import encode_batch
from vd_observer_node.bag.repair import repair_bag

PACKAGE_DIR = Path(__file__).resolve().parents[1]
TOPIC = SENSORS_WHEEL_ANGLES
MSGTYPE = 'vd_msgs/msg/WheelAngles'


def _messages(n: int, period_ns: int = 1_000_000) -> tuple[np.ndarray, list[bytes]]:
    stamps = np.arange(n, dtype=np.int64) * period_ns
    angles = np.arange(4 * n, dtype=np.float64).reshape(n, 4)
    return stamps, encode_batch(MSGTYPE, stamps, 'base_link', {'angle': angles})


class FakeClock:
    """Monotonic clock [s] the test advances by hand."""

    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def test_loss_after_kill_is_bounded_by_chunk_duration(tmp_path: Path) -> None:
    # 1 kHz of WheelAngles (~80 B each) fills 256 kB only every ~3 s, so the time bound rules.
    clock = FakeClock()
    bag = tmp_path / 'live'
    writer = BagWriter(bag, chunk_duration_s=0.5, clock=clock)
    writer.add_topic(TOPIC, MSGTYPE)
    stamps, datas = _messages(3700)
    for k in range(3700):
        clock.now = k * 1e-3
        writer.write(TOPIC, datas[k], int(stamps[k]))
    # What a SIGKILL leaves: the bytes handed to the OS so far; no summary, no metadata.yaml.
    snapshot = writer.mcap_path.read_bytes()
    copy = tmp_path / 'killed'
    copy.mkdir()
    (copy / 'killed_0.mcap').write_bytes(snapshot)
    report = repair_bag(copy)
    lost_s = (3699 - report.messages_recovered + 1) * 1e-3
    assert report.problems, 'a killed file must be reported as damaged'
    assert 0 < lost_s <= 0.5 + 1e-3
    got = [m.data for m in BagReader(copy).raw_messages()]
    assert got == datas[: len(got)]
    assert (copy / 'metadata.yaml').is_file()
    assert report.backup is not None and report.backup.is_file()
    writer.close()


def test_flush_if_due_bounds_loss_when_topics_go_quiet(tmp_path: Path) -> None:
    clock = FakeClock()
    writer = BagWriter(tmp_path / 'q', chunk_duration_s=0.5, clock=clock)
    writer.add_topic(TOPIC, MSGTYPE)
    stamps, datas = _messages(10)
    for k in range(10):
        writer.write(TOPIC, datas[k], int(stamps[k]))
    size = writer.mcap_path.stat().st_size
    clock.now = 0.4
    assert not writer.flush_if_due()
    clock.now = 0.6
    assert writer.flush_if_due()
    assert writer.mcap_path.stat().st_size > size
    writer.close()


_CHILD = """
import sys, time
sys.path.insert(0, {pkg!r})
from vd_observer_node.bag import BagWriter
from vd_observer_node.bag.cdr_batch import encode_batch
import numpy as np
writer = BagWriter({bag!r}, chunk_size=4096)
writer.add_topic({topic!r}, {msgtype!r})
k = 0
while True:
    stamps = np.array([k], dtype=np.int64)
    data = encode_batch({msgtype!r}, stamps, 'base_link', {{'angle': np.full((1, 4), float(k))}})
    writer.write({topic!r}, data[0], k)
    k += 1
    if k == 2000:
        print('ready', flush=True)
    if k >= 2000:
        time.sleep(0.0005)
"""


def test_sigkill_of_writing_process_then_repair(tmp_path: Path) -> None:
    bag = tmp_path / 'rec'
    code = _CHILD.format(pkg=str(PACKAGE_DIR), bag=str(bag), topic=TOPIC, msgtype=MSGTYPE)
    child = subprocess.Popen([sys.executable, '-c', code], stdout=subprocess.PIPE, text=True)
    try:
        assert child.stdout is not None
        assert child.stdout.readline().strip() == 'ready'
        time.sleep(0.2)
    finally:
        os.kill(child.pid, signal.SIGKILL)
        child.wait(timeout=10)
    assert child.returncode == -signal.SIGKILL
    assert not (bag / 'metadata.yaml').exists()
    report = repair_bag(bag)
    assert report.messages_recovered >= 1900  # 4 kB chunks of ~80 B messages: <= 51 lost
    values = [float(m.log_time_ns) for m in BagReader(bag).raw_messages()]
    assert values == [float(k) for k in range(report.messages_recovered)]
    assert report.topic_counts == {TOPIC: report.messages_recovered}


def test_repair_of_intact_bag_keeps_everything(tmp_path: Path) -> None:
    stamps, datas = _messages(500)
    with BagWriter(tmp_path / 'ok', chunk_size=2048) as writer:
        writer.add_topic(TOPIC, MSGTYPE)
        writer.write_batch(TOPIC, datas, stamps.tolist())
    report = repair_bag(tmp_path / 'ok', keep_backup=False)
    assert report.problems == []
    assert report.messages_recovered == 500
    assert report.backup is None
    assert [m.data for m in BagReader(tmp_path / 'ok').raw_messages()] == datas


def test_existing_bag_is_refused(tmp_path: Path) -> None:
    (tmp_path / 'b').mkdir()
    (tmp_path / 'b' / 'x').write_text('x')
    with pytest.raises(BagExistsError, match='already exists'):
        BagWriter(tmp_path / 'b')


def test_unwritable_location(tmp_path: Path) -> None:
    (tmp_path / 'file').write_text('not a folder')
    with pytest.raises(BagPathError, match='cannot create bag'):
        BagWriter(tmp_path / 'file' / 'bag')


def test_unknown_topic_and_closed_writer(tmp_path: Path) -> None:
    writer = BagWriter(tmp_path / 'u')
    with pytest.raises(BagUsageError, match='was not added'):
        writer.write('/nope', b'\x00\x01\x00\x00', 0)
    writer.add_topic(TOPIC, MSGTYPE)
    with pytest.raises(BagUsageError, match='already has type'):
        writer.add_topic(TOPIC, 'vd_msgs/msg/Slope')
    with pytest.raises(BagUsageError, match='times must be'):
        writer.write(TOPIC, b'\x00\x01\x00\x00', -1)
    with pytest.raises(BagUsageError, match='times must be'):
        writer.write_interleaved([TOPIC], np.zeros(1, dtype=int), [b''], np.array([-5]))
    writer.close()
    with pytest.raises(BagUsageError, match='closed'):
        writer.write(TOPIC, b'', 0)


def test_disk_full_keeps_complete_chunks(tmp_path: Path, monkeypatch: Any) -> None:
    stamps, datas = _messages(2000)
    writer = BagWriter(tmp_path / 'full', chunk_size=4096)
    writer.add_topic(TOPIC, MSGTYPE)
    fill_disk_after(writer, 30_000, monkeypatch)
    with pytest.raises(BagDiskFullError, match='disk full'):
        for k in range(2000):
            writer.write(TOPIC, datas[k], int(stamps[k]))
    with pytest.raises(BagUsageError, match='failed earlier'):
        writer.write(TOPIC, datas[0], 0)
    writer.close()
    report = repair_bag(tmp_path / 'full')
    assert report.messages_recovered > 0
    got = [m.data for m in BagReader(tmp_path / 'full').raw_messages()]
    assert got == datas[: len(got)]
