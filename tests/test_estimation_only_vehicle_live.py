"""Every node runs with an estimation-only vehicle file (no ``tire``).

pipeline_node, given a file with only the estimators' keys, publishes its estimates from a
car's standard-type topics (tests/ros_scripts/publish_std_inputs.py), says once in its log
that the friction potential and the alerts are off and why, does not publish them, and shows
the note on /diagnostics at level OK. alerts_node, given the same file, starts, says it has
nothing to do and why, and stays up.
"""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml
from rosproc import RosProcess, RosProcessGroup
from test_input_mapping_live import MAPPING, params_file
from vd_common.topics import ESTIMATES_ALERTS, ESTIMATES_FRICTION_POTENTIAL, ESTIMATES_SLOPE
from vd_common.vehicle.params import default_vehicle_file

SCRIPTS = Path(__file__).resolve().parent / 'ros_scripts'
RATE_HZ = 200.0
DURATION_S = 4.0
#: the estimators' keys only (docs/vehicle_file.md): no tyre, no simulator section
ESTIMATION_KEYS = ('name', 'chassis', 'wheel', 'aero', 'rolling_resistance')
CHASSIS = ('mass', 'wheelbase', 'cg_to_front_axle', 'cg_height')
WHEEL = ('inertia_front', 'inertia_rear', 'effective_radius')


def _estimation_only_file(path: Path) -> Path:
    """The shipped Clio's estimation keys alone (gravity left to its default)."""
    clio = yaml.safe_load(default_vehicle_file().read_text(encoding='utf-8'))
    data = {key: clio[key] for key in ESTIMATION_KEYS}
    data['chassis'] = {key: clio['chassis'][key] for key in CHASSIS}
    data['wheel'] = {key: clio['wheel'][key] for key in WHEEL}
    path.write_text(yaml.safe_dump(data), encoding='utf-8')
    return path


def _start(procs: RosProcessGroup, name: str, exe: str, params: Path) -> RosProcess:
    from vd_observer_node.testing.launcher import NodeSpec

    argv = [*NodeSpec('vd_observer_node', exe, name, {}).argv(), '--params-file', str(params)]
    return procs.start(name, argv)


@pytest.mark.ros  # about 15 s
def test_the_nodes_run_with_an_estimation_only_vehicle_file(
    procs: RosProcessGroup, tmp_path: Path
) -> None:
    car = _estimation_only_file(tmp_path / 'car.yaml')
    params = params_file(tmp_path / 'p.yaml', MAPPING, vehicle_file=str(car))
    pipe = _start(procs, 'pipeline', 'pipeline_node', params)
    alerts = _start(procs, 'alerts', 'alerts_node', params)
    log = pipe.wait_for('pipeline ready', timeout=300)
    log = pipe.wait_for('every estimate runs', timeout=5)
    off = [
        line for line in log.splitlines() if 'friction potential and alerts off (no tire' in line
    ]
    assert len(off) == 1 and str(car) in off[0], log
    alerts_log = alerts.wait_for('nothing to do', timeout=300)
    assert f'no tire in vehicle file {car}' in alerts_log
    collector = procs.python(
        'collector',
        SCRIPTS / 'collect_outputs.py',
        str(DURATION_S + 5.0),
        f'{ESTIMATES_SLOPE}=vd_msgs.msg/Slope',
    )
    # never SUBSCRIBED: nobody publishes these two; any MSG line would be a failure
    silent = procs.python(
        'silent',
        SCRIPTS / 'collect_outputs.py',
        str(DURATION_S + 5.0),
        f'{ESTIMATES_ALERTS}=vd_msgs.msg/Alerts',
        f'{ESTIMATES_FRICTION_POTENTIAL}=vd_msgs.msg/FrictionPotential',
    )
    collector.wait_for('SUBSCRIBED', timeout=60)
    publisher = procs.python(
        'publisher', SCRIPTS / 'publish_std_inputs.py', str(RATE_HZ), str(DURATION_S)
    )
    publisher.wait_for('DONE', timeout=90)
    for proc in (collector, silent):
        assert proc.popen.wait(timeout=60) == 0, proc.output()
    lines = collector.output().splitlines()
    slopes = [line.split() for line in lines if line.startswith(f'MSG {ESTIMATES_SLOPE} ')]
    assert len(slopes) > 0.5 * RATE_HZ * DURATION_S, len(slopes)
    assert {m[3] for m in slopes} == {'1'}  # finite
    assert sum(m[5] == '1' for m in slopes) > 0.5 * len(slopes)  # valid slope estimates
    pipe_diags = [line for line in lines if line.startswith('DIAG vd: pipeline ')]
    # OK while fed, with the note (the stopped inputs' WARN after the run takes the message)
    fed = [d for d in pipe_diags if d.split()[3] == '0']
    assert fed, '\n'.join(pipe_diags)
    assert all('ok; friction potential and alerts off: no tire' in d for d in fed), fed
    alert_diags = [line for line in lines if line.startswith('DIAG vd: alerts ')]
    assert alert_diags and all(d.split()[3] == '0' for d in alert_diags), '\n'.join(alert_diags)
    assert all('off: no tire in the vehicle file' in d for d in alert_diags)
    silent_out = silent.output()
    assert 'MSG ' not in silent_out and 'SUBSCRIBED' not in silent_out, silent_out
    # both stay up (a launch file of the whole graph must not die)
    assert pipe.popen.poll() is None, pipe.output()
    assert alerts.popen.poll() is None, alerts.output()
