"""Sensor models: quantised wheel encoders, noisy body speed, wheel torque and IMU.

The noise generators are seeded and consume one draw per sample in sample order, so the
measured series do not depend on how the simulator splits the run into integration chunks.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from vd_sim_node.vehicle.scenario import SensorSettings

__all__ = ['SensorModel', 'imu_specific_force', 'quantise_angle']

FloatArray = NDArray[np.float64]


def quantise_angle(angle: FloatArray, counts_per_rev: int) -> FloatArray:
    """Angle seen by an incremental encoder with ``counts_per_rev`` counts per revolution.

    Args:
        angle: true unwrapped angle, any shape, [rad].
        counts_per_rev: encoder resolution; 0 returns the angle unchanged (ideal sensor).

    Returns:
        ``floor(angle / step) * step`` with ``step = 2 pi / counts_per_rev``, [rad].
    """
    if counts_per_rev <= 0:
        return np.array(angle, dtype=float, copy=True)
    step = 2.0 * math.pi / counts_per_rev
    out: FloatArray = np.floor(np.asarray(angle) / step) * step
    return out


def imu_specific_force(
    accel: FloatArray,
    slope: FloatArray,
    pitch: FloatArray,
    mount_pitch: float,
    gravity: float,
    normal_accel: FloatArray | float = 0.0,
) -> FloatArray:
    """Specific force an IMU on the body measures, in its own x (forward) and z (up) axes.

    In road axes (x along the road, z normal to it) the specific force is
    ``(a + g sin(alpha), a_n + g cos(alpha))``; the sensor's x axis is pitched nose up by
    ``phi = -(mount_pitch + pitch)`` from the road, so it reads
    ``f_x = (a + g sin(alpha)) cos(phi) + (a_n + g cos(alpha)) sin(phi)`` and
    ``f_z = -(a + g sin(alpha)) sin(phi) + (a_n + g cos(alpha)) cos(phi)``.

    Args:
        accel: acceleration along the road, shape (M,), [m/s^2].
        slope: road slope, positive uphill, shape (M,), [rad].
        pitch: body pitch relative to the road, nose down positive, shape (M,), [rad].
        mount_pitch: pitch of the sensor's frame in the body frame about y (REP 103: nose
            down positive), [rad].
        gravity: [m/s^2].
        normal_accel: acceleration of the sensor normal to the road, (M,) or scalar, [m/s^2].

    Returns:
        Shape (M, 2): f_x, f_z, [m/s^2].
    """
    phi = -(mount_pitch + np.asarray(pitch, dtype=float))
    along = np.asarray(accel, dtype=float) + gravity * np.sin(slope)
    normal = normal_accel + gravity * np.cos(slope)
    c, s = np.cos(phi), np.sin(phi)
    out: FloatArray = np.stack([along * c + normal * s, -along * s + normal * c], axis=1)
    return out


class SensorModel:
    """Turns true signals into measured ones, sample by sample in order."""

    def __init__(self, settings: SensorSettings, seed: int | None = None) -> None:
        """Create the generators.

        Args:
            settings: sensor settings of the scenario.
            seed: overrides ``settings.seed`` when given.
        """
        self.settings = settings
        seq = np.random.SeedSequence(settings.seed if seed is None else seed)
        # the IMU's stream is a third child, its gyro's a fourth: the first ones stay as they
        # were (a SeedSequence's children do not depend on how many are spawned)
        speed_seq, torque_seq, imu_seq, gyro_seq = seq.spawn(4)
        self._speed_rng = np.random.default_rng(speed_seq)
        self._torque_rng = np.random.default_rng(torque_seq)
        self._imu_rng = np.random.default_rng(imu_seq)
        self._gyro_rng = np.random.default_rng(gyro_seq)

    def measure(
        self, angle: FloatArray, speed: FloatArray, torque: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Measure a block of consecutive samples.

        Args:
            angle: true wheel angles, shape (M, 4), [rad].
            speed: true body speed, shape (M,), [m/s].
            torque: true wheel torques, shape (M, 4), [N m].

        Returns:
            (angle, speed, torque) as measured, same shapes.
        """
        s = self.settings
        a = quantise_angle(angle, s.encoder_counts_per_rev)
        v = np.array(speed, dtype=float, copy=True)
        if s.speed_noise_std > 0.0:
            v += s.speed_noise_std * self._speed_rng.standard_normal(v.shape)
        tq = np.array(torque, dtype=float, copy=True)
        if s.torque_noise_std > 0.0:
            tq += s.torque_noise_std * self._torque_rng.standard_normal(tq.shape)
        return a, v, tq

    def measure_imu(self, specific_force: FloatArray) -> FloatArray:
        """The IMU's reading of a block of true specific forces (noise and bias added).

        Args:
            specific_force: shape (M, 2), f_x and f_z in the sensor's axes, [m/s^2]
                (:func:`imu_specific_force`).

        Returns:
            Same shape: f_x + bias + noise, f_z + noise, [m/s^2].
        """
        s = self.settings
        out = np.array(specific_force, dtype=float, copy=True)
        out[:, 0] += s.imu_bias
        if s.imu_noise_std > 0.0:
            out += s.imu_noise_std * self._imu_rng.standard_normal(out.shape)
        return out

    def measure_gyro(self, rate: FloatArray) -> FloatArray:
        """The IMU's reading of a block of true pitch rates (bias and noise added).

        Args:
            rate: shape (M,), the sensor's rate about its y axis, [rad/s].

        Returns:
            Same shape, [rad/s].
        """
        s = self.settings
        out = np.asarray(rate, dtype=float) + s.imu_gyro_bias
        if s.imu_gyro_noise_std > 0.0:
            out = out + s.imu_gyro_noise_std * self._gyro_rng.standard_normal(out.shape)
        return out
