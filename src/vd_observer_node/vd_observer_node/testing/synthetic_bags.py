"""Synthetic drive bags (sensors + truth) for tests and the replay benchmark.

The drive is a smooth speed profile v(t) = v0 + dv * sin(2 pi f t) on a flat road, rolling
without slip, so the true wheel speed is v / R_eff and its derivative is known exactly.
"""

from __future__ import annotations

import os

import numpy as np
from vd_common.topics import (
    SENSORS_BODY_VELOCITY,
    SENSORS_WHEEL_ANGLES,
    SENSORS_WHEEL_TORQUES,
    TRUTH_BODY_ACCEL,
    TRUTH_WHEEL_STATES,
)

from vd_observer_node.bag.cdr_batch import encode_batch
from vd_observer_node.bag.writer import BagWriter

__all__ = ['SyntheticDrive', 'synthetic_drive', 'write_synthetic_drive_bag']

_R_EFF = 0.26  # [m] the Clio's effective rolling radius


class SyntheticDrive:
    """Arrays of a synthetic drive sampled at ``rate_hz``.

    Attributes:
        stamp_ns: shape (N,), [ns].
        speed: shape (N,), [m/s].
        accel: shape (N,), [m/s^2].
        angle: shape (N, 4), [rad], order FL, FR, RL, RR.
        omega: shape (N, 4), [rad/s].
        omega_dot: shape (N, 4), [rad/s^2].
        torque: shape (N, 4), [N m].
    """

    def __init__(self, duration_s: float, rate_hz: float, seed: int) -> None:
        rng = np.random.default_rng(seed)
        n = round(duration_s * rate_hz)
        t = np.arange(n) / rate_hz
        self.stamp_ns = np.round(t * 1e9).astype(np.int64) + 1_000_000_000
        v0, dv, f = 15.0, 3.0, 0.1
        w = 2 * np.pi * f
        self.speed = v0 + dv * np.sin(w * t)
        self.accel = dv * w * np.cos(w * t)
        distance = v0 * t - dv / w * (np.cos(w * t) - 1.0)
        self.angle = np.repeat((distance / _R_EFF)[:, None], 4, axis=1)
        self.omega = np.repeat((self.speed / _R_EFF)[:, None], 4, axis=1)
        self.omega_dot = np.repeat((self.accel / _R_EFF)[:, None], 4, axis=1)
        front = 905.0 * self.accel * _R_EFF / 2 + 20.0
        self.torque = np.stack([front, front, np.zeros(n) - 2.0, np.zeros(n) - 2.0], axis=1)
        # Small measurement noise so decoders see non-trivial values.
        self.torque += rng.normal(0.0, 0.5, size=self.torque.shape)


def synthetic_drive(duration_s: float, rate_hz: float = 100.0, seed: int = 0) -> SyntheticDrive:
    """Build the arrays of a synthetic drive (see :class:`SyntheticDrive`)."""
    return SyntheticDrive(duration_s, rate_hz, seed)


def write_synthetic_drive_bag(
    path: str | os.PathLike[str],
    duration_s: float,
    rate_hz: float = 100.0,
    seed: int = 0,
    *,
    with_truth: bool = True,
    frame_id: str = 'base_link',
) -> SyntheticDrive:
    """Write a bag with the three sensor topics (and truth) of a synthetic drive.

    Log time of every message = its header stamp. Truth: ``/vd/truth/wheel_states``
    (WheelStates) and ``/vd/truth/body_accel`` (AccelStamped).
    """
    drive = synthetic_drive(duration_s, rate_hz, seed)
    n = drive.stamp_ns.shape[0]
    zeros = np.zeros(n)
    stamps = drive.stamp_ns
    topics: dict[str, tuple[str, dict[str, np.ndarray]]] = {
        SENSORS_WHEEL_ANGLES: ('vd_msgs/msg/WheelAngles', {'angle': drive.angle}),
        SENSORS_BODY_VELOCITY: (
            'geometry_msgs/msg/TwistStamped',
            {
                'twist.linear.x': drive.speed,
                'twist.linear.y': zeros,
                'twist.linear.z': zeros,
                'twist.angular.x': zeros,
                'twist.angular.y': zeros,
                'twist.angular.z': zeros,
            },
        ),
        SENSORS_WHEEL_TORQUES: (
            'vd_msgs/msg/WheelTorques',
            {
                'torque': drive.torque,
                'engine_torque': drive.torque[:, 0] / 4.0,
                'engine_speed': drive.omega[:, 0] * 4.0,
                'gear': np.full(n, 3, dtype=np.int8),
            },
        ),
    }
    if with_truth:
        topics[TRUTH_WHEEL_STATES] = (
            'vd_msgs/msg/WheelStates',
            {'angle': drive.angle, 'omega': drive.omega, 'omega_dot': drive.omega_dot},
        )
        topics[TRUTH_BODY_ACCEL] = (
            'geometry_msgs/msg/AccelStamped',
            {
                'accel.linear.x': drive.accel,
                'accel.linear.y': zeros,
                'accel.linear.z': zeros,
                'accel.angular.x': zeros,
                'accel.angular.y': zeros,
                'accel.angular.z': zeros,
            },
        )
    encoded = {
        name: encode_batch(msgtype, stamps, frame_id, values)
        for name, (msgtype, values) in topics.items()
    }
    with BagWriter(path) as writer:
        for name, (msgtype, _) in topics.items():
            writer.add_topic(name, msgtype)
        log = stamps.tolist()
        names = list(encoded)
        for k in range(n):  # interleaved as a live recording would be
            for name in names:
                writer.write(name, encoded[name][k], log[k])
    return drive
