"""`replay_bag` on truncated and corrupted MCAP bytes: a specific BagError, or a replay whose
estimates are all finite (reading alone is fuzzed in test_bag_corruption.py)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from vd_common.topics import (
    ESTIMATES_FRICTION,
    ESTIMATES_SLOPE,
    ESTIMATES_TIRE_FORCES,
    SENSORS_BODY_VELOCITY,
    SENSORS_WHEEL_ANGLES,
    SENSORS_WHEEL_TORQUES,
)
from vd_observer_node.bag import BagError, BagReader
from vd_observer_node.testing.synthetic_bags import write_synthetic_drive_bag
from vd_observer_node.tools.replay import replay_bag

ESTIMATES = (ESTIMATES_TIRE_FORCES, ESTIMATES_FRICTION, ESTIMATES_SLOPE)


@pytest.fixture(scope='module')
def original(tmp_path_factory: pytest.TempPathFactory) -> bytes:
    folder = tmp_path_factory.mktemp('fuzz') / 'in'
    write_synthetic_drive_bag(folder, duration_s=1.0, rate_hz=100.0, seed=11)
    (mcap,) = folder.glob('*.mcap')
    return mcap.read_bytes()


def _finite_fields(msg: object) -> bool:
    for name in ('fx', 'fz', 'mu', 'slip', 'angle'):
        value = getattr(msg, name, None)
        if value is not None and not np.all(np.isfinite(np.asarray(value, dtype=np.float64))):
            return False
    return True


def _replay(tmp_path: Path, data: bytes) -> BagError | None:
    work = tmp_path / 'case'
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir()
    damaged = work / 'damaged.mcap'
    damaged.write_bytes(data)
    try:
        report = replay_bag(damaged, work / 'out', progress=False)
    except BagError as exc:
        assert str(exc), 'a bag error must say what is wrong'
        return exc
    assert report.samples >= 0
    for _, _, _, msg in BagReader(work / 'out').messages(list(ESTIMATES)):
        assert _finite_fields(msg)
    return None


def test_intact_bag_replays(tmp_path: Path, original: bytes) -> None:
    assert _replay(tmp_path, original) is None


def test_truncated_bag_gives_a_bag_error(tmp_path: Path, original: bytes) -> None:
    error = _replay(tmp_path, original[: len(original) // 2])
    assert isinstance(error, BagError)


@settings(
    max_examples=30,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
@given(
    cut=st.floats(min_value=0.0, max_value=1.0),
    flips=st.lists(
        st.tuples(st.floats(min_value=0.0, max_value=0.9999), st.integers(1, 255)), max_size=4
    ),
)
def test_replay_of_any_damage_is_a_bag_error_or_finite_estimates(
    tmp_path: Path, original: bytes, cut: float, flips: list[tuple[float, int]]
) -> None:
    damaged = bytearray(original[: int(len(original) * cut)] if cut < 1.0 else original)
    for where, mask in flips:
        if damaged:
            damaged[int(where * len(damaged))] ^= mask
    _replay(tmp_path, bytes(damaged))


def test_messy_bag_with_non_finite_values_and_a_loop_replays_finite(tmp_path: Path) -> None:
    from vd_observer_node.bag import BagWriter
    from vd_observer_node.bag.cdr_batch import encode_batch
    from vd_observer_node.testing.synthetic_bags import synthetic_drive

    drive = synthetic_drive(1.0, 100.0, seed=5)
    n = drive.stamp_ns.shape[0]
    angle, speed, torque = drive.angle.copy(), drive.speed.copy(), drive.torque.copy()
    angle[30, 1] = np.nan
    speed[40] = np.inf
    torque[50, 2] = -np.inf
    stamps = np.concatenate([drive.stamp_ns, drive.stamp_ns])  # a looped recording
    twice = {'angle': np.concatenate([angle, angle])}
    zeros = np.zeros(2 * n)
    topics = {
        SENSORS_WHEEL_ANGLES: ('vd_msgs/msg/WheelAngles', twice),
        SENSORS_BODY_VELOCITY: (
            'geometry_msgs/msg/TwistStamped',
            {'twist.linear.x': np.concatenate([speed, speed])}
            | {
                f'twist.{a}.{x}': zeros
                for a in ('linear', 'angular')
                for x in 'xyz'
                if (a, x) != ('linear', 'x')
            },
        ),
        SENSORS_WHEEL_TORQUES: (
            'vd_msgs/msg/WheelTorques',
            {
                'torque': np.concatenate([torque, torque]),
                'engine_torque': zeros,
                'engine_speed': zeros,
                'gear': np.full(2 * n, 3, dtype=np.int8),
            },
        ),
    }
    with BagWriter(tmp_path / 'in') as writer:
        encoded = {}
        for topic, (msgtype, fields) in topics.items():
            writer.add_topic(topic, msgtype)
            encoded[topic] = encode_batch(msgtype, stamps, 'base_link', fields)
        log = int(drive.stamp_ns[0])
        for k in range(2 * n):
            log += 10_000_000  # log time keeps increasing although the stamps loop
            for topic in topics:
                writer.write(topic, encoded[topic][k], log)
    report = replay_bag(tmp_path / 'in', tmp_path / 'out', progress=False)
    assert report.samples == n  # the loop's stamps coincide with the first pass's
    count = 0
    for _, _, _, msg in BagReader(tmp_path / 'out').messages(list(ESTIMATES)):
        assert _finite_fields(msg)
        count += 1
    assert count == 3 * n
