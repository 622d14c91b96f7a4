"""`vd report` on a car's bag without a reference, as a user runs it on day one: standard
types (ABS wheel speeds as JointState, Odometry, a headerless Float64MultiArray torque), a
mapping and a vehicle file, no /vd/truth/* topic. It must replay the bag and write an
estimates-only report, having said so before the replay."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from vd_common.topics import NAMESPACE
from vd_common.vehicle.params import load_vehicle
from vd_observer_node.bag import BagReader
from vd_observer_node.testing.standard_bags import CarSensors, write_standard_bag
from vd_observer_node.tools.cli import main
from vd_sim_node.vehicle.scenario import load_scenario
from vd_sim_node.vehicle.simulation import simulate

ROOT = Path(__file__).resolve().parents[1]
MAPPING = ROOT / 'src' / 'vd_observer_node' / 'config' / 'input_mapping_abs_example.yaml'
VEHICLE = ROOT / 'src' / 'vd_common' / 'config' / 'clio_rl_1_1.yaml'
SCENARIO = ROOT / 'src' / 'vd_sim_node' / 'config' / 'scenarios' / 'paper_table1.yaml'


def test_a_mapped_bag_without_reference_gives_an_estimates_only_report(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scenario = load_scenario(SCENARIO)
    # 0 deg to 10 s, 5 deg to 20 s, 10 deg to 24 s (the car drives from 8 s)
    short = dataclasses.replace(scenario, duration=24.0)
    sim = simulate(load_vehicle(VEHICLE), short)
    bag = tmp_path / 'car'
    write_standard_bag(bag, sim, CarSensors(seed=11))
    assert not any(t.startswith(NAMESPACE) for t in BagReader(bag).topics)  # a car's own
    out = tmp_path / 'report'
    argv = ['report', str(bag), '--mapping', str(MAPPING), '--vehicle', str(VEHICLE)]
    assert main([*argv, '--out', str(out), '--no-progress']) == 0
    printed = capsys.readouterr().out.splitlines()
    # told before the replay, not after it
    assert 'has no reference' in printed[0] and 'estimates-only' in printed[0]
    assert 'replayed it with' in printed[1]
    data = json.loads((out / 'metrics.json').read_text())
    assert data['reference'] == 'none' and data['quantities'] == [] and data['targets'] == {}
    stats = {e['key']: e for e in data['estimates']}
    assert {'omega', 'fx', 'fz', 'mu', 'slope'} <= set(stats)
    slope = stats['slope']['overall']
    assert slope['samples'] > 1000 and 30.0 < slope['valid_pct'] < 90.0  # standstill invalid
    # the estimate's own range follows the road's 0 / 5 / 10 deg (no reference is needed to
    # see that; the accuracy itself is what the report cannot give here)
    assert slope['minimum'] < 1.5 and 8.0 < slope['maximum'] < 13.0
    valid_mean = slope['mean']
    t = np.asarray(sim.t)
    moving = (t > 8.5) & (np.abs(t - 10.0) > 1.0) & (np.abs(t - 20.0) > 1.0)
    assert abs(valid_mean - float(np.degrees(np.mean(sim.slope[moving])))) < 1.5
    md = (out / 'metrics.md').read_text()
    assert 'This bag has no reference' in md and 'Estimate vs' not in md
    assert 'Targets' not in md and 'MISSED' not in md
    assert {'slope.png', 'friction_mu.png', 'summary.png'} <= {p.name for p in out.iterdir()}
