"""`vd fleet` on a car's bag whose reference runs on its own clock, as `vd report` sees it:
standard types read with a mapping, a grade reference at 10 Hz on /vd/truth/slope, 3.3 ms
off every sensor stamp. The fleet once paired it by stamp only and showed no accuracy; it
must give `vd report`'s figure, from the same code, and never judge the simulator's targets."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from vd_common.topics import TRUTH_SLOPE
from vd_common.vehicle.params import load_vehicle
from vd_observer_node.bag import BagReader
from vd_observer_node.bag.cdr_batch import encode_batch
from vd_observer_node.bag.writer import BagWriter
from vd_observer_node.testing.standard_bags import CarSensors, write_standard_bag
from vd_observer_node.tools.cli import main
from vd_observer_node.tools.fleet import FleetSettings, process_bag
from vd_sim_node.vehicle.scenario import load_scenario
from vd_sim_node.vehicle.simulation import simulate

ROOT = Path(__file__).resolve().parents[1]
MAPPING = ROOT / 'src' / 'vd_observer_node' / 'config' / 'input_mapping_abs_example.yaml'
VEHICLE = ROOT / 'src' / 'vd_common' / 'config' / 'clio_rl_1_1.yaml'
SCENARIO = ROOT / 'src' / 'vd_sim_node' / 'config' / 'scenarios' / 'paper_table1.yaml'
SLOPE_TYPE = 'vd_msgs/msg/Slope'


def _car_bag_with_reference(tmp_path: Path) -> Path:
    scenario = load_scenario(SCENARIO)
    sim = simulate(load_vehicle(VEHICLE), dataclasses.replace(scenario, duration=24.0))
    raw = tmp_path / 'raw'
    write_standard_bag(raw, sim, CarSensors(seed=7))
    t_ref = np.arange(0.0, 24.0, 0.1) + 0.0033  # the reference's own clock
    stamp = np.round(t_ref * 1e9).astype(np.int64)
    grade = np.interp(t_ref, np.asarray(sim.t), np.asarray(sim.slope))
    datas = encode_batch(
        SLOPE_TYPE,
        stamp,
        'base_link',
        {
            'angle': grade,
            'valid': np.ones(stamp.size, bool),
            'torque_source': np.zeros(stamp.size, np.uint8),
            'sources': np.zeros(stamp.size, np.uint8),
        },
    )
    reader = BagReader(raw)
    bag = tmp_path / 'car'
    with BagWriter(bag) as writer:
        for name, info in reader.topics.items():
            writer.add_topic(name, info.msgtype)
        for message in reader.raw_messages(ordered=True):
            writer.write(message.topic, message.data, message.log_time_ns)
        writer.add_topic(TRUTH_SLOPE, SLOPE_TYPE)
        writer.write_batch(TRUTH_SLOPE, datas, stamp.tolist())
    return bag


def test_fleet_gives_vd_reports_figure_on_a_reference_on_its_own_clock(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = _car_bag_with_reference(tmp_path)
    settings = FleetSettings(mapping_file=str(MAPPING), vehicle_file=str(VEHICLE))
    row = process_bag(str(bag), settings)['row']
    assert row['status'] == 'ok', row['error']
    out = tmp_path / 'report'
    argv = ['report', str(bag), '--mapping', str(MAPPING), '--vehicle', str(VEHICLE)]
    assert main([*argv, '--out', str(out), '--no-figures', '--no-progress']) == 0
    capsys.readouterr()
    data = json.loads((out / 'metrics.json').read_text())
    slope = next(q for q in data['quantities'] if q['key'] == 'slope')['overall']
    assert slope['samples'] > 500  # interpolated onto the estimates, none shares a stamp
    assert row['has_truth'] is True
    assert row['slope_rms_deg'] == pytest.approx(slope['rms'], rel=1e-8)
    assert row['slope_rms_deg'] < 1.0  # 0.39 deg measured: a slope, not noise (0-10 deg road)
    assert row['targets_met'] is None and data['targets'] == {}
    assert data['reference'] == 'reference'
