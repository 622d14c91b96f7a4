"""A publish the middleware refuses ends no node (issue: `make demo` died twice of one).

Observer and estimator run as separate processes with every third publish on one of their
topics refused (``RCLError: cannot publish data``, made at rclpy's boundary by
``ros_scripts/refuse_publishes``); the simulator drives them through a short scenario. Both
nodes live on, keep publishing, log the first refusal once, put a WARN that names the topic
on /diagnostics and stop cleanly; the simulator ends its scenario with one INFO line and exit
code 0, without the executor's FATAL of a callback that raised.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest
from rosproc import RosProcessGroup
from test_graph import wait_exit, wait_for_last_stamp
from vd_common.topics import ESTIMATES_SLOPE, OBSERVER_BODY_ACCEL

#: every test here is a long end-to-end run (CI runs it; locally: make test-all)
pytestmark = pytest.mark.slow

SCENARIO = Path(__file__).parent / 'data' / 'short_launch.yaml'
COLLECT = Path(__file__).parent / 'ros_scripts' / 'collect_outputs.py'
INJECT = Path(__file__).parent / 'ros_scripts' / 'refuse_publishes'
N_SAMPLES = 401  # 4 s at 100 Hz, t = 0 inclusive


def refusing(topic: str, every: int = 3) -> dict[str, str]:
    """Environment of a node process whose every `every`-th publish on `topic` is refused."""
    path = os.environ.get('PYTHONPATH', '')
    return {
        'PYTHONPATH': f'{INJECT}{os.pathsep}{path}' if path else str(INJECT),
        'VD_TEST_REFUSE_TOPICS': topic,
        'VD_TEST_REFUSE_EVERY': str(every),
    }


@pytest.mark.ros
def test_refused_publishes_are_counted_reported_and_survived(procs: RosProcessGroup) -> None:
    obs = procs.node(
        'observer', 'vd_observer_node', 'observer_node', env=refusing(OBSERVER_BODY_ACCEL)
    )
    est = procs.node(
        'estimator', 'vd_observer_node', 'estimator_node', env=refusing(ESTIMATES_SLOPE)
    )
    for proc, text in ((obs, 'observer ready'), (est, 'estimator ready')):
        proc.wait_for(text, timeout=60)
    collect = procs.python('collect', COLLECT, '40', f'{ESTIMATES_SLOPE}=vd_msgs.msg/Slope')
    collect.wait_for('SUBSCRIBED', timeout=60)
    waiter = wait_for_last_stamp(
        procs, 'waiter', 4_000_000_000, {ESTIMATES_SLOPE: 'vd_msgs.msg/Slope'}
    )
    sim = procs.node(
        'sim',
        'vd_sim_node',
        'sim_node',
        scenario_file=str(SCENARIO),
        rate_hz=100.0,
        real_time_factor=1.0,
    )
    assert wait_exit(sim, 60) == 0, sim.output()
    sim_out = sim.output()
    assert sim_out.count('scenario finished') == 1, sim_out
    assert 'FATAL' not in sim_out and 'Traceback' not in sim_out, sim_out
    # the last sample went through the observer and the estimator, despite the refusals
    assert wait_exit(waiter, 180) == 0, waiter.output()
    collect.wait_for('DIAG vd: estimator 1', timeout=30)
    collect.wait_for('DIAG vd: observer 1', timeout=30)
    for proc in (obs, est):
        assert proc.popen.poll() is None, f'{proc.name} died:\n{proc.output()[-3000:]}'
    assert wait_exit(collect, 60) == 0
    out = collect.output()

    # The rest came. The estimator estimates every stamp, a refused body acceleration
    # replaced by the one before ('latest' alignment), and every third of its slopes was
    # refused.
    slopes = {int(line.split()[2]) for line in out.splitlines() if line.startswith('MSG ')}
    assert len(slopes) == N_SAMPLES - N_SAMPLES // 3, len(slopes)
    # the WARN names what was refused, where
    warnings = re.findall(r'^DIAG vd: (observer|estimator) 1 (.*)$', out, re.M)
    for name, topic in (('observer', OBSERVER_BODY_ACCEL), ('estimator', ESTIMATES_SLOPE)):
        said = f'publishes refused by the middleware ({topic})'
        assert any(n == name and said in msg for n, msg in warnings), warnings
    for proc, topic in ((obs, OBSERVER_BODY_ACCEL), (est, ESTIMATES_SLOPE)):
        text = proc.output()
        assert text.count(f'publish refused on {topic}') == 1, text[-3000:]
        assert 'Traceback' not in text, text[-3000:]
        assert proc.stop() == 0, proc.output()[-3000:]
