"""Friction potential: convergence on known curves, no confidence without evidence, noisy slip,
forgetting, road class, the tyre curve and peaks against vd_common's, and the wrapper against
the step functions on records."""

from __future__ import annotations

import math
from dataclasses import replace
from functools import cache
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from vd_common.vehicle.friction import unit_peak
from vd_common.vehicle.params import load_vehicle
from vd_common.vehicle.tire import magic_formula_fx
from vd_observer_node.errors import InputShapeError, ObserverError
from vd_observer_node.kernel._jit import new_record
from vd_observer_node.situation.friction_fit import (
    POTENTIAL,
    classify_road,
    fit_solution,
    fit_step,
    mu_at_scales,
    unfloored_slip,
)
from vd_observer_node.situation.friction_potential import (
    ROAD_DRY,
    ROAD_ICE,
    ROAD_SNOW,
    ROAD_UNKNOWN,
    ROAD_WET,
    FrictionConfigError,
    FrictionPotentialConfig,
    FrictionPotentialEstimator,
    TyreCurves,
    friction_params,
)

RATE = 1000.0  # [Hz]
SPEED = 20.0  # [m/s]
LOAD = 3000.0  # [N]
STATIC = (LOAD, LOAD)
VEHICLE_FILE = Path(__file__).resolve().parents[2] / 'vd_common' / 'config' / 'clio_rl_1_1.yaml'


@cache
def curves() -> TyreCurves:
    return TyreCurves.from_tire(load_vehicle(VEHICLE_FILE).tire)


def true_mu(slip: np.ndarray, road: float) -> np.ndarray:
    return magic_formula_fx(slip, LOAD, road, curves().tire) / LOAD


def true_peak(road: float) -> float:
    grid = np.linspace(0.0, 1.0, 20001)
    return float(np.max(true_mu(grid, road)))


def slip_velocity_of(slip: np.ndarray, speed: float = SPEED) -> np.ndarray:
    """omega R - v giving the slip ratio at body speed v (slip < 1)."""
    return np.where(slip >= 0.0, speed * slip / (1.0 - slip), speed * slip)


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
        sv = np.zeros(4)
        mu = np.zeros(4)
        valid = np.zeros(4, dtype=bool)
        sv[list(wheels)] = slip_velocity_of(np.asarray(s))
        mu[list(wheels)] = m
        valid[list(wheels)] = True
        est.update(t, sv, SPEED, mu, valid, np.full(4, LOAD))
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
    with pytest.raises(FrictionConfigError, match='road_scales'):
        FrictionPotentialConfig(road_scales=(0.5, 0.4))
    with pytest.raises(FrictionConfigError, match='class_bounds'):
        FrictionPotentialConfig(class_bounds=(0.5, 0.4, 0.8))
    with pytest.raises(FrictionConfigError, match='evidence_low'):
        FrictionPotentialConfig(evidence_low=5.0, evidence_high=5.0)
    with pytest.raises(FrictionConfigError, match='unknown'):
        FrictionPotentialConfig.from_mapping({'no_such': 1.0})
    cfg = FrictionPotentialConfig.from_mapping({'road_scales': [0.2, 1.0], 'min_slip': 0.01})
    assert cfg.road_scales == (0.2, 1.0)


def test_slip_ratio() -> None:
    pairs = [unfloored_slip(sv, 20.0) for sv in (10.0, -19.0, 0.0, 1.0)]
    np.testing.assert_allclose([p[0] for p in pairs], [10.0 / 30.0, -19.0 / 20.0, 0.0, 1 / 21])
    np.testing.assert_allclose([p[1] for p in pairs], [30.0, 20.0, 20.0, 21.0])
    slip, _ = unfloored_slip(0.0, 0.0)
    assert math.isnan(slip)  # standing still: no slip at all, not 0/0


@settings(max_examples=50, deadline=None)
@given(
    slip=st.floats(min_value=-1.0, max_value=1.0),
    load=st.floats(min_value=200.0, max_value=8000.0),
)
def test_mu_at_scales_is_the_magic_formula(slip: float, load: float) -> None:
    """The fit's curve at every road scale is vd_common's Magic Formula (the simulator's)."""
    scales = np.asarray(FrictionPotentialConfig().road_scales)
    out = np.empty(scales.size)
    mu_at_scales(curves().record(), slip, load, scales, out)
    expected = magic_formula_fx(np.full(scales.size, slip), load, scales, curves().tire) / load
    np.testing.assert_allclose(out, expected, rtol=1e-12, atol=1e-15)


def test_reset_reports_the_prior_road_at_the_tyre_peak() -> None:
    """Without data: mu_max and slip_peak are vd_common's unit peak at the static load."""
    cfg = FrictionPotentialConfig(prior_road_scale=0.8)
    est = FrictionPotentialEstimator(curves(), (3300.0, 2400.0), cfg)
    mu, slip = unit_peak(curves().table, np.array([3300.0, 2400.0]), np.ones(2, bool))
    np.testing.assert_allclose(est.last.mu_max, 0.8 * mu, rtol=1e-12)
    np.testing.assert_allclose(est.last.slip_peak, 0.8 * slip, rtol=1e-12)
    np.testing.assert_array_equal(est.last.road_scale, 0.8)


def test_no_data_reports_the_prior_with_zero_confidence() -> None:
    est = FrictionPotentialEstimator(curves(), STATIC)
    out = est.update(0.0, np.zeros(4), SPEED, np.zeros(4), np.zeros(4, dtype=bool), np.ones(4))
    np.testing.assert_allclose(out.mu_max, true_peak(1.0), atol=0.02)
    np.testing.assert_array_equal(out.confidence, 0.0)
    np.testing.assert_array_equal(out.road_class, ROAD_UNKNOWN)
    assert out.vehicle_road_class() == ROAD_UNKNOWN


@settings(max_examples=12)
@given(road=st.floats(min_value=0.1, max_value=1.3), braking=st.booleans())
def test_converges_on_the_tyre_curve_at_any_road(road: float, braking: bool) -> None:
    """A sweep past the peak on any road: the estimate lands on the true peak."""
    rng = np.random.default_rng(5)
    est = FrictionPotentialEstimator(curves(), STATIC)
    slips = sweep(800, 3.0 * 0.15 * road, rng) * (-1.0 if braking else 1.0)
    mus = true_mu(slips, road) + rng.normal(0.0, 0.01, slips.size)
    feed(est, 0.0, slips, mus)
    grid = np.linspace(0.0, 1.0, 20001) * (-1.0 if braking else 1.0)
    peak = float(np.max(np.abs(true_mu(grid, road))))
    assert abs(est.last.mu_max[0] - peak) <= 0.03
    # the sweep ends with slips too small to use (< 2 sigma_s): for those last ~0.1 s the
    # confidence has begun to decay over the 5 s evidence_hold_time
    assert est.last.confidence[0] >= 0.95
    assert est.last.confidence[1] == 0.0  # the rear axle saw nothing
    assert est.last.slip_peak[0] == pytest.approx(0.148 * road, rel=0.15)


@pytest.mark.parametrize(
    ('road', 'expected'), [(1.0, ROAD_DRY), (0.6, ROAD_WET), (0.3, ROAD_SNOW), (0.12, ROAD_ICE)]
)
def test_road_class_after_excitation(road: float, expected: int) -> None:
    rng = np.random.default_rng(7)
    est = FrictionPotentialEstimator(curves(), STATIC)
    slips = sweep(600, 3.0 * 0.15 * road, rng)
    feed(est, 0.0, slips, true_mu(slips, road) + rng.normal(0.0, 0.01, slips.size))
    assert est.last.road_class[0] == expected
    assert est.last.vehicle_road_class() == expected


def test_linear_region_data_give_no_confidence() -> None:
    """Cruise data (slip well below the peak) fit every road: report the prior, unconfident.

    This is the failure of the first design: noisy cruise data made a low, flat curve win
    and confirmed itself. Slip noise here is what a 96-count encoder and 0.05 m/s speed noise
    give at 20 m/s (slip velocity noise std 0.07 m/s).
    """
    rng = np.random.default_rng(11)
    est = FrictionPotentialEstimator(curves(), STATIC)
    true_slip = 0.012 + 0.004 * np.sin(np.linspace(0.0, 20.0, 5000))
    measured = true_slip + rng.normal(0.0, 0.07 / SPEED, true_slip.size)
    feed(est, 0.0, measured, true_mu(true_slip, 1.0) + rng.normal(0.0, 0.02, true_slip.size))
    assert est.last.confidence[0] < 0.5
    assert abs(est.last.mu_max[0] - true_peak(1.0)) <= 0.1
    assert est.last.road_class[0] == ROAD_UNKNOWN


def test_noisy_slip_around_zero_is_not_ice() -> None:
    """Coasting: true slip ~0, mu -0.025, slip noise flips the sign. Not a tyre on ice."""
    rng = np.random.default_rng(12)
    est = FrictionPotentialEstimator(curves(), STATIC)
    measured = -0.001 + rng.normal(0.0, 0.07 / SPEED, 5000)
    feed(est, 0.0, measured, np.full(measured.size, -0.025) + rng.normal(0.0, 0.01, 5000))
    assert est.last.confidence[0] < 0.5
    assert est.last.mu_max[0] > 0.75


def test_forgetting_follows_a_road_change() -> None:
    est = FrictionPotentialEstimator(curves(), STATIC, FrictionPotentialConfig())
    rng = np.random.default_rng(9)
    t = 0.0
    for _ in range(2):
        s = sweep(1000, 0.4, rng)
        t = feed(est, t, s, true_mu(s, 1.0))
    dry = float(est.last.mu_max[0])
    for _ in range(3):
        s = sweep(1000, 0.1, rng)
        t = feed(est, t, s, true_mu(s, 0.2))
    icy = float(est.last.mu_max[0])
    assert dry == pytest.approx(true_peak(1.0), abs=0.03)
    assert icy == pytest.approx(true_peak(0.2), abs=0.03)


def test_ignored_samples_leave_the_fit_unchanged() -> None:
    est = FrictionPotentialEstimator(curves(), STATIC)
    loads = np.full(4, LOAD)

    def step(t: float, sv: list[float], speed: float, mu: list[float], ok: list[bool]) -> bool:
        return bool(
            fit_step(est.parts, t, np.asarray(sv), speed, np.asarray(mu), np.asarray(ok), loads)
        )

    assert step(0.0, [2.0] * 4, SPEED, [0.5] * 4, [True] * 4)
    cost, count = est.cost.copy(), est.state.count.copy()
    # invalid, opposite signs, non-finite, below the slip noise, walking pace
    assert step(
        0.001,
        [2.0, 2.0, math.nan, 0.01],
        SPEED,
        [0.6, -0.4, 0.5, 0.01],
        [False, True, True, True],
    )
    np.testing.assert_array_equal(est.cost, cost)
    np.testing.assert_array_equal(est.state.count, count)
    assert step(0.002, [0.5] * 4, 1.0, [0.3] * 4, [True] * 4)
    np.testing.assert_array_equal(est.cost, cost)
    # a stale stamp is rejected outright
    assert not step(0.0, [2.0] * 4, SPEED, [0.5] * 4, [True] * 4)
    np.testing.assert_array_equal(est.cost, cost)
    assert est.state.t == 0.002
    with pytest.raises(InputShapeError):
        est.update(1.0, [0.1] * 3, SPEED, [0.5] * 4, [True] * 4, loads)


def test_road_class_bands_and_hysteresis() -> None:
    cfg = friction_params(
        FrictionPotentialConfig(class_bounds=(0.2, 0.45, 0.75), class_margin=0.03)
    )
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


@settings(max_examples=100)
@given(mu=st.floats(min_value=0.0, max_value=2.0), prev=st.integers(0, 4))
def test_road_class_moves_at_most_to_the_raw_band(mu: float, prev: int) -> None:
    """The hysteresis only ever keeps the previous class or picks the raw band's class."""
    cfg = friction_params(FrictionPotentialConfig())
    raw = classify_road(mu, 1.0, ROAD_UNKNOWN, cfg)
    got = classify_road(mu, 1.0, prev, cfg)
    assert got in (raw, prev)
    assert got != ROAD_UNKNOWN


def test_confidence_decays_without_fresh_evidence() -> None:
    """A confident estimate fades to the prior once the tyre is no longer excited."""
    cfg = FrictionPotentialConfig(evidence_hold_time=2.0)
    est = FrictionPotentialEstimator(curves(), STATIC, cfg)
    rng = np.random.default_rng(13)
    slips = sweep(600, 0.1, rng)
    t = feed(est, 0.0, slips, true_mu(slips, 0.3))
    assert est.last.confidence[0] >= 0.95
    assert est.last.road_class[0] == ROAD_SNOW
    for k in range(int(4.0 * RATE)):  # 4 s of cruising with nothing usable
        est.update(t + k / RATE, np.zeros(4), SPEED, np.zeros(4), np.zeros(4, bool), np.ones(4))
    undecayed = new_record(POTENTIAL)
    held = friction_params(replace(cfg, evidence_hold_time=0.0))
    fit_solution(held, est.scales, est.table, est.state, est.cost, undecayed)
    age = est.state.t - est.state.last_sample[0]
    assert age > 4.0
    assert est.last.confidence[0] == pytest.approx(undecayed.confidence[0] * math.exp(-age / 2.0))
    assert est.last.road_class[0] == ROAD_UNKNOWN
    assert est.last.mu_max[0] > 0.75  # most of the way back to the prior dry road (1.03)


@pytest.mark.parametrize('second_road', [0.3, 1.0])
def test_data_no_curve_explains_are_not_held(second_road: float) -> None:
    """A snow sweep, then 0.1 s on a second road, then 1 s with nothing usable; the road-change
    test off (``change_evidence`` 0), so the forgetting window holds both roads.

    The same road again: the confidence decays over the hold time (5 s) alone and the snow
    class is kept. A dry road: the forgetting window holds both roads when the samples stop
    (the braking_low_mu patch's exit, where the car slows below the usable slip), no curve
    explains them (misfit about 17, against below 0.01 for one road), and within the second
    the class is UNKNOWN and mu_max back near the prior dry road. Before, a confident 0.46
    (snow) was held for seconds on the dry road.
    """
    est = FrictionPotentialEstimator(curves(), STATIC, FrictionPotentialConfig(change_evidence=0))
    rng = np.random.default_rng(13)
    slips = sweep(600, 0.1, rng)
    t = feed(est, 0.0, slips, true_mu(slips, 0.3))
    burst = np.linspace(0.0, 0.08, 100) + rng.normal(0.0, 0.001, 100)
    t = feed(est, t, burst, true_mu(burst, second_road))
    assert est.last.confidence[0] >= 0.95  # both: confident while the samples come
    assert est.last.road_class[0] == ROAD_SNOW
    for k in range(int(RATE)):
        est.update(t + k / RATE, np.zeros(4), SPEED, np.zeros(4), np.zeros(4, bool), np.ones(4))
    if second_road == 0.3:
        assert est.last.confidence[0] == pytest.approx(math.exp(-1.0 / 5.0), rel=1e-3)
        assert est.last.road_class[0] == ROAD_SNOW
    else:
        assert est.last.confidence[0] < 0.1  # measured 0.03
        assert est.last.road_class[0] == ROAD_UNKNOWN
        assert est.last.mu_max[0] > 0.9  # measured 1.00 (prior 1.03); the truth is 1.05


def _snow_then(second_road: float, change_evidence: float) -> tuple[list[float], int]:
    """A snow sweep, then a sweep to slip 0.2 on a second road, 1 ms a stamp: the front
    axle's mu_max at every stamp of the second sweep, and the road changes detected."""
    est = FrictionPotentialEstimator(
        curves(), STATIC, FrictionPotentialConfig(change_evidence=change_evidence)
    )
    rng = np.random.default_rng(21)
    slips = sweep(600, 0.1, rng)
    t = feed(est, 0.0, slips, true_mu(slips, 0.3))
    second = np.linspace(0.0, 0.2, 200) + rng.normal(0.0, 0.001, 200)
    trace = []
    for s in second:
        t = feed(est, t, np.array([s]), true_mu(np.array([s]), second_road))
        trace.append(float(est.last.mu_max[0]))
    return trace, int(est.state.changes[0])


def test_a_road_change_restarts_the_window() -> None:
    """Snow, then a dry road pushed towards its peak (slip 0 to 0.2 in 0.2 s; the first
    ~40 ms are below the usable slip): the recent samples reject the snow road, the window
    restarts from them, and mu_max stays within 0.1 of the dry peak from 68 ms on (measured).
    Without the test (``change_evidence`` 0) the window mixes the two roads and crawls from
    snow to dry: within 0.1 from 165 ms on. The same road again is no change."""
    dry = true_peak(1.0)

    def settled(trace: list[float]) -> int:
        """Stamps before mu_max stays within 0.1 of the dry peak."""
        off = np.flatnonzero(np.abs(np.asarray(trace) - dry) > 0.1)
        return int(off[-1]) + 1 if off.size else 0

    with_test, changes = _snow_then(1.0, FrictionPotentialConfig().change_evidence)
    without, none = _snow_then(1.0, 0.0)
    assert changes >= 1 and none == 0
    assert settled(with_test) <= 80
    assert settled(without) >= 150
    _, same = _snow_then(0.3, FrictionPotentialConfig().change_evidence)
    assert same == 0


def test_noise_on_one_road_is_no_change() -> None:
    """10 s of noisy samples around one road's peak (slip noise of a 96-count encoder and
    0.05 mu): no road change is detected."""
    rng = np.random.default_rng(5)
    est = FrictionPotentialEstimator(curves(), STATIC)
    slips = np.abs(0.08 + 0.05 * np.sin(np.arange(10000) / 300.0)) + rng.normal(0, 0.004, 10000)
    feed(est, 0.0, slips, true_mu(slips, 0.6) + rng.normal(0.0, 0.05, slips.size))
    assert int(est.state.changes[0]) == 0
    assert est.last.mu_max[0] == pytest.approx(true_peak(0.6), abs=0.1)


@pytest.mark.parametrize(('stamps', 'confident'), [(2, False), (20, True)])
def test_a_few_samples_are_not_a_hundred(stamps: int, confident: bool) -> None:
    """Near the snow road's peak (slip 0.04): the evidence counts at most as many independent
    samples as the window holds (2 per stamp here). Two stamps (4 samples) leave the class
    unknown (confidence measured 0.03); 20 stamps (38 samples after forgetting) give snow.
    Before, evidence_samples (100) was claimed from the first stamp on: one stamp after a
    pause gave snow with confidence 1."""
    rng = np.random.default_rng(3)
    est = FrictionPotentialEstimator(curves(), STATIC)
    slips = np.full(stamps, 0.04) + rng.normal(0.0, 0.001, stamps)
    feed(est, 0.0, slips, true_mu(slips, 0.3))
    if confident:
        assert est.last.confidence[0] == 1.0
        assert est.last.road_class[0] == ROAD_SNOW
    else:
        assert est.last.confidence[0] < 0.1
        assert est.last.road_class[0] == ROAD_UNKNOWN
