"""Offline replay on small synthetic bags: inputs and truth copied, estimates = run_cascade."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from vd_observer_node.bag import BagReader, BagWriter, ReplayInputError
from vd_observer_node.bag.cdr_batch import decode_batch
from vd_observer_node.bag.replay import (
    ESTIMATE_TOPICS,
    SENSOR_TOPICS,
    default_vehicle_file,
    replay_bag,
)
from vd_observer_node.bag.synthetic import write_synthetic_drive_bag
from vd_observer_node.cascade import run_cascade
from vd_observer_node.vehicle import load_estimator_vehicle


@pytest.fixture(scope='module')
def replayed(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, object]:
    folder = tmp_path_factory.mktemp('replay')
    write_synthetic_drive_bag(folder / 'in', duration_s=3.0, rate_hz=100.0, seed=3)
    report = replay_bag(folder / 'in', folder / 'out', progress=False)
    return folder / 'in', folder / 'out', report


def _by_topic(path: Path) -> dict[str, list[tuple[int, bytes]]]:
    out: dict[str, list[tuple[int, bytes]]] = {}
    for m in BagReader(path).raw_messages():
        out.setdefault(m.topic, []).append((m.log_time_ns, m.data))
    return out


def test_inputs_and_truth_copied_raw(replayed: tuple[Path, Path, object]) -> None:
    in_bag, out_bag, _ = replayed
    source, result = _by_topic(in_bag), _by_topic(out_bag)
    assert set(source) <= set(result)
    for topic, messages in source.items():
        assert result[topic] == messages, topic
    assert set(result) - set(source) == set(ESTIMATE_TOPICS)


def test_estimates_equal_run_cascade_on_the_same_arrays(
    replayed: tuple[Path, Path, object],
) -> None:
    in_bag, out_bag, report = replayed
    raw = BagReader(in_bag).topic_arrays(SENSOR_TOPICS)
    angles = decode_batch('vd_msgs/msg/WheelAngles', raw['/vd/sensors/wheel_angles'].datas)
    speed = decode_batch('geometry_msgs/msg/TwistStamped', raw['/vd/sensors/body_velocity'].datas)
    torque = decode_batch('vd_msgs/msg/WheelTorques', raw['/vd/sensors/wheel_torques'].datas)
    expected = run_cascade(
        angles.stamp_ns * 1e-9,
        angles.values['angle'],
        speed.values['twist.linear.x'],
        torque.values['torque'],
        load_estimator_vehicle(default_vehicle_file()),
    )
    out = BagReader(out_bag).topic_arrays(ESTIMATE_TOPICS)
    log_angles = raw['/vd/sensors/wheel_angles'].log_time_ns
    for topic, msgtype in ESTIMATE_TOPICS.items():
        assert out[topic].msgtype == msgtype
        decoded = decode_batch(msgtype, out[topic].datas)
        np.testing.assert_array_equal(decoded.stamp_ns, angles.stamp_ns)
        np.testing.assert_array_equal(out[topic].log_time_ns, log_angles)
        assert set(decoded.frame_id.tolist()) == {b'base_link'}
    est = {t: decode_batch(ESTIMATE_TOPICS[t], out[t].datas).values for t in ESTIMATE_TOPICS}
    np.testing.assert_array_equal(est['/vd/observer/wheel_states']['omega'], expected.omega)
    np.testing.assert_array_equal(
        est['/vd/observer/wheel_states']['omega_dot'], expected.omega_dot
    )
    np.testing.assert_array_equal(est['/vd/observer/body_accel']['accel.linear.x'], expected.accel)
    np.testing.assert_array_equal(
        est['/vd/observer/body_velocity']['twist.linear.x'], expected.speed
    )
    np.testing.assert_array_equal(est['/vd/estimates/tire_forces']['fx'], expected.fx)
    np.testing.assert_array_equal(est['/vd/estimates/tire_forces']['fz'], expected.fz)
    np.testing.assert_array_equal(est['/vd/estimates/friction']['mu'], expected.mu)
    np.testing.assert_array_equal(est['/vd/estimates/friction']['valid'], expected.mu_valid)
    np.testing.assert_array_equal(est['/vd/estimates/resistances']['aero'], expected.aero)
    np.testing.assert_array_equal(est['/vd/estimates/slope']['angle'], expected.slope)
    assert report.samples == 300  # type: ignore[attr-defined]
    assert report.unmatched == 0  # type: ignore[attr-defined]


def test_output_is_in_log_time_order(replayed: tuple[Path, Path, object]) -> None:
    _, out_bag, _ = replayed
    times = [m.log_time_ns for m in BagReader(out_bag).raw_messages()]
    assert times == sorted(times)


def test_only_common_stamps_are_estimated(tmp_path: Path) -> None:
    write_synthetic_drive_bag(tmp_path / 'full', duration_s=1.0, rate_hz=100.0, with_truth=False)
    reader = BagReader(tmp_path / 'full')
    with BagWriter(tmp_path / 'gaps') as writer:
        for name, info in reader.topics.items():
            writer.add_topic(name, info.msgtype)
        dropped = 0
        for m in reader.raw_messages():
            # Every 10th speed sample lost: those stamps cannot be estimated.
            if m.topic == '/vd/sensors/body_velocity' and (m.log_time_ns // 10_000_000) % 10 == 3:
                dropped += 1
                continue
            writer.write(m.topic, m.data, m.log_time_ns)
    report = replay_bag(tmp_path / 'gaps', tmp_path / 'out', progress=False)
    assert dropped == 10
    assert report.samples == 90
    assert report.unmatched == 2 * dropped
    counts = {t: i.message_count for t, i in BagReader(tmp_path / 'out').topics.items()}
    assert counts['/vd/estimates/slope'] == 90


def test_missing_sensor_topic(tmp_path: Path) -> None:
    with BagWriter(tmp_path / 'empty') as writer:
        writer.add_topic('/vd/sensors/wheel_angles', 'vd_msgs/msg/WheelAngles')
    with pytest.raises(ReplayInputError, match='no messages on sensor topic'):
        replay_bag(tmp_path / 'empty', tmp_path / 'out', progress=False)


def test_replay_config_reaches_the_cascade(tmp_path: Path) -> None:
    from vd_observer_node.bag.replay import load_replay_config
    from vd_observer_node.errors import ConfigurationError
    from vd_observer_node.observer import ObserverConfig

    write_synthetic_drive_bag(tmp_path / 'in', duration_s=1.0, rate_hz=100.0, with_truth=False)
    settings = tmp_path / 'settings.yaml'
    settings.write_text('observer:\n  speed_lipschitz: 55.0\n')
    config = load_replay_config(settings)
    assert config.observer == ObserverConfig.from_mapping({'speed_lipschitz': 55.0})
    assert config.estimator is None
    calls: list[tuple[object, ...]] = []

    def spy(*args: object, **kwargs: object) -> object:
        calls.append((*args, kwargs))
        return run_cascade(*args, **kwargs)  # type: ignore[arg-type]

    replay_bag(
        tmp_path / 'in',
        tmp_path / 'out',
        observer_config=config.observer,
        cascade_kwargs={},
        progress=False,
        cascade=spy,  # type: ignore[arg-type]
    )
    assert calls[0][5] == config.observer
    bad = tmp_path / 'bad.yaml'
    bad.write_text('observer:\n  no_such_setting: 1\n')
    with pytest.raises(ConfigurationError):
        load_replay_config(bad)
    bad.write_text('something: else\n')
    with pytest.raises(ConfigurationError, match='mapping'):
        load_replay_config(bad)
