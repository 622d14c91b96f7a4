"""The streamed replay: tiny blocks give exactly the output and report of one whole-bag block.

Input bags are re-chunked small so that hundreds of block boundaries fall inside the drive:
vd's own topics with truth (exact alignment) on the measured and engine torque paths (the
launch's clutch slip crosses blocks), and a car's standard-types recording (wheel speeds,
'latest' alignment, every topic on its own clock, torques stamped by log time). Messages are
compared as (topic, log time, bytes) in file order; the report field by field but wall times.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from vd_common.topics import ESTIMATES_TORQUE_OFFSET, SENSORS_IMU, TRUTH_NAMESPACE
from vd_common.vehicle.params import default_vehicle_file, load_vehicle
from vd_observer_node.bag import BagReader, BagWriter
from vd_observer_node.bag.cdr_batch import decode_batch
from vd_observer_node.estimation.observer import ObserverConfig
from vd_observer_node.inputs.decode import decode_engine, decode_input, input_stats
from vd_observer_node.inputs.mapping import ENGINE_INPUT, default_mapping, mapping_from_dict
from vd_observer_node.testing.devbag import sim_topics, write_topic_arrays_bag
from vd_observer_node.testing.standard_bags import (
    STANDARD_MAPPING,
    CarSensors,
    write_standard_bag,
)
from vd_observer_node.tools.replay import ReplayReport, replay_bag
from vd_sim_node.vehicle.scenario import load_scenario
from vd_sim_node.vehicle.simulation import simulate

#: the simulator's scenarios (the tests' oracle; vd_common holds only the vehicle file)
SCENARIOS = Path(__file__).resolve().parents[2] / 'vd_sim_node' / 'config' / 'scenarios'

CHUNK = 4096  # [B] input chunks of a few dozen messages: a block ends at a chunk's end
TINY = 5  # messages per block: each block is one chunk
_TIMES = ('wall_time_s', 'cascade_time_s', 'situation_time_s')


def _simulate(duration_s: float, rate_hz: float) -> Any:
    """The paper scenario (launch at 8 s, an upshift later) with ideal sensors."""
    scenario = load_scenario(SCENARIOS / 'paper_table1.yaml')
    scenario = dataclasses.replace(
        scenario,
        duration=duration_s,
        sensors=dataclasses.replace(scenario.sensors, rate_hz=rate_hz),
    )
    return simulate(load_vehicle(default_vehicle_file()), scenario)


def _rechunk(source: Path, target: Path) -> None:
    """The same messages (same order and log times) in small chunks."""
    reader = BagReader(source)
    with BagWriter(target, chunk_size=CHUNK) as writer:
        for name, info in reader.topics.items():
            writer.add_topic(name, info.msgtype, info.qos_profiles_yaml)
        for m in reader.raw_messages():
            writer.write(m.topic, m.data, m.log_time_ns)


def _messages(bag: Path) -> list[tuple[str, int, bytes]]:
    return [(m.topic, m.log_time_ns, bytes(m.data)) for m in BagReader(bag).raw_messages()]


def _figures(report: ReplayReport) -> dict[str, Any]:
    return {
        f.name: getattr(report, f.name) for f in dataclasses.fields(report) if f.name not in _TIMES
    }


@pytest.fixture(scope='module')
def vd_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """12 s at 100 Hz of vd's own sensor and truth topics, small chunks."""
    folder = tmp_path_factory.mktemp('vd')
    sim = _simulate(12.0, 100.0)
    stamps = np.round(sim.t * 1e9).astype(np.int64) + 1_000_000_000
    write_topic_arrays_bag(folder / 'whole', stamps, sim_topics(sim))
    _rechunk(folder / 'whole', folder / 'bag')
    return folder / 'bag'


@pytest.fixture(scope='module')
def car_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """12 s of a car's standard-types recording (topics on their own clocks), small chunks."""
    folder = tmp_path_factory.mktemp('car')
    write_standard_bag(folder / 'whole', _simulate(12.0, 1000.0), CarSensors(seed=3))
    _rechunk(folder / 'whole', folder / 'bag')
    return folder / 'bag'


def _check(bag: Path, tmp_path: Path, **kwargs: Any) -> ReplayReport:
    """Replay in tiny blocks and in one block; assert the two are equal."""
    blocks = sum(1 for _ in BagReader(bag).topic_array_blocks(block_messages=TINY))
    assert blocks > 100  # boundaries all along the drive
    whole = replay_bag(bag, tmp_path / 'whole', progress=False, block_messages=None, **kwargs)
    tiny = replay_bag(bag, tmp_path / 'tiny', progress=False, block_messages=TINY, **kwargs)
    expected = _messages(tmp_path / 'whole')
    got = _messages(tmp_path / 'tiny')
    assert len(got) == len(expected) == whole.messages_written
    assert got == expected
    assert _figures(tiny) == _figures(whole)
    return whole


@pytest.mark.parametrize('source', ['measured', 'engine'])
def test_vd_topics_in_tiny_blocks_equal_one_block(
    vd_bag: Path, tmp_path: Path, source: str
) -> None:
    report = _check(
        vd_bag, tmp_path, mapping=dataclasses.replace(default_mapping(), torque_source=source)
    )
    assert report.samples == 1201
    # the input summary, accumulated per block, is `input_stats` of each whole input
    mapping = dataclasses.replace(default_mapping(), torque_source=source)
    arrays = BagReader(vd_bag).topic_arrays([s.topic for s in mapping.used_specs])
    expected = tuple(
        input_stats(
            spec,
            decode_engine(spec, arrays[spec.topic])
            if spec.name == ENGINE_INPUT
            else decode_input(spec, arrays[spec.topic]),
            ObserverConfig().max_gap,
        )
        for spec in mapping.used_specs
    )
    assert report.inputs == expected
    offsets = [m for m in BagReader(tmp_path / 'whole').raw_messages()
               if m.topic == ESTIMATES_TORQUE_OFFSET]  # fmt: skip
    if source == 'measured':
        assert offsets == []
        return
    # the clutch slip and the upshift are in the drive: the torque holds on a fifth of the
    # stamps, blocks or not (measured 0.1998, as the whole-bag replay's)
    assert report.torque_valid_fraction == pytest.approx(0.20, abs=0.01)
    # the engine-torque offset where it changes only, blocks or not: the first stamp, and
    # the stamp after the upshift's neutral (one episode; the only one in 12 s)
    decoded = decode_batch('vd_msgs/msg/TorqueOffsetEstimate', [bytes(m.data) for m in offsets])
    sim = _simulate(12.0, 100.0)
    neutral_end = int(np.flatnonzero(np.diff((sim.gear == 0).astype(int)) == -1)[-1]) + 1
    expected_ns = np.round(sim.t[[0, neutral_end]] * 1e9).astype(np.int64) + 1_000_000_000
    np.testing.assert_array_equal(decoded.stamp_ns, expected_ns)
    np.testing.assert_array_equal(decoded.values['episodes'], [0, 1])
    np.testing.assert_array_equal(decoded.values['offset_used'], [0.0, 0.0])  # not converged
    assert abs(decoded.values['offset'][1]) < 0.05  # the map is exact


def test_standard_bag_latest_alignment_in_tiny_blocks_equals_one_block(
    car_bag: Path, tmp_path: Path
) -> None:
    report = _check(car_bag, tmp_path, mapping=mapping_from_dict(STANDARD_MAPPING))
    assert report.samples > 1000 and report.stale >= 1 and report.unmatched > 0


def test_a_bag_out_of_log_time_order_is_replayed_as_one_block(
    vd_bag: Path, tmp_path: Path
) -> None:
    """A truth topic appended after the rest of the drive (earlier log times later in the
    file): the streamed replay notices and starts again in one block, same output."""
    reader = BagReader(vd_bag)
    last = next(t for t in reader.topics if t.startswith(TRUTH_NAMESPACE))
    bag = tmp_path / 'appended'
    with BagWriter(bag, chunk_size=CHUNK) as writer:
        for name, info in reader.topics.items():
            writer.add_topic(name, info.msgtype, info.qos_profiles_yaml)
        for m in reader.raw_messages():
            if m.topic != last:
                writer.write(m.topic, m.data, m.log_time_ns)
        for m in reader.raw_messages([last]):
            writer.write(m.topic, m.data, m.log_time_ns)
    _check(bag, tmp_path)
    logs = [log for _, log, _ in _messages(tmp_path / 'tiny')]
    assert logs == sorted(logs)


def test_a_failed_replay_leaves_no_output(vd_bag: Path, tmp_path: Path) -> None:
    from vd_observer_node.errors import ConfigurationError

    def broken(*args: Any, **kwargs: Any) -> Any:
        raise ConfigurationError('broken cascade')

    with pytest.raises(ConfigurationError, match='broken'):
        replay_bag(vd_bag, tmp_path / 'out', progress=False, cascade=broken, block_messages=TINY)
    assert not (tmp_path / 'out').exists()
    with pytest.raises(ConfigurationError, match='block_messages'):
        replay_bag(vd_bag, tmp_path / 'out', progress=False, block_messages=0)


def test_a_write_failing_while_the_cascade_runs_leaves_no_output(
    vd_bag: Path, tmp_path: Path, monkeypatch: Any
) -> None:
    """The blocks before are written while the next block's cascade runs on a thread: an
    error there (a full disk) ends the replay with that error, as it did in sequence."""
    import threading

    from vd_observer_node.bag import BagDiskFullError
    from vd_observer_node.tools import merged_writer

    real_flush = merged_writer.MergedWriter.flush
    calls = {'n': 0}

    def failing_flush(self: Any, before_ns: int | None) -> None:
        calls['n'] += 1
        if calls['n'] == 3:
            raise BagDiskFullError('disk full (test)')
        real_flush(self, before_ns)

    monkeypatch.setattr(merged_writer.MergedWriter, 'flush', failing_flush)
    with pytest.raises(BagDiskFullError, match='disk full'):
        replay_bag(vd_bag, tmp_path / 'out', progress=False, block_messages=TINY)
    assert calls['n'] == 3
    assert not (tmp_path / 'out').exists()
    assert not [t for t in threading.enumerate() if t.name.startswith(('replay-', 'bag-'))]


def test_an_imu_logged_ahead_of_the_wheels_in_tiny_blocks_equals_one_block(
    tmp_path: Path,
) -> None:
    """The IMU's messages logged 15 ms (1.5 samples) before the wheels' of the same stamp,
    as a recorder that receives the IMU first logs them: a block read by log time then holds
    IMU samples of the next block's stamps, which those stamps must still take (the demo's
    replay lost them at a block boundary and restarted the fusion)."""
    sim = _simulate(12.0, 100.0)
    stamps = np.round(sim.t * 1e9).astype(np.int64) + 1_000_000_000
    write_topic_arrays_bag(tmp_path / 'stamped', stamps, sim_topics(sim, imu=True))
    reader = BagReader(tmp_path / 'stamped')
    ahead = {SENSORS_IMU: 15_000_000}
    rows = sorted(
        (m.log_time_ns - ahead.get(m.topic, 0), m.topic, bytes(m.data))
        for m in reader.raw_messages()
    )
    bag = tmp_path / 'bag'
    with BagWriter(bag, chunk_size=CHUNK) as writer:
        for name, info in reader.topics.items():
            writer.add_topic(name, info.msgtype, info.qos_profiles_yaml)
        for log, topic, data in rows:
            writer.write(topic, data, log)
    imu = {'topic': SENSORS_IMU, 'type': 'sensor_msgs/msg/Imu', 'mount_rpy_deg': [0, 0, 0]}
    report = _check(bag, tmp_path, mapping=mapping_from_dict({'imu': imu}))
    assert 'angular rate used on' in report.imu
