"""`vd report` on a real (short) simulator run: the bag round trip changes no number.

Simulates the paper scenario for 12 s (launch at 8 s, 1->2 upshift, slope step at 10 s),
runs the estimator cascade on the sensors, writes sensors + truth + estimates to a bag and
checks that the report finds the simulator's own events and reproduces metrics computed
directly on the arrays.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from vd_observer_node.testing.devbag import cascade_topics, sim_topics, write_topic_arrays_bag
from vd_observer_node.tools.report.evaluation import evaluate
from vd_observer_node.tools.report.load import load_bag_series
from vd_observer_node.tools.report.metrics import error_stats, evaluation_mask

ROOT = Path(__file__).resolve().parents[3]
VEHICLE = ROOT / 'src' / 'vd_common' / 'config' / 'clio_rl_1_1.yaml'
SCENARIO = ROOT / 'src' / 'vd_sim_node' / 'config' / 'scenarios' / 'paper_table1.yaml'
RATE = 500.0  # [Hz] lower than the demo's 1 kHz to keep the cascade short


@pytest.fixture(scope='module')
def run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Any, Any, Path]:
    from vd_common.vehicle.params import load_vehicle
    from vd_observer_node.estimation.cascade import CascadeSeries, CascadeSettings, run_cascade
    from vd_observer_node.estimation.vehicle import load_estimator_vehicle
    from vd_sim_node.vehicle.scenario import load_scenario
    from vd_sim_node.vehicle.simulation import simulate

    scenario = dataclasses.replace(load_scenario(SCENARIO), duration=12.0)
    sim = simulate(load_vehicle(VEHICLE), scenario, rate_hz=RATE)
    est = run_cascade(
        CascadeSeries(sim.t, sim.wheel_angle, sim.body_speed, sim.wheel_torque),
        CascadeSettings(load_estimator_vehicle(VEHICLE)),
    )
    topics = sim_topics(sim)
    topics.update(cascade_topics(est, sim.wheel_angle))
    bag = tmp_path_factory.mktemp('sim') / 'paper12'
    write_topic_arrays_bag(bag, np.round(sim.t * 1e9).astype(np.int64), topics)
    return sim, est, bag


def test_events_found_in_the_bag_are_the_simulators(run: tuple[Any, Any, Path]) -> None:
    sim, _, bag = run
    report, _ = evaluate(load_bag_series(bag, progress=False))
    assert report.slope_steps_s == pytest.approx((10.0,))
    gear = np.asarray(sim.gear)
    changes = sim.t[1:][gear[1:] != gear[:-1]]
    assert changes.size >= 2  # the 1 -> 2 upshift passes through neutral
    assert report.gear_changes_s == pytest.approx(tuple(changes.tolist()))


def test_bag_metrics_equal_direct_array_metrics(run: tuple[Any, Any, Path]) -> None:
    sim, est, bag = run
    report, _ = evaluate(load_bag_series(bag, progress=False))
    by_key = {q.key: q for q in report.quantities}
    events = [*report.slope_steps_s, *report.gear_changes_s]
    mask = evaluation_mask(sim.t, start=1.0, events=events, half_width=0.5)
    pairs = {
        'omega': (est.omega, sim.omega),
        'omega_dot': (est.omega_dot, sim.omega_dot),
        'accel': (est.accel, sim.accel_true),
        'fx': (est.fx, sim.fx),
        'fz': (est.fz, sim.fz),
        'aero': (est.aero, sim.aero),
    }
    for key, (estimate, truth) in pairs.items():
        direct = error_stats(estimate, truth, mask)
        assert by_key[key].overall.samples == direct.samples, key
        assert by_key[key].overall.rms == pytest.approx(direct.rms, rel=1e-12), key
    slope_mask = mask & est.slope_valid
    direct = error_stats(np.degrees(est.slope), np.degrees(sim.slope), slope_mask)
    assert by_key['slope'].overall.rms == pytest.approx(direct.rms, rel=1e-9)
    excited = mask[:, None] & (np.abs(sim.fx) > 0.05 * sim.fz) & est.mu_valid
    direct = error_stats(est.mu, sim.mu, excited)
    assert by_key['mu'].overall.rms == pytest.approx(direct.rms, rel=1e-12)
    assert by_key['mu'].overall.samples == direct.samples > 0
