"""Friction potential: curve maths, convergence on known curves, forgetting, road class."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from vd_observer_node.errors import InputShapeError, ObserverError
from vd_observer_node.friction_potential import (
    ROAD_DRY,
    ROAD_ICE,
    ROAD_SNOW,
    ROAD_UNKNOWN,
    ROAD_WET,
    FrictionConfigError,
    FrictionPotentialConfig,
    FrictionPotentialEstimator,
    burckhardt_shape,
    classify_road,
    fit_solution,
    fit_step,
    floored_slip,
    initial_fit_state,
    make_bank,
    shape_peak,
)

RATE = 1000.0
VEHICLE_FILE = Path(__file__).resolve().parents[2] / 'vd_sim_node' / 'config' / 'clio_rl_1_1.yaml'


def feed(
    est: FrictionPotentialEstimator,
    t0: float,
    slips: np.ndarray,
    mus: np.ndarray,
    wheels: tuple[int, ...] = (0, 1),
) -> float:
    """Feed one sample per stamp to the given wheels; return the next stamp."""
    t = t0
    for s, m in zip(slips, mus, strict=True):
        slip = np.zeros(4)
        mu = np.zeros(4)
        valid = np.zeros(4, dtype=bool)
        slip[list(wheels)] = s
        mu[list(wheels)] = m
        valid[list(wheels)] = True
        est.update(t, slip, mu, valid)
        t += 1.0 / RATE
    return t


def sweep(n: int, s_max: float, rng: np.random.Generator) -> np.ndarray:
    """Slips going 0 -> s_max -> 0 (a tyre pushed past its peak and back), seeded jitter."""
    ramp = np.concatenate([np.linspace(0.0, s_max, n // 2), np.linspace(s_max, 0.0, n - n // 2)])
    return ramp + rng.normal(0.0, 0.001, n)


def test_config_errors_are_specific() -> None:
    assert issubclass(FrictionConfigError, ObserverError)
    with pytest.raises(FrictionConfigError, match='forgetting_time'):
        FrictionPotentialConfig(forgetting_time=0.0)
    with pytest.raises(FrictionConfigError, match='falloff'):
        FrictionPotentialConfig(falloff=(1.2,))
    with pytest.raises(FrictionConfigError, match='class_bounds'):
        FrictionPotentialConfig(class_bounds=(0.5, 0.4, 0.8))
    with pytest.raises(FrictionConfigError, match='unknown'):
        FrictionPotentialConfig.from_mapping({'no_such': 1.0})
    cfg = FrictionPotentialConfig.from_mapping({'falloff': [0.0, 0.3], 'prior_mu_max': 0.8})
    assert cfg.falloff == (0.0, 0.3)


@settings(max_examples=60, deadline=None)
@given(
    c2=st.floats(min_value=5.0, max_value=600.0),
    kappa=st.floats(min_value=0.0, max_value=0.9),
)
def test_shape_peak_is_the_curve_maximum(c2: float, kappa: float) -> None:
    peak, s_peak = shape_peak(c2, kappa, 1.0)
    grid = np.linspace(0.0, 1.0, 200001)
    values = burckhardt_shape(grid, c2, kappa)
    assert float(peak) == pytest.approx(values.max(), abs=1e-6)
    # the value at the reported slip is the peak (position alone is ill-posed on a flat top)
    assert 0.0 < float(s_peak) <= 1.0
    assert float(burckhardt_shape(s_peak, c2, kappa)) == pytest.approx(float(peak), abs=1e-12)


def test_shape_is_odd() -> None:
    s = np.linspace(-1.0, 1.0, 101)
    np.testing.assert_allclose(burckhardt_shape(s, 30.0, 0.3), -burckhardt_shape(-s, 30.0, 0.3))


def test_floored_slip() -> None:
    sv = np.array([0.5, -0.5, 10.0, -19.0])
    s = floored_slip(sv, 0.0, 1.0)
    np.testing.assert_allclose(s[:2], [0.5, -0.5])
    s = floored_slip(np.array([10.0, -19.0, 0.0, 1.0]), 20.0, 1.0)
    np.testing.assert_allclose(s, [10.0 / 30.0, -19.0 / 20.0, 0.0, 1.0 / 21.0])


def test_no_data_reports_the_prior_with_zero_confidence() -> None:
    est = FrictionPotentialEstimator(FrictionPotentialConfig(prior_mu_max=1.0))
    out = est.update(0.0, np.zeros(4), np.zeros(4), np.zeros(4, dtype=bool))
    np.testing.assert_allclose(out.mu_max, 1.0, atol=0.05)
    np.testing.assert_array_equal(out.confidence, 0.0)
    np.testing.assert_array_equal(out.road_class, ROAD_UNKNOWN)
    assert out.vehicle_road_class() == ROAD_UNKNOWN


@pytest.mark.parametrize(('c1', 'c2', 'c3'), [(1.2, 15.0, 0.36), (0.3, 60.0, 0.06)])
def test_converges_on_a_known_burckhardt_curve(c1: float, c2: float, c3: float) -> None:
    """The curve is in the model family: the estimate must converge to its exact peak."""
    cfg = FrictionPotentialConfig(
        sharpness=(5.0, 15.0, 30.0, 60.0, 120.0), falloff=(0.0, 0.1, 0.2, 0.3, 0.4)
    )
    est = FrictionPotentialEstimator(cfg)
    rng = np.random.default_rng(3)
    slips = sweep(1500, 0.5, rng)
    mus = c1 * (1.0 - np.exp(-c2 * slips)) - c3 * slips + rng.normal(0.0, 0.005, slips.size)
    feed(est, 0.0, slips, mus)
    out = est.last
    assert out is not None
    grid = np.linspace(0.0, 1.0, 100001)
    true_peak = float(np.max(c1 * (1.0 - np.exp(-c2 * grid)) - c3 * grid))
    assert out.mu_max[0] == pytest.approx(true_peak, abs=0.01)
    assert out.confidence[0] == pytest.approx(1.0)
    assert out.confidence[1] == 0.0  # the rear axle saw nothing


@pytest.mark.parametrize(('road_mu', 'expected_class'), [(1.0, ROAD_DRY), (0.3, ROAD_SNOW)])
def test_converges_on_the_simulator_magic_formula(road_mu: float, expected_class: int) -> None:
    """Not in the model family: the goal is |error| <= 0.1 once past half the peak."""
    from vd_sim_node.vehicle.params import load_vehicle
    from vd_sim_node.vehicle.tire import magic_formula_fx

    tp = load_vehicle(VEHICLE_FILE).tire
    fz = 2500.0
    grid = np.linspace(0.0, 1.0, 20001)
    true_peak = float(np.max(magic_formula_fx(grid, fz, road_mu, tp) / fz))
    rng = np.random.default_rng(5)
    est = FrictionPotentialEstimator()
    # Braking sweep to 3x the peak slip and back, wheels FL and FR, mu noise 0.01.
    slips = -sweep(1000, 3.0 * 0.15 * road_mu, rng)
    mus = magic_formula_fx(slips, fz, road_mu, tp) / fz + rng.normal(0.0, 0.01, slips.size)
    feed(est, 0.0, slips, mus)
    assert est.last is not None
    assert abs(est.last.mu_max[0] - true_peak) <= 0.1
    assert est.last.road_class[0] == expected_class


def test_forgetting_follows_a_road_change() -> None:
    cfg = FrictionPotentialConfig(forgetting_time=0.5)
    est = FrictionPotentialEstimator(cfg)
    rng = np.random.default_rng(9)

    def curve(s: np.ndarray, peak: float) -> np.ndarray:
        return peak / 0.95 * (1.0 - np.exp(-18.0 / peak * s) - 0.3 * s)

    t = 0.0
    for _ in range(2):
        s = sweep(1000, 0.4, rng)
        t = feed(est, t, s, curve(s, 1.0))
    assert est.last is not None
    dry = float(est.last.mu_max[0])
    for _ in range(4):
        s = sweep(1000, 0.2, rng)
        t = feed(est, t, s, curve(s, 0.2))
    ice = float(est.last.mu_max[0])
    assert dry > 0.8
    assert ice == pytest.approx(0.2, abs=0.05)


def test_ignored_samples_leave_the_fit_unchanged() -> None:
    cfg = FrictionPotentialConfig()
    bank = make_bank(cfg)
    state = initial_fit_state(bank)
    state = fit_step(state, 0.0, [0.1] * 4, [0.5] * 4, [True] * 4, bank, cfg)
    # invalid, below min_slip, opposite signs, non-finite: statistics unchanged
    after = fit_step(
        state,
        0.001,
        [0.2, 0.001, 0.2, math.nan],
        [0.6, 0.3, -0.4, 0.5],
        [False, True, True, True],
        bank,
        cfg,
    )
    np.testing.assert_array_equal(after.s_pp, state.s_pp)
    np.testing.assert_array_equal(after.s_py, state.s_py)
    # a stale stamp is rejected outright
    assert fit_step(after, 0.0, [0.3] * 4, [0.5] * 4, [True] * 4, bank, cfg) is after
    with pytest.raises(InputShapeError):
        fit_step(state, 1.0, [0.1] * 3, [0.5] * 4, [True] * 4, bank, cfg)


def test_wrapper_equals_pure_steps() -> None:
    cfg = FrictionPotentialConfig()
    bank = make_bank(cfg)
    rng = np.random.default_rng(1)
    est = FrictionPotentialEstimator(cfg)
    state = initial_fit_state(bank)
    classes = np.full(2, ROAD_UNKNOWN)
    for k in range(300):
        t = k / RATE
        slip = rng.uniform(-0.3, 0.3, 4)
        mu = np.tanh(10.0 * slip) * 0.4 + rng.normal(0.0, 0.01, 4)
        valid = rng.uniform(size=4) > 0.1
        out = est.update(t, slip, mu, valid)
        state = fit_step(state, t, slip, mu, valid, bank, cfg)
        ref = fit_solution(state, bank, cfg, classes)
        classes = ref.road_class
        np.testing.assert_array_equal(out.mu_max, ref.mu_max)
        np.testing.assert_array_equal(out.confidence, ref.confidence)
        np.testing.assert_array_equal(out.road_class, ref.road_class)


def test_road_class_bands_and_hysteresis() -> None:
    cfg = FrictionPotentialConfig(class_bounds=(0.2, 0.45, 0.75), class_margin=0.03)
    assert classify_road(0.1, 1.0, ROAD_UNKNOWN, cfg) == ROAD_ICE
    assert classify_road(0.3, 1.0, ROAD_UNKNOWN, cfg) == ROAD_SNOW
    assert classify_road(0.6, 1.0, ROAD_UNKNOWN, cfg) == ROAD_WET
    assert classify_road(0.9, 1.0, ROAD_UNKNOWN, cfg) == ROAD_DRY
    assert classify_road(0.9, 0.2, ROAD_DRY, cfg) == ROAD_UNKNOWN  # not confident
    # inside the margin the previous class holds, beyond it the class changes
    assert classify_road(0.73, 1.0, ROAD_DRY, cfg) == ROAD_DRY
    assert classify_road(0.71, 1.0, ROAD_DRY, cfg) == ROAD_WET
    assert classify_road(0.77, 1.0, ROAD_WET, cfg) == ROAD_WET
    assert classify_road(0.79, 1.0, ROAD_WET, cfg) == ROAD_DRY


@settings(max_examples=100, deadline=None)
@given(mu=st.floats(min_value=0.0, max_value=2.0), prev=st.integers(0, 4))
def test_road_class_moves_at_most_to_the_raw_band(mu: float, prev: int) -> None:
    """The hysteresis only ever keeps the previous class or picks the raw band's class."""
    cfg = FrictionPotentialConfig()
    raw = classify_road(mu, 1.0, ROAD_UNKNOWN, cfg)
    got = classify_road(mu, 1.0, prev, cfg)
    assert got in (raw, prev)
    assert got != ROAD_UNKNOWN
