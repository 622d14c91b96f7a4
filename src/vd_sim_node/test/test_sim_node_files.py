"""The simulator node finds its files: scenarios by name, the vehicle file by path or name.

The default vehicle file moved to vd_common (share/vd_common/config); a name given as the
``vehicle_file`` parameter is still found, in vd_sim_node's config/ first, then vd_common's.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from vd_common.vehicle.params import default_vehicle_file
from vd_sim_node.errors import ScenarioError
from vd_sim_node.sim_node import resolve_config_file

VEHICLE_PACKAGES = ('vd_sim_node', 'vd_common')


def test_the_vehicle_file_is_found_by_its_installed_name() -> None:
    found = resolve_config_file('clio_rl_1_1.yaml', '', '', packages=VEHICLE_PACKAGES)
    assert found.name == 'clio_rl_1_1.yaml'
    assert found.parent.parent.name == 'vd_common'  # share/vd_common/config
    assert found.read_bytes() == default_vehicle_file().read_bytes()
    stem = resolve_config_file('clio_rl_1_1', '', '', packages=VEHICLE_PACKAGES)
    assert stem == found


def test_a_path_is_taken_as_it_is(tmp_path: Path) -> None:
    mine = tmp_path / 'my_car.yaml'
    mine.write_text('name: mine\n', encoding='utf-8')
    assert resolve_config_file(str(mine), '', '', packages=VEHICLE_PACKAGES) == mine


def test_scenarios_are_found_by_name_and_a_missing_one_is_refused() -> None:
    found = resolve_config_file('paper_table1', 'scenarios', 'paper_table1')
    assert found.name == 'paper_table1.yaml' and found.parent.name == 'scenarios'
    with pytest.raises(ScenarioError, match="scenarios file 'absent' not found; installed: "):
        resolve_config_file('absent', 'scenarios', 'paper_table1')
    with pytest.raises(ScenarioError, match=r"config file 'absent\.yaml' not found"):
        resolve_config_file('absent.yaml', '', '', packages=VEHICLE_PACKAGES)
