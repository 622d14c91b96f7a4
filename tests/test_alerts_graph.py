"""alerts_node in the live graph: hard braking on a low-friction patch raises a lock alert.

sim_node (braking_low_mu_hard: 80 % brake at 12 s on a mu 0.3 patch) -> observer_node ->
estimator_node -> alerts_node, recorded; the bag must show a front-wheel lock alert whose
onset stamp lies just after the brake application, finite friction-potential estimates, and
every alert carrying the stamp of a measurement.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from rosproc import RosProcessGroup
from test_graph import wait_for_last_stamp
from vd_common.topics import ESTIMATES_ALERTS, ESTIMATES_FRICTION_POTENTIAL, SENSORS_WHEEL_ANGLES
from vd_observer_node.bag import BagReader

from vd_msgs.msg import Alert

#: every test here is a long end-to-end run (CI runs it; locally: make test-all)
pytestmark = pytest.mark.slow

NS = 1_000_000_000


@pytest.mark.ros
def test_lock_alert_on_hard_braking_over_low_friction(
    procs: RosProcessGroup, tmp_path: Path
) -> None:
    bag = tmp_path / 'bag'
    rec = procs.node('recorder', 'vd_observer_node', 'recorder_node', output=str(bag))
    others = [
        procs.node('observer', 'vd_observer_node', 'observer_node'),
        procs.node('estimator', 'vd_observer_node', 'estimator_node'),
        procs.node('alerts', 'vd_observer_node', 'alerts_node'),
    ]
    for proc, text in zip(
        [rec, *others],
        ['recording to', 'observer ready', 'estimator ready', 'alerts ready'],
        strict=True,
    ):
        proc.wait_for(text, timeout=60)
    waiter = wait_for_last_stamp(
        procs,
        'waiter',
        16 * NS,  # braking_low_mu_hard lasts 16 s
        {ESTIMATES_ALERTS: 'vd_msgs.msg/Alerts'},
    )
    sim = procs.node(
        'sim',
        'vd_sim_node',
        'sim_node',
        scenario_file='braking_low_mu_hard',
        rate_hz=100.0,
        real_time_factor=0.5,
    )
    sim.wait_for('scenario finished', timeout=120)
    assert waiter.popen.wait(180) == 0, waiter.output()  # the last stamp went through
    for proc in [*reversed(others), rec]:
        assert proc.stop() == 0, proc.output()[-3000:]

    reader = BagReader(bag)
    sensor_stamps = {
        m.header.stamp.sec * NS + m.header.stamp.nanosec
        for _, _, _, m in reader.messages([SENSORS_WHEEL_ANGLES])
    }
    alerts = [m for _, _, _, m in reader.messages([ESTIMATES_ALERTS])]
    potential = [m for _, _, _, m in reader.messages([ESTIMATES_FRICTION_POTENTIAL])]
    assert len(alerts) > 0.9 * len(sensor_stamps)
    assert all(a.header.stamp.sec * NS + a.header.stamp.nanosec in sensor_stamps for a in alerts)
    assert all(math.isfinite(x) for p in potential for x in [*p.mu_max, *p.confidence])

    lock_onsets = sorted(
        a.onset.sec + a.onset.nanosec * 1e-9
        for m in alerts
        for a in m.alerts
        if a.kind == Alert.KIND_LOCK and a.active and a.wheel in (Alert.FL, Alert.FR)
    )
    assert lock_onsets, 'no front-wheel lock alert while braking on mu 0.3'
    assert 12.0 <= lock_onsets[0] <= 12.3, lock_onsets[:5]
