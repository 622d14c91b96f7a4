"""Vehicle parameter view: the shared parser's file, its values and its refusals."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import yaml
from vd_common.vehicle.params import load_vehicle
from vd_observer_node.errors import VehicleParameterError
from vd_observer_node.estimation.axle_loads import VerticalModel
from vd_observer_node.estimation.vehicle import (
    EstimatorVehicle,
    load_estimator_vehicle,
    load_vehicle_params,
)
from vd_observer_node.situation.chain_settings import chain_settings

VEHICLE_FILE = Path(__file__).resolve().parents[2] / 'vd_common' / 'config' / 'clio_rl_1_1.yaml'


def test_loads_the_shared_clio_file() -> None:
    vehicle = load_estimator_vehicle(VEHICLE_FILE)
    assert vehicle.mass == 905.0
    assert vehicle.effective_radius == 0.26
    assert vehicle.cg_to_rear_axle == pytest.approx(2.472 - 0.95)
    np.testing.assert_allclose(vehicle.wheel_inertia, [0.75, 0.75, 0.60, 0.60])
    loads = vehicle.static_wheel_loads
    assert loads.sum() == pytest.approx(905.0 * 9.81)
    # Front-heavy FWD car: about 61 % on the front axle.
    assert (loads[0] + loads[1]) / loads.sum() == pytest.approx(1.522 / 2.472, rel=1e-3)
    assert vehicle.drag_factor == pytest.approx(0.5 * 1.225 * 0.33 * 1.85)


def test_values_are_the_files_own_numbers() -> None:
    """Every field is the YAML value itself, bit for bit, as the old key table read it.

    The kernel-equivalence and cross-process tests compare estimates at 1e-9 against runs
    made with these numbers, so any rounding or recomputation here would show there.
    """
    raw = yaml.safe_load(VEHICLE_FILE.read_text(encoding='utf-8'))
    vehicle = load_estimator_vehicle(VEHICLE_FILE)
    expected = {
        'mass': raw['chassis']['mass'],
        'wheelbase': raw['chassis']['wheelbase'],
        'cg_to_front_axle': raw['chassis']['cg_to_front_axle'],
        'cg_height': raw['chassis']['cg_height'],
        'inertia_front': raw['wheel']['inertia_front'],
        'inertia_rear': raw['wheel']['inertia_rear'],
        'effective_radius': raw['wheel']['effective_radius'],
        'drag_coefficient': raw['aero']['drag_coefficient'],
        'frontal_area': raw['aero']['frontal_area'],
        'air_density': raw['aero']['air_density'],
        'rolling_c0': raw['rolling_resistance']['c0'],
        'rolling_c1': raw['rolling_resistance']['c1'],
        'gravity': raw['environment']['gravity'],
        'rolling_regularisation_speed': raw['rolling_resistance']['regularisation_speed'],
        'name': raw['name'],
        # the chassis's vertical dynamics: the file's suspension, tyres and masses
        'vertical': dataclasses.asdict(VerticalModel.from_params(load_vehicle(VEHICLE_FILE))),
    }
    assert dataclasses.asdict(vehicle) == expected  # exact: tolerance 0
    # The values the old estimator-only reader gave (pinned before issue 19 merged the two).
    assert vehicle == EstimatorVehicle(
        mass=905.0,
        wheelbase=2.472,
        cg_to_front_axle=0.95,
        cg_height=0.55,
        inertia_front=0.75,
        inertia_rear=0.6,
        effective_radius=0.26,
        drag_coefficient=0.33,
        frontal_area=1.85,
        air_density=1.225,
        rolling_c0=0.01,
        rolling_c1=3.6,
        gravity=9.81,
        rolling_regularisation_speed=0.05,
        name='Renault Clio RL 1.1',
        vertical=VerticalModel(
            sprung_mass=791.0,
            pitch_inertia=1050.0,
            sprung_cg_to_front=(905.0 * 0.95 - 50.0 * 2.472) / 791.0,
            wheelbase=2.472,
            cg_height=0.55,
            unsprung=(64.0, 50.0),
            spring=(38000.0, 34000.0),
            damper=(3200.0, 2800.0),
            tyre=(320000.0, 300.0),
        ),
    )
    assert vehicle.static_wheel_loads.tolist() == [
        2733.0890169902914,
        2733.0890169902914,
        1705.935983009709,
        1705.935983009709,
    ]
    assert vehicle.drag_factor == 0.37393125000000005


def test_same_numbers_as_the_simulator() -> None:
    params = load_vehicle(VEHICLE_FILE)
    assert EstimatorVehicle.from_params(params) == load_estimator_vehicle(VEHICLE_FILE)
    read = load_vehicle_params(VEHICLE_FILE)
    # the estimators' own parse reads no suspension: rigid until given the file's model
    assert EstimatorVehicle.from_params(read).vertical is None
    vertical = VerticalModel.from_params(params)
    assert EstimatorVehicle.from_params(read).with_vertical(vertical) == (
        EstimatorVehicle.from_params(params)
    )
    assert read.tire == params.tire
    default = load_vehicle_params()  # the Clio: the installed copy, or the source tree's
    assert dataclasses.replace(default, source='') == dataclasses.replace(read, source='')


def test_an_estimation_only_file_estimates_and_says_what_it_lacks(tmp_path: Path) -> None:
    """A vehicle file with only the estimators' keys: the cascade runs, the engine path and
    the alerts are refused in one line naming the section, vd replay skips the alerts and
    says so, and says which vehicle file it used."""
    import yaml
    from vd_observer_node.errors import ConfigurationError, VehicleParameterError
    from vd_observer_node.estimation.drivetrain import Drivetrain
    from vd_observer_node.estimation.vehicle import vehicle_tire
    from vd_observer_node.testing.synthetic_bags import write_synthetic_drive_bag
    from vd_observer_node.tools.replay import ALERT_TOPICS, replay_bag

    full = yaml.safe_load(VEHICLE_FILE.read_text(encoding='utf-8'))
    only = {k: full[k] for k in ('name', 'chassis', 'wheel', 'aero', 'rolling_resistance',
                                 'environment')}  # fmt: skip
    path = tmp_path / 'estimation_only.yaml'
    path.write_text(yaml.safe_dump(only), encoding='utf-8')
    params = load_vehicle_params(path)
    # the same numbers, but no suspension: a rigid body (no vertical model)
    rigid = load_estimator_vehicle(path)
    assert rigid.vertical is None
    assert EstimatorVehicle.from_params(params) == rigid
    assert rigid == load_estimator_vehicle(VEHICLE_FILE).with_vertical(None)
    with pytest.raises(VehicleParameterError, match=r'tire is missing'):
        vehicle_tire(params)
    with pytest.raises(ConfigurationError, match=r'gearbox is missing'):
        Drivetrain.from_params(params)
    write_synthetic_drive_bag(tmp_path / 'in', duration_s=1.0, rate_hz=100.0, with_truth=False)
    settings = chain_settings(vehicle_file=path)
    report = replay_bag(tmp_path / 'in', tmp_path / 'out', settings, progress=False)
    assert report.vehicle == f'{only["name"]} ({path})'
    assert report.notes == (
        f'friction potential and alerts off (no tire in vehicle file {path}: the friction '
        'potential and the alerts need its Magic Formula coefficients)',
    )
    from vd_observer_node.bag import BagReader

    written = set(BagReader(tmp_path / 'out').topics)
    assert not written & set(ALERT_TOPICS) and report.samples > 0


def _write(tmp_path: Path, data: dict[str, object]) -> Path:
    path = tmp_path / 'vehicle.yaml'
    path.write_text(yaml.safe_dump(data), encoding='utf-8')
    return path


def _refusal(path: Path) -> str:
    with pytest.raises(VehicleParameterError) as info:
        load_estimator_vehicle(path)
    message = str(info.value)
    assert '\n' not in message  # a node prints it as its one error line
    return message


def test_missing_key_is_reported(tmp_path: Path) -> None:
    data = yaml.safe_load(VEHICLE_FILE.read_text(encoding='utf-8'))
    del data['wheel']['inertia_rear']
    path = _write(tmp_path, data)
    assert _refusal(path) == f'vehicle file {path}: wheel.inertia_rear is missing'


@pytest.mark.parametrize(
    ('section', 'key', 'value', 'message'),
    [
        ('chassis', 'mass', -1200.0, 'chassis.mass must be > 0 kg, got -1200.0'),
        ('chassis', 'mass', 'heavy', "chassis.mass must be a number kg, got 'heavy'"),
        ('chassis', 'cg_to_front_axle', 3.0, 'chassis.cg_to_front_axle must be < 2.472 m'),
        ('wheel', 'effective_radius', 0.0, 'wheel.effective_radius must be > 0 m, got 0.0'),
        ('aero', 'air_density', float('nan'), 'aero.air_density must be finite, got nan'),
        (
            'rolling_resistance',
            'regularisation_speed',
            'fast',
            "rolling_resistance.regularisation_speed must be a number m/s, got 'fast'",
        ),
    ],
)
def test_invalid_values_are_rejected(
    tmp_path: Path, section: str, key: str, value: object, message: str
) -> None:
    data = yaml.safe_load(VEHICLE_FILE.read_text(encoding='utf-8'))
    data[section][key] = value
    path = _write(tmp_path, data)
    assert _refusal(path).startswith(f'vehicle file {path}: {message}')


def test_unreadable_file(tmp_path: Path) -> None:
    absent = tmp_path / 'absent.yaml'
    assert _refusal(absent).startswith(f'cannot read vehicle file {absent}: ')
    bad = tmp_path / 'bad.yaml'
    bad.write_text('chassis: {mass: [1,\n', encoding='utf-8')
    assert _refusal(bad).startswith(f'vehicle file {bad} is not valid YAML: ')


def test_resistances_switched_off_in_the_file_are_allowed(tmp_path: Path) -> None:
    """Zero c0, Cx, A or rho switch a resistance off in both the simulator and here."""
    data = yaml.safe_load(VEHICLE_FILE.read_text(encoding='utf-8'))
    data['aero'].update(frontal_area=0.0, air_density=0.0)
    data['rolling_resistance'].update(c0=0.0, c1=0.0)
    vehicle = load_estimator_vehicle(_write(tmp_path, data))
    assert vehicle.drag_factor == 0.0
    assert vehicle.rolling_c0 == 0.0


def test_zero_resistances_are_allowed() -> None:
    vehicle = EstimatorVehicle(
        mass=1000.0,
        wheelbase=2.5,
        cg_to_front_axle=1.0,
        cg_height=0.5,
        inertia_front=1.0,
        inertia_rear=1.0,
        effective_radius=0.3,
        drag_coefficient=0.0,
        frontal_area=2.0,
        air_density=1.2,
        rolling_c0=0.0,
        rolling_c1=0.0,
        gravity=9.81,
    )
    assert vehicle.drag_factor == 0.0


def test_direct_construction_is_checked() -> None:
    with pytest.raises(VehicleParameterError, match=r'EstimatorVehicle\.mass must be'):
        EstimatorVehicle(
            mass=-1.0,
            wheelbase=2.5,
            cg_to_front_axle=1.0,
            cg_height=0.5,
            inertia_front=1.0,
            inertia_rear=1.0,
            effective_radius=0.3,
            drag_coefficient=0.3,
            frontal_area=2.0,
            air_density=1.2,
            rolling_c0=0.01,
            rolling_c1=0.0,
            gravity=9.81,
        )
