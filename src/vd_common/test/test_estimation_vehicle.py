"""The vehicle file as the estimators read it: only their keys, the simulator's optional."""

from __future__ import annotations

import copy
import re
from pathlib import Path
from typing import Any

import pytest
import yaml
from vd_common.errors import ParameterError
from vd_common.vehicle.estimation import load_estimation_vehicle, parse_estimation_vehicle
from vd_common.vehicle.params import default_vehicle_file, load_vehicle

#: what the estimators use, and nothing of the simulator's
MINIMAL: dict[str, Any] = {
    'name': 'estimation only',
    'chassis': {'mass': 1650.0, 'wheelbase': 2.66, 'cg_to_front_axle': 1.1, 'cg_height': 0.6},
    'wheel': {'inertia_front': 1.4, 'inertia_rear': 1.3, 'effective_radius': 0.345},
    'aero': {'drag_coefficient': 0.33, 'frontal_area': 2.6, 'air_density': 1.2},
    'rolling_resistance': {'c0': 0.011, 'c1': 3.6},
    'environment': {'gravity': 9.81},
}
# environment.gravity has a default (test_vehicle_keys.py)
REQUIRED = [
    ('chassis', 'mass'), ('chassis', 'wheelbase'), ('chassis', 'cg_to_front_axle'),
    ('chassis', 'cg_height'), ('wheel', 'inertia_front'), ('wheel', 'inertia_rear'),
    ('wheel', 'effective_radius'), ('aero', 'drag_coefficient'), ('rolling_resistance', 'c0'),
]  # fmt: skip


def test_the_simulators_file_reads_to_the_same_numbers() -> None:
    full = load_vehicle(default_vehicle_file())
    est = load_estimation_vehicle(default_vehicle_file())
    assert est.source == str(default_vehicle_file()) and est.name == full.name
    assert (est.chassis.mass, est.chassis.wheelbase) == (full.chassis.mass, full.chassis.wheelbase)
    assert est.chassis.cg_to_front_axle == full.chassis.cg_to_front_axle
    assert est.wheel.effective_radius == full.wheel.effective_radius
    assert (est.aero, est.rolling_resistance, est.environment) == (
        full.aero,
        full.rolling_resistance,
        full.environment,
    )
    assert est.tire == full.tire
    line = est.require_driveline()
    assert line.ratios == tuple(full.gearbox.ratios)
    assert (line.final_drive, line.engine_inertia) == (
        full.gearbox.final_drive,
        full.engine.inertia,
    )


def test_a_file_with_only_the_estimators_keys_is_enough(tmp_path: Path) -> None:
    path = tmp_path / 'car.yaml'
    path.write_text(yaml.safe_dump(MINIMAL), encoding='utf-8')
    est = load_estimation_vehicle(path)
    assert est.chassis.mass == 1650.0 and est.wheel.effective_radius == 0.345
    assert est.tire is None and est.driveline is None
    with pytest.raises(ParameterError, match=rf'^vehicle file {re.escape(str(path))}: tire is'):
        est.require_tire()
    with pytest.raises(ParameterError, match=rf'^vehicle file {re.escape(str(path))}: gearbox'):
        est.require_driveline()
    with pytest.raises(ParameterError, match=r'engine is missing'):
        load_vehicle(path)  # the simulator still wants its sections


@pytest.mark.parametrize(('section', 'key'), REQUIRED)
def test_a_missing_key_is_refused_in_one_line_naming_it(
    tmp_path: Path, section: str, key: str
) -> None:
    data = copy.deepcopy(MINIMAL)
    del data[section][key]
    path = tmp_path / 'car.yaml'
    path.write_text(yaml.safe_dump(data), encoding='utf-8')
    with pytest.raises(ParameterError) as info:
        load_estimation_vehicle(path)
    message = str(info.value)
    assert '\n' not in message and f'{section}.{key}' in message and str(path) in message


def test_a_gearbox_needs_the_engine_inertia_and_its_ratios() -> None:
    data = copy.deepcopy(MINIMAL)
    data['gearbox'] = {'ratios': [3.3, 1.9, 1.42, 1.0, 0.713, 0.608], 'final_drive': 3.8}
    with pytest.raises(ParameterError, match=r'engine\.inertia'):
        parse_estimation_vehicle(data)
    data['engine'] = {'inertia': 0.2}
    line = parse_estimation_vehicle(data).require_driveline()
    assert line.ratios[0] == 3.3 and line.engine_inertia == 0.2
    data['gearbox'] = {'ratios': [3.3, -1.0], 'final_drive': 3.8}
    with pytest.raises(ParameterError, match=r'gearbox\.ratios'):
        parse_estimation_vehicle(data)
