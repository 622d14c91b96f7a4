"""The input mapping on the live side: the params form, per-message decoding, hold and watch.

The nodes build their mapping from ``inputs.<input>.<key>`` parameters or a file with one
parser; decode each message with `InputDecoder`, which must give what the bag path
(`decode_input`) gives for every supported type; match stamped inputs and hold headerless
ones (`InputMatcher`); and report a stopped topic (`InputWatch`).
"""

from __future__ import annotations

import array
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from test_inputs import USER_MAPPING, _arrays, _joint_state
from vd_observer_node.bag.errors import BagFormatError
from vd_observer_node.bag.typestore import message_class, serialize
from vd_observer_node.inputs.decode import InputDecoder, decode_input, has_header
from vd_observer_node.inputs.errors import MappingError
from vd_observer_node.inputs.mapping import (
    INPUT_KEYS,
    InputSpec,
    default_mapping,
    load_input_mapping,
    mapping_from_dict,
    mapping_from_params,
)
from vd_observer_node.nodes.raw_io import InputMatcher, InputWatch, mapped_input, matched_inputs
from vd_observer_node.testing.standard_bags import float64_array, header, odometry

NS = 1_000_000_000
EXAMPLE = Path(__file__).resolve().parents[1] / 'config' / 'input_mapping_example.yaml'


def _as_params(mapping: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """The flat parameters a ROS params file gives: numeric arrays as array.array."""
    flat: dict[str, Any] = {}
    for name, settings in mapping.items():
        for key, value in settings.items():
            if isinstance(value, list) and value and not isinstance(value[0], str):
                value = array.array('q' if isinstance(value[0], int) else 'd', value)
            flat[f'inputs.{name}.{key}'] = value
    return flat


# --- the params form --------------------------------------------------------------------


def test_the_params_form_builds_the_mapping_the_file_form_builds() -> None:
    import yaml

    got = mapping_from_params(_as_params(USER_MAPPING))
    assert got.specs == mapping_from_dict(USER_MAPPING).specs
    example = yaml.safe_load(EXAMPLE.read_text(encoding='utf-8'))
    assert mapping_from_params(_as_params(example)).specs == load_input_mapping(EXAMPLE).specs


def test_unset_parameters_keep_vds_own_topics() -> None:
    unset = {f'inputs.wheel_angles.{key}': None for key in INPUT_KEYS}
    assert mapping_from_params({**unset, 'kernel': 'compiled'}).specs == default_mapping().specs
    one = mapping_from_params({**unset, **_as_params({'body_speed': USER_MAPPING['body_speed']})})
    assert one.body_speed.topic == '/odom'
    assert one.wheels == default_mapping().wheels


@pytest.mark.parametrize(
    ('params', 'words'),
    [
        ({'inputs.wheel_angles.joints': ['a', 'b', 'c']}, 'wheel_angles.topic is missing'),
        (
            {**_as_params(USER_MAPPING), 'inputs.wheel_angles.joints': ['a', 'b', 'c']},
            'wheel_angles.joints must list 4 distinct joint names',
        ),
        ({**_as_params(USER_MAPPING), 'inputs.body_speed.unit': 'mph'}, "body_speed.unit 'mph'"),
        ({'inputs.wheel_angle.topic': '/x'}, 'wheel_angle: unknown input'),
        ({'inputs.body_speed.topc': '/x'}, 'body_speed.topc: unknown key'),
        ({'inputs.body_speed': '/x'}, 'inputs.body_speed: expected inputs.<input>.<key>'),
    ],
)
def test_bad_parameters_are_refused_in_one_line_naming_the_key(
    params: dict[str, Any], words: str
) -> None:
    with pytest.raises(MappingError) as caught:
        mapping_from_params(params)
    message = str(caught.value)
    assert '\n' not in message
    assert words in message and message.startswith('parameters inputs.*: ')


# --- one message at a time equals the bag path ------------------------------------------


def _vd_messages(msgtype: str, field: str) -> list[Any]:
    cls = message_class(msgtype)
    out = []
    for k in range(3):
        values = np.array([0.1 * k + i for i in range(4)], dtype=np.float64)
        extra = (
            {'engine_torque': 0.0, 'engine_speed': 0.0, 'gear': 0} if 'Torques' in msgtype else {}
        )
        out.append(cls(header=header(k * 10_000_000), **{field: values}, **extra))
    return out


def _twists() -> list[Any]:
    vec = message_class('geometry_msgs/msg/Vector3')
    twist = message_class('geometry_msgs/msg/Twist')
    cls = message_class('geometry_msgs/msg/TwistStamped')
    return [
        cls(
            header=header(k * 10_000_000),
            twist=twist(linear=vec(x=3.0 + k, y=0.0, z=0.0), angular=vec(x=0.0, y=0.0, z=0.0)),
        )
        for k in range(3)
    ]


CASES = [
    (
        InputSpec(
            'wheel_angles', '/a', 'vd_msgs/msg/WheelAngles', factor=2.0, sign=(1, -1, 1, -1)
        ),
        lambda: _vd_messages('vd_msgs/msg/WheelAngles', 'angle'),
    ),
    (
        InputSpec('wheel_torques', '/t', 'vd_msgs/msg/WheelTorques'),
        lambda: _vd_messages('vd_msgs/msg/WheelTorques', 'torque'),
    ),
    (
        InputSpec(
            'body_speed', '/v', 'geometry_msgs/msg/TwistStamped', factor=1 / 3.6, sign=(1.0,)
        ),
        _twists,
    ),
    (
        mapping_from_dict(USER_MAPPING).wheels,
        lambda: [_joint_state(k * NS, [0.0, -1.0 * k, 2.0 * k, 3.0, -4.0]) for k in range(3)],
    ),
    (
        InputSpec(
            'wheel_torques',
            '/j',
            'sensor_msgs/msg/JointState',
            joints=('wheel_fl', 'wheel_fr', 'wheel_rl', 'wheel_rr'),
            factor=1000.0,
        ),
        lambda: [_joint_state(k * NS, [0.0] * 5, [9.0, 1.0 * k, 2.0, 3.0, 4.0]) for k in range(3)],
    ),
    (
        InputSpec('body_speed', '/o', 'nav_msgs/msg/Odometry', sign=(1.0,)),
        lambda: [odometry(k * NS, 5.0 + k) for k in range(3)],
    ),
    (
        mapping_from_dict(USER_MAPPING).wheel_torques,
        lambda: [float64_array([1.0 * k, 2.0, 3.0, 4.0]) for k in range(3)],
    ),
]


@pytest.mark.parametrize(('spec', 'messages'), CASES, ids=lambda c: getattr(c, 'msgtype', ''))
def test_the_live_decoder_gives_what_the_bag_decoder_gives(spec: InputSpec, messages: Any) -> None:
    msgs = messages()
    receive = [7 * NS + k for k in range(len(msgs))]  # log times of the bag, receive times live
    series = decode_input(spec, _arrays(spec.msgtype, msgs, receive))
    decoder = InputDecoder(spec)
    for k, msg in enumerate(msgs):
        stamp, frame, values = decoder.decode(serialize(msg, spec.msgtype), receive[k])
        assert stamp == series.stamp_ns[k]
        assert frame == series.frame_ids[k]
        assert values == tuple(series.values[k].tolist())  # bit for bit
    assert has_header(spec) == (spec.msgtype != 'std_msgs/msg/Float64MultiArray')


def test_the_live_decoder_refuses_bad_bytes_and_absent_joints() -> None:
    spec = mapping_from_dict(USER_MAPPING).wheels
    with pytest.raises(BagFormatError):
        InputDecoder(spec).decode(b'\x00\x01\x00\x00garbage', 0)
    other = InputSpec('wheel_angles', '/j', spec.msgtype, joints=('a', 'b', 'c', 'd'))
    with pytest.raises(MappingError, match=r"wheel_angles\.joints: 'a' is not among the joints"):
        InputDecoder(other).decode(serialize(_joint_state(0, [0.0] * 5)), 0)


# --- matching, holding, watching ---------------------------------------------------------


def test_headerless_inputs_are_held_and_the_wheel_angles_drive() -> None:
    names = ('wheel_angles', 'body_speed', 'wheel_torques')
    assert matched_inputs(default_mapping(), names) == names
    user = mapping_from_dict(USER_MAPPING)  # torques on Float64MultiArray
    assert matched_inputs(user, names) == ('wheel_angles', 'body_speed')
    headerless = dict(
        USER_MAPPING,
        wheel_angles={'topic': '/a', 'type': 'std_msgs/msg/Float64MultiArray'},
    )
    assert matched_inputs(mapping_from_dict(headerless), names) == ('wheel_angles',)
    # the engine path's input in the torque slot: vd's WheelTorques matched by stamp, a
    # Float64MultiArray from CAN held
    engine_names = ('wheel_angles', 'body_speed', 'engine_torque')
    own = mapping_from_dict({'torque_source': 'engine'})
    assert matched_inputs(own, engine_names) == engine_names
    can = mapping_from_dict(
        {
            'torque_source': 'engine',
            'engine_torque': {
                'topic': '/can/engine',
                'type': 'std_msgs/msg/Float64MultiArray',
                'indices': [0, 1],
            },
        }
    )
    assert matched_inputs(can, engine_names) == ('wheel_angles', 'body_speed')


def test_a_held_input_joins_each_match_until_it_is_too_old() -> None:
    matcher = InputMatcher(['a', 'v'], ['t'], capacity=10, max_jump_back_ns=None, max_age_ns=100)
    assert matcher.push('a', 1, 'a1', receive_ns=0) is None
    assert matcher.push('v', 1, 'v1', receive_ns=0) is None  # no torque yet: withheld
    assert matcher.withheld_stale == 1
    matcher.hold('t', 10, 't1')
    matcher.push('a', 2, 'a2', receive_ns=20)
    assert matcher.push('v', 2, 'v2', receive_ns=20) == {'a': 'a2', 'v': 'v2', 't': 't1'}
    matcher.push('a', 3, 'a3', receive_ns=111)
    assert matcher.push('v', 3, 'v3', receive_ns=111) is None  # the torque is 101 ns old
    assert matcher.counts()['withheld_held_input_old'] == 2
    matcher.hold('t', 120, 't2')
    matcher.push('a', 4, 'a4', receive_ns=130)
    assert matcher.push('v', 4, 'v4', receive_ns=130) == {'a': 'a4', 'v': 'v4', 't': 't2'}


def test_the_watch_reports_a_stopped_topic_and_its_return() -> None:
    watch = InputWatch(['/joint_states', '/odom'], timeout_ns=NS // 2)
    assert watch.status(0)[:2] == (0, '')  # nothing yet: not an alarm before data flow
    watch.seen('/joint_states', 0)
    level, message, values = watch.status(NS // 10)
    assert (level, message) == (1, 'no message on /odom yet')
    watch.seen('/odom', NS // 10)
    assert watch.status(NS // 5)[:2] == (0, '')
    watch.seen('/joint_states', 2 * NS)
    level, message, values = watch.status(2 * NS + NS // 10)
    assert level == 1 and message == '/odom stopped: no message for 2.0 s'
    assert values['/odom messages'] == 1 and values['/joint_states messages'] == 2
    watch.seen('/odom', 2 * NS + NS // 5)
    assert watch.status(2 * NS + NS // 4)[:2] == (0, '')
    watch.unfit('/odom', 'body_speed: bad')
    assert watch.status(2 * NS + NS // 4)[:2] == (2, '/odom: body_speed: bad')
    assert watch.status(2 * NS + NS // 4)[0] == 0  # reported once


def test_a_mapped_subscription_decodes_matches_holds_and_never_raises() -> None:
    mapping = mapping_from_dict(USER_MAPPING)
    names = tuple(s.name for s in mapping.specs)
    matched = matched_inputs(mapping, names)
    matcher = InputMatcher(matched, ['wheel_torques'], 10, None, max_age_ns=10 * NS)
    watch = InputWatch([s.topic for s in mapping.specs], NS)
    counts = {'undecodable': 0}
    got: list[tuple[int, dict[str, Any]]] = []
    callbacks = {
        s.name: mapped_input(
            s, matcher, lambda t, m: got.append((t, m)), counts, watch, lambda: 42
        )
        for s in mapping.specs
    }
    callbacks['wheel_torques'](serialize(float64_array([1.0, 2.0, 3.0, 4.0])))
    callbacks['wheel_angles'](serialize(_joint_state(5, [0.0, 4.0, 1.0, 3.0, 2.0])))
    callbacks['body_speed'](serialize(odometry(5, 9.0)))
    assert len(got) == 1
    stamp, sample = got[0]
    assert stamp == 5
    assert sample['wheel_angles'] == (b'base_link', (1.0, -2.0, 3.0, -4.0))
    assert sample['body_speed'] == (b'odom', (9.0,))
    assert sample['wheel_torques'] == (b'', (4.0, 3.0, 2.0, 1.0))  # indices [3, 2, 1, 0]
    callbacks['body_speed'](b'\x00\x01\x00\x00')  # not an Odometry
    renamed = _joint_state(6, [0.0] * 5)
    renamed.name = ['a', 'b', 'c', 'd', 'e']  # not the mapped joints
    callbacks['wheel_angles'](serialize(renamed))
    assert counts == {'undecodable': 1, 'unfit': 1}  # dropped, counted, no exception
    assert watch.messages == {'/joint_states': 2, '/odom': 2, '/can/wheel_torques': 1}
    level, message, _ = watch.status(0)
    assert level == 2 and message.startswith("/joint_states: wheel_angles.joints: 'wheel_fl'")


# --- gaps in the replay summary and vd report --mapping -----------------------------------


def _user_bag_with_truth(
    path: Path, seconds: float, rate: float, gap: tuple[float, float]
) -> None:
    """USER_MAPPING's topics and vd's wheel-state truth; the torque topic silent in `gap` [s]."""
    from vd_common.topics import TRUTH_WHEEL_STATES
    from vd_observer_node.bag import BagWriter
    from vd_observer_node.bag.cdr_batch import encode_batch
    from vd_observer_node.testing.synthetic_bags import synthetic_drive

    drive = synthetic_drive(seconds, rate)
    t0 = int(drive.stamp_ns[0])
    truth = encode_batch(
        'vd_msgs/msg/WheelStates',
        drive.stamp_ns,
        'base_link',
        {'angle': drive.angle, 'omega': drive.omega, 'omega_dot': drive.omega_dot},
    )
    with BagWriter(path) as writer:
        writer.add_topic('/joint_states', 'sensor_msgs/msg/JointState')
        writer.add_topic('/odom', 'nav_msgs/msg/Odometry')
        writer.add_topic('/can/wheel_torques', 'std_msgs/msg/Float64MultiArray')
        writer.add_topic(TRUTH_WHEEL_STATES, 'vd_msgs/msg/WheelStates')
        sign = np.array([1.0, -1.0, 1.0, -1.0])
        for k, stamp in enumerate(drive.stamp_ns.tolist()):
            fl, fr, rl, rr = (drive.angle[k] * sign).tolist()
            writer.write(
                '/joint_states', serialize(_joint_state(stamp, [0.0, rr, fl, rl, fr])), stamp
            )
            writer.write('/odom', serialize(odometry(stamp, float(drive.speed[k]))), stamp)
            if not gap[0] <= (stamp - t0) * 1e-9 < gap[1]:
                torque = drive.torque[k][::-1].tolist()  # indices [3, 2, 1, 0]
                writer.write('/can/wheel_torques', serialize(float64_array(torque)), stamp)
            writer.write(TRUTH_WHEEL_STATES, truth[k], stamp)


def test_the_replay_summary_reports_a_topic_that_stopped_and_the_estimates_stay_finite(
    tmp_path: Path,
) -> None:
    from vd_common.topics import ESTIMATES_SLOPE, ESTIMATES_TIRE_FORCES
    from vd_observer_node.bag import BagReader
    from vd_observer_node.bag.cdr_batch import decode_batch
    from vd_observer_node.tools.replay import replay_bag

    bag = tmp_path / 'user'
    _user_bag_with_truth(bag, 4.0, 100.0, gap=(1.0, 1.8))
    report = replay_bag(
        bag, tmp_path / 'out', progress=False, mapping=mapping_from_dict(USER_MAPPING)
    )
    by_name = {s.name: s for s in report.inputs}
    torques = by_name['wheel_torques']
    assert (torques.topic, torques.messages, torques.long_gaps) == ('/can/wheel_torques', 320, 1)
    assert torques.longest_gap_s == pytest.approx(0.81, abs=1e-6)  # 1.0 s to 1.81 s
    assert torques.text() == (
        'wheel_torques (/can/wheel_torques): 320 messages, longest gap 0.810 s, 1 gaps > 0.5 s'
    )
    for name in ('wheel_angles', 'body_speed'):
        assert by_name[name].messages == 400 and by_name[name].long_gaps == 0
        assert by_name[name].longest_gap_s == pytest.approx(0.01, abs=1e-6)
    assert report.samples == 320  # the stamps without torque are not estimated
    out = BagReader(tmp_path / 'out')
    for topic in (ESTIMATES_SLOPE, ESTIMATES_TIRE_FORCES):
        arrays = out.topic_arrays([topic])[topic]
        fields = decode_batch(arrays.msgtype, arrays.datas)
        for values in fields.values.values():
            assert np.isfinite(values.astype(np.float64)).all(), topic


def test_vd_report_takes_a_mapping_replays_a_bag_without_estimates_and_summarises_inputs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import json

    import yaml
    from vd_observer_node.tools.cli import main

    bag = tmp_path / 'user'
    _user_bag_with_truth(bag, 3.0, 100.0, gap=(1.0, 1.8))
    mapping = tmp_path / 'car.yaml'
    mapping.write_text(yaml.safe_dump(USER_MAPPING))
    out = tmp_path / 'report'
    args = ['report', str(bag), '--mapping', str(mapping), '--out', str(out), '--no-figures']
    assert main([*args, '--no-progress']) == 0
    text = capsys.readouterr().out
    assert f'{bag} has no estimates: replayed it with {mapping} first' in text
    line = 'input wheel_torques (/can/wheel_torques): 220 messages, longest gap 0.810 s, 1 gaps'
    assert line in text
    notes = json.loads((out / 'metrics.json').read_text())['notes']
    assert any(n.startswith(line) for n in notes)
    assert any(n.startswith('input wheel_angles (/joint_states): 300 messages') for n in notes)
    bad = tmp_path / 'bad.yaml'
    bad.write_text(yaml.safe_dump({'body_speed': {'topic': '/odom'}}))
    assert main([*args[:3], str(bad), *args[4:]]) == 2
    err = capsys.readouterr().err
    assert err.strip().splitlines()[-1].startswith('vd: error: ') and 'body_speed.type' in err


def test_separate_estimating_nodes_refuse_a_torque_path_they_cannot_run(tmp_path: Path) -> None:
    import yaml
    from vd_observer_node.nodes.node_params import take_input_mapping

    path = tmp_path / 'car.yaml'
    path.write_text(yaml.safe_dump({'torque_source': 'engine'}), encoding='utf-8')

    def values() -> dict[str, object]:
        return {'input_mapping': str(path), 'kernel': 'compiled'}

    # the observer and the player do not read torques: the file is theirs as it is
    assert take_input_mapping(values()).torque_source == 'engine'
    with pytest.raises(MappingError, match="torque_source 'engine' runs in pipeline_node") as info:
        take_input_mapping(values(), estimates=True)
    assert '\n' not in str(info.value) and str(path) in str(info.value)
    # pipeline_node runs every torque path
    assert take_input_mapping(values(), estimates=True, torque_paths=True).torque_source == (
        'engine'
    )
