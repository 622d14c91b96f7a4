"""Settings that follow the inputs' rate: the law, the rate measurement, config and estimator."""

from __future__ import annotations

import math

import numpy as np
import pytest
from vd_common.vehicle.params import default_vehicle_file
from vd_observer_node.errors import ConfigurationError
from vd_observer_node.estimation.estimator import Estimator, EstimatorConfig
from vd_observer_node.estimation.rate_settings import (
    FOLLOW_AFTER,
    REFERENCE_SLOPE_FILTER_TAU,
    RateMeter,
    follow_rate_hz,
    nominal_rate_hz,
    sample_rate_hz,
    slope_filter_tau_for_rate,
)
from vd_observer_node.estimation.vehicle import load_estimator_vehicle


def test_the_law_is_the_reference_at_and_above_1khz_and_a_quarter_power_below() -> None:
    assert slope_filter_tau_for_rate(1000.0) == REFERENCE_SLOPE_FILTER_TAU == 0.1
    assert slope_filter_tau_for_rate(5000.0) == 0.1  # never shorter than tuned
    assert slope_filter_tau_for_rate(100.0) == pytest.approx(0.1 * 10**0.25, rel=1e-12)
    assert slope_filter_tau_for_rate(62.5) == pytest.approx(0.2, rel=1e-12)  # 16^(1/4) = 2
    for unknown in (math.nan, 0.0, -5.0, math.inf):
        assert slope_filter_tau_for_rate(unknown) == 0.1


def test_sample_rate_is_what_the_stream_delivers_with_loss_repeats_and_pauses() -> None:
    rng = np.random.default_rng(3)
    stamps = np.cumsum(np.full(1000, 10_000_000)) + rng.integers(-200_000, 200_000, 1000)
    assert sample_rate_hz(stamps) == pytest.approx(100.0, rel=1e-3)  # jitter: the same rate
    kept = rng.random(1000) >= 0.3  # 30 % lost at random: 70 Hz delivered
    delivered = 100.0 * kept.sum() / 1000  # [Hz] the oracle: stamps kept per second
    assert sample_rate_hz(stamps[kept]) == pytest.approx(delivered, rel=2e-3)
    assert sample_rate_hz(stamps[::2]) == pytest.approx(50.0, rel=1e-3)  # every second one
    repeated = np.repeat(stamps, 2)  # a repeated stamp is no interval
    assert sample_rate_hz(repeated) == pytest.approx(100.0, rel=1e-3)
    shuffled = rng.permutation(stamps)  # arrival order does not matter
    assert sample_rate_hz(shuffled) == sample_rate_hz(stamps)
    paused = np.concatenate([stamps[:500], stamps[500:] + 2_000_000_000])  # a 2 s pause
    assert sample_rate_hz(paused) == pytest.approx(100.0, rel=1e-3)
    assert math.isnan(sample_rate_hz([5]))
    assert math.isnan(sample_rate_hz([7, 7, 7]))


def test_rate_meter_keeps_the_first_stamps() -> None:
    meter = RateMeter(size=5)
    assert [meter.add(k * 20_000_000) for k in range(4)] == [False] * 4
    assert meter.add(80_000_000) and meter.count == 5  # this one filled it
    assert not meter.add(81_000_000) and meter.stamps[-1] == 80_000_000
    more = RateMeter(size=3)
    more.add_many(np.array([1, 2]))
    more.add_many(np.array([3, 4, 5]))
    assert more.stamps == [1, 2, 3]


def test_followed_rate_is_the_slower_input_to_three_digits() -> None:
    wheels = np.arange(FOLLOW_AFTER) * 10_000_000  # 100 Hz
    assert follow_rate_hz(wheels) == 100.0
    jitter = np.random.default_rng(2).integers(-3000, 3000, FOLLOW_AFTER)
    assert follow_rate_hz(wheels + jitter) == 100.0  # a few us of jitter: the same rate
    speed = np.arange(0, 4_000_000_000, 20_000_000)  # 50 Hz, longer than the wheels
    assert follow_rate_hz(wheels, speed) == 50.0
    fast = np.arange(0, 2_000_000_000, 1_000_000)  # 1 kHz speed: the wheels are slower
    assert follow_rate_hz(wheels, fast) == 100.0
    assert follow_rate_hz(wheels, [5]) == 100.0  # one speed stamp tells no rate
    assert math.isnan(follow_rate_hz([7]))
    assert nominal_rate_hz(41.9712) == 42.0 and nominal_rate_hz(1234.5) == 1230.0


def test_config_follows_the_rate_only_where_unset() -> None:
    unset = EstimatorConfig()
    assert unset.slope_filter_tau is None and unset.slope_tau == 0.1
    fixed, derived = unset.at_rate(100.0)
    assert derived == {'slope_filter_tau': slope_filter_tau_for_rate(100.0)}
    assert fixed.slope_filter_tau == fixed.slope_tau == slope_filter_tau_for_rate(100.0)
    assert fixed.at_rate(50.0) == (fixed, {})  # fixed once
    given = EstimatorConfig(slope_filter_tau=0.3)
    assert given.at_rate(100.0) == (given, {})
    assert unset.at_rate(math.nan) == (unset, {})
    assert EstimatorConfig.from_mapping({'slope_filter_tau': 1}).slope_filter_tau == 1.0
    with pytest.raises(ConfigurationError, match='slope_filter_tau'):
        EstimatorConfig(slope_filter_tau=-0.1)
    with pytest.raises(ConfigurationError, match='slope_filter_tau'):
        EstimatorConfig.from_mapping({'slope_filter_tau': 'fast'})


def _slopes(estimator: Estimator, rate_hz: float, follow_at: int | None) -> np.ndarray:
    """Slopes of a 100 Hz drive: accelerating on a noisy speed, torques to match."""
    rng = np.random.default_rng(11)
    dt = 1.0 / rate_hz
    out = []
    for k in range(300):
        if follow_at is not None and k == follow_at:
            estimator.follow_rate(rate_hz)
        v = 10.0 + 0.5 * k * dt + rng.normal(0.0, 0.05)
        omega = np.full(4, v / estimator.vehicle.effective_radius)
        est = estimator.update(k * dt, omega, np.zeros(4), v, 0.5, np.full(4, 120.0))
        out.append(est.slope)
    return np.asarray(out)


def test_estimator_follows_the_rate_in_place_as_if_built_with_it() -> None:
    vehicle = load_estimator_vehicle(str(default_vehicle_file()))
    tau = slope_filter_tau_for_rate(100.0)
    live = Estimator(vehicle)
    assert live.follow_rate(100.0) == {'slope_filter_tau': tau}
    assert live.params.slope_tau == tau and live.follow_rate(50.0) == {}
    built = Estimator(vehicle, EstimatorConfig(slope_filter_tau=tau))
    np.testing.assert_array_equal(_slopes(live, 100.0, None), _slopes(built, 100.0, None))
    # following later changes the filter from then on; the state carries over
    late = _slopes(Estimator(vehicle), 100.0, 150)
    early = _slopes(Estimator(vehicle), 100.0, None)  # the 0.1 s of the reference rate
    np.testing.assert_array_equal(late[:150], early[:150])
    assert not np.array_equal(late[150:], early[150:])
    kept = Estimator(vehicle, EstimatorConfig(slope_filter_tau=0.3))
    assert kept.follow_rate(100.0) == {} and kept.params.slope_tau == 0.3
