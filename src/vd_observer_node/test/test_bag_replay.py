"""Offline replay on small synthetic bags: inputs and truth copied, estimates = run_cascade."""

from __future__ import annotations

import dataclasses
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from vd_common.topics import (
    ESTIMATES_ALERTS,
    ESTIMATES_FRICTION,
    ESTIMATES_FRICTION_POTENTIAL,
    ESTIMATES_MASS,
    ESTIMATES_RESISTANCES,
    ESTIMATES_ROLLING_RADIUS,
    ESTIMATES_SLOPE,
    ESTIMATES_TIRE_FORCES,
    ESTIMATES_TORQUE_OFFSET,
    OBSERVER_BODY_ACCEL,
    OBSERVER_WHEEL_STATES,
    SENSORS_BODY_VELOCITY,
    SENSORS_WHEEL_ANGLES,
    SENSORS_WHEEL_TORQUES,
)
from vd_common.vehicle.params import default_vehicle_file
from vd_observer_node.bag import BagReader, BagWriter, ReplayInputError
from vd_observer_node.bag.cdr_batch import decode_batch
from vd_observer_node.estimation.cascade import (
    run_cascade,
)
from vd_observer_node.estimation.vehicle import load_estimator_vehicle
from vd_observer_node.inputs.mapping import default_mapping
from vd_observer_node.situation.chain_settings import chain_settings
from vd_observer_node.testing.synthetic_bags import synthetic_drive, write_synthetic_drive_bag
from vd_observer_node.tools.replay import (
    ALERT_TOPICS,
    ESTIMATE_TOPICS,
    SENSOR_TOPICS,
    replay_bag,
)

#: What a replay writes with the default settings: the online mass and radius topics only
#: where adapted (off by default), as the nodes publish them; the engine-torque offset only
#: on the engine path (these bags have measured wheel torques).
DEFAULT_ESTIMATES = {
    t: m
    for t, m in ESTIMATE_TOPICS.items()
    if t not in (ESTIMATES_MASS, ESTIMATES_ROLLING_RADIUS, ESTIMATES_TORQUE_OFFSET)
}


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
    assert set(result) - set(source) == set(DEFAULT_ESTIMATES) | set(ALERT_TOPICS)


#: stamps the observers take to converge from their first sample (0.2 s at 100 Hz): the
#: figures below are checked after them
_SETTLED = 20


def test_estimates_against_the_drives_closed_forms(
    replayed: tuple[Path, Path, object],
) -> None:
    """The replay's estimates on the synthetic drive against its closed forms (not against
    `run_cascade` again): wheel speeds and accelerations of the analytic motion, the spin
    balance's Fx = (T - J omega_dot) / R on the true omega_dot, drag from the speed."""
    in_bag, out_bag, report = replayed
    drive = synthetic_drive(3.0, 100.0, seed=3)  # the fixture's drive
    vehicle = load_estimator_vehicle(default_vehicle_file())
    out = BagReader(out_bag).topic_arrays(DEFAULT_ESTIMATES)
    log_angles = (
        BagReader(in_bag).topic_arrays([SENSORS_WHEEL_ANGLES])[SENSORS_WHEEL_ANGLES].log_time_ns
    )
    for topic, msgtype in DEFAULT_ESTIMATES.items():
        assert out[topic].msgtype == msgtype
        decoded = decode_batch(msgtype, out[topic].datas)
        # stamped with the wheel angles' stamps, logged at their log times
        np.testing.assert_array_equal(decoded.stamp_ns, drive.stamp_ns)
        np.testing.assert_array_equal(out[topic].log_time_ns, log_angles)
        assert set(decoded.frame_id.tolist()) == {b'base_link'}
    est = {t: decode_batch(DEFAULT_ESTIMATES[t], out[t].datas).values for t in DEFAULT_ESTIMATES}
    s = slice(_SETTLED, None)
    wheels = est[OBSERVER_WHEEL_STATES]
    # measured 2.2e-6, 0.046 rad/s^2, 2.5e-5 m/s^2: bounds twice that
    np.testing.assert_allclose(wheels['omega'][s], drive.omega[s], rtol=5e-6)
    np.testing.assert_allclose(wheels['omega_dot'][s], drive.omega_dot[s], atol=0.1)
    np.testing.assert_allclose(
        est[OBSERVER_BODY_ACCEL]['accel.linear.x'][s], drive.accel[s], atol=5e-5
    )
    inertia = np.array([vehicle.inertia_front] * 2 + [vehicle.inertia_rear] * 2)
    fx = (drive.torque - inertia * drive.omega_dot) / vehicle.effective_radius
    # measured 0.13 N (omega_dot's error times J/R) on up to 915 N
    np.testing.assert_allclose(est[ESTIMATES_TIRE_FORCES]['fx'][s], fx[s], atol=0.3)
    drag = vehicle.drag_coefficient * vehicle.frontal_area * vehicle.air_density / 2.0
    np.testing.assert_allclose(
        est[ESTIMATES_RESISTANCES]['aero'], drag * drive.speed * np.abs(drive.speed), rtol=1e-12
    )
    valid = est[ESTIMATES_FRICTION]['valid']
    assert valid.any()
    forces = est[ESTIMATES_TIRE_FORCES]
    np.testing.assert_allclose(
        est[ESTIMATES_FRICTION]['mu'][valid], (forces['fx'] / forces['fz'])[valid], rtol=1e-12
    )
    assert report.samples == 300  # type: ignore[attr-defined]
    assert report.unmatched == 0  # type: ignore[attr-defined]
    # a 100 Hz bag: the replay's slope filter followed the rate after FOLLOW_AFTER stamps
    assert report.input_rate_hz == 100.0  # type: ignore[attr-defined]


def test_output_is_in_log_time_order(replayed: tuple[Path, Path, object]) -> None:
    _, out_bag, _ = replayed
    times = [m.log_time_ns for m in BagReader(out_bag).raw_messages()]
    assert times == sorted(times)


def _lossy_speed_bag(tmp_path: Path) -> Path:
    """A 1 s 100 Hz drive whose every 10th body-speed message was lost (10 of 100)."""
    write_synthetic_drive_bag(tmp_path / 'full', duration_s=1.0, rate_hz=100.0, with_truth=False)
    reader = BagReader(tmp_path / 'full')
    with BagWriter(tmp_path / 'gaps') as writer:
        for name, info in reader.topics.items():
            writer.add_topic(name, info.msgtype)
        dropped = 0
        for m in reader.raw_messages():
            if m.topic == SENSORS_BODY_VELOCITY and (m.log_time_ns // 10_000_000) % 10 == 3:
                dropped += 1
                continue
            writer.write(m.topic, m.data, m.log_time_ns)
    assert dropped == 10
    return tmp_path / 'gaps'


def test_a_stamp_that_lost_one_input_is_estimated_with_the_latest_sample(tmp_path: Path) -> None:
    # the default ('latest' alignment): the lost speed is held from the stamp before
    report = replay_bag(_lossy_speed_bag(tmp_path), tmp_path / 'out', progress=False)
    assert report.samples == 100
    counts = {t: i.message_count for t, i in BagReader(tmp_path / 'out').topics.items()}
    assert counts[ESTIMATES_SLOPE] == 100


def test_with_exact_alignment_only_common_stamps_are_estimated(tmp_path: Path) -> None:
    exact = dataclasses.replace(default_mapping(), alignment='exact')
    report = replay_bag(
        _lossy_speed_bag(tmp_path), tmp_path / 'out', progress=False, mapping=exact
    )
    assert report.samples == 90
    assert report.unmatched == 2 * 10
    counts = {t: i.message_count for t, i in BagReader(tmp_path / 'out').topics.items()}
    assert counts[ESTIMATES_SLOPE] == 90


def test_missing_sensor_topic(tmp_path: Path) -> None:
    with BagWriter(tmp_path / 'empty') as writer:
        writer.add_topic(SENSORS_WHEEL_ANGLES, 'vd_msgs/msg/WheelAngles')
    with pytest.raises(ReplayInputError, match='no messages on sensor topic'):
        replay_bag(tmp_path / 'empty', tmp_path / 'out', progress=False)


def test_the_settings_file_reaches_the_cascade(tmp_path: Path) -> None:
    from vd_observer_node.errors import ConfigurationError
    from vd_observer_node.estimation.observer import ObserverConfig
    from vd_observer_node.tools.settings_file import load_settings_file

    write_synthetic_drive_bag(tmp_path / 'in', duration_s=1.0, rate_hz=100.0, with_truth=False)
    settings = tmp_path / 'settings.yaml'
    settings.write_text(
        'observer:\n  speed_lipschitz: 55.0\ncascade:\n  estimator_speed: observer\n'
    )
    config = load_settings_file(settings)
    built = config.settings()
    assert built.observer == ObserverConfig.from_mapping({'speed_lipschitz': 55.0})
    assert built.estimator_speed == 'observer'
    assert config.given == {
        'observer.speed_lipschitz': 55.0,
        'cascade.estimator_speed': 'observer',
    }
    calls: list[object] = []

    def spy(*args: Any) -> object:
        calls.append(args[1])
        return run_cascade(*args)

    replay_bag(tmp_path / 'in', tmp_path / 'out', built, progress=False, cascade=spy)
    # what the cascade got is what the file said (its speed Lipschitz constant), not a default
    assert calls and all(c == built for c in calls)
    bad = tmp_path / 'bad.yaml'
    bad.write_text('observer:\n  no_such_setting: 1\n')
    with pytest.raises(ConfigurationError, match='no_such_setting'):
        load_settings_file(bad)
    bad.write_text('cascade:\n  imu_config: 1\n')
    with pytest.raises(ConfigurationError, match='imu_config'):
        load_settings_file(bad)
    bad.write_text('something: else\n')
    with pytest.raises(ConfigurationError, match='mapping'):
        load_settings_file(bad)


def test_settings_for_another_mapping_are_refused(tmp_path: Path) -> None:
    from vd_observer_node.errors import ConfigurationError
    from vd_observer_node.inputs.mapping import default_mapping
    from vd_observer_node.situation.chain_settings import chain_settings

    write_synthetic_drive_bag(tmp_path / 'in', duration_s=1.0, rate_hz=100.0, with_truth=False)
    engine = replace(default_mapping(), torque_source='engine')
    with pytest.raises(ConfigurationError, match='torque_source'):
        replay_bag(tmp_path / 'in', tmp_path / 'out', chain_settings(engine), progress=False)
    assert not (tmp_path / 'out').exists()


# -- friction potential and alerts (SituationMonitor) ------------------------------------------

CONFIG = Path(__file__).resolve().parents[2] / 'vd_sim_node' / 'config'
SIM_RATE = 200.0  # [Hz] enough for the launch's spin-up, small enough for a fast test


@pytest.fixture(scope='module')
def launch(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, object]:
    """launch_low_mu at 200 Hz written as a recording, and its replay (compared with the
    per-stamp objects below; the same source uncompiled is compared with it in
    `test_the_uncompiled_source_replays_the_same`)."""
    from vd_common.vehicle.params import load_vehicle
    from vd_observer_node.testing.devbag import sim_topics, write_topic_arrays_bag
    from vd_sim_node.vehicle.scenario import load_scenario
    from vd_sim_node.vehicle.simulation import simulate

    folder = tmp_path_factory.mktemp('launch')
    sim = simulate(
        load_vehicle(default_vehicle_file()),
        load_scenario(CONFIG / 'scenarios' / 'launch_low_mu.yaml'),
        rate_hz=SIM_RATE,
    )
    stamps = np.round(sim.t * 1e9).astype(np.int64) + 1_700_000_000 * 10**9
    write_topic_arrays_bag(folder / 'in', stamps, sim_topics(sim))
    report = replay_bag(folder / 'in', folder / 'out', progress=False)
    return folder / 'in', folder / 'out', report


def test_the_uncompiled_source_replays_the_same(
    launch: tuple[Path, Path, object], tmp_path: Path
) -> None:
    """Every replayed topic: the step functions run as plain Python (``VD_JIT=0``, what a
    user debugs) within 1e-9 of their compiled code (numba's semantics are Python's)."""
    import os
    import subprocess
    import sys

    in_bag, compiled_bag, _ = launch
    code = (
        'import sys; from vd_observer_node.tools.replay import replay_bag; '
        'from vd_observer_node.kernel import _jit; assert not _jit.JIT_ENABLED; '
        'replay_bag(sys.argv[1], sys.argv[2], progress=False)'
    )
    env = dict(os.environ, VD_JIT='0')
    subprocess.run(
        [sys.executable, '-c', code, str(in_bag), str(tmp_path / 'uncompiled')],
        env=env,
        check=True,
        timeout=600,
    )
    python_bag, compiled = tmp_path / 'uncompiled', compiled_bag
    potential = ESTIMATES_FRICTION_POTENTIAL
    fixed = {**DEFAULT_ESTIMATES, potential: ALERT_TOPICS[potential]}
    ref = BagReader(python_bag).topic_arrays(list(fixed))
    got = BagReader(compiled).topic_arrays(list(fixed))
    for topic, msgtype in fixed.items():
        a = decode_batch(msgtype, ref[topic].datas)
        b = decode_batch(msgtype, got[topic].datas)
        np.testing.assert_array_equal(a.stamp_ns, b.stamp_ns)
        for name, values in a.values.items():
            np.testing.assert_allclose(
                b.values[name].astype(float),
                values.astype(float),
                rtol=1e-9,
                atol=1e-9 * max(1.0, float(np.max(np.abs(values), initial=0.0))),
                err_msg=f'{topic}.{name}',
            )
    alerts = ESTIMATES_ALERTS
    for (_, _, _, x), (_, _, _, y) in zip(
        BagReader(python_bag).messages([alerts]),
        BagReader(compiled).messages([alerts]),
        strict=True,
    ):
        assert x == y


def _expected_situation(in_bag: Path, out_bag: Path, vehicle_file: Path) -> list[object]:
    """SituationMonitor fed per stamp, independently of replay's batch code, on the sensors
    and the cascade's estimates the replay wrote."""
    from vd_common.vehicle.params import load_vehicle
    from vd_observer_node.situation.friction_potential import TyreCurves
    from vd_observer_node.situation.monitor import SituationMonitor

    raw = BagReader(in_bag).topic_arrays(SENSOR_TOPICS)
    angles = decode_batch('vd_msgs/msg/WheelAngles', raw[SENSORS_WHEEL_ANGLES].datas)
    speed = decode_batch('geometry_msgs/msg/TwistStamped', raw[SENSORS_BODY_VELOCITY].datas)
    torque = decode_batch('vd_msgs/msg/WheelTorques', raw[SENSORS_WHEEL_TORQUES].datas)
    vehicle = load_estimator_vehicle(vehicle_file)
    t = angles.stamp_ns * 1e-9
    v = speed.values['twist.linear.x']
    out = BagReader(out_bag).topic_arrays(
        [OBSERVER_WHEEL_STATES, ESTIMATES_FRICTION, ESTIMATES_TIRE_FORCES]
    )
    omega = decode_batch('vd_msgs/msg/WheelStates', out[OBSERVER_WHEEL_STATES].datas)
    friction = decode_batch('vd_msgs/msg/Friction', out[ESTIMATES_FRICTION].datas)
    forces = decode_batch('vd_msgs/msg/TireForces', out[ESTIMATES_TIRE_FORCES].datas)
    monitor = SituationMonitor(
        TyreCurves.from_tire(load_vehicle(vehicle_file).tire),
        vehicle.static_wheel_loads[[0, 2]],
        vehicle.effective_radius,
    )
    return [
        monitor.update(
            float(t[k]),
            angles.values['angle'][k],
            float(v[k]),
            torque.values['torque'][k],
            omega.values['omega'][k],
            friction.values['mu'][k],
            friction.values['valid'][k],
            forces.values['fz'][k],
        )
        for k in range(t.size)
    ]


def _time_ns(stamp: object) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)  # type: ignore[attr-defined]


def test_alerts_and_potential_equal_the_situation_monitor(
    launch: tuple[Path, Path, object],
) -> None:
    """Decoded with the rosbags typestore (not replay's encoders): every stamp carries the 12
    records and the friction potential SituationMonitor gives on the same inputs."""
    in_bag, out_bag, report = launch
    expected = _expected_situation(in_bag, out_bag, default_vehicle_file())
    sensor_stamps = [
        _time_ns(m.header.stamp)
        for _, _, _, m in BagReader(in_bag).messages([SENSORS_WHEEL_ANGLES])
    ]
    alerts = list(BagReader(out_bag).messages([ESTIMATES_ALERTS]))
    potentials = list(BagReader(out_bag).messages([ESTIMATES_FRICTION_POTENTIAL]))
    assert len(alerts) == len(potentials) == len(expected) == report.samples  # type: ignore[attr-defined]
    active = 0
    for k, (sit, (_, _, _, msg), (_, _, _, pot)) in enumerate(
        zip(expected, alerts, potentials, strict=True)
    ):
        assert _time_ns(msg.header.stamp) == _time_ns(pot.header.stamp) == sensor_stamps[k]
        assert len(msg.alerts) == 12
        for rec, a in zip(msg.alerts, sit.alerts, strict=True):  # type: ignore[attr-defined]
            assert (rec.kind, rec.wheel, rec.level, rec.active) == (
                a.kind_code,
                a.wheel,
                a.level,
                a.active,
            )
            for field in ('onset', 'detected'):
                value = getattr(a, field)
                want = round(value * 1e9) if np.isfinite(value) else 0
                assert _time_ns(getattr(rec, field)) == want, (k, field)
            active += bool(rec.active)
        p = sit.potential  # type: ignore[attr-defined]
        np.testing.assert_array_equal(pot.mu_max, p.mu_max)
        np.testing.assert_array_equal(pot.slip_peak, p.slip_peak)
        np.testing.assert_array_equal(pot.confidence, p.confidence)
        np.testing.assert_array_equal(pot.road_class, p.road_class)
        assert pot.vehicle_road_class == p.vehicle_road_class()
    # the launch on the low-mu patch spins the driven wheels: the comparison is not all-OK
    assert active > 0
    assert report.situation_time_s > 0.0  # type: ignore[attr-defined]


def test_traction_alert_on_the_launch_reaches_the_report(
    launch: tuple[Path, Path, object], tmp_path: Path
) -> None:
    """`vd report` of the replayed recording has the alerts section with figures."""
    from vd_observer_node.tools.report.evaluation import evaluate
    from vd_observer_node.tools.report.load import load_bag_series

    _, out_bag, _ = launch
    report, _ = evaluate(load_bag_series(out_bag, progress=False))
    section = report.alerts
    assert section is not None
    assert section.samples > 0 and section.mu_max
    traction = [e for e in section.episodes if e.kind == 'traction']
    assert traction and any(e.detected_s is not None for e in traction)


def test_situation_off_writes_no_alerts(tmp_path: Path) -> None:
    write_synthetic_drive_bag(tmp_path / 'in', duration_s=1.0, rate_hz=100.0, with_truth=False)
    report = replay_bag(tmp_path / 'in', tmp_path / 'out', progress=False, situation=False)
    assert report.situation_time_s == 0.0
    assert not set(ALERT_TOPICS) & set(BagReader(tmp_path / 'out').topics)


def test_vehicle_file_supplies_the_tyre(tmp_path: Path) -> None:
    """A tyre with a lower peak (pDx1) in the vehicle file lowers the friction potential."""
    import yaml

    write_synthetic_drive_bag(tmp_path / 'in', duration_s=2.0, rate_hz=100.0, with_truth=False)
    data = yaml.safe_load(default_vehicle_file().read_text())
    data['tire']['pDx1'] = 0.5 * data['tire']['pDx1']
    low = tmp_path / 'low_grip.yaml'
    low.write_text(yaml.safe_dump(data))
    replay_bag(tmp_path / 'in', tmp_path / 'default', progress=False)
    replay_bag(tmp_path / 'in', tmp_path / 'low', chain_settings(vehicle_file=low), progress=False)

    def mu_max(bag: Path) -> np.ndarray:
        arr = BagReader(bag).topic_arrays([ESTIMATES_FRICTION_POTENTIAL])
        msgs = arr[ESTIMATES_FRICTION_POTENTIAL].datas
        return decode_batch('vd_msgs/msg/FrictionPotential', msgs).values['mu_max']

    default, lowered = mu_max(tmp_path / 'default'), mu_max(tmp_path / 'low')
    # the prior (no informative data on a gentle drive) is the tyre's own peak: halved
    np.testing.assert_allclose(lowered[-1], 0.5 * default[-1], rtol=0.05)


def test_the_settings_file_reads_the_alert_sections(tmp_path: Path) -> None:
    from vd_observer_node.errors import ConfigurationError
    from vd_observer_node.situation.alerts import AlertConfig
    from vd_observer_node.situation.friction_potential import FrictionPotentialConfig
    from vd_observer_node.situation.monitor import SituationConfig
    from vd_observer_node.tools.settings_file import load_settings_file

    settings = tmp_path / 'settings.yaml'
    settings.write_text('situation:\n  alert_wheel_lipschitz: 10000.0\nalerts: {}\n')
    built = load_settings_file(settings).settings()
    assert built.situation == SituationConfig(alert_wheel_lipschitz=10000.0)
    assert built.alerts == AlertConfig()
    assert built.friction == FrictionPotentialConfig()
    settings.write_text('situation:\n  no_such_setting: 1.0\n')
    with pytest.raises(ConfigurationError):
        load_settings_file(settings)
