"""The IMU's mounting learnt online (`inputs.mount_learner`): against a closed-form drive, the
same whatever the streams' interleaving, and read through bit for bit alike live and in a
replay's blocks."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation
from vd_observer_node.inputs.mapping import mapping_from_dict
from vd_observer_node.inputs.mount_learner import (
    FIT_EVERY,
    MIN_WINDOWS,
    WINDOW_S,
    MountingLearner,
    new_learner,
    project,
    project_held,
    project_sample,
    unstated_mounting_note,
)
from vd_observer_node.inputs.rotation import mount_rotation

RADIUS = 0.3  # [m]
G = 9.81
RATE_HZ = 100.0


def _drive(
    rpy_deg: tuple[float, float, float], seconds: float = 90.0, seed: int = 0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A straight drive that speeds up and slows down (0.9 m/s^2 amplitude) on a gentle
    grade, its wheel speeds [rad/s] and an IMU mounted at ``rpy_deg`` with noise.

    Returns:
        stamps [ns] (one clock for both at ``RATE_HZ``), wheel speeds shape (N, 4), IMU
        vectors shape (N, 6) (specific force, angular rate in the sensor's frame).
    """
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, 1.0 / RATE_HZ)
    stamps = np.round((t + 1000.0) * 1e9).astype(np.int64)
    speed = 15.0 + 3.0 * np.sin(0.3 * t)
    accel = 0.9 * np.cos(0.3 * t)
    grade = np.radians(1.0) * np.sin(0.05 * t)
    body = np.column_stack(
        [accel + G * np.sin(grade), np.zeros_like(t), G * np.cos(grade)]
    )  # specific force in the body frame
    rows = np.array(mount_rotation(*np.radians(rpy_deg)))  # body <- sensor
    sensor = body @ rows + rng.normal(0.0, 0.05, body.shape)  # R^T f_b, by rows
    rate = np.column_stack([np.zeros_like(t), 0.01 * np.sin(t), np.zeros_like(t)]) @ rows
    wheels = np.repeat((speed / RADIUS)[:, None], 4, axis=1) + rng.normal(0.0, 0.02, (t.size, 4))
    return stamps, wheels, np.column_stack([sensor, rate])


def _learn(
    order: str, stamps: np.ndarray, wheels: np.ndarray, imu: np.ndarray, imu_from: int = 0
) -> MountingLearner:
    """The learner fed in ``order``; the IMU's samples from index ``imu_from`` on."""
    learner = MountingLearner(RADIUS, angles=False)
    imu_stamps, imu = stamps[imu_from:], imu[imu_from:]
    if order == 'wheels first':
        learner.wheels_many(stamps, wheels)
        learner.imu_many(imu_stamps, imu)
    elif order == 'imu first':
        learner.imu_many(imu_stamps, imu)
        learner.wheels_many(stamps, wheels)
    else:  # one sample of each in turn, the IMU's 0.3 s late (a live node's queues)
        lag = 30
        for k in range(stamps.size + lag):
            if k < stamps.size:
                learner.wheels(int(stamps[k]), tuple(wheels[k]))
            if lag <= k < imu_stamps.size + lag:
                learner.imu(int(imu_stamps[k - lag]), tuple(imu[k - lag]))
    return learner


@pytest.mark.parametrize('rpy', [(0.0, 0.0, 0.0), (180.0, -3.0, 5.0), (-20.0, 3.0, 178.0)])
def test_the_drive_s_mounting_is_learnt(rpy: tuple[float, float, float]) -> None:
    stamps, wheels, imu = _drive(rpy)
    learner = _learn('wheels first', stamps, wheels, imu)
    learnt = learner.learnt
    assert learnt is not None, learner.reason
    error = (np.array(learnt.fit.rpy_deg) - rpy + 180.0) % 360.0 - 180.0
    assert np.all(np.abs(error) < 0.3), error
    # fitted on whole windows, every FIT_EVERY from MIN_WINDOWS on, and read from the window
    # after the last one it rests on
    assert learnt.windows >= MIN_WINDOWS and learnt.windows % FIT_EVERY == 0
    assert (learnt.from_s / WINDOW_S) == pytest.approx(round(learnt.from_s / WINDOW_S))
    assert learnt.from_s - 1000.0 == pytest.approx((learnt.windows + 2) * WINDOW_S, abs=0.51)


@pytest.mark.parametrize('imu_from', [0, 345])
def test_what_is_learnt_does_not_depend_on_the_streams_interleaving(imu_from: int) -> None:
    """Also where the IMU starts 3.45 s after the wheels (the windows counted from the first
    both have samples in, however the streams came)."""
    stamps, wheels, imu = _drive((180.0, -3.0, 5.0))
    orders = ('wheels first', 'imu first', 'live')
    runs = [_learn(order, stamps, wheels, imu, imu_from) for order in orders]
    assert runs[0].learnt is not None
    assert all(r.learnt == runs[0].learnt for r in runs[1:])


def test_wheel_angles_teach_what_wheel_speeds_teach() -> None:
    stamps, wheels, imu = _drive((180.0, -3.0, 5.0))
    angles = np.cumsum(wheels, axis=0) / RATE_HZ  # [rad], integrated
    by_angle = MountingLearner(RADIUS, angles=True)
    by_angle.wheels_many(stamps, angles)
    by_angle.imu_many(stamps, imu)
    by_speed = _learn('wheels first', stamps, wheels, imu)
    assert by_angle.learnt is not None and by_speed.learnt is not None
    np.testing.assert_allclose(by_angle.learnt.fit.rpy_deg, by_speed.learnt.fit.rpy_deg, atol=0.2)


def test_a_drive_at_constant_speed_teaches_nothing_and_says_why() -> None:
    stamps, wheels, imu = _drive((180.0, 0.0, 0.0))
    steady = np.full_like(wheels, 15.0 / RADIUS)
    learner = MountingLearner(RADIUS, angles=False)
    learner.wheels_many(stamps, steady)
    learner.imu_many(stamps, imu)
    assert learner.learnt is None
    assert 'the acceleration varies by 0.00 m/s^2' in learner.reason


def test_a_drive_that_never_shows_the_mounting_keeps_the_last_windows_only(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr('vd_observer_node.inputs.mount_learner.MAX_WINDOWS', 60)
    stamps, wheels, imu = _drive((180.0, 0.0, 0.0), seconds=60.0)
    learner = MountingLearner(RADIUS, angles=False)
    learner.wheels_many(stamps, np.full_like(wheels, 15.0 / RADIUS))
    learner.imu_many(stamps, imu)
    assert learner.learnt is None and 'varies by 0.00' in learner.reason
    assert len(learner._speed) == 62  # 60 rows with both neighbours
    assert learner._taken == 119  # complete windows of 60 s, fitted every FIT_EVERY still


def test_a_sample_stamped_before_its_stream_s_open_window_is_left_out() -> None:
    learner = MountingLearner(RADIUS, angles=False)
    learner.wheels(2_000_000_000, (1.0,) * 4)
    learner.wheels(1_000_000_000, (1.0,) * 4)  # a window closed before the open one
    learner.wheels(2_100_000_000, (1.0,) * 4)
    assert learner._wheels.early == 1


@settings(max_examples=100, deadline=None)
@given(
    rpy=st.tuples(*(st.floats(-180.0, 180.0),) * 3),
    vectors=st.lists(st.floats(-50.0, 50.0), min_size=6, max_size=6),
)
def test_a_sample_is_read_alike_live_and_in_a_block(
    rpy: tuple[float, float, float], vectors: list[float]
) -> None:
    """`project` on floats (a live sample) and on a replay's arrays gives the same bits; and
    what it gives is scipy's rotation of the sensor's vectors into the body."""
    rows = mount_rotation(*np.radians(rpy))
    live = project(rows, vectors[:3], vectors[3:])
    held = np.array([[1.0, *vectors], [2.0, *vectors]])
    block = project(rows, held[:, 1:4].T, held[:, 4:7].T)
    assert live[0] == block[0][0] and live[1] == block[1][1]
    body = Rotation.from_euler('xyz', rpy, degrees=True)  # tf's fixed-axis roll, pitch, yaw
    expected_force = body.apply(vectors[:3])[0]
    assert live[0] == pytest.approx(expected_force, abs=1e-9)


def test_before_the_mounting_applies_the_fusion_gets_no_sample() -> None:
    stamps, wheels, imu = _drive((180.0, -3.0, 5.0))
    learner = _learn('wheels first', stamps, wheels, imu)
    learnt = learner.learnt
    assert learnt is not None
    held = np.column_stack([stamps * 1e-9, imu])
    held[5] = np.nan  # no sample yet at that stamp
    got = project_held(learnt, held)
    for row, out in zip(held, got, strict=True):
        sample = None if math.isnan(row[0]) else tuple(row)
        expected = project_sample(learnt, sample)
        if expected is None:
            assert np.isnan(out).all()
        else:
            assert tuple(out) == expected  # bit for bit
    after = held[:, 0] >= learnt.from_s  # (not the row without a sample)
    assert after.any() and (~after).any()
    assert np.isnan(got[~after]).all() and np.isfinite(got[after, :2]).all()
    assert np.isnan(project_held(None, held)).all()


def test_only_an_unstated_three_axis_imu_learns_its_mounting() -> None:
    imu = {'topic': '/imu', 'type': 'sensor_msgs/msg/Imu'}
    unstated = mapping_from_dict({'imu': imu})
    stated = mapping_from_dict({'imu': {**imu, 'mount_rpy_deg': [0, 0, 0]}})
    one = mapping_from_dict(
        {'imu': {'topic': '/a', 'type': 'std_msgs/msg/Float64MultiArray', 'indices': [0]}}
    )
    assert unstated.imu is not None and unstated.imu.width == 6
    assert stated.imu is not None and stated.imu.width == 2
    assert new_learner(unstated, RADIUS) is not None
    assert new_learner(stated, RADIUS) is None and new_learner(one, RADIUS) is None
    assert 'learnt from the drive' in unstated_mounting_note(unstated.imu)
    assert unstated_mounting_note(stated.imu) == '' == unstated_mounting_note(one.imu)
