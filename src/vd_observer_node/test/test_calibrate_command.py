"""`vd calibrate` end to end on a simulated car that is not its file, and its bad inputs.

The oracle is the simulator's true car (a loaded Clio on worn tyres, with more drag and
another final drive than vd's Clio file, the calibration's base), driven on a seeded
everyday drive with 96-count encoders and speed noise.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from vd_common.topics import SENSORS_BODY_VELOCITY, SENSORS_IMU, TRUTH_SLOPE
from vd_common.vehicle.estimation import load_estimation_vehicle
from vd_common.vehicle.params import VehicleParams, default_vehicle_file, load_vehicle
from vd_observer_node.inputs.rotation import mount_rotation, mount_rpy
from vd_observer_node.testing.devbag import sim_topics, write_topic_arrays_bag
from vd_observer_node.tools.calibrate.calibration import calibrate
from vd_observer_node.tools.calibrate.drive import read_drive
from vd_observer_node.tools.cli import main

vehicle = pytest.importorskip('vd_sim_node.vehicle.everyday')
simulation = pytest.importorskip('vd_sim_node.vehicle.simulation')
variants = pytest.importorskip('vd_sim_node.vehicle.variants')
scenario_module = pytest.importorskip('vd_sim_node.vehicle.scenario')

RATE_HZ = 100.0
SEED = 11  # an everyday drive the calibration was not written on (smoke runs: 300, 301)


def _true_car(params: VehicleParams) -> tuple[VehicleParams, object]:
    car = dataclasses.replace(
        params,
        aero=dataclasses.replace(params.aero, drag_coefficient=0.38),
        gearbox=dataclasses.replace(params.gearbox, final_drive=3.9),
    )
    return car, scenario_module.VehicleVariant(extra_mass_kg=220.0, tyre_radius_scale=0.975)


def _scenario(params: VehicleParams) -> object:
    # a driver who keeps 50-130 km/h: the drag needs speeds above 60 km/h (the default band's
    # drive of this seed tops at 53 km/h, where the drag is rightly not determined)
    settings = vehicle.EverydaySettings(
        duration=150.0, rate_hz=RATE_HZ, speed_band=(50.0 / 3.6, 130.0 / 3.6)
    )
    return vehicle.everyday_scenario(SEED, params, settings)


@pytest.fixture(scope='module')
def drive(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, VehicleParams, object]:
    """A 150 s everyday drive of the true car: the bag with truth, and the true parameters."""
    params = load_vehicle(default_vehicle_file())
    car, variant = _true_car(params)
    scenario = dataclasses.replace(_scenario(params), true_vehicle=variant)
    sim = simulation.simulate(car, scenario, rate_hz=RATE_HZ)
    folder = tmp_path_factory.mktemp('calibrate')
    stamps = np.round(sim.t * 1e9).astype(np.int64)
    write_topic_arrays_bag(folder / 'drive', stamps, sim_topics(sim))
    write_topic_arrays_bag(folder / 'no_truth', stamps, sim_topics(sim, truth=False))
    short = sim.t < 8.0
    short_topics = {
        topic: {k: v[short] for k, v in fields.items()}
        for topic, fields in sim_topics(sim).items()
    }
    write_topic_arrays_bag(folder / 'short', stamps[short], short_topics)
    return folder, variants.apply_variant(car, variant), sim


def test_the_command_writes_a_file_the_estimators_load_with_the_true_values(
    drive: tuple[Path, VehicleParams, object], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder, truth, _ = drive
    out = tmp_path / 'car.yaml'
    report = tmp_path / 'report'
    assert (
        main(['calibrate', str(folder / 'drive'), '--out', str(out), '--report', str(report)]) == 0
    )
    printed = capsys.readouterr().out
    assert 'fitted chassis.mass' in printed
    fitted = load_estimation_vehicle(out)
    # issue #37's goals; measured on this drive: mass 0.1 %, radius 0.01 %, final drive
    # 0.01 %, drag 1 %, c0 1 % (scripts/eval_calibrate.py prints eight cars)
    assert fitted.chassis.mass == pytest.approx(truth.chassis.mass, rel=0.03)
    assert fitted.wheel.effective_radius == pytest.approx(truth.wheel.effective_radius, rel=0.003)
    assert fitted.require_driveline().final_drive == pytest.approx(3.9, rel=0.005)
    assert fitted.aero.drag_coefficient == pytest.approx(0.38, rel=0.10)
    assert fitted.rolling_resistance.c0 == pytest.approx(truth.rolling_resistance.c0, rel=0.20)
    assert fitted.require_driveline().layout == 'FWD'
    # what a drive never determines comes from the base, and says so
    base = load_estimation_vehicle(default_vehicle_file())
    assert fitted.chassis.wheelbase == base.chassis.wheelbase
    lines = {
        line.split(':')[0].strip(): line for line in out.read_text().splitlines() if ':' in line
    }
    assert '# fitted ±' in lines['mass'] and 'samples' in lines['mass']
    assert lines['wheelbase'].endswith('# base')
    summary = json.loads((report / 'calibration.json').read_text())
    assert {f['key'] for f in summary['fitted']} >= {'chassis.mass', 'gearbox.final_drive'}
    assert (report / 'residuals_force_balance.png').stat().st_size > 1000
    assert '| `chassis.mass` |' in (report / 'calibration.md').read_text()


def test_a_bag_without_a_speed_reference_is_one_line_and_writes_nothing(
    drive: tuple[Path, VehicleParams, object], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder, _, _ = drive
    out = tmp_path / 'car.yaml'
    assert main(['calibrate', str(folder / 'no_truth'), '--out', str(out)]) == 2
    error = capsys.readouterr().err
    assert error.count('\n') == 1 and 'no speed reference' in error
    assert not out.exists() and not list(tmp_path.iterdir())


def test_a_drive_too_short_is_one_line_and_writes_nothing(
    drive: tuple[Path, VehicleParams, object], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder, _, _ = drive
    out = tmp_path / 'car.yaml'
    assert main(['calibrate', str(folder / 'short'), '--out', str(out)]) == 2
    error = capsys.readouterr().err
    assert error.count('\n') == 1 and 'need 10 s' in error
    assert not out.exists()


def test_what_the_drive_lacks_is_not_determined_with_the_reason(
    drive: tuple[Path, VehicleParams, object],
) -> None:
    folder, _, _ = drive
    base = load_estimation_vehicle(default_vehicle_file())
    full = read_drive(folder / 'drive', None, base.wheel.effective_radius)
    no_engine_speed = dataclasses.replace(
        full, engine_radps=np.full_like(full.speed_mps, np.nan), turbine_radps=None
    )
    result = calibrate(no_engine_speed, base)
    assert 'engine (or turbine) speed' in result.not_determined['gearbox.final_drive']
    slow = full.speed_mps < 50.0 / 3.6
    crawl = dataclasses.replace(
        full,
        **{
            f.name: getattr(full, f.name)[slow]
            for f in dataclasses.fields(full)
            if isinstance(getattr(full, f.name), np.ndarray)
        },
    )
    result = calibrate(crawl, base)
    assert 'never above 60 km/h' in result.not_determined['aero.drag_coefficient']
    assert 'aero.drag_coefficient' not in result.fits
    no_grade = dataclasses.replace(full, grade_rad=None)
    result = calibrate(no_grade, base)
    assert 'no grade reference' in result.not_determined['chassis.mass']


def test_a_mapping_reference_replaces_the_truth_topics(
    drive: tuple[Path, VehicleParams, object], tmp_path: Path
) -> None:
    folder, truth, _ = drive
    mapping = tmp_path / 'mapping.yaml'
    # the noisy sensor speed as the "GNSS" speed: the reference is the one the mapping names
    mapping.write_text(
        yaml.safe_dump(
            {
                'reference': {
                    'speed': {
                        'topic': SENSORS_BODY_VELOCITY,
                        'type': 'geometry_msgs/msg/TwistStamped',
                    },
                    'grade': {'topic': TRUTH_SLOPE, 'type': 'vd_msgs/msg/Slope'},
                }
            }
        )
    )
    out = tmp_path / 'car.yaml'
    assert (
        main(['calibrate', str(folder / 'no_truth'), '--out', str(out), '--mapping', str(mapping)])
        == 2
    )
    assert (
        main(['calibrate', str(folder / 'drive'), '--out', str(out), '--mapping', str(mapping)])
        == 0
    )
    fitted = load_estimation_vehicle(out)
    assert fitted.wheel.effective_radius == pytest.approx(truth.wheel.effective_radius, rel=0.003)


def test_the_brake_gain_from_a_pressure_against_the_deceleration(
    drive: tuple[Path, VehicleParams, object],
) -> None:
    """The engine path with a brake pressure: one master-cylinder pressure for all wheels,
    made from the simulator's true front brake torque at 100 N m per bar. One pressure
    determines the sum of the gains only: the base's front/rear split (the true one, at half
    the scale) divides it."""
    from vd_common.vehicle.estimation import EstimationBrakes
    from vd_observer_node.tools.calibrate.drive import WINDOW_S, _Windows

    folder, _, sim = drive
    base = load_estimation_vehicle(default_vehicle_file())
    full = read_drive(folder / 'drive', None, base.wheel.effective_radius)
    brake = np.asarray(sim.brake_torque)  # type: ignore[attr-defined]
    pressure = brake[:, 0] / 100.0  # bar
    pressed = brake[:, 0] > 1.0
    ratio = float(np.median(brake[pressed, 2] / brake[pressed, 0]))
    windows = _Windows(full.t, WINDOW_S)
    bar = windows.mean(np.asarray(sim.t), np.repeat(pressure[:, None], 4, axis=1))  # type: ignore[attr-defined]
    braking = windows.count(np.asarray(sim.t), pressed) > 0  # type: ignore[attr-defined]
    with_pressure = dataclasses.replace(
        full, brake_bar=bar, braking=braking, has_brake_input=True, engine_path=True
    )
    half = EstimationBrakes(gain_front=50.0, gain_rear=50.0 * ratio)
    result = calibrate(with_pressure, dataclasses.replace(base, brakes=half))
    assert 'chassis.mass' in result.fits  # the engine path's force balance
    front = result.fits['brakes.gain_front'].value
    rear = result.fits['brakes.gain_rear'].value
    assert isinstance(front, float) and isinstance(rear, float)
    # measured 1.9 % low on both (the window's edges at the brake's onset and release)
    assert front == pytest.approx(100.0, rel=0.03)
    assert rear == pytest.approx(100.0 * ratio, rel=0.03)


def test_on_level_road_without_a_grade_reference(tmp_path: Path) -> None:
    """`--level-road`: a test track's drive with a speed reference and no grade reference
    (the simulator's road is level throughout; its slope topic is left out of the bag)."""
    params = load_vehicle(default_vehicle_file())
    car, variant = _true_car(params)
    settings = vehicle.EverydaySettings(
        duration=120.0, rate_hz=RATE_HZ, speed_band=(50.0 / 3.6, 130.0 / 3.6), max_grade_deg=0.0
    )
    # an everyday drive starts on a grade of up to 2 deg whatever max_grade_deg says: level it
    scenario = dataclasses.replace(
        vehicle.everyday_scenario(SEED + 1, params, settings),
        true_vehicle=variant,
        slope=scenario_module.PiecewiseConstant((0.0,), (0.0,)),
    )
    sim = simulation.simulate(car, scenario, rate_hz=RATE_HZ)
    assert not np.asarray(sim.slope).any()  # type: ignore[attr-defined]
    topics = sim_topics(sim)
    stamps = np.round(sim.t * 1e9).astype(np.int64)
    write_topic_arrays_bag(tmp_path / 'with_grade', stamps, topics)
    del topics[TRUTH_SLOPE]
    write_topic_arrays_bag(tmp_path / 'track', stamps, topics)
    out = tmp_path / 'car.yaml'
    assert main(['calibrate', str(tmp_path / 'track'), '--out', str(out)]) == 0
    assert 'mass:' in out.read_text() and 'no grade reference' in out.read_text()
    assert (
        main(['calibrate', str(tmp_path / 'with_grade'), '--out', str(out), '--level-road']) == 2
    )
    assert main(['calibrate', str(tmp_path / 'track'), '--out', str(out), '--level-road']) == 0
    fitted = load_estimation_vehicle(out)
    truth = variants.apply_variant(car, variant)
    # the goals; measured: mass +0.02 %, drag +1.0 %, c0 -0.7 %
    assert fitted.chassis.mass == pytest.approx(truth.chassis.mass, rel=0.03)
    assert fitted.aero.drag_coefficient == pytest.approx(0.38, rel=0.10)
    assert fitted.rolling_resistance.c0 == pytest.approx(truth.rolling_resistance.c0, rel=0.20)


def _turned_imu_bag(sim: object, tmp_path: Path) -> tuple[Path, np.ndarray]:
    """The drive with its IMU written upside down, pitched -3 deg and turned 5 deg, and the
    mounting [deg] to find: the everyday drive's IMU is itself pitched in the body (its
    ``imu_mount_pitch``), so that pitch, then the rotation written."""
    written = (180.0, -3.0, 5.0)
    sim_pitch = _scenario(load_vehicle(default_vehicle_file())).sensors.imu_mount_pitch  # type: ignore[attr-defined]
    rows = np.array(mount_rotation(0.0, sim_pitch, 0.0)) @ mount_rotation(*np.radians(written))
    mounted = np.degrees(mount_rpy(tuple(map(tuple, rows))))
    stamps = np.round(sim.t * 1e9).astype(np.int64)  # type: ignore[attr-defined]
    bag = tmp_path / 'imu'
    write_topic_arrays_bag(bag, stamps, sim_topics(sim, imu=True, imu_mount_rpy_deg=written))
    return bag, mounted


def test_the_imu_mounting_is_learnt_from_the_drive(
    drive: tuple[Path, VehicleParams, object], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The simulator's IMU (its specific force and pitch rate on the sprung body, with the
    scenario's noise) written as a sensor mounted upside down, pitched and turned would read
    it (`_turned_imu_bag`); the mapping does not state the mounting."""
    bag, mounted = _turned_imu_bag(drive[2], tmp_path)
    mapping = tmp_path / 'mapping.yaml'
    mapping.write_text(
        yaml.safe_dump({'imu': {'topic': SENSORS_IMU, 'type': 'sensor_msgs/msg/Imu'}})
    )
    report = tmp_path / 'report'
    args = ['calibrate', str(bag), '--out', str(tmp_path / 'car.yaml'), '--mapping', str(mapping)]
    assert main([*args, '--report', str(report)]) == 0
    printed = capsys.readouterr().out
    found = json.loads((report / 'calibration.json').read_text())['imu_mounting']
    error = (np.array(found['mount_rpy_deg']) - mounted + 180.0) % 360.0 - 180.0
    # measured: roll 0.08 deg, yaw 0.004 deg off; the pitch 0.91 deg, the body's squat in the
    # second order on a drive that brakes harder than it accelerates (module docstring of
    # inputs/mounting.py; the fusion learns a pitch as its bias)
    assert abs(error[0]) < 0.15 and abs(error[2]) < 0.05, error
    assert abs(error[1]) < 1.2, error
    assert found['std_deg'][0] < 0.05 and found['std_deg'][2] < 0.01  # 0.02, 0.0007 measured
    assert found['std_deg'][1] < 0.5  # 0.25 measured
    assert 'fitted imu.mount_rpy_deg: [' in printed
    assert "the mapping's imu.mount_rpy_deg puts the body's forward axis" in printed
    assert "the mapping's imu.mount_rpy_deg puts the body's lateral axis 175.0 deg" in printed


def test_vd_replay_learns_the_imu_mounting_online(
    drive: tuple[Path, VehicleParams, object], tmp_path: Path
) -> None:
    """The same upside-down, pitched and turned IMU replayed with a mapping that does not
    state its mounting (#36 item 1): the replay learns it from the drive, as it goes, and
    fuses the IMU from then on, what it gives is the same in tiny blocks as in one, and the
    mounting is the one the drive shows."""
    from vd_observer_node.bag.reader import BagReader
    from vd_observer_node.inputs.mapping import mapping_from_dict
    from vd_observer_node.tools.replay import replay_bag

    bag, mounted = _turned_imu_bag(drive[2], tmp_path)
    imu = {'topic': SENSORS_IMU, 'type': 'sensor_msgs/msg/Imu'}
    mapping = mapping_from_dict({'imu': imu})
    whole = replay_bag(bag, tmp_path / 'whole', mapping=mapping, progress=False)
    tiny = replay_bag(bag, tmp_path / 'tiny', mapping=mapping, progress=False, block_messages=2000)
    assert tiny.imu == whole.imu
    written = [  # every message of both outputs, bytes and log times
        [(m.topic, m.log_time_ns, bytes(m.data)) for m in BagReader(out).raw_messages()]
        for out in (tmp_path / 'whole', tmp_path / 'tiny')
    ]
    assert written[0] == written[1]
    assert 'mounting learnt: [' in whole.imu, whole.imu
    text = whole.imu.split('mounting learnt: [')[1].split(']')[0]
    learnt = np.array([float(a) for a in text.split(',')])
    error = (learnt - mounted + 180.0) % 360.0 - 180.0
    # measured: roll 0.08, pitch 0.95 (the squat), yaw 0.00 deg off; fused from 46 s on
    assert abs(error[0]) < 0.3 and abs(error[2]) < 0.3, error
    assert abs(error[1]) < 1.2, error
    assert 'trusted after' in whole.imu, whole.imu
