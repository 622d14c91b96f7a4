"""Scenario files and loader."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st
from vd_sim_node.errors import ScenarioError
from vd_sim_node.vehicle.scenario import PiecewiseConstant, load_scenario, parse_scenario

SCENARIOS = Path(__file__).resolve().parents[1] / 'config' / 'scenarios'
DEG = math.pi / 180.0


def test_paper_table1_matches_the_paper() -> None:
    s = load_scenario(SCENARIOS / 'paper_table1.yaml')
    assert s.duration == 150.0
    assert [s.throttle.at(t) for t in (0.0, 7.999, 8.0, 99.999, 100.0, 150.0)] == [
        0.0,
        0.0,
        1.0,
        1.0,
        0.0,
        0.0,
    ]
    for t, deg in ((0.0, 0.0), (9.99, 0.0), (10.0, 5.0), (19.9, 5.0), (20.0, 10.0), (49.9, 10.0)):
        assert s.slope.at(t) == pytest.approx(deg * DEG)
    assert s.slope.at(50.0) == pytest.approx(3.0 * DEG)
    assert s.slope.at(149.0) == pytest.approx(3.0 * DEG)
    assert s.road_mu.at(75.0) == 1.0  # dry road
    assert s.sensors.rate_hz == 1000.0
    assert s.breakpoints() == (8.0, 10.0, 20.0, 50.0, 100.0)


def test_braking_low_mu_crosses_a_low_friction_patch() -> None:
    s = load_scenario(SCENARIOS / 'braking_low_mu.yaml')
    mus = s.road_mu.sample(np.linspace(0.0, s.duration, 2501))
    assert mus.max() == 1.0 and mus.min() == pytest.approx(0.3)
    assert s.road_mu.at(0.0) == 1.0 and s.road_mu.at(s.duration) == 1.0
    patch = [t for t in s.road_mu.times if s.road_mu.at(t) < 1.0]
    assert patch and s.brake.at(patch[0]) > 0.0  # the car brakes while on the patch
    assert s.sensors.encoder_counts_per_rev > 0 and s.sensors.speed_noise_std > 0.0


def _base() -> dict[str, Any]:
    return {'duration': 10.0, 'signals': {'throttle': [[0, 0.0], [2, 1.0]]}}


@pytest.mark.parametrize(
    ('patch', 'message'),
    [
        ({'duration': -1}, r'duration must be > 0 s'),
        ({'signals': {'throttle': [[0, 1.5]]}}, r'signals\.throttle\[0\] value must be in'),
        ({'signals': {'throttle': [[1, 0.5]]}}, r'signals\.throttle must start at t = 0'),
        ({'signals': {'brake': [[0, 0.0], [0, 1.0]]}}, r'signals\.brake: breakpoint times'),
        ({'signals': {'road_mu': [[0, 'wet']]}}, r'signals\.road_mu\[0\] must be a \[t_start'),
        ({'signals': {'slope': [[0, 0.1]], 'slope_deg': [[0, 5]]}}, r'either slope'),
        ({'signals': {'slope_deg': [[0, 60]]}}, r'signals\.slope_deg\[0\] value must be in'),
        ({'sensors': {'rate_hz': 0}}, r'sensors\.rate_hz must be > 0'),
        ({'sensors': {'encoder_counts_per_rev': -4}}, r'sensors\.encoder_counts_per_rev'),
        ({'initial_gear': 0}, r'initial_gear must be >= 1'),
    ],
)
def test_invalid_scenarios_are_refused_by_name(patch: dict[str, Any], message: str) -> None:
    data = _base() | patch
    with pytest.raises(ScenarioError, match=message):
        parse_scenario(data)


def test_missing_duration_and_defaults(tmp_path: Path) -> None:
    with pytest.raises(ScenarioError, match='duration is missing'):
        parse_scenario({'signals': {}})
    p = tmp_path / 'flat.yaml'
    p.write_text(yaml.safe_dump({'duration': 3.0}))
    s = load_scenario(p)
    assert s.name == 'flat'
    assert s.throttle.at(1.0) == 0.0 and s.road_mu.at(1.0) == 1.0 and s.slope.at(1.0) == 0.0
    assert s.sensors.rate_hz == 1000.0 and s.sensors.encoder_counts_per_rev == 0


@settings(max_examples=100, deadline=None)
@given(
    steps=st.lists(st.floats(0.01, 10.0), min_size=0, max_size=6),
    values=st.lists(st.floats(-5.0, 5.0), min_size=7, max_size=7),
    probe=st.lists(st.floats(-1.0, 70.0), min_size=1, max_size=30),
)
def test_piecewise_signal_is_right_continuous(
    steps: list[float], values: list[float], probe: list[float]
) -> None:
    times = tuple(np.cumsum([0.0, *steps]).tolist())
    sig = PiecewiseConstant(times, tuple(values[: len(times)]))
    sampled = sig.sample(np.array(probe))
    for t, v in zip(probe, sampled, strict=True):
        assert v == sig.at(t)
        expected = sig.values[max(i for i, tb in enumerate(times) if tb <= max(t, 0.0))]
        assert v == expected
    for tb, vb in zip(sig.times, sig.values, strict=True):
        assert sig.at(tb) == vb
