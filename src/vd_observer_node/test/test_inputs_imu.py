"""The ``imu`` input of the mapping (issue 27): its keys and refusals, and its decoding from
sensor_msgs/Imu, AccelStamped and Float64MultiArray with a mounting rotation, against scipy's
rotations."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from vd_observer_node.bag.reader import TopicArrays
from vd_observer_node.bag.typestore import message_class, serialize
from vd_observer_node.errors import ConfigurationError
from vd_observer_node.estimation.body_pitch import BodyPitch
from vd_observer_node.estimation.imu_settings import ImuGradeConfig, imu_grade_config
from vd_observer_node.inputs.decode import InputDecoder, decode_input
from vd_observer_node.inputs.errors import MappingError
from vd_observer_node.inputs.mapping import default_mapping, mapping_from_dict

G = 9.80665
#: the sensor's frame in the body: rolled 4, pitched -7 (nose up), yawed 90 deg (its x
#: points to the car's left)
RPY_DEG = [4.0, -7.0, 90.0]
#: the body's specific force: 1.3 m/s^2 forward, 0.4 left, gravity
BODY = np.array([1.3, 0.4, G])
#: the body's angular rate: rolling, pitching (0.05 rad/s nose up: -0.05 in REP 103), yawing
BODY_RATE = np.array([0.2, -0.05, 0.3])


def _sensor_vector(body: np.ndarray = BODY) -> np.ndarray:
    # tf's convention: the sensor frame's orientation in the body is Rz(yaw) Ry(pitch) Rx(roll)
    mount = Rotation.from_euler('ZYX', RPY_DEG[::-1], degrees=True)
    vector: np.ndarray = mount.inv().apply(body)
    return vector


def _header(stamp_ns: int) -> Any:
    time = message_class('builtin_interfaces/msg/Time')(
        sec=stamp_ns // 1_000_000_000, nanosec=stamp_ns % 1_000_000_000
    )
    return message_class('std_msgs/msg/Header')(stamp=time, frame_id='imu_link')


def _imu_message(stamp_ns: int, a: np.ndarray, w: np.ndarray | None = None) -> bytes:
    """An Imu of specific force ``a`` and angular rate ``w`` (None: marked unknown, REP 145)."""
    vec = message_class('geometry_msgs/msg/Vector3')
    quat = message_class('geometry_msgs/msg/Quaternion')(x=0.0, y=0.0, z=0.0, w=1.0)
    rate_covariance = np.zeros(9)
    if w is None:
        rate_covariance[0] = -1.0
        w = np.zeros(3)
    msg = message_class('sensor_msgs/msg/Imu')(
        header=_header(stamp_ns),
        orientation=quat,
        orientation_covariance=np.zeros(9),
        angular_velocity=vec(x=float(w[0]), y=float(w[1]), z=float(w[2])),
        angular_velocity_covariance=rate_covariance,
        linear_acceleration=vec(x=float(a[0]), y=float(a[1]), z=float(a[2])),
        linear_acceleration_covariance=np.zeros(9),
    )
    return serialize(msg, 'sensor_msgs/msg/Imu')


def _accel_message(stamp_ns: int, a: np.ndarray) -> bytes:
    vec = message_class('geometry_msgs/msg/Vector3')
    accel = message_class('geometry_msgs/msg/Accel')(
        linear=vec(x=float(a[0]), y=float(a[1]), z=float(a[2])), angular=vec(x=0.0, y=0.0, z=0.0)
    )
    msg = message_class('geometry_msgs/msg/AccelStamped')(header=_header(stamp_ns), accel=accel)
    return serialize(msg, 'geometry_msgs/msg/AccelStamped')


def _array_message(values: list[float]) -> bytes:
    layout = message_class('std_msgs/msg/MultiArrayLayout')(dim=[], data_offset=0)
    msg = message_class('std_msgs/msg/Float64MultiArray')(
        layout=layout, data=np.array(values, dtype=np.float64)
    )
    return serialize(msg, 'std_msgs/msg/Float64MultiArray')


def _mapping(**imu: Any) -> Any:
    return mapping_from_dict({'imu': {'topic': '/imu', **imu}}, source='car.yaml')


def test_the_imu_is_optional_and_off_by_default() -> None:
    assert default_mapping().imu is None
    assert default_mapping().is_default
    mapping = _mapping(type='sensor_msgs/msg/Imu')
    assert mapping.imu is not None and not mapping.is_default
    assert mapping.imu.axis == pytest.approx((1.0, 0.0, 0.0))


@pytest.mark.parametrize(
    ('imu', 'match'),
    [
        ({'type': 'sensor_msgs/msg/JointState'}, 'not supported'),
        ({'type': 'sensor_msgs/msg/Imu', 'mount_rpy_deg': [0, 1]}, 'roll, pitch, yaw'),
        ({'type': 'sensor_msgs/msg/Imu', 'unit': 'ft/s^2'}, 'unit'),
        (
            {'type': 'std_msgs/msg/Float64MultiArray', 'indices': [0], 'mount_rpy_deg': [0, 2, 0]},
            'needs the 3 axes',
        ),
        ({'type': 'std_msgs/msg/Float64MultiArray', 'indices': [0, 1]}, 'indices must list'),
        ({'type': 'sensor_msgs/msg/Imu', 'fusion': {'bandwidth': 3.0}}, 'not a setting'),
        ({'type': 'sensor_msgs/msg/Imu', 'fusion': [1.0]}, 'must map settings'),
    ],
)
def test_refusals(imu: dict[str, Any], match: str) -> None:
    with pytest.raises(MappingError, match=match):
        _mapping(**imu)
    with pytest.raises(MappingError, match='mount_rpy_deg is for imu only'):
        mapping_from_dict(
            {
                'body_speed': {
                    'topic': '/odom',
                    'type': 'nav_msgs/msg/Odometry',
                    'mount_rpy_deg': [0, 0, 0],
                }
            }
        )


def test_the_mapping_carries_the_sensor_s_fusion_settings() -> None:
    mapping = _mapping(
        type='sensor_msgs/msg/Imu', fusion={'lag_compensation': False, 'tau': 0.2, 'step_tau': 0}
    )
    assert mapping.imu is not None
    config = imu_grade_config(BodyPitch(1e-6, 1.5, 0.4), mapping.imu.fusion)
    assert config.lag_compensation is False
    assert (config.tau, config.step_tau, config.pitch_compliance) == (0.2, 0.0, 1e-6)
    assert (config.pitch_frequency, config.pitch_damping) == (1.5, 0.4)
    assert imu_grade_config(BodyPitch()) == ImuGradeConfig()
    negative = _mapping(type='sensor_msgs/msg/Imu', fusion={'tau': -1}).imu
    assert negative is not None
    with pytest.raises(ConfigurationError, match=r'imu\.tau'):
        imu_grade_config(BodyPitch(), negative.fusion)


def test_imu_and_accel_stamped_give_the_body_forward_specific_force() -> None:
    a = _sensor_vector()
    for msgtype, encode in (
        ('sensor_msgs/msg/Imu', _imu_message),
        ('geometry_msgs/msg/AccelStamped', _accel_message),
    ):
        spec = _mapping(type=msgtype, mount_rpy_deg=RPY_DEG).imu
        assert spec is not None
        stamp, frame, row = InputDecoder(spec).decode(encode(1_500_000_000, a))
        assert stamp == 1_500_000_000 and frame == b'imu_link'
        assert row[0] == pytest.approx(BODY[0], abs=1e-12)
        # no angular rate: an AccelStamped has none, this Imu marks its unknown
        assert math.isnan(row[1])
        # the batch decoder of a bag gives the same
        arrays = TopicArrays(msgtype, np.array([7], dtype=np.int64), [encode(2_000, a)])
        series = decode_input(spec, arrays)
        np.testing.assert_allclose(series.values, [row], atol=1e-12)  # nan as nan
        assert series.stamp_ns.tolist() == [2_000]


def test_the_imu_s_angular_velocity_gives_the_body_s_pitch_rate() -> None:
    a, w = _sensor_vector(), _sensor_vector(BODY_RATE)
    # in g: the specific force's unit; the rate is rad/s (REP 103) whatever it says
    spec = _mapping(type='sensor_msgs/msg/Imu', mount_rpy_deg=RPY_DEG, unit='g').imu
    assert spec is not None
    message = _imu_message(3_000, a / G, w)
    _, _, row = InputDecoder(spec).decode(message)
    assert row == pytest.approx((BODY[0], BODY_RATE[1]), abs=1e-12)
    arrays = TopicArrays(spec.msgtype, np.array([7], dtype=np.int64), [message])
    np.testing.assert_allclose(decode_input(spec, arrays).values, [row], atol=1e-12)
    # REP 145: a covariance of -1 marks the angular velocity unknown
    _, _, row = InputDecoder(spec).decode(_imu_message(3_000, a / G, None))
    assert row[0] == pytest.approx(BODY[0]) and math.isnan(row[1])


def test_float64_array_with_three_axes_in_g_or_one_forward_element() -> None:
    a = _sensor_vector() / G
    spec = _mapping(
        type='std_msgs/msg/Float64MultiArray', indices=[1, 2, 0], unit='g', mount_rpy_deg=RPY_DEG
    ).imu
    assert spec is not None
    # the array holds z, x, y at 0, 1, 2: indices name x, y, z's elements
    _, _, row = InputDecoder(spec).decode(_array_message([a[2], a[0], a[1]]), receive_ns=5)
    assert row[0] == pytest.approx(BODY[0], abs=1e-12) and math.isnan(row[1])
    forward = _mapping(type='std_msgs/msg/Float64MultiArray', indices=[1], sign=[-1]).imu
    assert forward is not None
    stamp, _, row = InputDecoder(forward).decode(_array_message([9.0, -0.8]), receive_ns=42)
    assert stamp == 42 and row[0] == pytest.approx(0.8) and math.isnan(row[1])


def test_the_player_plays_a_recorded_imu_with_the_mapped_inputs() -> None:
    from vd_observer_node.nodes.player_node import mapped_topics

    mapping = _mapping(type='sensor_msgs/msg/Imu')
    own = {spec.topic: spec.msgtype for spec in default_mapping().specs}
    assert mapped_topics(mapping, own) == list(own)  # not recorded: not played, not refused
    assert mapped_topics(mapping, {**own, '/imu': 'sensor_msgs/msg/Imu'}) == [*own, '/imu']
    with pytest.raises(MappingError, match=r'imu\.type: /imu is'):
        mapped_topics(mapping, {**own, '/imu': 'geometry_msgs/msg/AccelStamped'})


def test_the_sensor_s_own_vectors_for_learning_its_mounting() -> None:
    """`decode_imu_vectors` gives what the sensor measured, in its frame and SI units: the
    mounting is not applied (vd calibrate learns it), the unit and sign of the specific force
    are."""
    from vd_observer_node.inputs.decode import decode_imu_vectors

    a, w = _sensor_vector(), _sensor_vector(BODY_RATE)
    spec = _mapping(type='sensor_msgs/msg/Imu', mount_rpy_deg=RPY_DEG, unit='g').imu
    assert spec is not None and spec.three_axes
    datas = [_imu_message(3_000, a / G, w), _imu_message(4_000, a / G, None)]
    series = decode_imu_vectors(spec, TopicArrays(spec.msgtype, np.array([1, 2]), datas))
    assert series.stamp_ns.tolist() == [3_000, 4_000]
    np.testing.assert_allclose(series.values[0], [*a, *w], atol=1e-12)
    np.testing.assert_allclose(series.values[1, :3], a, atol=1e-12)
    assert np.isnan(series.values[1, 3:]).all()  # REP 145: the rate unknown
    array = _mapping(type='std_msgs/msg/Float64MultiArray', indices=[1, 2, 0], sign=[-1]).imu
    assert array is not None
    message = _array_message([a[2], a[0], a[1]])
    series = decode_imu_vectors(array, TopicArrays(array.msgtype, np.array([9]), [message]))
    np.testing.assert_allclose(series.values[0, :3], -a, atol=1e-12)
    assert series.stamp_ns.tolist() == [9]  # no header: the log time
    forward = _mapping(type='std_msgs/msg/Float64MultiArray', indices=[1]).imu
    assert forward is not None and not forward.three_axes
    with pytest.raises(MappingError, match='needs the 3 axes'):
        decode_imu_vectors(forward, TopicArrays(forward.msgtype, np.array([9]), [message]))


def test_an_unstated_mounting_gives_the_sensor_s_six_values_live_and_from_a_bag() -> None:
    """Without ``mount_rpy_deg`` the mounting is learnt online (`mount_learner`): every type
    decodes to the sensor's own specific force in m/s^2 (whatever its unit) and angular rate,
    no rotation, the live decoder as the bag's."""
    a, w = _sensor_vector(), _sensor_vector(BODY_RATE)
    nan3 = [math.nan] * 3
    cases = [
        ({'type': 'sensor_msgs/msg/Imu', 'unit': 'g'}, _imu_message(3_000, a / G, w), [*a, *w]),
        ({'type': 'sensor_msgs/msg/Imu'}, _imu_message(3_000, a, None), [*a, *nan3]),
        ({'type': 'geometry_msgs/msg/AccelStamped'}, _accel_message(3_000, a), [*a, *nan3]),
        (
            {'type': 'std_msgs/msg/Float64MultiArray', 'indices': [1, 2, 0], 'unit': 'g'},
            _array_message([a[2] / G, a[0] / G, a[1] / G]),
            [*a, *nan3],
        ),
    ]
    for given, message, expected in cases:
        spec = _mapping(**given).imu
        assert spec is not None and spec.learns_mounting and spec.width == 6
        _, _, row = InputDecoder(spec).decode(message, receive_ns=3_000)
        np.testing.assert_allclose(row, expected, atol=1e-12)  # nan as nan
        arrays = TopicArrays(spec.msgtype, np.array([3_000], dtype=np.int64), [message])
        np.testing.assert_array_equal(decode_input(spec, arrays).values, [row])  # bit for bit
