"""sim_node in lockstep: a consumer slower than the simulator loses nothing; in real time it does.

A 1 kHz scenario (4 001 samples) feeds a consumer that spends 2 ms on each wheel-angle
message (so at most 500 Hz) and reports its progress as a Header. In real time its queue of
1 000 overflows and samples are lost; in lockstep on its progress the simulator waits, every
sample arrives, and the recorder, followed through its own progress topic, has every message
of every sensor and truth topic in its bag.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from rosproc import RosProcessGroup, wait_recording
from test_graph import wait_exit
from vd_common.topics import (
    SENSORS,
    SENSORS_WHEEL_ANGLES,
    STATUS_RECORDER_PROGRESS,
    TRUTH,
)
from vd_observer_node.bag import BagReader

#: every test here is a long end-to-end run (CI runs it; locally: make test-all)
pytestmark = pytest.mark.slow

SCENARIO = Path(__file__).parent / 'data' / 'short_launch.yaml'
SLOW = Path(__file__).parent / 'ros_scripts' / 'slow_consumer.py'
RATE_HZ = 1000.0
N_SAMPLES = 4001  # 4 s at 1 kHz, t = 0 inclusive
LAST_STAMP_NS = 4_000_000_000
PROGRESS = '/lockstep_test/progress'  # the slow consumer's


def run(procs: RosProcessGroup, lockstep: str, bag: Path | None = None) -> tuple[str, str]:
    """Start the slow consumer (and a recorder), run the scenario; their outputs."""
    rec = None
    if bag is not None:
        rec = procs.node('recorder', 'vd_observer_node', 'recorder_node', output=str(bag))
        rec.wait_for('recording to', timeout=60)
    slow = procs.python(
        'slow',
        SLOW,
        f'{SENSORS_WHEEL_ANGLES}=vd_msgs.msg/WheelAngles',
        PROGRESS,
        '0.002',
        str(LAST_STAMP_NS),
        '120',
    )
    sim = procs.node(
        'sim',
        'vd_sim_node',
        'sim_node',
        scenario_file=str(SCENARIO),
        rate_hz=RATE_HZ,
        real_time_factor=1.0,
        min_sensor_subscribers=2 if rec is not None else 1,
        **(
            {'lockstep_topics': lockstep, 'lockstep_window': 0.1, 'lockstep_timeout': 30.0}
            if lockstep
            else {}
        ),
    )
    slow.wait_for('SUBSCRIBED', timeout=60)
    if rec is not None:
        wait_recording(rec, [SENSORS_WHEEL_ANGLES])
    assert wait_exit(sim, 150) == 0, sim.output()[-3000:]
    assert wait_exit(slow, 150) == 0, slow.output()[-3000:]
    if rec is not None:
        assert rec.stop() == 0, rec.output()[-3000:]
    out = sim.output()
    assert out.count('scenario finished') == 1, out
    assert 'FATAL' not in out and 'gave up' not in out and 'going on without' not in out, out
    return out, slow.output()


def got(output: str) -> tuple[int, int, int, int]:
    line = next(line for line in output.splitlines() if line.startswith('GOT '))
    n, first, last, gap = (int(v) for v in line.split()[1:])
    return n, first, last, gap


@pytest.mark.ros
def test_in_real_time_a_slow_consumer_loses_samples(procs: RosProcessGroup) -> None:
    _, slow = run(procs, lockstep='')
    n, _, last, gap = got(slow)
    # it took the last sample, but not every one: its queue of 1000 overflowed
    assert last == LAST_STAMP_NS
    assert n < N_SAMPLES - 500 and gap > 1_000_000, (n, gap)


@pytest.mark.ros
def test_in_lockstep_a_slow_consumer_and_the_recorder_miss_nothing(
    procs: RosProcessGroup, tmp_path: Path
) -> None:
    bag = tmp_path / 'bag'
    sim, slow = run(procs, lockstep=f'{PROGRESS},{STATUS_RECORDER_PROGRESS}', bag=bag)
    assert 'lockstep on ' in sim
    assert got(slow) == (N_SAMPLES, 0, LAST_STAMP_NS, 1_000_000)
    counts = {topic: info.message_count for topic, info in BagReader(bag).topics.items()}
    for topic in [*SENSORS, *TRUTH]:
        assert counts.get(topic) == N_SAMPLES, (topic, counts.get(topic))
    assert STATUS_RECORDER_PROGRESS not in counts  # progress is not data
