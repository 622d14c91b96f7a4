"""Vehicle parameter view: loading the shared file and validation."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from vd_observer_node.errors import VehicleParameterError
from vd_observer_node.estimation.vehicle import EstimatorVehicle, load_estimator_vehicle

VEHICLE_FILE = Path(__file__).resolve().parents[2] / 'vd_sim_node' / 'config' / 'clio_rl_1_1.yaml'


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


def _write(tmp_path: Path, data: dict[str, object]) -> Path:
    path = tmp_path / 'vehicle.yaml'
    path.write_text(yaml.safe_dump(data), encoding='utf-8')
    return path


def test_missing_key_is_reported(tmp_path: Path) -> None:
    data = yaml.safe_load(VEHICLE_FILE.read_text(encoding='utf-8'))
    del data['wheel']['effective_radius']
    with pytest.raises(VehicleParameterError, match=r'wheel\.effective_radius'):
        load_estimator_vehicle(_write(tmp_path, data))


@pytest.mark.parametrize(
    ('section', 'key', 'value'),
    [
        ('chassis', 'mass', -1.0),
        ('chassis', 'mass', 'heavy'),
        ('chassis', 'cg_to_front_axle', 3.0),
        ('wheel', 'effective_radius', 0.0),
        ('aero', 'air_density', float('nan')),
        ('rolling_resistance', 'regularisation_speed', 'fast'),
    ],
)
def test_invalid_values_are_rejected(
    tmp_path: Path, section: str, key: str, value: object
) -> None:
    data = yaml.safe_load(VEHICLE_FILE.read_text(encoding='utf-8'))
    data[section][key] = value
    with pytest.raises(VehicleParameterError):
        load_estimator_vehicle(_write(tmp_path, data))


def test_unreadable_file(tmp_path: Path) -> None:
    with pytest.raises(VehicleParameterError):
        load_estimator_vehicle(tmp_path / 'absent.yaml')
    bad = tmp_path / 'bad.yaml'
    bad.write_text('chassis: [1, 2', encoding='utf-8')
    with pytest.raises(VehicleParameterError):
        load_estimator_vehicle(bad)


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
