"""Vehicle files are checked as strictly as input mappings: an unknown key is refused, naming
the closest known one, by both parsers (simulator and estimators) from one schema."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import pytest
import yaml
from vd_common.errors import ParameterError
from vd_common.vehicle.estimation import load_estimation_vehicle, parse_estimation_vehicle
from vd_common.vehicle.params import (
    DEFAULT_GRAVITY,
    VEHICLE_FILE_KEYS,
    load_vehicle,
    parse_vehicle,
)
from vd_common.yaml_reader import check_known_keys

CONFIG = Path(__file__).resolve().parents[1] / 'config'
CLIO: dict[str, Any] = yaml.safe_load((CONFIG / 'clio_rl_1_1.yaml').read_text())
RAV4: dict[str, Any] = yaml.safe_load((CONFIG / 'toyota_rav4_2017_estimation.yaml').read_text())
PARSERS = [parse_vehicle, parse_estimation_vehicle]


def _with(data: dict[str, Any], section: str, key: str, value: Any) -> dict[str, Any]:
    out = copy.deepcopy(data)
    out.setdefault(section, {})[key] = value
    return out


@pytest.mark.parametrize('path', sorted(CONFIG.glob('*.yaml')), ids=lambda p: p.name)
def test_every_shipped_file_passes_the_estimators_key_check(path: Path) -> None:
    assert load_estimation_vehicle(path).chassis.mass > 0.0


def test_the_simulators_file_passes_both_parsers() -> None:
    full = load_vehicle(CONFIG / 'clio_rl_1_1.yaml')
    est = load_estimation_vehicle(CONFIG / 'clio_rl_1_1.yaml')
    assert full.chassis.mass == est.chassis.mass == 905.0


def test_an_estimation_only_file_is_refused_by_the_simulator_for_what_it_lacks() -> None:
    # its keys are all known: the simulator names a section it needs, not a key it does not know
    with pytest.raises(ParameterError, match=r'^engine\.full_load_speed is missing$'):
        parse_vehicle(RAV4)


@pytest.mark.parametrize('parse', PARSERS, ids=lambda f: f.__name__)
def test_a_misspelt_brake_gain_names_the_known_key(parse: Any) -> None:
    data = _with(CLIO, 'brakes', 'gain_frnt', 30.0)
    with pytest.raises(ParameterError) as info:
        parse(data)
    assert (
        str(info.value) == 'brakes.gain_frnt is not a known key; did you mean brakes.gain_front?'
    )


@pytest.mark.parametrize('parse', PARSERS, ids=lambda f: f.__name__)
def test_a_misspelt_required_key_is_named_not_reported_missing(parse: Any) -> None:
    data = copy.deepcopy(CLIO)
    data['chassis']['mas'] = data['chassis'].pop('mass')
    with pytest.raises(ParameterError) as info:
        parse(data)
    assert str(info.value) == 'chassis.mas is not a known key; did you mean chassis.mass?'


def test_an_unknown_section_without_a_close_match_lists_the_known_ones(tmp_path: Path) -> None:
    path = tmp_path / 'car.yaml'
    path.write_text(yaml.safe_dump({**RAV4, 'hvac': {'power': 3.0}}), encoding='utf-8')
    with pytest.raises(ParameterError) as info:
        load_estimation_vehicle(path)
    message = str(info.value)
    assert message.startswith(f'vehicle file {path}: hvac is not a known key; known keys: ')
    assert 'chassis, ' in message and '\n' not in message


def test_a_misspelt_section_is_named_with_the_section() -> None:
    data = copy.deepcopy(RAV4)
    data['torque_convertor'] = data.pop('torque_converter')
    with pytest.raises(
        ParameterError,
        match=r'^torque_convertor is not a known key; did you mean torque_converter\?$',
    ):
        parse_estimation_vehicle(data)


def test_an_estimation_key_in_a_simulator_file_is_known_to_both() -> None:
    data = _with(CLIO, 'gearbox', 'efficiency', 0.95)
    data = _with(data, 'brakes', 'gain_front', 30.0)
    data = _with(data, 'brakes', 'gain_rear', 12.0)
    assert parse_vehicle(data).gearbox.final_drive == CLIO['gearbox']['final_drive']
    brakes = parse_estimation_vehicle(data).brakes
    assert brakes is not None and (brakes.gain_front, brakes.gain_rear) == (30.0, 12.0)


@pytest.mark.parametrize('parse', PARSERS, ids=lambda f: f.__name__)
def test_gravity_defaults_to_9_81_and_is_still_checked(parse: Any) -> None:
    assert DEFAULT_GRAVITY == 9.81
    no_gravity = copy.deepcopy(CLIO)
    del no_gravity['environment']['gravity']
    assert parse(no_gravity).environment.gravity == 9.81
    del no_gravity['environment']
    assert parse(no_gravity).environment.gravity == 9.81
    assert parse(_with(CLIO, 'environment', 'gravity', 9.79)).environment.gravity == 9.79
    with pytest.raises(ParameterError, match=r'^environment\.gravity must be > 0'):
        parse(_with(CLIO, 'environment', 'gravity', -9.81))


def test_a_value_that_is_not_a_mapping_is_left_to_the_typed_reader() -> None:
    data = copy.deepcopy(RAV4)
    data['chassis'] = [1660.0]
    with pytest.raises(ParameterError, match=r'^chassis must be a mapping, got list$'):
        parse_estimation_vehicle(data)


def test_the_schema_check_walks_nested_mappings() -> None:
    schema = {'a': {'b': {'c': None}}, 'd': None}
    check_known_keys({'a': {'b': {'c': 1}}, 'd': [1, 2]}, schema, ValueError)
    with pytest.raises(ValueError, match=r'^a\.b\.cc is not a known key; did you mean a\.b\.c\?$'):
        check_known_keys({'a': {'b': {'cc': 1}}}, schema, ValueError)
    with pytest.raises(ValueError, match=r'^1 is not a known key'):
        check_known_keys({1: 2}, schema, ValueError)
    assert set(VEHICLE_FILE_KEYS) >= set(CLIO) | set(RAV4)
