"""The whole graph as separate processes over the real middleware, recorded to an MCAP bag.

sim_node (short scenario) -> observer_node -> estimator_node, all recorded by recorder_node.
Then: the estimates arrived for every sensor stamp, are finite, carry the measurement
stamps, follow the truth, and are exactly what the offline cascade (`vd replay`) computes
from the recorded sensors. A second part plays the recorded sensors back with player_node
(live replay, use_sim_time) and checks that the observers recompute the same estimates.
"""

from __future__ import annotations

import itertools
import math
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosproc import RosProcessGroup, wait_recording
from vd_common.topics import (
    ESTIMATES_FRICTION,
    ESTIMATES_RESISTANCES,
    ESTIMATES_SLOPE,
    ESTIMATES_TIRE_FORCES,
    SENSORS_WHEEL_ANGLES,
    SENSORS_WHEEL_TORQUES,
    TRUTH_SLOPE,
    TRUTH_TIRE_FORCES,
)
from vd_observer_node.bag import BagReader
from vd_observer_node.tools.replay import replay_bag

#: every test here is a long end-to-end run (CI runs it; locally: make test-all)
pytestmark = pytest.mark.slow

SCENARIO = Path(__file__).parent / 'data' / 'short_launch.yaml'
WAIT_FOR_STAMP = Path(__file__).parent / 'ros_scripts' / 'wait_for_stamp.py'
RATE_HZ = 100.0
N_SAMPLES = 401  # 4 s at 100 Hz, t = 0 inclusive
LAST_STAMP_NS = 4_000_000_000
ESTIMATE_TOPICS = [
    ESTIMATES_TIRE_FORCES,
    ESTIMATES_FRICTION,
    ESTIMATES_RESISTANCES,
    ESTIMATES_SLOPE,
]


def stamp_ns(msg: Any) -> int:
    return int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)


def by_topic(bag: Path, topics: list[str]) -> dict[str, dict[int, Any]]:
    """Decoded messages per topic, keyed by header stamp [ns]."""
    out: dict[str, dict[int, Any]] = defaultdict(dict)
    for topic, _, _, msg in BagReader(bag).messages(topics):
        out[topic][stamp_ns(msg)] = msg
    return out


def wait_exit(proc: Any, timeout: float) -> int:
    deadline = time.monotonic() + timeout
    while proc.popen.poll() is None and time.monotonic() < deadline:
        time.sleep(0.1)
    assert proc.popen.poll() is not None, f'{proc.name} did not finish:\n{proc.output()[-3000:]}'
    return int(proc.popen.returncode)


def wait_for_last_stamp(
    procs: RosProcessGroup, name: str, stamp_ns: int, topics: dict[str, str]
) -> Any:
    """A process that exits 0 once each topic has carried `stamp_ns` (started, subscribed).

    Graph tests wait on it, with a generous bound, instead of sleeping until the last sample
    has gone through the nodes: on a loaded machine no sleep is long enough.
    """
    args = [f'{topic}={kind}' for topic, kind in topics.items()]
    waiter = procs.python(name, WAIT_FOR_STAMP, str(stamp_ns), '180', *args)
    waiter.wait_for('SUBSCRIBED', timeout=60)
    return waiter


ESTIMATES_DONE = {
    ESTIMATES_SLOPE: 'vd_msgs.msg/Slope',
    ESTIMATES_TIRE_FORCES: 'vd_msgs.msg/TireForces',
    ESTIMATES_FRICTION: 'vd_msgs.msg/Friction',
    ESTIMATES_RESISTANCES: 'vd_msgs.msg/Resistances',
}


def run_live_graph(procs: RosProcessGroup, bag: Path) -> None:
    rec = procs.node('recorder', 'vd_observer_node', 'recorder_node', output=str(bag))
    obs = procs.node('observer', 'vd_observer_node', 'observer_node')
    est = procs.node('estimator', 'vd_observer_node', 'estimator_node')
    for proc, text in ((rec, 'recording to'), (obs, 'observer ready'), (est, 'estimator ready')):
        proc.wait_for(text, timeout=60)
    wait_recording(rec, ESTIMATE_TOPICS)  # the observer's and estimator's publishers
    waiter = wait_for_last_stamp(procs, 'waiter', LAST_STAMP_NS, ESTIMATES_DONE)
    # the simulator itself waits until its streams have subscribers and discovery settled
    sim = procs.node(
        'sim',
        'vd_sim_node',
        'sim_node',
        scenario_file=str(SCENARIO),
        rate_hz=RATE_HZ,
        real_time_factor=1.0,
        min_sensor_subscribers=2,  # the recorder and an estimation node on every sensor topic
    )
    assert wait_exit(sim, 60) == 0, sim.output()
    assert 'scenario finished' in sim.output()
    assert wait_exit(waiter, 180) == 0, waiter.output()  # the last sample went through
    for proc in (est, obs, rec):
        assert proc.stop() == 0, proc.output()[-3000:]
    assert 'bag closed' in rec.output(), rec.output()[-3000:]


@pytest.mark.ros
def test_live_graph_estimates_every_sample_and_matches_the_offline_cascade(
    procs: RosProcessGroup, tmp_path: Path
) -> None:
    bag = tmp_path / 'live'
    run_live_graph(procs, bag)

    topics = [
        SENSORS_WHEEL_ANGLES,
        SENSORS_WHEEL_TORQUES,
        TRUTH_SLOPE,
        TRUTH_TIRE_FORCES,
        *ESTIMATE_TOPICS,
    ]
    live = by_topic(bag, topics)
    sensor_stamps = sorted(live[SENSORS_WHEEL_ANGLES])
    assert len(sensor_stamps) == N_SAMPLES, 'the recorder lost sensor samples'
    assert sensor_stamps[0] == 0 and sensor_stamps[-1] == 4_000_000_000
    for topic in ESTIMATE_TOPICS:
        # every estimate carries the stamp of a measurement, and none is missing
        assert sorted(live[topic]) == sensor_stamps, topic

    for msg in live[ESTIMATES_TIRE_FORCES].values():
        assert all(math.isfinite(v) for v in [*msg.fx, *msg.fz])
    # after the slope step (2.0 s) and settling, the slope estimate follows the truth,
    # away from gear shifts (torque interruptions), as in the accuracy targets
    gears = live[SENSORS_WHEEL_TORQUES]
    shifts = [s for a, s in itertools.pairwise(sensor_stamps) if gears[s].gear != gears[a].gear]
    late = [
        s
        for s in sensor_stamps
        if s >= 3_000_000_000 and all(abs(s - k) > 500_000_000 for k in shifts)
    ]
    assert len(late) > 20
    err = [live[ESTIMATES_SLOPE][s].angle - live[TRUTH_SLOPE][s].angle for s in late]
    assert max(abs(e) for e in err) < math.radians(1.0), np.degrees(err)
    fx_err = [
        np.subtract(live[ESTIMATES_TIRE_FORCES][s].fx, live[TRUTH_TIRE_FORCES][s].fx) for s in late
    ]
    fx_scale = max(abs(v) for s in late for v in live[TRUTH_TIRE_FORCES][s].fx)
    assert np.max(np.abs(fx_err)) < 0.05 * fx_scale

    # offline replay of the recorded sensors computes exactly the live estimates
    offline_bag = tmp_path / 'offline'
    replay_bag(bag, offline_bag, progress=False)
    offline = by_topic(offline_bag, ESTIMATE_TOPICS)
    for s in sensor_stamps:
        a, b = live[ESTIMATES_TIRE_FORCES][s], offline[ESTIMATES_TIRE_FORCES][s]
        np.testing.assert_allclose(a.fx, b.fx, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(a.fz, b.fz, rtol=1e-9, atol=1e-9)
        a, b = live[ESTIMATES_SLOPE][s], offline[ESTIMATES_SLOPE][s]
        assert a.angle == pytest.approx(b.angle, rel=1e-9, abs=1e-12)
        assert a.valid == b.valid

    # live replay: the player plays the recorded sensors, the observers recompute
    replay = tmp_path / 'replayed'
    rec = procs.node('recorder2', 'vd_observer_node', 'recorder_node', output=str(replay))
    obs = procs.node('observer2', 'vd_observer_node', 'observer_node', use_sim_time=True)
    est = procs.node('estimator2', 'vd_observer_node', 'estimator_node', use_sim_time=True)
    for proc, text in ((rec, 'recording to'), (obs, 'observer ready'), (est, 'estimator ready')):
        proc.wait_for(text, timeout=60)
    wait_recording(rec, [ESTIMATES_SLOPE, ESTIMATES_TIRE_FORCES])
    waiter = wait_for_last_stamp(procs, 'waiter2', LAST_STAMP_NS, ESTIMATES_DONE)
    # start_delay: time for the observers' publishers and the recorder to discover each other
    player = procs.node(
        'player',
        'vd_observer_node',
        'player_node',
        bag=str(bag),
        rate=1.0,
        start_delay=2.0,
        min_subscribers=2,
    )
    assert wait_exit(player, 60) == 0, player.output()
    assert wait_exit(waiter, 180) == 0, waiter.output()
    for proc in (est, obs, rec):
        assert proc.stop() == 0, proc.output()[-3000:]
    again = by_topic(replay, [ESTIMATES_SLOPE, ESTIMATES_TIRE_FORCES])
    assert sorted(again[ESTIMATES_SLOPE]) == sensor_stamps
    for s in sensor_stamps:
        a, b = live[ESTIMATES_SLOPE][s], again[ESTIMATES_SLOPE][s]
        assert a.angle == pytest.approx(b.angle, rel=1e-9, abs=1e-12)
