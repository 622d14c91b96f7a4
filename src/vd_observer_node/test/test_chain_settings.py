"""One way to build the settings (`situation.chain_settings`): from node parameters, a settings
file and the mapping, each value where its class reads it; settings for another mapping are
refused."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
import yaml
from vd_common.vehicle.params import default_vehicle_file
from vd_observer_node.errors import ConfigurationError
from vd_observer_node.estimation.drivetrain import MAX_GEARS, Drivetrain
from vd_observer_node.estimation.estimator import EstimatorConfig
from vd_observer_node.estimation.observer import ObserverConfig
from vd_observer_node.estimation.vehicle import load_vehicle_params
from vd_observer_node.inputs.mapping import (
    default_mapping,
    load_input_mapping,
    mapping_from_dict,
)
from vd_observer_node.situation.alerts import AlertConfig
from vd_observer_node.situation.chain_settings import (
    SETTINGS_SECTIONS,
    chain_settings,
    check_settings_fit,
    parameter_sections,
)
from vd_observer_node.situation.friction_potential import FrictionPotentialConfig
from vd_observer_node.situation.monitor import SituationConfig

CONFIG = Path(__file__).resolve().parents[1] / 'config'
#: a brake switch, as the RAV4's mapping reads it
BRAKE = {
    'brake': {
        'topic': '/can/brake',
        'type': 'std_msgs/msg/Float64MultiArray',
        'signal': 'switch',
        'indices': [0],
    }
}


def test_node_parameters_reach_the_class_that_reads_them() -> None:
    values = {
        'speed_lipschitz': 55.0,
        'l0': 1.2,
        'slope_filter_tau': 0.3,
        'mass.mass_tau': 40.0,
        'speed_source': 'observer',
        'alert_wheel_lipschitz': 9000.0,
        'forgetting_time': 7.0,
        'traction.warning_on': 0.2,
    }
    sections = parameter_sections(values)
    assert set(sections) == set(SETTINGS_SECTIONS)
    built = chain_settings(None, None, sections)
    # each against the class's own reading of its keys (not the sections it was given)
    assert built.observer == ObserverConfig.from_mapping({'speed_lipschitz': 55.0, 'l0': 1.2})
    assert built.estimator == EstimatorConfig.from_mapping(
        {'slope_filter_tau': 0.3, 'mass.mass_tau': 40.0}
    )
    assert built.estimator_speed == 'observer'
    assert built.situation == SituationConfig(alert_wheel_lipschitz=9000.0)
    assert built.friction == FrictionPotentialConfig.from_mapping({'forgetting_time': 7.0})
    assert built.alerts == AlertConfig.from_mapping({'traction.warning_on': 0.2})
    assert built.alerts != AlertConfig()
    # the shipped file: the Clio, its tyre, the monitor on
    assert built.curves is not None and built.situation_off is None
    assert built.vehicle_label.endswith(f'({default_vehicle_file()})')


def test_a_key_of_no_class_is_refused() -> None:
    with pytest.raises(ConfigurationError, match='no_such_setting'):
        chain_settings(None, None, parameter_sections({'no_such_setting': 1.0}))
    with pytest.raises(ConfigurationError, match='imu_config'):
        chain_settings(None, None, {'cascade': {'imu_config': 1.0}})
    with pytest.raises(ConfigurationError, match='section'):
        chain_settings(None, None, {'cascad': {}})


def test_the_mapping_says_what_the_sensors_are(tmp_path: Path) -> None:
    speeds = load_input_mapping(CONFIG / 'input_mapping_abs_example.yaml')
    # the mapping's wheel speeds win over a section that says angles
    built = chain_settings(speeds, None, {'observer': {'wheel_input': 'angle'}})
    assert speeds.wheel_input == 'speed' and built.observer.wheel_input == 'speed'
    engine = chain_settings(dataclasses.replace(default_mapping(), torque_source='engine'))
    assert engine.drivetrain == Drivetrain.from_params(load_vehicle_params(None))
    assert chain_settings().drivetrain is None
    braked = mapping_from_dict(BRAKE)
    assert chain_settings(braked).brakes is not None
    imu = load_input_mapping(CONFIG / 'input_mapping_sim_imu.yaml')
    assert chain_settings(imu).imu is not None and chain_settings().imu is None
    # an estimation-only file: no tyre, the monitor off and why
    full = yaml.safe_load(default_vehicle_file().read_text())
    only = {k: full[k] for k in ('name', 'chassis', 'wheel', 'aero', 'rolling_resistance',
                                 'environment')}  # fmt: skip
    path = tmp_path / 'estimation_only.yaml'
    path.write_text(yaml.safe_dump(only), encoding='utf-8')
    bare = chain_settings(None, path)
    assert bare.curves is None and bare.situation_off is not None
    assert str(path) in bare.situation_off


@pytest.mark.parametrize(
    ('change', 'field'),
    [
        ({'torque_source': 'none'}, 'torque_source'),
        ({'wheel_input': 'speed'}, 'wheel_input'),
        ({'imu': True}, 'imu'),
        ({'brake': True}, 'brakes'),
    ],
)
def test_settings_for_other_sensors_are_refused(change: dict[str, object], field: str) -> None:
    settings = chain_settings()
    check_settings_fit(settings, default_mapping())  # made for it: fits
    mapping = default_mapping()
    if 'torque_source' in change:
        mapping = dataclasses.replace(mapping, torque_source='none')
    if 'wheel_input' in change:
        mapping = load_input_mapping(CONFIG / 'input_mapping_abs_example.yaml')
    if 'imu' in change:
        mapping = load_input_mapping(CONFIG / 'input_mapping_sim_imu.yaml')
    if 'brake' in change:
        mapping = mapping_from_dict(BRAKE)
    with pytest.raises(ConfigurationError, match=field):
        check_settings_fit(settings, mapping)
    check_settings_fit(chain_settings(mapping), mapping)


def test_a_gearbox_beyond_the_record_is_refused() -> None:
    with pytest.raises(ConfigurationError, match='forward gears'):
        Drivetrain(ratios=(3.0,) * (MAX_GEARS + 1), final_drive=4.0, reverse_ratio=3.0)
    line = Drivetrain(ratios=(3.0, 2.0), final_drive=4.0, reverse_ratio=3.5)
    p = line.params()[0]
    assert p['gears'] == 2 and tuple(p['ratios'][:2]) == (3.0, 2.0)
    assert p['final_drive'] == 4.0 and p['reverse_ratio'] == 3.5
