"""A car's recording on standard ROS types only, made from a simulator run (issue 15's example).

What a real car logs instead of vd's sensor topics (:class:`CarSensors`): ABS wheel speeds as
``sensor_msgs/JointState`` velocities at 100 Hz, the body speed as ``nav_msgs/Odometry`` at
50 Hz, the wheel torques decoded from CAN as ``std_msgs/Float64MultiArray`` at 100 Hz (no
header: stamped by their log time), each topic on its own clock phase. The simulator's true
signals at 1 kHz give the samples:

* an ABS wheel-speed sensor reports the mean speed over its last sample period (the tone
  wheel's edges counted or timed over the period), plus white noise;
* odometry and torque add white noise to the true body speed and wheel torque.

:data:`STANDARD_MAPPING` is the input mapping of such a bag (shipped as
``config/input_mapping_abs_example.yaml``, a test checks the two agree).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any, Final

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vd_observer_node.bag.typestore import message_class, serialize
from vd_observer_node.bag.writer import BagWriter

__all__ = [
    'IMU_MAPPING',
    'JOINTS',
    'JOINT_TORQUES',
    'STANDARD_MAPPING',
    'CarSensors',
    'abs_wheel_speeds',
    'float64_array',
    'header',
    'imu',
    'joint_state',
    'odometry',
    'write_standard_bag',
]

FloatArray = NDArray[np.float64]
_NS: Final = 1_000_000_000
#: URDF-style joint names of the four wheels, FL, FR, RL, RR.
JOINTS: Final = ('wheel_fl_joint', 'wheel_fr_joint', 'wheel_rl_joint', 'wheel_rr_joint')
#: As a robot publishes them: another order, and a joint vd does not use.
_PUBLISHED: Final = ('steering_joint', 'wheel_rr_joint', 'wheel_fl_joint', 'wheel_rl_joint',
                     'wheel_fr_joint')  # fmt: skip
_ORDER: Final = [JOINTS.index(j) if j in JOINTS else -1 for j in _PUBLISHED]

STANDARD_MAPPING: Final[dict[str, Any]] = {
    'wheel_speeds': {
        'topic': '/joint_states',
        'type': 'sensor_msgs/msg/JointState',
        'joints': list(JOINTS),
        'unit': 'rad/s',
        'sign': [1, -1, 1, -1],
    },
    'body_speed': {'topic': '/odom', 'type': 'nav_msgs/msg/Odometry', 'unit': 'm/s'},
    'wheel_torques': {
        'topic': '/can/wheel_torques',
        'type': 'std_msgs/msg/Float64MultiArray',
        'indices': [0, 1, 2, 3],
        'unit': 'N m',
    },
    'alignment': 'latest',
}
#: :data:`STANDARD_MAPPING` for ``CarSensors(imu_rate_hz=...)``: the IMU fused (aligned with
#: the body, as stated: unstated, its mounting would be learnt first)
IMU_MAPPING: Final[dict[str, Any]] = {
    **STANDARD_MAPPING,
    'imu': {
        'topic': '/imu', 'type': 'sensor_msgs/msg/Imu', 'unit': 'm/s^2',
        'mount_rpy_deg': [0, 0, 0],
    },
}  # fmt: skip
#: :data:`STANDARD_MAPPING` for ``CarSensors(torques_in_joint_states=True)``.
JOINT_TORQUES: Final[dict[str, Any]] = {
    **STANDARD_MAPPING,
    'wheel_torques': {**STANDARD_MAPPING['wheel_speeds'], 'unit': 'N m'},
}


@dataclass(frozen=True)
class CarSensors:
    """Rates, phases and noise of the recorded topics.

    Attributes:
        wheel_rate_hz: ABS wheel speeds [Hz].
        wheel_noise_std: white noise on each wheel speed [rad/s].
        odom_rate_hz: odometry [Hz].
        speed_noise_std: white noise on the body speed [m/s].
        torque_rate_hz: CAN wheel torques [Hz].
        torque_noise_std: white noise on each wheel torque [N m].
        phase_s: (wheel, odometry, torque) clock offsets [s], so no two topics share stamps.
        seed: noise generator seed.
        torques_in_joint_states: carry the torques as the JointState's ``effort`` (at the
            wheel stamps, mirrored like the speeds) instead of a CAN Float64MultiArray: every
            input then has a header stamp (:data:`JOINT_TORQUES`).
        imu_rate_hz: an accelerometer on ``/imu`` (``sensor_msgs/Imu``, the true specific
            force of the simulator's ``imu_true``, forward axis x) at this rate [Hz]; 0: none
            (:data:`IMU_MAPPING` maps it).
        imu_noise_std: white noise on its forward specific force [m/s^2].
        imu_bias: constant offset of its forward specific force [m/s^2].
        imu_phase_s: its clock offset [s].
    """

    wheel_rate_hz: float = 100.0
    wheel_noise_std: float = 0.05
    odom_rate_hz: float = 50.0
    speed_noise_std: float = 0.05
    torque_rate_hz: float = 100.0
    torque_noise_std: float = 2.0
    phase_s: tuple[float, float, float] = (0.0, 0.003, 0.006)
    seed: int = 0
    torques_in_joint_states: bool = False
    imu_rate_hz: float = 0.0
    imu_noise_std: float = 0.05
    imu_bias: float = 0.0
    imu_phase_s: float = 0.001


def header(stamp_ns: int, frame: str = 'base_link') -> Any:
    """A std_msgs/Header (rosbags class) stamped ``stamp_ns`` [ns]."""
    time_cls = message_class('builtin_interfaces/msg/Time')
    stamp = time_cls(sec=stamp_ns // _NS, nanosec=stamp_ns % _NS)
    return message_class('std_msgs/msg/Header')(stamp=stamp, frame_id=frame)


def joint_state(
    stamp_ns: int,
    names: list[str],
    position: ArrayLike = (),
    velocity: ArrayLike = (),
    effort: ArrayLike = (),
) -> Any:
    """A sensor_msgs/JointState (rosbags class); empty arrays where not given."""
    return message_class('sensor_msgs/msg/JointState')(
        header=header(stamp_ns),
        name=list(names),
        position=np.asarray(position, dtype=np.float64),
        velocity=np.asarray(velocity, dtype=np.float64),
        effort=np.asarray(effort, dtype=np.float64),
    )


def float64_array(values: ArrayLike) -> Any:
    """A std_msgs/Float64MultiArray (rosbags class) without layout dimensions."""
    layout = message_class('std_msgs/msg/MultiArrayLayout')(dim=[], data_offset=0)
    return message_class('std_msgs/msg/Float64MultiArray')(
        layout=layout, data=np.asarray(values, dtype=np.float64)
    )


def odometry(stamp_ns: int, speed: float) -> Any:
    """A nav_msgs/Odometry (rosbags class) with twist.twist.linear.x = speed [m/s]."""
    vec = message_class('geometry_msgs/msg/Vector3')
    twist = message_class('geometry_msgs/msg/Twist')(
        linear=vec(x=speed, y=0.0, z=0.0), angular=vec(x=0.0, y=0.0, z=0.0)
    )
    point = message_class('geometry_msgs/msg/Point')(x=0.0, y=0.0, z=0.0)
    quat = message_class('geometry_msgs/msg/Quaternion')(x=0.0, y=0.0, z=0.0, w=1.0)
    pose = message_class('geometry_msgs/msg/Pose')(position=point, orientation=quat)
    cov = np.zeros(36)
    return message_class('nav_msgs/msg/Odometry')(
        header=header(stamp_ns, 'odom'),
        child_frame_id='base_link',
        pose=message_class('geometry_msgs/msg/PoseWithCovariance')(pose=pose, covariance=cov),
        twist=message_class('geometry_msgs/msg/TwistWithCovariance')(twist=twist, covariance=cov),
    )


def imu(stamp_ns: int, forward: float, pitch_rate: float | None = None) -> Any:
    """A sensor_msgs/Imu (rosbags class) reading ``forward`` [m/s^2] on its x axis, gravity
    on z, and ``pitch_rate`` [rad/s] about y (None: the angular velocity unknown, as an ESC
    cluster's forward acceleration logged alone); orientation unknown (covariance[0] = -1, as
    the message's comment says)."""
    vec = message_class('geometry_msgs/msg/Vector3')
    quat = message_class('geometry_msgs/msg/Quaternion')(x=0.0, y=0.0, z=0.0, w=1.0)
    unknown = np.zeros(9)
    unknown[0] = -1.0
    return message_class('sensor_msgs/msg/Imu')(
        header=header(stamp_ns, 'imu_link'),
        orientation=quat,
        orientation_covariance=unknown,
        angular_velocity=vec(x=0.0, y=pitch_rate or 0.0, z=0.0),
        angular_velocity_covariance=unknown if pitch_rate is None else np.zeros(9),
        linear_acceleration=vec(x=forward, y=0.0, z=9.81),
        linear_acceleration_covariance=np.zeros(9),
    )


def _stamps(t: FloatArray, rate_hz: float, phase_s: float) -> FloatArray:
    """Sample instants [s] of a sensor at rate_hz within the simulated span t."""
    period = 1.0 / rate_hz
    first = t[0] + period + phase_s  # one period of history for the ABS mean
    stamps: FloatArray = np.arange(first, t[-1], period)
    return stamps


def abs_wheel_speeds(
    t: ArrayLike, true_angle: ArrayLike, stamps: ArrayLike, period: float
) -> FloatArray:
    """Mean wheel speed over the period before each stamp, from the true angle.

    Args:
        t: shape (N,), [s], simulator stamps.
        true_angle: shape (N, 4), [rad], true unwrapped wheel angles.
        stamps: shape (M,), [s], sensor stamps (at least ``period`` after t[0]).
        period: [s] the averaging window (the sensor's sample period).

    Returns:
        shape (M, 4), [rad/s].
    """
    ts = np.asarray(t, dtype=np.float64)
    angle = np.asarray(true_angle, dtype=np.float64)
    at = np.asarray(stamps, dtype=np.float64)
    now = np.stack([np.interp(at, ts, angle[:, i]) for i in range(4)], axis=1)
    before = np.stack([np.interp(at - period, ts, angle[:, i]) for i in range(4)], axis=1)
    speeds: FloatArray = (now - before) / period
    return speeds


def write_standard_bag(path: str | os.PathLike[str], sim: Any, sensors: CarSensors) -> None:
    """Write a simulator run as a car's standard-types recording (module docstring).

    Args:
        path: new bag folder.
        sim: a simulator run's ``SimResult`` (duck-typed: only its arrays; 1 kHz ideal
            sensors are best: its true angle, speed and torque are sampled here).
        sensors: rates, phases and noise.
    """
    rng = np.random.default_rng(sensors.seed)
    t = np.asarray(sim.t, dtype=np.float64)
    sign = np.array([1.0, -1.0, 1.0, -1.0])
    wheel_t = _stamps(t, sensors.wheel_rate_hz, sensors.phase_s[0])
    speeds = abs_wheel_speeds(t, sim.angle_true, wheel_t, 1.0 / sensors.wheel_rate_hz)
    speeds = speeds + rng.normal(0.0, sensors.wheel_noise_std, speeds.shape)
    odom_t = _stamps(t, sensors.odom_rate_hz, sensors.phase_s[1])
    body = np.interp(odom_t, t, sim.speed_true)
    body = body + rng.normal(0.0, sensors.speed_noise_std, body.shape)
    in_joints = sensors.torques_in_joint_states
    torque_t = wheel_t if in_joints else _stamps(t, sensors.torque_rate_hz, sensors.phase_s[2])
    torque = np.stack([np.interp(torque_t, t, sim.wheel_torque[:, i]) for i in range(4)], 1)
    torque = torque + rng.normal(0.0, sensors.torque_noise_std, torque.shape)
    rows: list[tuple[int, str, bytes]] = []
    for k, stamp in enumerate(np.round(wheel_t * _NS).astype(np.int64).tolist()):
        velocity = [0.0 if i < 0 else float(speeds[k, i] * sign[i]) for i in _ORDER]
        # only joint states carry the torques at the wheel stamps; on their own clock the
        # torque samples need not be as many as the wheel stamps
        effort = (
            [0.0 if i < 0 else float(torque[k, i] * sign[i]) for i in _ORDER] if in_joints else []
        )
        msg = joint_state(stamp, [*_PUBLISHED], (), velocity, effort)
        rows.append((stamp, '/joint_states', serialize(msg)))
    for k, stamp in enumerate(np.round(odom_t * _NS).astype(np.int64).tolist()):
        rows.append((stamp, '/odom', serialize(odometry(stamp, float(body[k])))))
    for k, stamp in enumerate(np.round(torque_t * _NS).astype(np.int64).tolist()):
        if not in_joints:
            rows.append((stamp, '/can/wheel_torques', serialize(float64_array(torque[k]))))
    if sensors.imu_rate_hz > 0.0:
        # drawn after every other sample: the bag without an IMU stays the same
        imu_t = _stamps(t, sensors.imu_rate_hz, sensors.imu_phase_s)
        forward = np.interp(imu_t, t, np.asarray(sim.imu_true, dtype=np.float64)[:, 0])
        forward = forward + sensors.imu_bias + rng.normal(0.0, sensors.imu_noise_std, imu_t.size)
        for k, stamp in enumerate(np.round(imu_t * _NS).astype(np.int64).tolist()):
            rows.append((stamp, '/imu', serialize(imu(stamp, float(forward[k])))))
    rows.sort(key=lambda row: row[0])
    with BagWriter(path) as writer:
        writer.add_topic('/joint_states', 'sensor_msgs/msg/JointState')
        writer.add_topic('/odom', 'nav_msgs/msg/Odometry')
        if not in_joints:
            writer.add_topic('/can/wheel_torques', 'std_msgs/msg/Float64MultiArray')
        if sensors.imu_rate_hz > 0.0:
            writer.add_topic('/imu', 'sensor_msgs/msg/Imu')
        for stamp, topic, data in rows:
            writer.write(topic, data, stamp)
