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

import numpy as np
import pytest
import yaml
from rosproc import RosProcess, RosProcessGroup
from vd_common.topics import (
    ESTIMATES_SLOPE,
    ESTIMATES_TIRE_FORCES,
    ESTIMATES_TORQUE_OFFSET,
    OBSERVER_WHEEL_STATES,
)
from vd_observer_node.estimation.rate_settings import slope_filter_tau_for_rate

NS = 1_000_000_000
ROOT = Path(__file__).resolve().parents[1]
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
    assert code is not None, f'{proc.name} still running:\n{proc.stacks()}'
    return code


@pytest.mark.slow
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
    # the slope filter left unset follows the rate the node measured on its first stamps
    tau = slope_filter_tau_for_rate(RATE_HZ)
    pipe.wait_for(f'settings: slope_filter_tau={tau:.3g} (input rate {RATE_HZ:g} Hz)', timeout=5)
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


def _refused(proc: RosProcess, *words: str) -> None:
    code = _wait_exit(proc, 120)  # several nodes start at once: generous on a busy machine
    out = proc.output()
    assert code == 2, out
    assert 'Traceback' not in out, out
    errors = [line for line in out.splitlines() if line.startswith('error:')]
    assert len(errors) == 1, out
    for word in words:
        assert word in errors[0], (word, errors[0])


def _standard_bag(path: Path, seconds: float, rate: float) -> Path:
    """A bag of publish_std_inputs.py's topics (JointState, Odometry, Float64MultiArray)."""
    import math

    from vd_observer_node.bag import BagWriter
    from vd_observer_node.bag.typestore import message_class, serialize

    def header(stamp: int, frame: str) -> object:
        t = message_class('builtin_interfaces/msg/Time')(sec=stamp // NS, nanosec=stamp % NS)
        return message_class('std_msgs/msg/Header')(stamp=t, frame_id=frame)

    vec = message_class('geometry_msgs/msg/Vector3')
    twist = message_class('geometry_msgs/msg/Twist')
    pose = message_class('geometry_msgs/msg/Pose')(
        position=message_class('geometry_msgs/msg/Point')(x=0.0, y=0.0, z=0.0),
        orientation=message_class('geometry_msgs/msg/Quaternion')(x=0.0, y=0.0, z=0.0, w=1.0),
    )
    cov = np.zeros(36)
    joints = ['wheel_fl_joint', 'wheel_fr_joint', 'wheel_rl_joint', 'wheel_rr_joint']
    with BagWriter(path) as writer:
        writer.add_topic('/joint_states', 'sensor_msgs/msg/JointState')
        writer.add_topic('/odom', 'nav_msgs/msg/Odometry')
        writer.add_topic('/can/wheel_torques', 'std_msgs/msg/Float64MultiArray')
        for k in range(round(seconds * rate)):
            t = k / rate
            stamp = NS + round(t * 1e9)
            angle = (10.0 * t + 1.0 - math.cos(0.5 * t)) / 0.3
            js = message_class('sensor_msgs/msg/JointState')(
                header=header(stamp, 'base_link'),
                name=joints,
                position=np.array([angle, -angle, angle, -angle]),
                velocity=np.zeros(0),
                effort=np.zeros(0),
            )
            speed = (10.0 + 0.5 * math.sin(0.5 * t)) * 3.6
            odom = message_class('nav_msgs/msg/Odometry')(
                header=header(stamp, 'odom'),
                child_frame_id='base_link',
                pose=message_class('geometry_msgs/msg/PoseWithCovariance')(
                    pose=pose, covariance=cov
                ),
                twist=message_class('geometry_msgs/msg/TwistWithCovariance')(
                    twist=twist(
                        linear=vec(x=speed, y=0.0, z=0.0), angular=vec(x=0.0, y=0.0, z=0.0)
                    ),
                    covariance=cov,
                ),
            )
            layout = message_class('std_msgs/msg/MultiArrayLayout')(dim=[], data_offset=0)
            torque = message_class('std_msgs/msg/Float64MultiArray')(
                layout=layout, data=np.array([0.05, 0.05, 0.0, 0.0])
            )
            writer.write('/joint_states', serialize(js), stamp)
            writer.write('/odom', serialize(odom), stamp)
            writer.write('/can/wheel_torques', serialize(torque), stamp)
    return path


@pytest.mark.ros
def test_bad_mappings_refuse_to_start_with_one_line_naming_the_key(
    procs: RosProcessGroup, tmp_path: Path
) -> None:
    bag = _standard_bag(tmp_path / 'std', 0.1, 100.0)
    mapping_file = tmp_path / 'car.yaml'
    mapping_file.write_text(yaml.safe_dump(MAPPING), encoding='utf-8')
    three = dict(MAPPING, wheel_angles=dict(MAPPING['wheel_angles'], joints=['a', 'b', 'c']))
    odom = dict(MAPPING, body_speed={'topic': '/odom', 'type': 'nav_msgs/msg/Odom'})
    unit = dict(MAPPING, wheel_torques=dict(MAPPING['wheel_torques'], unit='Nm'))
    untyped = {'wheel_angles': {'topic': '/joint_states'}}
    absent = dict(MAPPING, body_speed={'topic': '/gps/vel', 'type': 'nav_msgs/msg/Odometry'})
    # not a declared parameter: ROS alone would ignore it and keep m/s
    misspelt = dict(MAPPING, body_speed=dict(MAPPING['body_speed'], unti='km/h'))
    cases = [
        ('pipeline_node', three, {}, ('wheel_angles.joints must list 4',)),
        ('observer_node', {}, {'input_mapping': str(tmp_path / 'absent.yaml')}, ('absent.yaml',)),
        ('estimator_node', odom, {}, ("body_speed.type 'nav_msgs/msg/Odom'",)),
        ('alerts_node', unit, {}, ("wheel_torques.unit 'Nm'",)),
        ('observer_node', untyped, {}, ('wheel_angles.type is missing',)),
        ('pipeline_node', MAPPING, {'input_mapping': str(mapping_file)}, ('both set',)),
        ('player_node', absent, {'bag': str(bag)}, ('body_speed.topic', '/gps/vel')),
        ('estimator_node', misspelt, {}, ('body_speed.unti: unknown key',)),
    ]
    # each alone: refused nodes in one domain can deadlock Fast DDS in one another
    # (rosproc.RosProcessGroup.without_discovery)
    alone = procs.without_discovery()
    started = [
        (_start(alone, f'case{i}', exe, params_file(tmp_path / f'{i}.yaml', m, **extra)), words)
        for i, (exe, m, extra, words) in enumerate(cases)
    ]
    for proc, words in started:
        _refused(proc, *words)


@pytest.mark.slow
@pytest.mark.ros
def test_the_player_plays_a_users_bag_to_the_nodes_given_the_same_mapping(
    procs: RosProcessGroup, tmp_path: Path
) -> None:
    bag = _standard_bag(tmp_path / 'std', 3.0, 100.0)
    mapping_file = tmp_path / 'car.yaml'
    mapping_file.write_text(yaml.safe_dump(MAPPING), encoding='utf-8')
    params = params_file(tmp_path / 'p.yaml', {}, input_mapping=str(mapping_file))
    observer = _start(procs, 'observer', 'observer_node', params)
    estimator = _start(procs, 'estimator', 'estimator_node', params)
    for proc, text in ((observer, 'observer ready'), (estimator, 'estimator ready')):
        proc.wait_for(text, timeout=90)
    collector = procs.python(
        'collector', SCRIPTS / 'collect_outputs.py', '18', f'{ESTIMATES_SLOPE}=vd_msgs.msg/Slope'
    )
    collector.wait_for('SUBSCRIBED', timeout=60)
    # The player waits for subscribers to its own topics only; the estimator's subscriptions
    # to the observer's outputs are discovered meanwhile. Two runs under load got 0 slopes
    # with the default 0.5 s (cause not pinned down): give that discovery 3 s.
    player_params = params_file(
        tmp_path / 'player.yaml',
        {},
        input_mapping=str(mapping_file),
        bag=str(bag),
        start_delay=3.0,
    )
    player = _start(procs, 'player', 'player_node', player_params)
    assert _wait_exit(player, 60) == 0, player.output()
    assert _wait_exit(collector, 60) == 0
    slopes = [line.split() for line in collector.output().splitlines() if line.startswith('MSG ')]
    # the separate nodes: the estimator holds the headerless torque; most samples get through
    assert len(slopes) > 0.5 * 300, collector.output()[-2000:]
    assert {s[3] for s in slopes} == {'1'}


def test_every_mapping_setting_is_a_declared_parameter_of_the_nodes() -> None:
    from vd_observer_node.inputs.mapping import INPUT_KEYS, INPUTS
    from vd_observer_node.nodes import (
        alerts_node,
        estimator_node,
        observer_node,
        pipeline_node,
        player_node,
    )

    wanted = {'input_mapping'} | {f'inputs.{i}.{k}' for i in INPUTS for k in INPUT_KEYS}
    for node in (observer_node, estimator_node, alerts_node, pipeline_node, player_node):
        names = {spec.name for spec in node.PARAMS}
        assert wanted <= names, node.__name__
        assert all(spec.default is None for spec in node.PARAMS if spec.name.startswith('inputs.'))


def test_the_separate_nodes_hold_what_derives_from_a_headerless_input() -> None:
    from vd_observer_node.inputs.mapping import default_mapping, mapping_from_dict
    from vd_observer_node.nodes.alerts_node import held_inputs as alerts_held
    from vd_observer_node.nodes.estimator_node import held_inputs as estimator_held

    assert estimator_held(default_mapping()) == []
    assert alerts_held(default_mapping()) == []
    user = mapping_from_dict(MAPPING)  # torques on Float64MultiArray
    assert estimator_held(user) == ['torques']
    assert alerts_held(user) == ['torques']
    array = {'topic': '/a', 'type': 'std_msgs/msg/Float64MultiArray'}
    speed = mapping_from_dict(dict(MAPPING, body_speed=array))
    assert estimator_held(speed) == ['accel', 'speed', 'torques']
    assert alerts_held(speed) == ['speed', 'torques']
    angles = mapping_from_dict({'wheel_angles': array})
    assert estimator_held(angles) == ['accel', 'speed', 'torques']
    assert alerts_held(angles) == ['angles', 'speed', 'torques']


def test_a_mapping_file_and_mapping_parameters_together_are_refused(tmp_path: Path) -> None:
    from vd_observer_node.inputs.errors import MappingError
    from vd_observer_node.nodes.node_params import take_input_mapping

    values = {'input_mapping': str(tmp_path / 'car.yaml'), 'inputs.body_speed.topic': '/odom'}
    with pytest.raises(MappingError, match=r'inputs\.body_speed\.topic are both'):
        take_input_mapping(dict(values))
    values = {'input_mapping': '', 'inputs.body_speed.topic': None, 'max_gap': 0.5}
    mapping = take_input_mapping(values)
    assert mapping.is_default and values == {'max_gap': 0.5}  # the mapping's taken out


def test_messages_serialized_by_rclpy_decode_like_the_replays() -> None:
    """What a raw subscription hands the nodes is rclpy's (Fast CDR's) serialization, which
    may end a JointState with 8 bytes past its last field; it decodes to the same values."""
    from nav_msgs.msg import Odometry
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray
    from vd_observer_node.inputs.decode import InputDecoder
    from vd_observer_node.inputs.mapping import mapping_from_dict

    mapping = mapping_from_dict(MAPPING)
    names = ['steering', 'wheel_fl_joint', 'wheel_fr_joint', 'wheel_rl_joint', 'wheel_rr_joint']
    for k in range(4):  # frame ids of several lengths: every tail of the message's alignment
        js = JointState(name=names, position=[9.0, 1.0, 2.0, 3.0, 4.0])
        js.header.frame_id = 'b' * k
        js.header.stamp.sec = 3
        decoded = InputDecoder(mapping.wheels).decode(serialize_message(js), 0)
        assert decoded == (3 * NS, b'b' * k, (1.0, -2.0, 3.0, -4.0))
    odom = Odometry()
    odom.header.stamp.nanosec = 5
    odom.twist.twist.linear.x = 36.0
    assert InputDecoder(mapping.body_speed).decode(serialize_message(odom), 0) == (
        5,
        b'',
        (pytest.approx(10.0),),
    )
    array = Float64MultiArray(data=[1.0, 2.0, 3.0, 4.0, 5.0])
    assert InputDecoder(mapping.wheel_torques).decode(serialize_message(array), 7) == (
        7,
        b'',
        (1000.0, 2000.0, 3000.0, 4000.0),
    )


def _play_through_pipeline(
    procs: RosProcessGroup,
    tmp_path: Path,
    mapping_file: Path,
    bag: Path,
    *,
    ready: str,
    seconds: int,
    topics: list[str],
) -> tuple[RosProcess, list[list[str]]]:
    """pipeline_node on `mapping_file` (started once it logs `ready`), a collector of `topics`
    ('topic=pkg.msg/Type') for `seconds`, then the player of `bag` with the same mapping; the
    pipeline's process and the collector's lines, split, once player and collector ended."""
    params = params_file(tmp_path / 'p.yaml', {}, input_mapping=str(mapping_file))
    pipeline = _start(procs, 'pipeline', 'pipeline_node', params)
    pipeline.wait_for(ready, timeout=90)
    collector = procs.python('collector', SCRIPTS / 'collect_outputs.py', str(seconds), *topics)
    collector.wait_for('SUBSCRIBED', timeout=60)
    player_params = params_file(
        tmp_path / 'player.yaml', {}, input_mapping=str(mapping_file), bag=str(bag)
    )
    player = _start(procs, 'player', 'player_node', player_params)
    assert _wait_exit(player, 60) == 0, player.output()
    assert _wait_exit(collector, 60) == 0
    return pipeline, [line.split() for line in collector.output().splitlines()]


def _drop_windows(src: Path, dst: Path, start_s: float, length_s: float) -> None:
    """Copy a bag without the messages logged in [start_s, start_s + length_s) of every
    second (from its first log time): a link that goes silent on every topic at once."""
    from vd_observer_node.bag import BagReader, BagWriter

    reader = BagReader(src)
    messages = list(reader.raw_messages())
    first = min(m.log_time_ns for m in messages)
    with BagWriter(dst) as writer:
        for name, info in reader.topics.items():
            qos = info.qos_profiles_yaml
            writer.add_topic(name, info.msgtype, qos, definition=info.definition)
        for m in messages:
            if not start_s <= ((m.log_time_ns - first) * 1e-9) % 1.0 < start_s + length_s:
                writer.write(m.topic, m.data, m.log_time_ns, m.publish_time_ns)


@pytest.mark.slow
@pytest.mark.ros
@pytest.mark.parametrize('gaps', [False, True], ids=['lossless', 'gaps_200ms'])
def test_pipeline_node_on_abs_wheel_speeds_computes_what_the_replay_computes(
    procs: RosProcessGroup, tmp_path: Path, gaps: bool
) -> None:
    """ABS wheel speeds, odometry at 50 Hz and torques on their own clocks ('latest'
    alignment): the live pipeline's slope estimates equal the replay's, stamp for stamp; also
    with 200 ms of every second lost on every topic (issue 28: the gaps bridged live as
    offline)."""
    import dataclasses

    from vd_common.vehicle.params import default_vehicle_file, load_vehicle
    from vd_observer_node.bag import BagReader
    from vd_observer_node.bag.cdr_batch import decode_batch
    from vd_observer_node.inputs.mapping import mapping_from_dict
    from vd_observer_node.testing.standard_bags import (
        JOINT_TORQUES,
        CarSensors,
        write_standard_bag,
    )
    from vd_observer_node.tools.replay import ESTIMATE_TOPICS, replay_bag
    from vd_sim_node.vehicle.scenario import load_scenario
    from vd_sim_node.vehicle.simulation import simulate

    scenarios = ROOT / 'src' / 'vd_sim_node' / 'config' / 'scenarios'
    scenario = load_scenario(scenarios / 'paper_table1.yaml')
    sim = simulate(
        load_vehicle(default_vehicle_file()), dataclasses.replace(scenario, duration=4.0)
    )
    bag = tmp_path / 'car'
    # every input with a header: the live stamps are the recorded ones (no receive time)
    write_standard_bag(bag, sim, CarSensors(torques_in_joint_states=True))
    if gaps:
        full, bag = bag, tmp_path / 'car_gaps'
        _drop_windows(full, bag, 0.5, 0.2)
    mapping_file = tmp_path / 'car.yaml'
    mapping_file.write_text(yaml.safe_dump(JOINT_TORQUES), encoding='utf-8')
    # the slope filter left to the rate: live and offline follow it from the same stamp on
    report = replay_bag(
        bag, tmp_path / 'replayed', progress=False, mapping=mapping_from_dict(JOINT_TORQUES)
    )
    tau = slope_filter_tau_for_rate(50.0)  # the odometry's rate, slower than the wheels'
    assert report.rate_settings == {'slope_filter_tau': tau}
    if gaps:  # the holes are there, each shorter than max_gap: bridged, not restarted
        wheels = report.inputs[0]
        assert 0.19 < wheels.longest_gap_s < 0.5 and wheels.long_gaps == 0, wheels
    datas = BagReader(tmp_path / 'replayed').topic_arrays([ESTIMATES_SLOPE])[ESTIMATES_SLOPE]
    offline = decode_batch(ESTIMATE_TOPICS[ESTIMATES_SLOPE], datas.datas)
    expected = dict(zip(offline.stamp_ns.tolist(), offline.values['angle'].tolist(), strict=True))

    pipeline, lines = _play_through_pipeline(
        procs, tmp_path, mapping_file, bag, ready='pipeline ready', seconds=14,
        topics=[f'{ESTIMATES_SLOPE}=vd_msgs.msg/Slope'],
    )  # fmt: skip
    live = {int(f[2]): float(f[4]) for f in lines if f[0] == 'MSG'}
    assert len(live) > 0.9 * len(expected), (len(live), len(expected))
    assert set(live) <= set(expected)
    # the same sets in the same order through the same compiled chain: the same bits
    assert all(live[t] == expected[t] for t in live)
    pipeline.wait_for(f'settings: slope_filter_tau={tau:.3g} (input rate 50 Hz)', timeout=5)


@pytest.mark.slow
@pytest.mark.ros
@pytest.mark.parametrize('source', ['engine', 'none'])
def test_pipeline_node_on_the_engine_and_no_torque_paths_computes_what_the_replay_computes(
    procs: RosProcessGroup, tmp_path: Path, source: str
) -> None:
    """A mapping with ``torque_source: engine`` (engine torque, gear and engine speed of vd's
    WheelTorques; its wheel torques unread): the live pipeline's slope estimates, their
    validity and torque_source (1, engine) equal the replay's, stamp for stamp, over a
    launch (clutch slip) and an upshift. With ``none`` and a bag without any torque topic:
    the same, every slope invalid, torque_source 2."""
    import dataclasses

    from vd_common.vehicle.params import default_vehicle_file, load_vehicle
    from vd_observer_node.bag import BagReader
    from vd_observer_node.bag.cdr_batch import decode_batch
    from vd_observer_node.estimation.drivetrain import TORQUE_SOURCES
    from vd_observer_node.inputs.mapping import mapping_from_dict
    from vd_observer_node.testing.devbag import sim_topics, write_topic_arrays_bag
    from vd_observer_node.tools.replay import ESTIMATE_TOPICS, replay_bag
    from vd_sim_node.vehicle.scenario import load_scenario
    from vd_sim_node.vehicle.simulation import simulate

    scenario = load_scenario(
        ROOT / 'src' / 'vd_sim_node' / 'config' / 'scenarios' / 'paper_table1.yaml'
    )
    # launch at 8 s, the upshift at 11.5 s
    sim = simulate(
        load_vehicle(default_vehicle_file()),
        dataclasses.replace(
            scenario,
            duration=12.5,
            sensors=dataclasses.replace(scenario.sensors, rate_hz=100.0),
        ),
    )
    assert np.any(np.diff(sim.gear) > 0)
    bag = tmp_path / 'car'
    stamps = np.round(sim.t * 1e9).astype(np.int64) + NS
    topics = sim_topics(sim, truth=False)
    # the engine path must not read the measured wheel torques: they are garbage here
    torque_topic = next(t for t in topics if t.endswith('wheel_torques'))
    topics[torque_topic]['torque'] = np.full((len(stamps), 4), 1.0e5)
    if source == 'none':
        del topics[torque_topic]  # no torque topic at all: the player and node need none
    write_topic_arrays_bag(bag, stamps, topics)
    data = {'torque_source': source}
    mapping_file = tmp_path / 'car.yaml'
    mapping_file.write_text(yaml.safe_dump(data), encoding='utf-8')
    report = replay_bag(
        bag, tmp_path / 'replayed', progress=False, mapping=mapping_from_dict(data)
    )
    assert report.torque_source == source
    datas = BagReader(tmp_path / 'replayed').topic_arrays([ESTIMATES_SLOPE])[ESTIMATES_SLOPE]
    offline = decode_batch(ESTIMATE_TOPICS[ESTIMATES_SLOPE], datas.datas)
    expected = {
        stamp: (angle, int(valid), int(source))
        for stamp, angle, valid, source in zip(
            offline.stamp_ns.tolist(),
            offline.values['angle'].tolist(),
            offline.values['valid'].tolist(),
            offline.values['torque_source'].tolist(),
            strict=True,
        )
    }
    expected_offsets = {}
    if source == 'engine':  # the offset where it changes: the first stamp, the upshift's end
        offsets = BagReader(tmp_path / 'replayed').topic_arrays([ESTIMATES_TORQUE_OFFSET])
        written = decode_batch(
            ESTIMATE_TOPICS[ESTIMATES_TORQUE_OFFSET], offsets[ESTIMATES_TORQUE_OFFSET].datas
        )
        expected_offsets = dict(
            zip(written.stamp_ns.tolist(), written.values['offset'].tolist(), strict=True)
        )
        assert len(expected_offsets) == 2
    assert {v[2] for v in expected.values()} == {TORQUE_SOURCES.index(source)}
    # the engine path holds and does not (the launch, the upshift); none never holds
    assert {v[1] for v in expected.values()} == ({0, 1} if source == 'engine' else {0})

    offset_topic = f'{ESTIMATES_TORQUE_OFFSET}=vd_msgs.msg/TorqueOffsetEstimate'
    _, lines = _play_through_pipeline(
        procs, tmp_path, mapping_file, bag, ready=f'torque source {source}', seconds=25,
        topics=[f'{ESTIMATES_SLOPE}=vd_msgs.msg/Slope',
                *([offset_topic] if source == 'engine' else [])],
    )  # fmt: skip
    live = {
        int(f[2]): (float(f[4]), int(f[5]), int(f[6]))
        for f in lines
        if f[0] == 'MSG' and f[1] == ESTIMATES_SLOPE
    }
    assert len(live) > 0.9 * len(expected), (len(live), len(expected))
    assert set(live) <= set(expected)
    # the same sets in the same order through the same compiled chain: the same bits
    assert all(live[t] == expected[t] for t in live)
    # the engine-torque offset: published where it changes, as the replay writes it
    live_offsets = {
        int(f[2]): float(f[4]) for f in lines if f[0] == 'MSG' and f[1] == ESTIMATES_TORQUE_OFFSET
    }
    assert live_offsets == expected_offsets


@pytest.mark.slow
@pytest.mark.ros
def test_pipeline_node_takes_a_brake_switch_as_the_replay_does(
    procs: RosProcessGroup, tmp_path: Path
) -> None:
    """A mapping with a ``brake`` switch (a headerless Float64MultiArray logged with each
    wheel stamp, on from 11 to 12.5 s of a drive; 'exact' alignment, the default with a
    headerless input, holds it at its latest value): the live pipeline subscribes to it and
    flags the slope invalid while braking, as the replay does; away from the switch's edges
    (where a headerless input's receive order decides) its validity equals the replay's
    stamp for stamp."""
    import dataclasses

    from vd_common.vehicle.params import default_vehicle_file, load_vehicle
    from vd_observer_node.bag import BagReader, BagWriter
    from vd_observer_node.bag.cdr_batch import decode_batch
    from vd_observer_node.bag.typestore import serialize
    from vd_observer_node.inputs.mapping import mapping_from_dict
    from vd_observer_node.testing.devbag import sim_topics, write_topic_arrays_bag
    from vd_observer_node.testing.standard_bags import float64_array
    from vd_observer_node.tools.replay import ESTIMATE_TOPICS, replay_bag
    from vd_sim_node.vehicle.scenario import load_scenario
    from vd_sim_node.vehicle.simulation import simulate

    scenario = load_scenario(
        ROOT / 'src' / 'vd_sim_node' / 'config' / 'scenarios' / 'paper_table1.yaml'
    )
    sim = simulate(  # the launch at 8 s, moving from there
        load_vehicle(default_vehicle_file()),
        dataclasses.replace(
            scenario, duration=14.0, sensors=dataclasses.replace(scenario.sensors, rate_hz=100.0)
        ),
    )
    stamps = np.round(sim.t * 1e9).astype(np.int64) + NS
    own = tmp_path / 'own'
    write_topic_arrays_bag(own, stamps, sim_topics(sim, truth=False))
    brake_topic = '/can/brake'
    brake_stamps = stamps
    t_brake = (brake_stamps - NS) * 1e-9
    switch = ((t_brake >= 11.0) & (t_brake < 12.5)).astype(float)
    arrays = BagReader(own).topic_arrays()
    rows = [
        (int(log), topic, bytes(data))
        for topic, a in arrays.items()
        for log, data in zip(a.log_time_ns.tolist(), a.datas, strict=True)
    ] + [
        (int(s), brake_topic, serialize(float64_array([v])))
        for s, v in zip(brake_stamps.tolist(), switch.tolist(), strict=True)
    ]
    rows.sort(key=lambda r: r[0])
    bag = tmp_path / 'car'
    with BagWriter(bag) as writer:
        for topic, a in arrays.items():
            writer.add_topic(topic, a.msgtype)
        writer.add_topic(brake_topic, 'std_msgs/msg/Float64MultiArray')
        for log, topic, data in rows:
            writer.write(topic, data, log)
    data = {
        'brake': {
            'topic': brake_topic,
            'type': 'std_msgs/msg/Float64MultiArray',
            'signal': 'switch',
            'indices': [0],
        }
    }
    mapping_file = tmp_path / 'car.yaml'
    mapping_file.write_text(yaml.safe_dump(data), encoding='utf-8')
    replay_bag(bag, tmp_path / 'replayed', progress=False, mapping=mapping_from_dict(data))
    datas = BagReader(tmp_path / 'replayed').topic_arrays([ESTIMATES_SLOPE])[ESTIMATES_SLOPE]
    offline = decode_batch(ESTIMATE_TOPICS[ESTIMATES_SLOPE], datas.datas)
    expected = dict(
        zip(offline.stamp_ns.tolist(), offline.values['valid'].astype(int).tolist(), strict=True)
    )
    t_est = (np.array(list(expected)) - NS) * 1e-9
    valid = np.array(list(expected.values()), dtype=bool)
    braking = (t_est >= 11.0) & (t_est < 12.5)
    assert not valid[braking].any() and valid[(t_est > 10.0) & (t_est < 11.0)].all()

    _, lines = _play_through_pipeline(
        procs, tmp_path, mapping_file, bag, ready='pipeline ready', seconds=25,
        topics=[f'{ESTIMATES_SLOPE}=vd_msgs.msg/Slope'],
    )  # fmt: skip
    live = {int(f[2]): int(f[5]) for f in lines if f[0] == 'MSG'}
    assert len(live) > 0.9 * len(expected), (len(live), len(expected))
    edges = np.array([11.0, 12.5])
    away = {
        s: v
        for s, v in live.items()
        if np.min(np.abs((s - NS) * 1e-9 - edges)) > 0.2 and s in expected
    }
    assert len(away) > 0.8 * len(live)
    assert all(v == expected[s] for s, v in away.items())
    live_t = (np.array(list(live)) - NS) * 1e-9
    live_valid = np.array(list(live.values()), dtype=bool)
    assert not live_valid[(live_t >= 11.2) & (live_t < 12.3)].any()
