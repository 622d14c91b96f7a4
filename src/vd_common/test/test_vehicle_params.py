"""Parameter loader: the shipped file loads, every bad value is refused with its name."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st
from vd_common.errors import ParameterError
from vd_common.vehicle import params as params_module
from vd_common.vehicle.params import default_vehicle_file, load_vehicle, parse_vehicle

CONFIG = Path(__file__).resolve().parents[1] / 'config' / 'clio_rl_1_1.yaml'
RAW: dict[str, Any] = yaml.safe_load(CONFIG.read_text())


def _leaf_paths(d: dict[str, Any], prefix: str = '') -> list[str]:
    out = []
    for k, v in d.items():
        path = f'{prefix}.{k}' if prefix else k
        if isinstance(v, dict):
            out += _leaf_paths(v, path)
        else:
            out.append(path)
    return out


def _set(d: dict[str, Any], path: str, value: Any) -> dict[str, Any]:
    d = copy.deepcopy(d)
    node = d
    keys = path.split('.')
    for k in keys[:-1]:
        node = node[k]
    if value is _DELETE:
        del node[keys[-1]]
    else:
        node[keys[-1]] = value
    return d


_DELETE = object()
# Keys that may be absent (defaults exist) or are free text.
_OPTIONAL = {
    'name',
    'environment.gravity',
    'rolling_resistance.regularisation_speed',
    'tire.pHx1',
    'tire.pHx2',
    'tire.pVx1',
    'tire.pVx2',
}
REQUIRED = [p for p in _leaf_paths(RAW) if p not in _OPTIONAL]


def eval_path(path: str) -> Any:
    node: Any = RAW
    for k in path.split('.'):
        node = node[k]
    return node


def test_shipped_file_loads_with_published_values() -> None:
    vp = load_vehicle(CONFIG)
    assert vp.chassis.mass == pytest.approx(905.0)
    assert vp.chassis.wheelbase == pytest.approx(2.472)
    assert vp.aero.drag_coefficient == pytest.approx(0.33)
    assert vp.aero.frontal_area == pytest.approx(1.85)
    assert len(vp.gearbox.ratios) == 5
    # 145/70 R13: 13 in rim / 2 + 70 % of 145 mm.
    assert vp.wheel.unloaded_radius == pytest.approx(13 * 0.0254 / 2 + 0.7 * 0.145, abs=1e-3)


def test_negative_mass_message_names_parameter_and_value() -> None:
    with pytest.raises(ParameterError, match=r'^chassis\.mass must be > 0 kg, got -3$'):
        parse_vehicle(_set(RAW, 'chassis.mass', -3))


@pytest.mark.parametrize('path', REQUIRED)
def test_every_required_key_missing_is_named(path: str) -> None:
    with pytest.raises(ParameterError) as info:
        parse_vehicle(_set(RAW, path, _DELETE))
    assert path in str(info.value)


@settings(max_examples=40, deadline=None)
@given(
    path=st.sampled_from([p for p in REQUIRED if not isinstance(eval_path(p), list)]),
    bad=st.sampled_from(['text', True, None, float('nan'), float('inf')]),
)
def test_non_numbers_are_refused_by_name(path: str, bad: Any) -> None:
    with pytest.raises(ParameterError) as info:
        parse_vehicle(_set(RAW, path, bad))
    assert path in str(info.value)


def test_cg_outside_wheelbase_is_refused() -> None:
    with pytest.raises(ParameterError, match=r'chassis\.cg_to_front_axle'):
        parse_vehicle(_set(RAW, 'chassis.cg_to_front_axle', 3.0))


def test_gear_ratios_must_decrease() -> None:
    with pytest.raises(ParameterError, match=r'gearbox\.ratios must be strictly decreasing'):
        parse_vehicle(_set(RAW, 'gearbox.ratios', [3.0, 3.5, 1.0]))


def test_full_load_curve_lengths_must_match() -> None:
    with pytest.raises(ParameterError, match=r'engine\.full_load_torque has 2 entries'):
        parse_vehicle(_set(RAW, 'engine.full_load_torque', [50.0, 60.0]))


def test_shift_hysteresis_is_checked() -> None:
    # Downshift threshold above the speed an upshift lands at would make the logic hunt.
    with pytest.raises(ParameterError, match=r'gearbox\.downshift_speed'):
        parse_vehicle(_set(RAW, 'gearbox.downshift_speed', 290.0))


def test_unsprung_heavier_than_car_is_refused() -> None:
    with pytest.raises(ParameterError, match=r'chassis\.unsprung_mass'):
        parse_vehicle(_set(RAW, 'chassis.unsprung_mass_front', 500.0))


def test_unreadable_file_is_a_parameter_error(tmp_path: Path) -> None:
    with pytest.raises(ParameterError, match=r'^cannot read vehicle file .*missing\.yaml'):
        load_vehicle(tmp_path / 'missing.yaml')
    bad = tmp_path / 'bad.yaml'
    bad.write_text('chassis: [1, 2\n')
    malformed = r'^vehicle file .*bad\.yaml is not valid YAML'
    with pytest.raises(ParameterError, match=malformed) as info:
        load_vehicle(bad)
    # A node refusing to start prints the message as its one error line.
    assert '\n' not in str(info.value)


def test_file_errors_name_the_file_and_the_key(tmp_path: Path) -> None:
    path = tmp_path / 'neg.yaml'
    path.write_text(yaml.safe_dump(_set(RAW, 'chassis.mass', -1200.0)))
    with pytest.raises(ParameterError) as info:
        load_vehicle(path)
    assert str(info.value) == f'vehicle file {path}: chassis.mass must be > 0 kg, got -1200.0'


def test_default_vehicle_file_is_the_shipped_clio() -> None:
    path = default_vehicle_file()
    assert path.name == 'clio_rl_1_1.yaml'
    assert load_vehicle(path).name == 'Renault Clio RL 1.1'


def test_default_vehicle_file_without_ros_is_the_source_tree(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import ament_index_python.packages as ament

    def not_installed(package: str) -> str:
        raise LookupError(package)

    monkeypatch.setattr(ament, 'get_package_share_directory', not_installed)
    assert default_vehicle_file() == CONFIG.resolve()
    # Neither copy found: the parser's own error, naming the file.
    monkeypatch.setattr(params_module, '_CLIO_FILE', 'absent.yaml')
    with pytest.raises(ParameterError, match=r'absent\.yaml not found'):
        default_vehicle_file()
