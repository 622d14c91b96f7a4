"""The IMU is an input like the others (issue 41, item 3): checked, counted, live parameters."""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from vd_common.topics import ESTIMATES_SLOPE
from vd_observer_node.bag.errors import ReplayInputError
from vd_observer_node.bag.writer import BagWriter
from vd_observer_node.estimation.imu_grade import ImuGrade
from vd_observer_node.estimation.imu_settings import ImuGradeConfig, tau_for_rate
from vd_observer_node.estimation.rate_settings import slope_filter_tau_for_rate
from vd_observer_node.inputs.errors import MappingError
from vd_observer_node.inputs.mapping import mapping_from_dict
from vd_observer_node.nodes.node_params import INPUT_PARAMS, take_input_mapping
from vd_observer_node.testing.standard_bags import (
    IMU_MAPPING,
    STANDARD_MAPPING,
    CarSensors,
    write_standard_bag,
)
from vd_observer_node.tools.replay import replay_bag

RADIUS = 0.29  # [m] about the Clio's


def _drive(seconds: float = 3.0) -> SimpleNamespace:
    """A 1 kHz 'simulator run' of a car speeding up at 0.5 m/s^2 on the flat (the arrays
    `write_standard_bag` samples)."""
    t = np.arange(0.0, seconds, 1e-3)
    speed = 5.0 + 0.5 * t
    angle = np.repeat(((5.0 * t + 0.25 * t * t) / RADIUS)[:, None], 4, axis=1)
    torque = np.tile([60.0, 60.0, 0.0, 0.0], (t.size, 1))
    imu_true = np.column_stack([np.full(t.size, 0.5), np.full(t.size, 9.81)])
    return SimpleNamespace(
        t=t, angle_true=angle, speed_true=speed, wheel_torque=torque, imu_true=imu_true
    )


@pytest.fixture(scope='module')
def imu_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Standard types with an IMU on /imu at 100 Hz."""
    path = tmp_path_factory.mktemp('imu') / 'car'
    write_standard_bag(path, _drive(), CarSensors(imu_rate_hz=100.0))
    return path


def test_replay_refuses_an_imu_topic_the_bag_does_not_have(imu_bag: Path, tmp_path: Path) -> None:
    typo = {**IMU_MAPPING, 'imu': {**IMU_MAPPING['imu'], 'topic': '/imu/data'}}
    with pytest.raises(ReplayInputError) as caught:
        replay_bag(
            imu_bag, tmp_path / 'out', progress=False, mapping=mapping_from_dict(typo, 'car.yaml')
        )
    text = str(caught.value)
    # one line, naming the mapping key and listing what the bag has
    assert '\n' not in text
    assert 'no messages on sensor topic /imu/data (car.yaml: imu)' in text
    assert '/can/wheel_torques, /imu, /joint_states, /odom' in text
    assert not (tmp_path / 'out').exists()


def test_replay_refuses_an_imu_topic_without_messages(tmp_path: Path) -> None:
    bag = tmp_path / 'car'
    write_standard_bag(bag, _drive(1.0), CarSensors())
    # the same bag with an /imu topic that never delivered a message
    empty = tmp_path / 'empty_imu'
    from vd_observer_node.bag.reader import BagReader

    reader = BagReader(bag)
    with BagWriter(empty) as writer:
        for name, info in reader.topics.items():
            writer.add_topic(name, info.msgtype)
        writer.add_topic('/imu', 'sensor_msgs/msg/Imu')
        for msg in reader.raw_messages():
            writer.write(msg.topic, msg.data, msg.log_time_ns)
    mapping = mapping_from_dict(IMU_MAPPING, 'car.yaml')
    with pytest.raises(ReplayInputError, match=r'/imu \(car.yaml: imu\): the topic is empty'):
        replay_bag(empty, tmp_path / 'out', progress=False, mapping=mapping)
    # without the IMU in the mapping the same bag replays (the topic is not an input then)
    replay_bag(
        empty, tmp_path / 'plain', progress=False, mapping=mapping_from_dict(STANDARD_MAPPING)
    )


def test_replay_refuses_an_imu_topic_of_another_type(imu_bag: Path, tmp_path: Path) -> None:
    other = {
        **IMU_MAPPING,
        'imu': {**IMU_MAPPING['imu'], 'type': 'geometry_msgs/msg/AccelStamped'},
    }
    with pytest.raises(ReplayInputError, match='/imu has type sensor_msgs/msg/Imu'):
        replay_bag(imu_bag, tmp_path / 'out', progress=False, mapping=mapping_from_dict(other))


def test_replay_summary_counts_the_fused_imu(imu_bag: Path, tmp_path: Path) -> None:
    report = replay_bag(
        imu_bag, tmp_path / 'out', progress=False, mapping=mapping_from_dict(IMU_MAPPING)
    )
    names = [stats.name for stats in report.inputs]
    assert names == ['wheel_speeds', 'body_speed', 'wheel_torques', 'imu']
    imu = report.inputs[-1]
    assert imu.topic == '/imu'
    # 3 s at 100 Hz less the one period of history `_stamps` leaves out, no gap
    assert imu.messages == 299
    assert imu.longest_gap_s == pytest.approx(0.01, abs=1e-6)
    assert imu.long_gaps == 0
    assert imu.lost == 0
    assert 'imu (/imu): 299 messages' in imu.text()
    # without the IMU in the mapping it is not an input
    plain = replay_bag(
        imu_bag, tmp_path / 'plain', progress=False, mapping=mapping_from_dict(STANDARD_MAPPING)
    )
    assert [s.name for s in plain.inputs] == ['wheel_speeds', 'body_speed', 'wheel_torques']


def _values(**given: object) -> dict[str, object]:
    """The declared input parameters' values as a node reads them: unset ones None."""
    values: dict[str, object] = {spec.name: spec.default for spec in INPUT_PARAMS}
    values.update(given)
    return values


def test_live_imu_parameters_build_the_mapping_of_the_file() -> None:
    names = {spec.name for spec in INPUT_PARAMS}
    for key in ('topic', 'type', 'indices', 'unit', 'scale', 'mount_rpy_deg'):
        assert f'inputs.imu.{key}' in names
    assert 'inputs.imu.fusion.tau' in names
    for name in ('pitch_compliance', 'pitch_frequency', 'pitch_damping'):
        assert f'inputs.imu.fusion.{name}' not in names  # from the vehicle file
    file_form = {
        **STANDARD_MAPPING,
        'imu': {
            'topic': '/imu',
            'type': 'sensor_msgs/msg/Imu',
            'mount_rpy_deg': [0.0, -2.5, 0.0],
            'unit': 'g',
            'fusion': {'tau': 0.4, 'mass_feedback': False},
        },
    }
    params = {
        'inputs.wheel_speeds.topic': '/joint_states',
        'inputs.wheel_speeds.type': 'sensor_msgs/msg/JointState',
        'inputs.wheel_speeds.joints': list(STANDARD_MAPPING['wheel_speeds']['joints']),
        'inputs.wheel_speeds.unit': 'rad/s',
        'inputs.wheel_speeds.sign': [1, -1, 1, -1],
        'inputs.body_speed.topic': '/odom',
        'inputs.body_speed.type': 'nav_msgs/msg/Odometry',
        'inputs.body_speed.unit': 'm/s',
        'inputs.wheel_torques.topic': '/can/wheel_torques',
        'inputs.wheel_torques.type': 'std_msgs/msg/Float64MultiArray',
        'inputs.wheel_torques.indices': [0, 1, 2, 3],
        'inputs.wheel_torques.unit': 'N m',
        'inputs.alignment': 'latest',
        'inputs.imu.topic': '/imu',
        'inputs.imu.type': 'sensor_msgs/msg/Imu',
        'inputs.imu.mount_rpy_deg': [0.0, -2.5, 0.0],
        'inputs.imu.unit': 'g',
        'inputs.imu.fusion.tau': 0.4,
        'inputs.imu.fusion.mass_feedback': False,
    }
    live = take_input_mapping(_values(**params))
    offline = mapping_from_dict(file_form)
    assert live.imu is not None and offline.imu is not None
    assert live.imu == offline.imu
    assert live.imu.fusion == (('tau', 0.4), ('mass_feedback', 0.0))


def test_live_imu_parameters_are_refused_as_the_file_is() -> None:
    with pytest.raises(MappingError, match=r'imu.fusion.tua is not a setting'):
        take_input_mapping(
            _values(**{'inputs.imu.topic': '/imu', 'inputs.imu.type': 'sensor_msgs/msg/Imu'}),
            ['inputs.imu.fusion.tua'],
        )
    with pytest.raises(MappingError, match=r'imu\.unit'):
        take_input_mapping(
            _values(
                **{
                    'inputs.imu.topic': '/imu',
                    'inputs.imu.type': 'sensor_msgs/msg/Imu',
                    'inputs.imu.unit': 'furlong',
                }
            )
        )


def test_the_fusion_low_passes_follow_the_input_rate_as_the_slope_filter_does() -> None:
    assert tau_for_rate('tau', 1000.0) == 0.3
    assert tau_for_rate('tau', 2000.0) == 0.3
    assert tau_for_rate('step_tau', math.nan) == 0.1
    # the slope filter's law: the same factor below 1 kHz
    factor = slope_filter_tau_for_rate(50.0) / slope_filter_tau_for_rate(1000.0)
    assert tau_for_rate('tau', 50.0) == pytest.approx(0.3 * factor, rel=1e-12)
    assert tau_for_rate('step_tau', 50.0) == pytest.approx(0.1 * factor, rel=1e-12)
    # unset: the reference values until the rate is known, then the rate's
    config = ImuGradeConfig()
    assert (config.tau_in_use, config.step_tau_in_use) == (0.3, 0.1)
    at_50, fixed = config.at_rate(50.0)
    assert fixed == {'tau': tau_for_rate('tau', 50.0), 'step_tau': tau_for_rate('step_tau', 50.0)}
    assert at_50.tau == fixed['tau']
    assert config.at_rate(math.nan) == (config, {})
    # a value the user gave is kept as given
    given, fixed = ImuGradeConfig(tau=0.2).at_rate(50.0)
    assert given.tau == 0.2 and set(fixed) == {'step_tau'}
    # the running fusion's records take them, the lead with them
    grade = ImuGrade(None, 9.81, 1000.0, 0.01, 3.6)
    assert grade.follow_rate(50.0) == fixed | {'tau': tau_for_rate('tau', 50.0)}
    assert grade.params.tau == tau_for_rate('tau', 50.0)
    assert grade.params.lead == pytest.approx(3 * grade.params.tau)
    assert grade.follow_rate(100.0) == {}  # fixed once, as the estimator's


def test_replay_fixes_the_fusion_settings_at_the_measured_rate(
    imu_bag: Path, tmp_path: Path
) -> None:
    report = replay_bag(
        imu_bag, tmp_path / 'out', progress=False, mapping=mapping_from_dict(IMU_MAPPING)
    )
    # wheels at 100 Hz, odometry at 50 Hz: the slower one's rate, as the slope filter's
    assert report.input_rate_hz == 50.0
    assert report.rate_settings['imu.fusion.tau'] == tau_for_rate('tau', 50.0)
    assert report.rate_settings['imu.fusion.step_tau'] == tau_for_rate('step_tau', 50.0)
    assert report.rate_settings['slope_filter_tau'] == slope_filter_tau_for_rate(50.0)
    # the mapping's own values are kept as given
    given = {**IMU_MAPPING, 'imu': {**IMU_MAPPING['imu'], 'fusion': {'tau': 0.2, 'step_tau': 0}}}
    kept = replay_bag(imu_bag, tmp_path / 'kept', progress=False, mapping=mapping_from_dict(given))
    assert not any(key.startswith('imu.') for key in kept.rate_settings)


@pytest.mark.slow
def test_a_well_behaved_100hz_imu_does_not_make_the_slope_worse(tmp_path: Path) -> None:
    """Issue 41: a 100 Hz IMU (0.05 m/s^2 noise) on a car logged on standard types made the
    slope worse than the force balance alone (0.318 deg against 0.245 deg on paper_table1)
    while the fusion's low-passes kept their 1 kHz values. Everyday drive 107 was not among
    the drives the rate law was chosen on (paper_table1 seeds 0-1, everyday drives 0-4;
    ``scripts/eval_imu_rate.py``). Measured: force balance 0.269 deg, fused 0.160 deg (a
    margin of 40 %); with the 1 kHz low-passes (tau 0.3 s, step_tau 0.1 s) 0.332 deg, which
    fails this test (everyday drives change with the simulator: the figure is checked too)."""
    from vd_common.vehicle.params import default_vehicle_file, load_vehicle
    from vd_observer_node.bag.cdr_batch import decode_batch
    from vd_observer_node.bag.reader import BagReader
    from vd_observer_node.tools.replay import ESTIMATE_TOPICS
    from vd_sim_node.vehicle.everyday import EverydaySettings, everyday_scenario
    from vd_sim_node.vehicle.simulation import simulate

    params = load_vehicle(default_vehicle_file())
    sim = simulate(params, everyday_scenario(102, params, EverydaySettings()))
    bag = tmp_path / 'car'
    write_standard_bag(bag, sim, CarSensors(seed=102, imu_rate_hz=100.0, imu_bias=0.009))

    def slope_rms_deg(mapping: dict[str, object], out: Path) -> float:
        replay_bag(bag, out, progress=False, mapping=mapping_from_dict(mapping))
        arrays = BagReader(out).topic_arrays([ESTIMATES_SLOPE])[ESTIMATES_SLOPE]
        fields = decode_batch(ESTIMATE_TOPICS[ESTIMATES_SLOPE], arrays.datas)
        t = fields.stamp_ns * 1e-9
        # as scripts/eval_imu_rate.py: moving, not within 0.5 s of a slope step or a shift
        moving = (t >= 1.0) & (np.interp(t, sim.t, sim.speed_true) > 1.0)
        for stamp, text in sim.events:
            if 'slope' in text or 'shift' in text:
                moving &= np.abs(t - stamp) > 0.5
        error = fields.values['angle'] - np.interp(t, sim.t, sim.slope)
        return math.degrees(float(np.sqrt(np.mean(error[moving] ** 2))))

    force = slope_rms_deg(STANDARD_MAPPING, tmp_path / 'force')
    fused = slope_rms_deg(IMU_MAPPING, tmp_path / 'fused')
    assert fused <= force, (fused, force)
    assert fused == pytest.approx(0.160, abs=0.01)  # the figure docs/estimation.md gives


def test_report_summary_lists_the_fused_imu(imu_bag: Path) -> None:
    from vd_observer_node.tools.report.load import load_bag_series

    series = load_bag_series(imu_bag, progress=False, mapping=mapping_from_dict(IMU_MAPPING))
    assert [s.name for s in series.inputs] == [
        'wheel_speeds',
        'body_speed',
        'wheel_torques',
        'imu',
    ]
    assert series.inputs[-1].messages == 299
    plain = load_bag_series(imu_bag, progress=False, mapping=mapping_from_dict(STANDARD_MAPPING))
    assert 'imu' not in [s.name for s in plain.inputs]


def test_vd_replay_says_when_the_mapping_states_no_mounting(
    imu_bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A mapping without ``imu.mount_rpy_deg`` has the mounting learnt from the drive; the
    replay says so, names vd calibrate, which learns it to be stated, and says what it learnt
    (this bag's 8 s are too short: not learnt, and why); a stated mounting, even [0, 0, 0],
    is not questioned."""
    import yaml
    from vd_observer_node.tools.cli import main

    hint = 'the mapping states no imu.mount_rpy_deg: the mounting is learnt from the drive'
    for k, imu in enumerate(
        [
            {k: v for k, v in IMU_MAPPING['imu'].items() if k != 'mount_rpy_deg'},
            IMU_MAPPING['imu'],  # [0, 0, 0]
        ]
    ):
        path = tmp_path / f'mapping{k}.yaml'
        path.write_text(yaml.safe_dump({**IMU_MAPPING, 'imu': imu}))
        args = ['replay', '--no-progress', '--mapping', str(path), str(imu_bag)]
        assert main([*args, str(tmp_path / f'out{k}')]) == 0
        printed = capsys.readouterr().out
        # unstated, the IMU is never read on this short drive: the line says why
        assert ('imu: angular rate used on' in printed) == (k == 1), printed
        assert (hint in printed) == (k == 0), printed
        assert ('imu: mounting not learnt: ' in printed) == (k == 0), printed
