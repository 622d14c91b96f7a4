"""Live nodes fed by a user's topics with standard types through an input mapping.

A publisher (tests/ros_scripts/publish_std_inputs.py) sends sensor_msgs/JointState,
nav_msgs/Odometry (km/h) and std_msgs/Float64MultiArray (kN m, no header); pipeline_node,
given the mapping as ``inputs.*`` parameters in a ROS params file, publishes finite estimates,
reports the torque topic on /diagnostics while it is silent and is back to OK after. Bad
mappings end the nodes at start with one line naming the key.
"""

from __future__ import annotations

import re
import time
from pathlib import Path

import pytest
import yaml
from rosproc import RosProcess, RosProcessGroup
from vd_sim_node.topics import ESTIMATES_SLOPE, ESTIMATES_TIRE_FORCES, OBSERVER_WHEEL_STATES

SCRIPTS = Path(__file__).resolve().parent / 'ros_scripts'
#: the mapping of publish_std_inputs.py's topics, in the mapping file's form
MAPPING = {
    'wheel_angles': {
        'topic': '/joint_states',
        'type': 'sensor_msgs/msg/JointState',
        'joints': ['wheel_fl_joint', 'wheel_fr_joint', 'wheel_rl_joint', 'wheel_rr_joint'],
        'sign': [1, -1, 1, -1],
    },
    'body_speed': {'topic': '/odom', 'type': 'nav_msgs/msg/Odometry', 'unit': 'km/h'},
    'wheel_torques': {
        'topic': '/can/wheel_torques',
        'type': 'std_msgs/msg/Float64MultiArray',
        'indices': [0, 1, 2, 3],
        'unit': 'kN m',
    },
}
RATE_HZ = 200.0
DURATION_S = 9.0
PAUSE_S = (3.0, 5.5)  # the torque topic is silent meanwhile


def params_file(path: Path, mapping: dict[str, dict[str, object]], **extra: object) -> Path:
    """A ROS params file for every node ('/**') carrying `mapping` as inputs.* parameters."""
    flat = {
        f'inputs.{name}.{key}': value
        for name, settings in mapping.items()
        for key, value in settings.items()
    }
    path.write_text(
        yaml.safe_dump({'/**': {'ros__parameters': {**flat, **extra}}}), encoding='utf-8'
    )
    return path


def _start(procs: RosProcessGroup, name: str, exe: str, params: Path) -> RosProcess:
    from vd_observer_node.testing.launcher import NodeSpec

    argv = [*NodeSpec('vd_observer_node', exe, name, {}).argv(), '--params-file', str(params)]
    return procs.start(name, argv)


def _wait_exit(proc: RosProcess, timeout: float) -> int:
    deadline = time.monotonic() + timeout
    while proc.popen.poll() is None and time.monotonic() < deadline:
        time.sleep(0.1)
    code = proc.popen.poll()
    assert code is not None, f'{proc.name} still running:\n{proc.output()}'
    return code


@pytest.mark.ros
def test_pipeline_node_runs_on_standard_types_and_reports_a_stopped_topic(
    procs: RosProcessGroup, tmp_path: Path
) -> None:
    pipe = _start(procs, 'pipeline', 'pipeline_node', params_file(tmp_path / 'p.yaml', MAPPING))
    pipe.wait_for('pipeline ready', timeout=90)
    collector = procs.python(
        'collector',
        SCRIPTS / 'collect_outputs.py',
        str(DURATION_S + 6.0),
        f'{OBSERVER_WHEEL_STATES}=vd_msgs.msg/WheelStates',
        f'{ESTIMATES_TIRE_FORCES}=vd_msgs.msg/TireForces',
        f'{ESTIMATES_SLOPE}=vd_msgs.msg/Slope',
    )
    collector.wait_for('SUBSCRIBED', timeout=60)
    publisher = procs.python(
        'publisher',
        SCRIPTS / 'publish_std_inputs.py',
        str(RATE_HZ),
        str(DURATION_S),
        *(str(s) for s in PAUSE_S),
    )
    publisher.wait_for('DONE', timeout=90)
    assert _wait_exit(collector, 60) == 0
    lines = collector.output().splitlines()
    msgs = [line.split() for line in lines if line.startswith('MSG ')]
    for topic in (OBSERVER_WHEEL_STATES, ESTIMATES_TIRE_FORCES, ESTIMATES_SLOPE):
        flags = [m[3] for m in msgs if m[1] == topic]
        # Estimates for the samples with torque: well over half of them, each one finite.
        assert len(flags) > 0.5 * RATE_HZ * (DURATION_S - (PAUSE_S[1] - PAUSE_S[0])), topic
        assert set(flags) == {'1'}, topic
    diags = [line for line in lines if line.startswith('DIAG vd: pipeline')]
    # the torque topic alone silent (the pause), then every topic at the end of the run
    stopped = [
        i
        for i, d in enumerate(diags)
        if re.search(r'/can/wheel_torques stopped: no message for \d', d)
        and '/joint_states' not in d
    ]
    assert stopped, '\n'.join(diags)
    assert all(diags[i].split()[3] in ('1', '2') for i in stopped)  # WARN (or worse)
    end = next((i for i, d in enumerate(diags) if '/joint_states stopped' in d), len(diags))
    # back to OK once the topic resumes: the statuses between the pause and the end
    after = diags[stopped[-1] + 1 : end]
    assert after and all('stopped' not in d for d in after), '\n'.join(diags)
    assert diags[end - 1].split()[3] == '0', '\n'.join(diags)
