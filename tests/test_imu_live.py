"""The IMU watched live like the other inputs (issue 41, item 3).

pipeline_node is given the standard-types mapping of `test_input_mapping_live` plus an IMU as
``inputs.imu.*`` parameters in a ROS params file; the publisher sends every input but the
IMU. The node estimates with the force balance (``Slope.sources`` = 1) and says on
/diagnostics, as for any mapped input that never arrives, that the IMU has sent nothing.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from rosproc import RosProcessGroup
from test_input_mapping_live import MAPPING, RATE_HZ, SCRIPTS, _start, _wait_exit, params_file
from vd_common.topics import ESTIMATES_SLOPE

DURATION_S = 6.0


@pytest.mark.slow
@pytest.mark.ros
def test_pipeline_node_reports_a_mapped_imu_that_never_arrives(
    procs: RosProcessGroup, tmp_path: Path
) -> None:
    imu = {'topic': '/imu', 'type': 'sensor_msgs/msg/Imu', 'fusion': {'tau': 0.4}}
    params = params_file(tmp_path / 'p.yaml', {**MAPPING, 'imu': imu})
    pipe = _start(procs, 'pipeline', 'pipeline_node', params)
    pipe.wait_for('pipeline ready', timeout=90)
    collector = procs.python(
        'collector',
        SCRIPTS / 'collect_outputs.py',
        str(DURATION_S + 4.0),
        f'{ESTIMATES_SLOPE}=vd_msgs.msg/Slope',
    )
    collector.wait_for('SUBSCRIBED', timeout=60)
    publisher = procs.python(
        'publisher', SCRIPTS / 'publish_std_inputs.py', str(RATE_HZ), str(DURATION_S)
    )
    publisher.wait_for('DONE', timeout=90)
    assert _wait_exit(collector, 60) == 0
    lines = collector.output().splitlines()
    slopes = [line.split() for line in lines if line.startswith(f'MSG {ESTIMATES_SLOPE} ')]
    # the force balance's slope goes on without the IMU, every sample finite
    assert len(slopes) > 0.5 * RATE_HZ * DURATION_S
    assert {s[3] for s in slopes} == {'1'}
    diags = [line for line in lines if line.startswith('DIAG vd: pipeline')]
    silent = [d for d in diags if 'no message on /imu yet' in d and '/joint_states' not in d]
    assert silent, '\n'.join(diags)
    assert all(d.split()[3] in ('1', '2') for d in silent)  # WARN (or worse)
