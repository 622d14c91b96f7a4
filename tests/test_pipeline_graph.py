"""pipeline_node (observer + estimator + alerts in one process) over the real middleware.

sim_node (short scenario) -> pipeline_node, recorded by recorder_node. Every estimate, the
friction potential and the alerts arrive for every sensor stamp, and they are what offline
replay (`vd replay`) computes from the recorded sensors, to 1e-9: the same step functions, one
stamp a call live, in blocks offline.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from rosproc import RosProcessGroup, wait_recording
from test_graph import (
    LAST_STAMP_NS,
    N_SAMPLES,
    RATE_HZ,
    SCENARIO,
    by_topic,
    wait_exit,
    wait_for_last_stamp,
)
from vd_common.topics import (
    ESTIMATES_ALERTS,
    ESTIMATES_COMBINED,
    ESTIMATES_FRICTION,
    ESTIMATES_FRICTION_POTENTIAL,
    ESTIMATES_RESISTANCES,
    ESTIMATES_SLOPE,
    ESTIMATES_TIRE_FORCES,
    OBSERVER_WHEEL_STATES,
    SENSORS_IMU,
    SENSORS_WHEEL_ANGLES,
)
from vd_observer_node.estimation.imu_grade import SOURCE_IMU
from vd_observer_node.inputs.mapping import load_input_mapping
from vd_observer_node.tools.replay import replay_bag

#: every test here is a long end-to-end run (CI runs it; locally: make test-all)
pytestmark = pytest.mark.slow

OUTPUTS = {
    OBSERVER_WHEEL_STATES: ('omega', 'omega_dot'),
    ESTIMATES_TIRE_FORCES: ('fx', 'fz'),
    ESTIMATES_FRICTION: ('mu', 'slip', 'valid'),
    ESTIMATES_RESISTANCES: ('rolling', 'aero'),
    ESTIMATES_SLOPE: ('angle', 'valid'),
    ESTIMATES_FRICTION_POTENTIAL: (
        'mu_max',
        'slip_peak',
        'confidence',
        'road_class',
        'vehicle_road_class',
    ),
}


#: (per-quantity topic, its field, the combined message's field)
COMBINED_FIELDS = (
    (OBSERVER_WHEEL_STATES, 'angle', 'angle'),
    (OBSERVER_WHEEL_STATES, 'omega', 'omega'),
    (OBSERVER_WHEEL_STATES, 'omega_dot', 'omega_dot'),
    (ESTIMATES_TIRE_FORCES, 'fx', 'fx'),
    (ESTIMATES_TIRE_FORCES, 'fz', 'fz'),
    (ESTIMATES_TIRE_FORCES, 'torque_source', 'torque_source'),
    (ESTIMATES_FRICTION, 'mu', 'mu'),
    (ESTIMATES_FRICTION, 'slip', 'slip'),
    (ESTIMATES_FRICTION, 'valid', 'mu_valid'),
    (ESTIMATES_RESISTANCES, 'rolling', 'rolling'),
    (ESTIMATES_RESISTANCES, 'aero', 'aero'),
    (ESTIMATES_SLOPE, 'angle', 'slope'),
    (ESTIMATES_SLOPE, 'valid', 'slope_valid'),
    (ESTIMATES_SLOPE, 'sources', 'slope_sources'),
)


@pytest.mark.ros
def test_pipeline_node_publishes_what_offline_replay_computes(
    procs: RosProcessGroup, tmp_path: Path
) -> None:
    bag = tmp_path / 'live'
    rec = procs.node('recorder', 'vd_observer_node', 'recorder_node', output=str(bag))
    # both layouts: the per-quantity topics and the one combined message per stamp
    pipe = procs.node('pipeline', 'vd_observer_node', 'pipeline_node', estimate_topics='both')
    for proc, text in ((rec, 'recording to'), (pipe, 'pipeline ready')):
        proc.wait_for(text, timeout=60)
    # the pipeline's publishers, connected
    wait_recording(rec, [*OUTPUTS, ESTIMATES_ALERTS, ESTIMATES_COMBINED])
    waiter = wait_for_last_stamp(
        procs,
        'waiter',
        LAST_STAMP_NS,
        {
            ESTIMATES_SLOPE: 'vd_msgs.msg/Slope',
            ESTIMATES_ALERTS: 'vd_msgs.msg/Alerts',
            ESTIMATES_FRICTION_POTENTIAL: 'vd_msgs.msg/FrictionPotential',
        },
    )
    sim = procs.node(
        'sim',
        'vd_sim_node',
        'sim_node',
        scenario_file=str(SCENARIO),
        rate_hz=RATE_HZ,
        real_time_factor=1.0,
        min_sensor_subscribers=2,  # the recorder and the pipeline
    )
    assert wait_exit(sim, 60) == 0, sim.output()
    assert wait_exit(waiter, 180) == 0, waiter.output()  # the last stamp went through
    for proc in (pipe, rec):
        assert proc.stop() == 0, proc.output()[-3000:]
    assert 'Traceback' not in pipe.output(), pipe.output()[-3000:]

    live = by_topic(bag, [SENSORS_WHEEL_ANGLES, *OUTPUTS, ESTIMATES_ALERTS, ESTIMATES_COMBINED])
    stamps = sorted(live[SENSORS_WHEEL_ANGLES])
    assert len(stamps) == N_SAMPLES, 'the recorder lost sensor samples'
    for topic in (*OUTPUTS, ESTIMATES_ALERTS, ESTIMATES_COMBINED):
        assert sorted(live[topic]) == stamps, topic
    # the combined message carries what the per-quantity messages of its stamp carry
    for s in stamps:
        c = live[ESTIMATES_COMBINED][s]
        for topic, field, name in COMBINED_FIELDS:
            a = np.asarray(getattr(c, name), dtype=float)
            b = np.asarray(getattr(live[topic][s], field), dtype=float)
            np.testing.assert_array_equal(a, b, err_msg=f'{name} vs {topic}.{field}')

    offline_bag = tmp_path / 'offline'
    replay_bag(bag, offline_bag, progress=False)
    offline = by_topic(offline_bag, [*OUTPUTS, ESTIMATES_ALERTS])
    for topic, fields in OUTPUTS.items():
        for s in stamps:
            for name in fields:
                a = np.asarray(getattr(live[topic][s], name), dtype=float)
                b = np.asarray(getattr(offline[topic][s], name), dtype=float)
                np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9, err_msg=f'{topic}.{name}')
    for s in stamps:
        a, b = live[ESTIMATES_ALERTS][s].alerts, offline[ESTIMATES_ALERTS][s].alerts
        assert [(r.kind, r.wheel, r.level, r.onset) for r in a] == [
            (r.kind, r.wheel, r.level, r.onset) for r in b
        ]


@pytest.mark.ros
def test_pipeline_node_fuses_a_mapped_imu(procs: RosProcessGroup, tmp_path: Path) -> None:
    """The simulator's whole IMU (specific force and pitch rate), mapped: the live slope says
    it used it and is what the replay computes with the same mapping, stamp for stamp (the
    live node holds each stamp until the IMU's sample of it has come, `ImuHold`, as the
    replay holds the newest sample not later than the stamp)."""
    scenario = tmp_path / 'launch_imu.yaml'
    scenario.write_text(
        SCENARIO.read_text(encoding='utf-8').replace(
            'sensors:\n', 'sensors:\n  imu: true\n  imu_noise_std: 0.02\n  imu_bias: 0.05\n'
        ),
        encoding='utf-8',
    )
    mapping = tmp_path / 'imu.yaml'
    mapping.write_text(
        f'imu:\n  topic: {SENSORS_IMU}\n  type: sensor_msgs/msg/Imu\n  mount_rpy_deg: [0, 0, 0]\n'
    )
    bag = tmp_path / 'live'
    rec = procs.node('recorder', 'vd_observer_node', 'recorder_node', output=str(bag))
    pipe = procs.node('pipeline', 'vd_observer_node', 'pipeline_node', input_mapping=str(mapping))
    for proc, text in ((rec, 'recording to'), (pipe, 'pipeline ready')):
        proc.wait_for(text, timeout=60)
    wait_recording(rec, [ESTIMATES_SLOPE])
    waiter = wait_for_last_stamp(
        procs, 'waiter', LAST_STAMP_NS, {ESTIMATES_SLOPE: 'vd_msgs.msg/Slope'}
    )
    sim = procs.node(
        'sim', 'vd_sim_node', 'sim_node', scenario_file=str(scenario), rate_hz=RATE_HZ,
        real_time_factor=1.0, min_sensor_subscribers=2,
    )  # fmt: skip
    assert wait_exit(sim, 60) == 0, sim.output()
    assert wait_exit(waiter, 180) == 0, waiter.output()
    for proc in (pipe, rec):
        assert proc.stop() == 0, proc.output()[-3000:]
    assert 'Traceback' not in pipe.output(), pipe.output()[-3000:]
    live = by_topic(bag, [SENSORS_IMU, ESTIMATES_SLOPE])
    assert len(live[SENSORS_IMU]) == N_SAMPLES
    stamps = sorted(live[ESTIMATES_SLOPE])
    assert len(stamps) == N_SAMPLES
    sources = np.array([live[ESTIMATES_SLOPE][s].sources for s in stamps])
    assert np.any(sources & SOURCE_IMU), 'the live slope never used the IMU'
    offline_bag = tmp_path / 'offline'
    report = replay_bag(bag, offline_bag, mapping=load_input_mapping(mapping), progress=False)
    offline = by_topic(offline_bag, [ESTIMATES_SLOPE])
    # the bias it learnt is logged once trusted, where the replay trusted it too
    assert ('IMU bias learnt' in pipe.output()) == ('trusted after' in report.imu), report.imu
    for field in ('angle', 'sources', 'valid'):
        a = np.array([getattr(live[ESTIMATES_SLOPE][s], field) for s in stamps])
        b = np.array([getattr(offline[ESTIMATES_SLOPE][s], field) for s in stamps])
        # (before ImuHold: within 0.1 deg, the newest sample that had arrived)
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12, err_msg=field)


@pytest.mark.ros
def test_pipeline_node_learns_the_imu_mounting_as_the_replay_does(
    procs: RosProcessGroup, tmp_path: Path
) -> None:
    """An IMU mounted upside down, pitched and turned, mapped without ``mount_rpy_deg`` (#36
    item 1): played live, pipeline_node learns the mounting from the drive, logs it and fuses
    the IMU from then on, stamp for stamp what the replay of the recorded sensors computes
    (`mount_learner`: a sample is read once both streams are past the windows the fit rests
    on, whichever the executor took first)."""

    from vd_common.vehicle.params import default_vehicle_file, load_vehicle
    from vd_observer_node.testing.devbag import sim_topics, write_topic_arrays_bag

    everyday = pytest.importorskip('vd_sim_node.vehicle.everyday')
    simulation = pytest.importorskip('vd_sim_node.vehicle.simulation')
    params = load_vehicle(default_vehicle_file())
    # seed 14 learns its mounting 21 s into this 40 s drive (offline, measured)
    settings = everyday.EverydaySettings(
        duration=40.0, rate_hz=100.0, speed_band=(50.0 / 3.6, 130.0 / 3.6)
    )
    sim = simulation.simulate(params, everyday.everyday_scenario(14, params, settings))
    stamps = np.round(sim.t * 1e9).astype(np.int64)
    drive = tmp_path / 'drive'
    topics = sim_topics(sim, truth=False, imu=True, imu_mount_rpy_deg=(180.0, -3.0, 5.0))
    write_topic_arrays_bag(drive, stamps, topics)
    mapping = tmp_path / 'imu.yaml'
    mapping.write_text(f'imu:\n  topic: {SENSORS_IMU}\n  type: sensor_msgs/msg/Imu\n')
    bag = tmp_path / 'live'
    rec = procs.node('recorder', 'vd_observer_node', 'recorder_node', output=str(bag))
    pipe = procs.node(
        'pipeline', 'vd_observer_node', 'pipeline_node', input_mapping=str(mapping),
        use_sim_time=True,
    )  # fmt: skip
    for proc, text in ((rec, 'recording to'), (pipe, 'pipeline ready')):
        proc.wait_for(text, timeout=60)
    assert 'the mounting is learnt from the drive' in pipe.output()
    wait_recording(rec, [ESTIMATES_SLOPE])
    waiter = wait_for_last_stamp(
        procs, 'waiter', int(stamps[-1]), {ESTIMATES_SLOPE: 'vd_msgs.msg/Slope'}
    )
    player = procs.node(
        'player', 'vd_observer_node', 'player_node', bag=str(drive), rate=2.0, start_delay=2.0,
        min_subscribers=2, input_mapping=str(mapping),  # it plays the mapped IMU too
    )  # fmt: skip
    assert wait_exit(player, 90) == 0, player.output()
    assert wait_exit(waiter, 180) == 0, waiter.output()
    for proc in (pipe, rec):
        assert proc.stop() == 0, proc.output()[-3000:]
    assert 'Traceback' not in pipe.output(), pipe.output()[-3000:]
    live = by_topic(bag, [SENSORS_IMU, ESTIMATES_SLOPE])
    assert len(live[SENSORS_IMU]) == stamps.size, 'the recorder lost IMU samples'
    slope_stamps = sorted(live[ESTIMATES_SLOPE])
    assert len(slope_stamps) == stamps.size
    report = replay_bag(
        bag, tmp_path / 'offline', mapping=load_input_mapping(mapping), progress=False
    )
    assert 'mounting learnt: [' in report.imu, report.imu
    angles = report.imu.split('mounting learnt: [')[1].split(']')[0]
    assert f'IMU mounting learnt: [{angles}]' in pipe.output(), pipe.output()[-3000:]
    offline = by_topic(tmp_path / 'offline', [ESTIMATES_SLOPE])
    sources = np.array([live[ESTIMATES_SLOPE][s].sources for s in slope_stamps])
    assert np.any(sources & SOURCE_IMU), 'the live slope never used the IMU'
    for field in ('angle', 'sources', 'valid'):
        a = np.array([getattr(live[ESTIMATES_SLOPE][s], field) for s in slope_stamps])
        b = np.array([getattr(offline[ESTIMATES_SLOPE][s], field) for s in slope_stamps])
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12, err_msg=field)
