"""recorder_node: a complete bag on SIGINT/SIGTERM; after SIGKILL, `vd bag repair` recovers it.

The simulator publishes a short scenario over the real middleware; the recorder is stopped
by a signal while (or after) the data flows; the bag is then read back with our reader, with
rosbags' rosbag2 Reader and with mcap's reader.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from rosproc import RosProcessGroup
from test_graph import wait_for_last_stamp
from vd_common.topics import SENSORS_WHEEL_ANGLES, TRUTH_SLOPE
from vd_observer_node.bag import BagReader

#: every test here is a long end-to-end run (CI runs it; locally: make test-all)
pytestmark = pytest.mark.slow

SCENARIO = Path(__file__).parent / 'data' / 'short_launch.yaml'


def count(bag: Path, topic: str, *, recover: bool = False) -> int:
    return sum(1 for _ in BagReader(bag, recover=recover).raw_messages([topic]))


@pytest.mark.ros
@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM])
def test_signal_closes_a_complete_bag(procs: RosProcessGroup, tmp_path: Path, sig: int) -> None:
    bag = tmp_path / 'bag'
    rec = procs.node('recorder', 'vd_observer_node', 'recorder_node', output=str(bag))
    rec.wait_for('recording to', timeout=60)
    sim = procs.node(
        'sim',
        'vd_sim_node',
        'sim_node',
        scenario_file=str(SCENARIO),
        rate_hz=100.0,
        real_time_factor=1.0,
        start_delay=1.5,
    )
    waiter = wait_for_last_stamp(
        procs,
        'waiter',
        4_000_000_000,
        {
            SENSORS_WHEEL_ANGLES: 'vd_msgs.msg/WheelAngles',
            TRUTH_SLOPE: 'vd_msgs.msg/Slope',
        },
    )
    sim.wait_for('scenario finished', timeout=60)
    assert waiter.popen.wait(180) == 0, waiter.output()  # the last sample is out
    assert rec.stop(sig) == 0, rec.output()
    assert 'bag closed' in rec.output()
    assert (bag / 'metadata.yaml').is_file()
    assert count(bag, SENSORS_WHEEL_ANGLES) == 401

    from rosbags.rosbag2 import Reader

    with Reader(bag) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
    assert counts[TRUTH_SLOPE] == 401

    from mcap.reader import make_reader

    with (bag / 'bag_0.mcap').open('rb') as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None
    assert {c.compression for c in summary.chunk_indexes} == {'zstd'}


@pytest.mark.ros
def test_the_recorder_says_which_stamps_it_missed(procs: RosProcessGroup, tmp_path: Path) -> None:
    # every third wheel-angle publish of the simulator is refused: 133 of its 401 stamps
    from test_publish_refusals_graph import refusing

    bag = tmp_path / 'bag'
    rec = procs.node('recorder', 'vd_observer_node', 'recorder_node', output=str(bag))
    rec.wait_for('recording to', timeout=60)
    sim = procs.node(
        'sim',
        'vd_sim_node',
        'sim_node',
        scenario_file=str(SCENARIO),
        rate_hz=100.0,
        real_time_factor=1.0,
        start_delay=1.5,
        env=refusing(SENSORS_WHEEL_ANGLES),
    )
    waiter = wait_for_last_stamp(
        procs, 'waiter', 4_000_000_000, {TRUTH_SLOPE: 'vd_msgs.msg/Slope'}
    )
    sim.wait_for('scenario finished', timeout=60)
    assert waiter.popen.wait(180) == 0, waiter.output()
    time.sleep(0.5)  # the recorder writes what is delivered
    assert rec.stop(signal.SIGINT) == 0, rec.output()
    assert count(bag, SENSORS_WHEEL_ANGLES) == 401 - 133
    closing = [line for line in rec.output().splitlines() if 'bag closed' in line]
    assert closing and closing[-1].endswith(f'missed stamps: {SENSORS_WHEEL_ANGLES} 133)'), closing


@pytest.mark.ros
def test_sigkill_loses_at_most_the_open_chunk_and_repair_recovers_the_rest(
    procs: RosProcessGroup, tmp_path: Path
) -> None:
    bag = tmp_path / 'bag'
    rec = procs.node(
        'recorder',
        'vd_observer_node',
        'recorder_node',
        output=str(bag),
        chunk_duration=0.5,
    )
    rec.wait_for('recording to', timeout=60)
    sim = procs.node(
        'sim',
        'vd_sim_node',
        'sim_node',
        scenario_file=str(SCENARIO),
        rate_hz=100.0,
        real_time_factor=1.0,
        start_delay=1.5,
        progress_period=0.5,
    )
    sim.wait_for('progress t=0.0', timeout=60)
    time.sleep(3.0)  # ~3 s of data at real time, then power cut for the recorder
    rec.stop(signal.SIGKILL)
    sim_t = _sim_time_now(sim.output())
    assert not (bag / 'metadata.yaml').exists()

    result = subprocess.run(
        [sys.executable, '-m', 'vd_observer_node.tools.cli', 'bag', 'repair', str(bag)],
        capture_output=True,
        text=True,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    assert (bag / 'metadata.yaml').is_file()
    recovered = count(bag, SENSORS_WHEEL_ANGLES)
    # at 100 Hz, the open chunk holds at most chunk_duration (0.5 s) + the 0.1 s flush timer
    assert recovered >= (sim_t - 0.6 - 0.5) * 100, (recovered, sim_t)
    assert count(bag, SENSORS_WHEEL_ANGLES, recover=False) == recovered


def _sim_time_now(log: str) -> float:
    """Rough simulated time reached (from the last progress line) [s]."""
    import re

    found = re.findall(r'progress t=([0-9.]+)/', log)
    return float(found[-1]) if found else 0.0
