"""Input mapping (issue 15): the mapping file, its refusals, the decoders, replay with it."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from vd_common.topics import SENSORS_BODY_VELOCITY, SENSORS_WHEEL_ANGLES
from vd_observer_node.bag import BagReader, BagWriter
from vd_observer_node.bag.errors import ReplayInputError
from vd_observer_node.bag.reader import TopicArrays
from vd_observer_node.bag.typestore import serialize
from vd_observer_node.errors import ConfigurationError
from vd_observer_node.inputs.decode import decode_input
from vd_observer_node.inputs.errors import MappingError
from vd_observer_node.inputs.mapping import (
    default_mapping,
    load_input_mapping,
    mapping_from_dict,
)
from vd_observer_node.testing.standard_bags import float64_array, joint_state, odometry
from vd_observer_node.testing.synthetic_bags import synthetic_drive
from vd_observer_node.tools.replay import ESTIMATE_TOPICS, replay_bag

NS = 1_000_000_000
FLOAT64 = 'std_msgs/msg/Float64MultiArray'
JOINTS = ['wheel_fl', 'wheel_fr', 'wheel_rl', 'wheel_rr']
#: as a URDF robot publishes them: another order, and a joint vd does not use
PUBLISHED_JOINTS = ['steering', 'wheel_rr', 'wheel_fl', 'wheel_rl', 'wheel_fr']

USER_MAPPING = {
    'wheel_angles': {
        'topic': '/joint_states',
        'type': 'sensor_msgs/msg/JointState',
        'joints': JOINTS,
        'sign': [1, -1, 1, -1],
    },
    'body_speed': {'topic': '/odom', 'type': 'nav_msgs/msg/Odometry'},
    'wheel_torques': {
        'topic': '/can/wheel_torques',
        'type': 'std_msgs/msg/Float64MultiArray',
        'indices': [3, 2, 1, 0],
    },
}


def _joint_state(
    stamp_ns: int,
    position: list[float],
    effort: list[float] | None = None,
    velocity: list[float] | None = None,
) -> Any:
    return joint_state(stamp_ns, PUBLISHED_JOINTS, position, velocity or (), effort or ())


def _arrays(msgtype: str, msgs: list[Any], log_ns: list[int]) -> TopicArrays:
    return TopicArrays(msgtype, np.array(log_ns, dtype=np.int64), [serialize(m) for m in msgs])


# --- the mapping file -------------------------------------------------------------------


def test_the_default_mapping_reads_vds_own_topics() -> None:
    mapping = mapping_from_dict({})
    assert mapping.specs == default_mapping().specs
    assert mapping.is_default
    assert mapping.wheels.topic == SENSORS_WHEEL_ANGLES


def test_a_mapping_file_is_read_with_units_signs_and_joints(tmp_path: Path) -> None:
    path = tmp_path / 'car.yaml'
    path.write_text(
        'wheel_angles:\n'
        '  topic: /joint_states\n'
        '  type: sensor_msgs/msg/JointState\n'
        f'  joints: {JOINTS}\n'
        '  unit: deg\n'
        '  sign: [1, -1, 1, -1]\n'
        'body_speed: {topic: /odom, type: nav_msgs/msg/Odometry, unit: km/h}\n'
        'wheel_torques: {topic: /tq, type: std_msgs/msg/Float64MultiArray, scale: 0.5}\n'
    )
    mapping = load_input_mapping(path)
    assert not mapping.is_default
    assert mapping.wheels.joints == tuple(JOINTS)
    assert mapping.wheels.factor == pytest.approx(math.pi / 180.0, rel=1e-15)
    assert mapping.wheels.sign == (1.0, -1.0, 1.0, -1.0)
    assert mapping.body_speed.factor == pytest.approx(1 / 3.6, rel=1e-15)
    assert mapping.wheel_torques.indices == (0, 1, 2, 3)  # the default order
    assert mapping.wheel_torques.factor == 0.5
    assert str(path) in mapping.source


@pytest.mark.parametrize(
    ('content', 'names'),
    [
        ({'wheel_speed': {}}, 'wheel_speed: unknown input'),
        ({'body_speed': {'topic': '/odom'}}, 'body_speed.type is missing'),
        ({'body_speed': {'type': 'nav_msgs/msg/Odometry'}}, 'body_speed.topic is missing'),
        ({'body_speed': {'topic': 'odom', 'type': 'nav_msgs/msg/Odometry'}}, 'absolute'),
        (
            {'body_speed': {'topic': '/o', 'type': 'nav_msgs/msg/Path'}},
            "body_speed.type 'nav_msgs/msg/Path' is not supported",
        ),
        (
            {'wheel_angles': {'topic': '/j', 'type': 'sensor_msgs/msg/JointState'}},
            'wheel_angles.joints must list 4 distinct joint names',
        ),
        (
            {
                'wheel_angles': {
                    'topic': '/j',
                    'type': 'sensor_msgs/msg/JointState',
                    'joints': ['a', 'a', 'b', 'c'],
                }
            },
            'wheel_angles.joints must list 4 distinct',
        ),
        (
            {'wheel_angles': {'topic': '/j', 'type': 'vd_msgs/msg/WheelAngles', 'joints': JOINTS}},
            'wheel_angles.joints is for sensor_msgs/msg/JointState only',
        ),
        (
            {
                'wheel_torques': {
                    'topic': '/t',
                    'type': 'std_msgs/msg/Float64MultiArray',
                    'indices': [0, 1, -2, 3],
                }
            },
            'wheel_torques.indices must list 4 element indices >= 0',
        ),
        (
            {'body_speed': {'topic': '/o', 'type': 'nav_msgs/msg/Odometry', 'unit': 'mph'}},
            "body_speed.unit 'mph' is unknown (use one of m/s, km/h)",
        ),
        (
            {'body_speed': {'topic': '/o', 'type': 'nav_msgs/msg/Odometry', 'scale': 0}},
            'body_speed.scale must not be 0',
        ),
        (
            {'wheel_torques': {'topic': '/t', 'type': 'vd_msgs/msg/WheelTorques', 'sign': [1]}},
            'wheel_torques.sign must list 4 values of +1 or -1',
        ),
        (
            {'body_speed': {'topic': '/o', 'type': 'nav_msgs/msg/Odometry', 'rate': 100}},
            'body_speed.rate: unknown key',
        ),
        (
            {'body_speed': {'topic': SENSORS_WHEEL_ANGLES, 'type': 'nav_msgs/msg/Odometry'}},
            f'body_speed.type: {SENSORS_WHEEL_ANGLES} is also mapped as vd_msgs/msg/WheelAngles',
        ),
        (
            {
                'wheel_angles': USER_MAPPING['wheel_angles'],
                'wheel_speeds': {'topic': '/w', 'type': 'std_msgs/msg/Float64MultiArray'},
            },
            'wheel_speeds: give wheel_angles or wheel_speeds, not both',
        ),
        (
            {'wheel_speeds': {'topic': '/w', 'type': 'vd_msgs/msg/WheelAngles'}},
            "wheel_speeds.type 'vd_msgs/msg/WheelAngles' is not supported",
        ),
        (
            {'wheel_speeds': {'topic': '/w', 'type': FLOAT64, 'unit': 'mph'}},
            "wheel_speeds.unit 'mph' is unknown (use one of rad/s, rpm, deg/s, m/s, km/h)",
        ),
        ({'alignment': 'nearest'}, "alignment 'nearest' is unknown (use one of exact, latest)"),
        ({'max_age': -1}, 'max_age must be > 0 s'),
        ({'max_age': 'long'}, 'max_age must be a finite number'),
        ([1, 2], 'expected a mapping'),
    ],
)
def test_a_bad_mapping_is_refused_in_one_line_naming_the_key(content: Any, names: str) -> None:
    with pytest.raises(MappingError) as info:
        mapping_from_dict(content, source='car.yaml')
    message = str(info.value)
    assert names in message
    assert message.startswith('car.yaml: ')
    assert '\n' not in message
    assert isinstance(info.value, ConfigurationError)  # the nodes print it as one line


def test_an_unreadable_or_malformed_file_is_one_line(tmp_path: Path) -> None:
    with pytest.raises(MappingError, match='cannot read input mapping'):
        load_input_mapping(tmp_path / 'absent.yaml')
    bad = tmp_path / 'bad.yaml'
    bad.write_text('wheel_angles: {topic: [\n')
    with pytest.raises(MappingError, match='is not valid YAML') as info:
        load_input_mapping(bad)
    assert '\n' not in str(info.value)


# --- decoding -----------------------------------------------------------------------------


def test_joint_state_positions_are_picked_by_name_converted_and_signed() -> None:
    mapping = mapping_from_dict(
        {
            'wheel_angles': {
                'topic': '/joint_states',
                'type': 'sensor_msgs/msg/JointState',
                'joints': JOINTS,
                'unit': 'deg',
                'sign': [1, -1, 1, -1],
            }
        }
    )
    # published order: steering, rr, fl, rl, fr
    msgs = [
        _joint_state(5 * NS + 10, [0.5, 40.0, 10.0, 30.0, -20.0]),
        _joint_state(5 * NS + 20, [0.5, 41.0, 11.0, 31.0, -21.0]),
    ]
    series = decode_input(mapping.wheels, _arrays(mapping.wheels.msgtype, msgs, [0, 0]))
    np.testing.assert_array_equal(series.stamp_ns, [5 * NS + 10, 5 * NS + 20])
    expected = np.radians([[10.0, 20.0, 30.0, -40.0], [11.0, 21.0, 31.0, -41.0]])
    np.testing.assert_allclose(series.values, expected, rtol=1e-15, atol=0)
    assert series.frame_ids.tolist() == [b'base_link', b'base_link']


def test_joint_state_efforts_are_wheel_torques() -> None:
    mapping = mapping_from_dict(
        {
            'wheel_torques': {
                'topic': '/joint_states',
                'type': 'sensor_msgs/msg/JointState',
                'joints': JOINTS,
                'unit': 'kN m',
            }
        }
    )
    msg = _joint_state(NS, [0.0] * 5, effort=[0.0, 0.4, 0.1, 0.3, 0.2])
    series = decode_input(mapping.wheel_torques, _arrays('sensor_msgs/msg/JointState', [msg], [0]))
    np.testing.assert_allclose(series.values, [[100.0, 200.0, 300.0, 400.0]], rtol=1e-15)


def test_odometry_and_float64_arrays_decode_with_their_stamps() -> None:
    mapping = mapping_from_dict(USER_MAPPING)
    odom = decode_input(
        mapping.body_speed,
        _arrays('nav_msgs/msg/Odometry', [odometry(3 * NS, 12.5)], [3 * NS + 999]),
    )
    np.testing.assert_array_equal(odom.stamp_ns, [3 * NS])  # the header stamp
    np.testing.assert_array_equal(odom.values, [[12.5]])
    torques = decode_input(
        mapping.wheel_torques,
        _arrays(
            'std_msgs/msg/Float64MultiArray',
            [float64_array([4.0, 3.0, 2.0, 1.0, 99.0])],
            [7 * NS],
        ),
    )
    np.testing.assert_array_equal(torques.stamp_ns, [7 * NS])  # no header: the log time
    np.testing.assert_array_equal(torques.values, [[1.0, 2.0, 3.0, 4.0]])


def test_data_that_does_not_fit_the_mapping_names_the_key() -> None:
    mapping = mapping_from_dict(USER_MAPPING)
    other = dict(USER_MAPPING['wheel_angles'], joints=['wheel_fl', 'wheel_fr', 'x', 'wheel_rr'])
    spec = mapping_from_dict({'wheel_angles': other}).wheels
    msgs = [_joint_state(NS, [0.0] * 5)]
    with pytest.raises(MappingError, match=r"wheel_angles.joints: 'x' is not among the joints"):
        decode_input(spec, _arrays('sensor_msgs/msg/JointState', msgs, [0]))
    no_effort = mapping_from_dict(
        {'wheel_torques': dict(USER_MAPPING['wheel_angles'], sign=[1, 1, 1, 1])}
    ).wheel_torques
    with pytest.raises(MappingError, match='carry no effort'):
        decode_input(no_effort, _arrays('sensor_msgs/msg/JointState', msgs, [0]))
    short = _arrays('std_msgs/msg/Float64MultiArray', [float64_array([1.0, 2.0])], [0])
    with pytest.raises(MappingError, match=r'wheel_torques\.indices: element 3 is beyond the 2'):
        decode_input(mapping.wheel_torques, short)


def test_wheel_speeds_from_joint_velocities_in_kmh_are_divided_by_the_radius() -> None:
    mapping = mapping_from_dict(
        {
            'wheel_speeds': {
                'topic': '/joint_states',
                'type': 'sensor_msgs/msg/JointState',
                'joints': JOINTS,
                'unit': 'km/h',
            }
        }
    )
    assert mapping.wheel_input == 'speed' and mapping.wheels.per_radius
    msgs = [_joint_state(NS, [0.0] * 5, velocity=[0.0, 36.0, 72.0, 18.0, 54.0])]
    arrays = _arrays('sensor_msgs/msg/JointState', msgs, [0])
    series = decode_input(mapping.wheels, arrays, radius=0.25)
    # 72 km/h = 20 m/s on a 0.25 m radius = 80 rad/s (FL); order FL, FR, RL, RR
    np.testing.assert_allclose(series.values, [[80.0, 60.0, 20.0, 40.0]], rtol=1e-15)
    with pytest.raises(MappingError, match='needs the rolling radius'):
        decode_input(mapping.wheels, arrays)
    rpm = mapping_from_dict(
        {'wheel_speeds': {'topic': '/w', 'type': FLOAT64, 'unit': 'rpm', 'indices': [0, 1, 2, 3]}}
    ).wheels
    assert not rpm.per_radius
    got = decode_input(rpm, _arrays(FLOAT64, [float64_array([60.0, 30.0, 0.0, -60.0])], [7]))
    np.testing.assert_allclose(got.values, [[2 * math.pi, math.pi, 0.0, -2 * math.pi]])
    assert got.stamp_ns.tolist() == [7]


def test_angles_and_torques_may_share_one_joint_state_topic() -> None:
    mapping = mapping_from_dict(
        {
            'wheel_angles': USER_MAPPING['wheel_angles'],
            'wheel_torques': dict(USER_MAPPING['wheel_angles'], sign=[1, 1, 1, 1]),
        }
    )
    assert mapping.topics == ('/joint_states', SENSORS_BODY_VELOCITY)


# --- replay ---------------------------------------------------------------------------------


def _standard_types_bag(path: Path, seconds: float, rate: float) -> None:
    """The synthetic drive on standard types only, as USER_MAPPING describes it."""
    drive = synthetic_drive(seconds, rate)
    with BagWriter(path) as writer:
        writer.add_topic('/joint_states', 'sensor_msgs/msg/JointState')
        writer.add_topic('/odom', 'nav_msgs/msg/Odometry')
        writer.add_topic('/can/wheel_torques', 'std_msgs/msg/Float64MultiArray')
        sign = np.array([1.0, -1.0, 1.0, -1.0])
        for k, stamp in enumerate(drive.stamp_ns.tolist()):
            fl, fr, rl, rr = (drive.angle[k] * sign).tolist()
            joints = _joint_state(stamp, [0.0, rr, fl, rl, fr])
            writer.write('/joint_states', serialize(joints), stamp)
            writer.write('/odom', serialize(odometry(stamp, float(drive.speed[k]))), stamp)
            torque = drive.torque[k][::-1].tolist()  # indices [3, 2, 1, 0]
            writer.write('/can/wheel_torques', serialize(float64_array(torque)), stamp)


def test_replay_of_standard_types_equals_replay_of_vd_topics(tmp_path: Path) -> None:
    from vd_observer_node.testing.synthetic_bags import write_synthetic_drive_bag

    seconds, rate = 4.0, 200.0
    ours = tmp_path / 'vd_topics'
    write_synthetic_drive_bag(ours, seconds, rate)
    theirs = tmp_path / 'standard_types'
    _standard_types_bag(theirs, seconds, rate)
    replay_bag(ours, tmp_path / 'ours_out', progress=False)
    mapping = mapping_from_dict(USER_MAPPING, source='car.yaml')
    report = replay_bag(theirs, tmp_path / 'theirs_out', progress=False, mapping=mapping)
    assert report.samples == round(seconds * rate)
    expected = BagReader(tmp_path / 'ours_out')
    got = BagReader(tmp_path / 'theirs_out')
    for topic in ESTIMATE_TOPICS:  # those written (the online mass/radius only where adapted)
        a = expected.topic_arrays([topic]).get(topic)
        b = got.topic_arrays([topic]).get(topic)
        assert (a is None) == (b is None), topic
        assert a is None or b is None or a.datas == b.datas, topic  # the same CDR bytes
    # the user's own input topics are copied to the output, with their types
    assert got.topics['/joint_states'].msgtype == 'sensor_msgs/msg/JointState'
    assert got.topics['/odom'].message_count == round(seconds * rate)


def test_replay_names_the_mapping_key_of_a_missing_or_mistyped_topic(tmp_path: Path) -> None:
    bag = tmp_path / 'standard_types'
    _standard_types_bag(bag, 0.2, 100.0)
    absent = dict(USER_MAPPING, body_speed={'topic': '/gps/vel', 'type': 'nav_msgs/msg/Odometry'})
    with pytest.raises(ReplayInputError, match=r'no messages on sensor topic /gps/vel \(car.yaml'):
        replay_bag(
            bag, tmp_path / 'o1', progress=False, mapping=mapping_from_dict(absent, 'car.yaml')
        )
    mistyped = dict(
        USER_MAPPING, body_speed={'topic': '/odom', 'type': 'geometry_msgs/msg/TwistStamped'}
    )
    with pytest.raises(ReplayInputError, match='/odom has type nav_msgs/msg/Odometry'):
        replay_bag(bag, tmp_path / 'o2', progress=False, mapping=mapping_from_dict(mistyped))


def test_the_shipped_example_mapping_is_valid() -> None:
    example = Path(__file__).resolve().parents[1] / 'config' / 'input_mapping_example.yaml'
    mapping = load_input_mapping(example)
    assert [s.topic for s in mapping.specs] == ['/joint_states', '/odom', '/can/wheel_torques']
    assert mapping.wheels.sign == (1.0, -1.0, 1.0, -1.0)


def test_vd_replay_takes_a_mapping_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import yaml
    from vd_observer_node.tools.cli import main

    bag = tmp_path / 'standard_types'
    _standard_types_bag(bag, 0.5, 100.0)
    good = tmp_path / 'car.yaml'
    good.write_text(yaml.safe_dump(USER_MAPPING))
    assert main(['replay', str(bag), str(tmp_path / 'out'), '--mapping', str(good)]) == 0
    assert 'replayed 50 samples' in capsys.readouterr().out
    bad = tmp_path / 'bad.yaml'
    bad.write_text(yaml.safe_dump({'body_speed': {'topic': '/odom', 'type': 'x/msg/Y'}}))
    assert main(['replay', str(bag), str(tmp_path / 'out2'), '--mapping', str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and err.startswith('vd: error: ')
    assert "body_speed.type 'x/msg/Y' is not supported" in err


def test_the_default_alignment_rides_through_loss_unless_an_input_has_no_header() -> None:
    from vd_observer_node.inputs.mapping import default_mapping, mapping_from_dict

    assert default_mapping().alignment == 'latest'
    # a user's topics with header stamps, on their own clocks: 'latest'
    odometry = {'body_speed': {'topic': '/odom', 'type': 'nav_msgs/msg/Odometry'}}
    assert mapping_from_dict(odometry).alignment == 'latest'
    # a headerless input is stamped on receipt and can only be held: 'exact' holds it
    headerless = {
        'wheel_torques': {
            'topic': '/can/torques',
            'type': 'std_msgs/msg/Float64MultiArray',
            'indices': [0, 1, 2, 3],
        }
    }
    assert mapping_from_dict(headerless).alignment == 'exact'
    # what the file says wins
    assert mapping_from_dict({**headerless, 'alignment': 'latest'}).alignment == 'latest'
    assert mapping_from_dict({**odometry, 'alignment': 'exact'}).alignment == 'exact'
