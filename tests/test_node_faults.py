"""Faults through the live nodes (separate processes): bad sensor data, bad parameters and an
unwritable recorder output. Nodes survive, publish only finite values, say what happened on
/diagnostics and recover; refused settings end the process with one clear line."""

from __future__ import annotations

import json
import textwrap
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from rosproc import RosProcess, RosProcessGroup

ROOT = Path(__file__).resolve().parents[1]
VEHICLE_FILE = ROOT / 'src' / 'vd_common' / 'config' / 'clio_rl_1_1.yaml'

# One process publishes the crafted sensor stream and records everything the nodes publish.
FEED_AND_CAPTURE = textwrap.dedent(
    """
    import json, math, os, sys, threading, time
    import numpy as np
    import rclpy
    import rclpy.executors
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import TwistStamped
    from rclpy.node import Node
    from vd_msgs.msg import Friction, Slope, TireForces, WheelAngles, WheelStates, WheelTorques
    from vd_observer_node.testing.synthetic import synthetic_trajectory
    from vd_observer_node.estimation.vehicle import load_estimator_vehicle
    from vd_common.ros.qos import DIAGNOSTICS_QOS, STREAM_QOS
    from vd_common.ros.stamps import ns_to_time
    from vd_common import topics
    from vd_common.vehicle.params import default_vehicle_file

    T0, DT = 100.0, 0.005
    vehicle = load_estimator_vehicle(default_vehicle_file())
    traj = synthetic_trajectory(np.arange(0.0, 2.4, DT), vehicle)

    def sample(k, **bad):
        row = {'t': T0 + traj.t[k], 'angle': traj.angle[k].tolist(),
               'speed': float(traj.speed[k]), 'torque': traj.torque[k].tolist()}
        row.update(bad)
        return row

    seq = []
    for k in range(200):                       # 1 s clean, with faults inside
        if k == 100:
            seq.append(sample(k, angle=[math.nan, 0.0, 0.0, 0.0]))
        elif k == 120:
            seq.append(sample(k, speed=math.inf))
        elif k == 140:
            seq.append(sample(k, torque=[0.0, -math.inf, 0.0, 0.0]))
        else:
            seq.append(sample(k))
        if k == 150:
            seq.append(sample(k))              # duplicate stamp
        if k == 170:
            seq.append(sample(165))            # 25 ms late
    seq += [sample(k) for k in range(320, 480)]   # after a 0.6 s dropout
    seq += [sample(k) for k in range(0, 200)]     # looped: back to the start

    rclpy.init()
    node = Node('fault_feed')
    got = {'states': [], 'forces': [], 'friction': [], 'slope': [], 'diag': []}
    def stamp(msg):
        return msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
    def keep(key, topic, kind, row):
        node.create_subscription(kind, topic, lambda m: got[key].append(row(m)), STREAM_QOS)
    keep('states', topics.OBSERVER_WHEEL_STATES, WheelStates,
         lambda m: [stamp(m), *m.angle, *m.omega, *m.omega_dot])
    keep('forces', topics.ESTIMATES_TIRE_FORCES, TireForces, lambda m: [stamp(m), *m.fx, *m.fz])
    keep('friction', topics.ESTIMATES_FRICTION, Friction,
         lambda m: [stamp(m), *m.mu, *m.slip, *[float(v) for v in m.valid]])
    keep('slope', topics.ESTIMATES_SLOPE, Slope, lambda m: [stamp(m), m.angle, float(m.valid)])
    def on_diag(m):
        for s in m.status:
            level = s.level[0] if isinstance(s.level, bytes) else int(s.level)
            values = {kv.key: kv.value for kv in s.values}
            got['diag'].append(
                {'name': s.name, 'level': level, 'message': s.message, 'values': values})
    node.create_subscription(DiagnosticArray, '/diagnostics', on_diag, DIAGNOSTICS_QOS)
    pub_a = node.create_publisher(WheelAngles, topics.SENSORS_WHEEL_ANGLES, STREAM_QOS)
    pub_v = node.create_publisher(TwistStamped, topics.SENSORS_BODY_VELOCITY, STREAM_QOS)
    pub_t = node.create_publisher(WheelTorques, topics.SENSORS_WHEEL_TORQUES, STREAM_QOS)
    # Receive in a thread of its own, so that publishing never starves the subscriptions.
    executor = rclpy.executors.SingleThreadedExecutor()
    executor.add_node(node)
    threading.Thread(target=executor.spin, daemon=True).start()
    deadline = time.monotonic() + 15
    while time.monotonic() < deadline and not (
        pub_a.get_subscription_count() >= 1 and pub_v.get_subscription_count() >= 2
        and pub_t.get_subscription_count() >= 1
        and node.count_publishers(topics.ESTIMATES_SLOPE) >= 1):
        time.sleep(0.05)
    time.sleep(0.5)
    print('feeding', len(seq), flush=True)
    for k, row in enumerate(seq):
        # Flow control: never run more than 40 samples ahead of the nodes' outputs, so that
        # no KEEP_LAST queue overflows on a loaded machine (losses would hide faults).
        wait_until = time.monotonic() + 5.0
        while time.monotonic() < wait_until and (
            len(got['states']) < k - 40 or len(got['slope']) < k - 45
        ):
            time.sleep(0.001)
        header_stamp = ns_to_time(round(row['t'] * 1e9))
        a = WheelAngles(); a.header.stamp = header_stamp; a.header.frame_id = 'base_link'
        a.angle = [float(x) for x in row['angle']]
        v = TwistStamped(); v.header.stamp = header_stamp; v.header.frame_id = 'base_link'
        v.twist.linear.x = float(row['speed'])
        q = WheelTorques(); q.header.stamp = header_stamp; q.header.frame_id = 'base_link'
        q.torque = [float(x) for x in row['torque']]
        pub_a.publish(a); pub_v.publish(v); pub_t.publish(q)
        time.sleep(0.003)
    # The 1 Hz diagnostics must have seen every fault, and the last estimate must be in.
    deadline = time.monotonic() + 6
    def done():
        names = {d['name']: d['values'] for d in got['diag']}
        obs, est = names.get('vd: observer', {}), names.get('vd: estimator', {})
        last = got['slope'][-1][0] if got['slope'] else 0.0
        return (obs.get('wheel.time_jump_back') == '1'
                and est.get('estimator.time_jump_back') == '1'
                and abs(last - seq[-1]['t']) < 1e-6)
    while time.monotonic() < deadline and not done():
        time.sleep(0.05)
    time.sleep(1.2)                             # one more period: levels back to OK
    with open(sys.argv[1], 'w') as f:
        json.dump({'sent': seq, 'got': got}, f)
    print('captured', flush=True)
    os._exit(0)  # the spinning thread would abort an orderly shutdown; nothing to clean up
    """
)


def _wait_exit(proc: RosProcess, timeout: float) -> int:
    deadline = time.monotonic() + timeout
    while proc.popen.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    assert proc.popen.poll() is not None, f'{proc.name} still running:\n{proc.stacks()[-6000:]}'
    return int(proc.popen.returncode)


def _last_diag(diag: list[dict[str, Any]], name: str) -> dict[str, Any]:
    mine = [d for d in diag if d['name'] == name]
    assert mine, f'no diagnostics from {name}'
    return mine[-1]


@pytest.mark.slow
@pytest.mark.ros
def test_sensor_faults_through_the_live_nodes(procs: RosProcessGroup, tmp_path: Path) -> None:
    obs = procs.node('observer', 'vd_observer_node', 'observer_node')
    # the slope filter set: left unset it would follow the feed's rate from the 200th stamp
    # on (rate_settings), which the offline comparison below would have to repeat
    est = procs.node('estimator', 'vd_observer_node', 'estimator_node', slope_filter_tau=0.1)
    for proc, text in ((obs, 'observer ready'), (est, 'estimator ready')):
        proc.wait_for(text, timeout=60)
    script = tmp_path / 'feed_and_capture.py'
    script.write_text(FEED_AND_CAPTURE, encoding='utf-8')
    out = tmp_path / 'captured.json'
    feed = procs.python('feed', script, str(out))
    assert _wait_exit(feed, 40) == 0, feed.output()[-3000:]
    data = json.loads(out.read_text(encoding='utf-8'))
    got, sent = data['got'], data['sent']
    # Nodes survived; nothing published is NaN or Inf.
    assert obs.popen.poll() is None and est.popen.poll() is None
    for key in ('states', 'forces', 'friction', 'slope'):
        rows = np.array(got[key], dtype=np.float64)
        assert rows.shape[0] > 300, key
        assert np.isfinite(rows).all(), key
    assert len(got['states']) == len(sent), 'the observer must answer every wheel sample'
    # Diagnostics name each fault kind with a counter.
    obs_diag = _last_diag(got['diag'], 'vd: observer')['values']
    for part in ('wheel', 'speed'):
        for kind, n in (('duplicate_stamp', 1), ('out_of_order', 1), ('gap', 1),
                        ('time_jump_back', 1), ('non_finite_value', 1)):  # fmt: skip
            assert obs_diag[f'{part}.{kind}'] == str(n), (part, kind, obs_diag)
    est_diag = _last_diag(got['diag'], 'vd: estimator')['values']
    assert est_diag['estimator.gap'] == '1', est_diag
    assert est_diag['estimator.time_jump_back'] == '1', est_diag
    assert int(est_diag['estimator.non_finite_value']) >= 1, est_diag
    assert int(est_diag['align.out_of_order']) >= 2, est_diag  # the duplicate and the late one
    warned = [d for d in got['diag'] if d['level'] == 1]
    assert any('time_jump_back' in d['message'] for d in warned), got['diag']
    assert any('gap' in d['message'] for d in warned), got['diag']
    # The faults are over; only the end of the feed may show, as inputs that stopped arriving.
    last = _last_diag(got['diag'], 'vd: observer')
    assert last['level'] == 0 or all(
        'stopped: no message for' in part for part in last['message'].split('; ')
    ), last
    # Recovery: after the loop the live estimates are exactly the offline cascade's on the
    # same messages, and the flags are set again.
    from vd_observer_node.estimation.cascade import CascadeSeries, CascadeSettings, run_cascade
    from vd_observer_node.estimation.vehicle import load_estimator_vehicle

    offline = run_cascade(
        CascadeSeries(
            [round(r['t'] * 1e9) * 1e-9 for r in sent],
            [r['angle'] for r in sent],
            [r['speed'] for r in sent],
            [r['torque'] for r in sent],
        ),
        CascadeSettings(load_estimator_vehicle(VEHICLE_FILE)),
    )
    loop = 200  # the last 200 samples: the replayed start after the jump back
    slope = np.array(got['slope'][-loop:])
    np.testing.assert_allclose(slope[:, 0], offline.t[-loop:], atol=1e-9)
    np.testing.assert_allclose(slope[:, 1], offline.slope[-loop:], rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(slope[:, 2].astype(bool), offline.slope_valid[-loop:])
    forces = np.array(got['forces'][-loop:])
    np.testing.assert_allclose(forces[:, 5:9], offline.fz[-loop:], rtol=1e-12)
    assert slope[-50:, 2].all()
    assert offline.faults['estimator.time_jump_back'] == 1


def _refused(proc: RosProcess, *words: str) -> None:
    code = _wait_exit(proc, 120)  # twelve nodes start at once: generous on a busy machine
    out = proc.output()
    assert code == 2, out
    assert 'Traceback' not in out, out
    errors = [line for line in out.splitlines() if line.startswith('error:')]
    assert len(errors) == 1, out
    for word in words:
        assert word in errors[0], (word, errors[0])


@pytest.mark.ros
def test_bad_parameters_refuse_to_start_with_one_line(
    procs: RosProcessGroup, tmp_path: Path
) -> None:
    vehicle = yaml.safe_load(VEHICLE_FILE.read_text(encoding='utf-8'))

    def variant(name: str, section: str, key: str, value: object) -> str:
        data = json.loads(json.dumps(vehicle))
        if value is None:
            del data[section][key]
        else:
            data[section][key] = value
        path = tmp_path / f'{name}.yaml'
        path.write_text(yaml.safe_dump(data), encoding='utf-8')
        return str(path)

    malformed = tmp_path / 'malformed.yaml'
    malformed.write_text('chassis: {mass: [1,\n', encoding='utf-8')
    cases = [
        (('observer_node', {'discretization': 'trapezoid'}), ('discretization', 'implicit')),
        (('observer_node', {'max_gap': -1.0}), ('max_gap', '> 0')),
        (('estimator_node', {'vehicle_file': str(tmp_path / 'absent.yaml')}), ('absent.yaml',)),
        (('estimator_node', {'vehicle_file': str(malformed)}), ('malformed.yaml',)),
        (
            ('estimator_node', {'vehicle_file': variant('neg', 'chassis', 'mass', -1200.0)}),
            ('chassis.mass', '> 0', '-1200'),
        ),
        (
            (
                'estimator_node',
                {'vehicle_file': variant('zero_r', 'wheel', 'effective_radius', 0.0)},
            ),
            ('wheel.effective_radius', '> 0'),
        ),
        (
            ('estimator_node', {'vehicle_file': variant('nokey', 'wheel', 'inertia_rear', None)}),
            ('wheel.inertia_rear',),
        ),
        (
            # a misspelt key is named with the known one, not dropped or reported as missing
            ('pipeline_node', {'vehicle_file': variant('typo', 'brakes', 'gain_frnt', 30.0)}),
            ('brakes.gain_frnt is not a known key; did you mean brakes.gain_front?',),
        ),
        (('estimator_node', {'max_mu': 0.0}), ('max_mu',)),
        (('alerts_node', {'traction.warning_off': 0.5}), ('warning_off', 'warning_on')),
        (('alerts_node', {'evidence_low': 500.0}), ('evidence_low',)),
    ]
    # Each process alone (no discovery): twelve short-lived participants in one domain
    # deadlocked Fast DDS in one of them now and then (rosproc.RosProcessGroup.without_discovery)
    alone = procs.without_discovery()
    started = [
        (alone.node(f'case{i}', 'vd_observer_node', exe, **params), words)
        for i, ((exe, params), words) in enumerate(cases)
    ]
    from vd_observer_node.testing.launcher import NodeSpec

    bad_params = tmp_path / 'params.yaml'
    bad_params.write_text('observer_node:\n  ros__parameters: {max_gap: [1,\n', encoding='utf-8')
    for i, (exe, path) in enumerate(
        (('observer_node', tmp_path / 'no_params.yaml'), ('estimator_node', bad_params))
    ):
        argv = [*NodeSpec('vd_observer_node', exe, f'pf{i}', {}).argv(), '--params-file']
        started.append((alone.start(f'pf{i}', [*argv, str(path)]), ('--params-file', path.name)))
    for proc, words in started:
        _refused(proc, *words)


@pytest.mark.ros
def test_recorder_with_unwritable_output_exits_with_one_line(
    procs: RosProcessGroup, tmp_path: Path
) -> None:
    blocker = tmp_path / 'a_file'
    blocker.write_text('not a folder', encoding='utf-8')
    rec = procs.node('recorder', 'vd_observer_node', 'recorder_node', output=str(blocker / 'bag'))
    _refused(rec, str(blocker / 'bag'))
    assert blocker.read_text(encoding='utf-8') == 'not a folder'
