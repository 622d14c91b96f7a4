"""Issue 15's example: a car's standard-types recording replayed with the shipped files."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
from vd_common.topics import ESTIMATES_SLOPE
from vd_common.vehicle.params import load_vehicle
from vd_observer_node.bag import BagReader
from vd_observer_node.bag.cdr_batch import decode_batch
from vd_observer_node.estimation.rate_settings import slope_filter_tau_for_rate
from vd_observer_node.inputs.mapping import load_input_mapping, mapping_from_dict
from vd_observer_node.testing.devbag import sim_topics, write_topic_arrays_bag
from vd_observer_node.testing.standard_bags import (
    STANDARD_MAPPING,
    CarSensors,
    abs_wheel_speeds,
    write_standard_bag,
)
from vd_observer_node.tools.replay import ESTIMATE_TOPICS, replay_bag
from vd_observer_node.tools.settings_file import load_settings_file
from vd_sim_node.vehicle.scenario import load_scenario
from vd_sim_node.vehicle.simulation import simulate

CONFIG = Path(__file__).resolve().parents[1] / 'config'
SIM_CONFIG = Path(__file__).resolve().parents[2] / 'vd_sim_node' / 'config'
MAPPING_FILE = CONFIG / 'input_mapping_abs_example.yaml'
REPLAY_FILE = CONFIG / 'replay_100hz_example.yaml'


def test_the_shipped_abs_mapping_is_the_example_bags_mapping() -> None:
    shipped = load_input_mapping(MAPPING_FILE)
    assert dataclasses.replace(shipped, source='') == mapping_from_dict(STANDARD_MAPPING, '')
    assert shipped.wheel_input == 'speed' and shipped.alignment == 'latest'


def test_abs_speed_is_the_mean_over_the_period() -> None:
    t = np.linspace(0.0, 1.0, 1001)
    angle = np.stack([3.0 * t**2, 2.0 * t, -t, t**3], axis=1)
    got = abs_wheel_speeds(t, angle, np.array([0.5, 1.0]), 0.1)
    mean = (angle[[500, 1000]] - angle[[400, 900]]) / 0.1
    np.testing.assert_allclose(got, mean, rtol=1e-12, atol=1e-12)


def _slope_rms_deg(bag: Path, sim: object) -> tuple[float, int]:
    reader = BagReader(bag)
    datas = reader.topic_arrays([ESTIMATES_SLOPE])[ESTIMATES_SLOPE].datas
    fields = decode_batch(ESTIMATE_TOPICS[ESTIMATES_SLOPE], datas)
    t = fields.stamp_ns * 1e-9
    keep = (t > 2.0) & (np.abs(t - 10.0) > 0.5) & (np.abs(t - 20.0) > 0.5)  # slope steps
    truth = np.interp(t, sim.t, sim.slope)  # type: ignore[attr-defined]
    error = (fields.values['angle'] - truth)[keep]
    assert np.all(np.isfinite(fields.values['angle']))
    return float(np.degrees(np.sqrt(np.mean(error**2)))), int(t.size)


def test_a_standard_types_bag_replays_with_the_shipped_files_near_vds_own(tmp_path: Path) -> None:
    scenario = load_scenario(SIM_CONFIG / 'scenarios' / 'paper_table1.yaml')
    sensors = dataclasses.replace(
        scenario.sensors, encoder_counts_per_rev=96, speed_noise_std=0.05
    )
    short = dataclasses.replace(scenario, duration=30.0, sensors=sensors)
    sim = simulate(
        load_vehicle(SIM_CONFIG.parents[1] / 'vd_common' / 'config' / 'clio_rl_1_1.yaml'), short
    )
    stamp_ns = np.round(sim.t * 1e9).astype(np.int64)
    write_topic_arrays_bag(tmp_path / 'vd', stamp_ns, sim_topics(sim, truth=False))
    write_standard_bag(tmp_path / 'car', sim, CarSensors(seed=5))
    report_mapping = load_input_mapping(MAPPING_FILE)
    settings = load_settings_file(REPLAY_FILE).settings(report_mapping)
    replay_bag(tmp_path / 'vd', tmp_path / 'vd_out', progress=False)
    report = replay_bag(
        tmp_path / 'car', tmp_path / 'car_out', settings, mapping=report_mapping, progress=False
    )
    assert report.stale <= 2  # the first wheel stamps, before the first odometry
    ours, n_ours = _slope_rms_deg(tmp_path / 'vd_out', sim)
    theirs, n_theirs = _slope_rms_deg(tmp_path / 'car_out', sim)
    assert n_ours == 30001 and abs(n_theirs - 2999) <= 3
    # 150 s: 0.17 deg on vd's topics, 0.23 deg on the standard bag (docs/estimation.md 2.4)
    assert ours < 0.3
    assert theirs < 1.5 * max(ours, 0.2)
    # Without the settings file the slope filter follows the measured rate: the odometry's
    # 50 Hz, the slower of wheels (100 Hz) and speed; issue 26's target is 1.15x the file.
    plain = replay_bag(
        tmp_path / 'car', tmp_path / 'plain_out', progress=False, mapping=report_mapping
    )
    assert abs(plain.input_rate_hz - 50.0) < 0.5
    assert plain.rate_settings == {'slope_filter_tau': slope_filter_tau_for_rate(50.0)}
    assert report.rate_settings == {}  # the file sets it
    default, _ = _slope_rms_deg(tmp_path / 'plain_out', sim)
    assert default <= 1.15 * theirs
