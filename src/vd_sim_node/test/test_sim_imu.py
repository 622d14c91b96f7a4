"""The simulator's IMU against the physics: rotated gravity plus the body's acceleration."""

from __future__ import annotations

import math
from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from vd_common.vehicle.params import load_vehicle
from vd_sim_node.vehicle.model import VehicleModel
from vd_sim_node.vehicle.scenario import parse_scenario
from vd_sim_node.vehicle.simulation import SimResult, simulate

ROOT = Path(__file__).resolve().parents[1]
VP = load_vehicle(ROOT.parent / 'vd_common' / 'config' / 'clio_rl_1_1.yaml')
G = VP.environment.gravity
MOUNT_DEG = 3.0  # the sensor's pitch on the body (REP 103: nose down)


def _scenario(
    imu_noise: float = 0.0, imu_bias: float = 0.0, gyro: tuple[float, float] = (0.0, 0.0)
) -> dict[str, object]:
    return {
        'name': 'imu_check',
        'duration': 12.0,
        'signals': {
            'throttle': [[0, 0.0], [1, 0.6], [7, 0.0]],
            'brake': [[0, 0.0], [9, 0.4]],
            'slope_deg': [[0, 4.0], [5, -3.0]],
        },
        'sensors': {
            'rate_hz': 200.0,
            'seed': 5,
            'speed_noise_std': 0.05,
            'imu': True,
            'imu_noise_std': imu_noise,
            'imu_bias': imu_bias,
            'imu_mount_pitch_deg': MOUNT_DEG,
            'imu_gyro_noise_std': gyro[0],
            'imu_gyro_bias': gyro[1],
        },
    }


@lru_cache(maxsize=3)
def _run(
    imu_noise: float = 0.0, imu_bias: float = 0.0, gyro: tuple[float, float] = (0.0, 0.0)
) -> SimResult:
    return simulate(VehicleModel(VP), parse_scenario(_scenario(imu_noise, imu_bias, gyro)))


def test_imu_is_the_specific_force_rotated_into_the_sensor_frame() -> None:
    r = _run()
    # the oracle: the world's specific force (acceleration minus gravity) in road axes,
    # seen from a frame rotated by the road grade, the body's pitch and the mounting
    # (scipy's rotations, not the simulator's sines and cosines)
    accel_road = np.stack([r.accel_true, np.zeros_like(r.t), np.zeros_like(r.t)], axis=1)
    road = Rotation.from_euler('y', -r.slope[:, None])  # uphill: nose up, a negative y rotation
    gravity_world = np.array([0.0, 0.0, -G])
    specific_world = road.apply(accel_road) - gravity_world
    sensor = (
        road
        * Rotation.from_euler('y', r.pitch[:, None])
        * Rotation.from_euler('y', math.radians(MOUNT_DEG))
    )
    expected = sensor.inv().apply(specific_world)
    np.testing.assert_allclose(r.imu_true[:, 0], expected[:, 0], atol=1e-9)
    np.testing.assert_allclose(r.imu_true[:, 1], expected[:, 2], atol=1e-9)
    # noise-free and unbiased, the reading is the truth
    np.testing.assert_array_equal(r.imu, r.imu_true)


def test_imu_at_rest_reads_gravity_along_the_tilted_axis() -> None:
    r = _run()
    # on a 4 deg grade, hold brake, before the throttle (settled from the initial state)
    still = (r.t > 0.5) & (r.t < 0.95)
    assert np.all(np.abs(r.accel_true[still]) < 5e-4)
    tilt = math.radians(4.0) - math.radians(MOUNT_DEG) - r.pitch[still]
    np.testing.assert_allclose(r.imu[still, 0], G * np.sin(tilt), atol=6e-4)
    # the pitch moves: squat under throttle (nose up: negative), dive under the brake
    driving = (r.t > 2.0) & (r.t < 4.0)
    braking = (r.t > 9.5) & (r.speed_true > 1.0)
    assert np.all(r.pitch[driving] < 0.0)
    assert np.all(r.pitch[braking] > 0.0)


def test_imu_noise_and_bias_have_their_settings_and_leave_the_other_sensors_alone() -> None:
    clean = _run()
    noisy = _run(0.2, 0.15)
    error = noisy.imu - noisy.imu_true
    assert abs(error[:, 0].mean() - 0.15) < 4.0 * 0.2 / math.sqrt(len(error))
    assert abs(error[:, 1].mean()) < 4.0 * 0.2 / math.sqrt(len(error))
    assert error.std(axis=0).min() > 0.19 and error.std(axis=0).max() < 0.21
    # the IMU's noise is a generator of its own: the speed noise is what it was
    np.testing.assert_array_equal(noisy.body_speed, clean.body_speed)
    np.testing.assert_array_equal(noisy.imu_true, clean.imu_true)


def test_the_gyro_turns_with_the_road_and_the_body() -> None:
    run = _run()
    dt = 1.0 / 200.0
    turned = np.cumsum(run.gyro_true) * dt  # [rad] nose down since the start
    # the scenario's grade steps from 4 to -3 deg at 5 s: the sensor turns 7 deg nose down
    # within the sample period of the step (the body's pitch moves on over the next second)
    step = round(5.0 / dt)
    assert run.gyro_true[step] * dt == pytest.approx(math.radians(7.0), abs=math.radians(0.05))
    # and over the run it has turned as the road and the body on its springs have (the pitch
    # the IMU's specific force is rotated by)
    tilt = run.pitch - run.slope
    np.testing.assert_allclose(turned, tilt - tilt[0], atol=1e-12)
    # the first sample has no period before it
    assert run.gyro_true[0] == 0.0


def test_gyro_noise_and_bias_have_their_settings_and_leave_the_other_sensors_alone() -> None:
    clean, noisy = _run(), _run(gyro=(0.01, 0.002))
    error = noisy.gyro - noisy.gyro_true
    assert abs(error.mean() - 0.002) < 4.0 * 0.01 / math.sqrt(len(error))
    assert 0.0095 < error.std() < 0.0105
    np.testing.assert_array_equal(clean.gyro, clean.gyro_true)
    # a generator of its own: the accelerometer and the speed are what they were
    np.testing.assert_array_equal(noisy.imu, clean.imu)
    np.testing.assert_array_equal(noisy.body_speed, clean.body_speed)
