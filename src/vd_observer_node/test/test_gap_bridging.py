"""Gaps below `max_gap` are bridged, not restarted (issue 28): differentiator, filters, chain.

Oracles: a quadratic (the implicit differentiator's exact case), a ramp and a quadratic through
first-order lags (closed forms), the analytic trajectory of `testing.synthetic`, and the
offline cascade for the live chain (the same step functions, stamp by stamp).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from vd_common.topics import ESTIMATES_SLOPE, SENSORS
from vd_common.vehicle.params import load_vehicle
from vd_observer_node.bag import BagReader
from vd_observer_node.bag.cdr_batch import decode_batch
from vd_observer_node.chain import Chain
from vd_observer_node.estimation.cascade import CascadeSeries, CascadeSettings, run_cascade
from vd_observer_node.estimation.differentiator import DifferentiatorSettings, LevantDifferentiator
from vd_observer_node.estimation.estimator import Estimator, EstimatorConfig
from vd_observer_node.estimation.estimator_step import GAP_FORCE_CHANGE
from vd_observer_node.estimation.filters import (
    BRIDGE_FROM,
    LOWPASS_META,
    LowPass,
    lowpass_bridge,
    lowpass_update,
)
from vd_observer_node.estimation.observer import ObserverConfig
from vd_observer_node.estimation.vehicle import EstimatorVehicle
from vd_observer_node.kernel._jit import new_record
from vd_observer_node.situation.chain_settings import ChainSettings
from vd_observer_node.situation.friction_potential import TyreCurves
from vd_observer_node.testing.devbag import sim_topics, write_topic_arrays_bag
from vd_observer_node.testing.synthetic import SyntheticTrajectory, synthetic_trajectory
from vd_observer_node.tools.replay import replay_bag
from vd_sim_node.vehicle.scenario import load_scenario
from vd_sim_node.vehicle.simulation import SimResult, simulate

SRC = Path(__file__).resolve().parents[2]
PARAMS = load_vehicle(SRC / 'vd_common' / 'config' / 'clio_rl_1_1.yaml')
PAPER_TABLE1 = SRC / 'vd_sim_node' / 'config' / 'scenarios' / 'paper_table1.yaml'
VEHICLE = EstimatorVehicle.from_params(PARAMS)
DT = 1e-3


def _quadratic(t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return 1.0 + 2.0 * t + 1.5 * t * t, 2.0 + 3.0 * t, np.full_like(t, 3.0)


def _stamps_with_hole(end: float, start: float, length: float) -> np.ndarray:
    t = np.round(np.arange(0.0, end, DT), 9)
    return t[(t < start) | (t >= start + length - 1e-9)]


def test_the_differentiator_steps_over_a_gap_below_max_gap_with_its_real_interval() -> None:
    # A quadratic is the implicit scheme's exact case: carried across 0.3 s of nothing and
    # stepped with the real 0.3 s, the state is exact at the first sample after the gap
    # (stepped with 1 ms, or restarted, it would not be).
    diff = LevantDifferentiator(50.0, n_channels=1, settings=DifferentiatorSettings(max_gap=0.5))
    t = _stamps_with_hole(2.0, 1.0, 0.3)
    f, df, ddf = _quadratic(t)
    after = int(np.searchsorted(t, 1.0))
    for k in range(after):
        diff.update(t[k], f[k])
    out = diff.update(t[after], f[after])
    assert t[after] - t[after - 1] == pytest.approx(0.3 + DT)
    assert out.valid[0]
    assert out.value[0] == pytest.approx(f[after], abs=1e-9)
    assert out.first[0] == pytest.approx(df[after], abs=1e-6)
    assert out.second[0] == pytest.approx(ddf[after], abs=1e-5)
    assert diff.faults.counts['gap'] == 0


def test_the_differentiator_restarts_beyond_max_gap() -> None:
    diff = LevantDifferentiator(
        50.0, n_channels=1, settings=DifferentiatorSettings(max_gap=0.5, init_baseline=0.05)
    )
    t = _stamps_with_hole(2.0, 1.0, 0.6)
    f, df, _ = _quadratic(t)
    after = int(np.searchsorted(t, 1.0))
    for k in range(after):
        diff.update(t[k], f[k])
    out = diff.update(t[after], f[after])
    assert diff.faults.counts['gap'] == 1
    # re-initialised: invalid until the finite difference over init_baseline
    assert not out.valid[0]
    for k in range(after + 1, after + 60):
        out = diff.update(t[k], f[k])
    assert out.valid[0]
    assert out.first[0] == pytest.approx(df[after + 59], rel=0.05)


def _ramp_filter(times: np.ndarray, rate: float) -> tuple[float, float]:
    lp = LowPass(0.1, order=2)
    previous = times[0]
    out = 0.0
    for tk in times:
        out = float(lp.update(tk - previous, rate * tk))
        previous = tk
    return out, float(lp.derivative())


def test_the_lowpass_bridges_a_gap_in_a_ramp() -> None:
    # A ramp through two lags: after the transient the output is the ramp delayed by
    # 2 tau and its rate is the ramp's (closed form). Held at its value after a 200 ms gap,
    # the input would be a step; bridged, the filter stays on the ramp.
    rate = 3.0
    whole = np.round(np.arange(0.0, 2.201, DT), 9)
    holed = _stamps_with_hole(2.201, 2.0, 0.2)
    assert holed[-1] == whole[-1] and holed.size == whole.size - 200
    lossless, lossless_rate = _ramp_filter(whole, rate)
    bridged, bridged_rate = _ramp_filter(holed, rate)
    # (each step holds its end value: the discrete filter leads by about one step)
    assert lossless == pytest.approx(rate * (whole[-1] - 0.2), abs=2.0 * rate * DT)
    assert lossless_rate == pytest.approx(rate, rel=1e-6)
    assert bridged == pytest.approx(lossless, rel=1e-9)
    assert bridged_rate == pytest.approx(rate, rel=1e-6)


def test_a_step_up_to_bridge_from_tau_is_one_plain_step() -> None:
    tau = 0.1
    stages, prev, meta = np.zeros((2, 1)), np.zeros((2, 1)), new_record(LOWPASS_META)
    out = np.empty(1)
    lowpass_update(tau, stages, prev, meta, 0.0, np.array([1.0]), out)
    lowpass_update(tau, stages, prev, meta, DT, np.array([1.5]), out)
    y = stages[:, 0].copy()
    dt = BRIDGE_FROM * tau
    lowpass_update(tau, stages, prev, meta, dt, np.array([4.0]), out)
    alpha = -math.expm1(-dt / tau)
    y1 = y[0] + alpha * (4.0 - y[0])
    assert out[0] == y[1] + alpha * (y1 - y[1])
    assert meta.last_dt == dt


def test_the_bridge_follows_a_quadratic_input_as_the_continuous_lag() -> None:
    # one lag y' = (x - y) / tau with x = c0 + c1 s + c2 s^2 from y(0) = y0 has the closed
    # form y = xp(s) + (y0 - xp(0)) exp(-s / tau), xp = c0 + c1 (s - tau) + c2 (s^2 - 2 tau s
    # + 2 tau^2); each 1 ms sub-step holds its end value: a lead of about half a step
    tau, span, y0 = 0.1, 0.4, 2.0
    c0, c1, c2 = 1.0, 3.0, -2.0
    stages, prev = np.full((1, 1), y0), np.zeros((2, 1))
    lowpass_bridge(tau, stages, prev, span, DT, np.array([c0]), np.array([c1]), np.array([c2]))

    def particular(s: float) -> float:
        return c0 + c1 * (s - tau) + c2 * (s * s - 2.0 * tau * s + 2.0 * tau * tau)

    exact = particular(span) + (y0 - particular(0.0)) * math.exp(-span / tau)
    lead = 0.5 * DT * abs(c1 + 2.0 * c2 * span)
    assert stages[0, 0] == pytest.approx(exact, abs=1.5 * lead)
    assert stages[0, 0] != pytest.approx(exact, abs=1e-2 * lead)  # the lead is there
    assert prev[1, 0] == pytest.approx(c0 + c1 * span + c2 * span * span, rel=1e-12)


def _estimator_across_a_gap(torque_change: float) -> list[tuple[float, bool]]:
    """Steady driving at 15 m/s with constant torques, 200 ms of nothing at t = 2 s, after
    which each wheel torque has changed by `torque_change` [N m]."""
    est = Estimator(VEHICLE, EstimatorConfig())
    v = 15.0
    omega = np.full(4, v / VEHICLE.effective_radius)
    torque = np.full(4, 40.0)
    out = []
    for tk in _stamps_with_hole(3.0, 2.0, 0.2):
        change = torque_change if tk >= 2.0 else 0.0
        e = est.update(tk, omega, np.zeros(4), v, 0.0, torque + change)
        out.append((float(tk), bool(e.slope_valid)))
    assert est.faults.counts['gap'] == 0
    return out


def test_the_slope_holds_through_a_gap_and_settles_after_a_hidden_transient() -> None:
    weight = VEHICLE.mass * VEHICLE.gravity
    radius = VEHICLE.effective_radius
    # a force change below GAP_FORCE_CHANGE * weight across the gap: valid throughout
    small = _estimator_across_a_gap(0.5 * GAP_FORCE_CHANGE * weight * radius / 4.0)
    assert all(valid for tk, valid in small if tk > 1.5)
    # above: invalid (held) for (order + 1) * slope_filter_tau = 0.3 s after the gap
    large = _estimator_across_a_gap(2.0 * GAP_FORCE_CHANGE * weight * radius / 4.0)
    invalid = [tk for tk, valid in large if tk > 1.5 and not valid]
    assert invalid[0] == pytest.approx(2.2)
    assert invalid[-1] == pytest.approx(2.5, abs=1.5 * DT)
    assert len(invalid) in (300, 301)  # 2.2 + 0.3 in floating point: 2.5 itself or not


def _synthetic_gaps(
    noise: float,
) -> tuple[np.ndarray, np.ndarray, tuple[SyntheticTrajectory, np.ndarray]]:
    t = np.round(np.arange(0.0, 8.0, DT), 9)
    traj = synthetic_trajectory(t, VEHICLE)
    rng = np.random.default_rng(7)
    speed = traj.speed + rng.normal(0.0, noise, t.size)
    keep = (np.round(t * 1000).astype(np.int64) % 1000) >= 200  # 200 ms of every second
    return t, keep, (traj, speed)


def test_the_cascade_rides_through_200_ms_gaps_on_the_analytic_trajectory() -> None:
    t, keep, (traj, speed) = _synthetic_gaps(0.05)
    config = ObserverConfig(wheel_lipschitz=1000.0, speed_lipschitz=100.0)

    def slope_rms(mask: np.ndarray) -> tuple[float, float, dict[str, int]]:
        est = run_cascade(
            CascadeSeries(t[mask], traj.angle[mask], speed[mask], traj.torque[mask]),
            CascadeSettings(VEHICLE, observer=config),
        )
        late = est.slope_valid & (t[mask] > 1.5)
        err = est.slope[late] - traj.slope[mask][late]
        share = float(est.slope_valid[t[mask] > 1.5].mean())
        return float(np.degrees(np.sqrt(np.mean(err**2)))), share, est.faults

    lossless, lossless_share, _ = slope_rms(np.ones(t.size, bool))
    gapped, gapped_share, faults = slope_rms(keep)
    assert faults['wheel.gap'] == faults['speed.gap'] == faults['estimator.gap'] == 0
    # with every stamp after a gap estimated: measured 1.22x (0.219 deg against 0.179, seeded);
    # the bound leaves 6 % for another platform's floating point, far inside the 1.5x
    assert gapped <= 1.3 * lossless, (gapped, lossless)
    assert gapped_share >= 0.95 * lossless_share


def test_the_live_chain_bridges_a_gap_as_the_offline_cascade() -> None:
    t, keep, (traj, speed) = _synthetic_gaps(0.05)
    n = int(np.searchsorted(t[keep], 3.5))
    tk, angle, v, torque = (
        t[keep][:n],
        traj.angle[keep][:n],
        speed[keep][:n],
        traj.torque[keep][:n],
    )
    offline = run_cascade(CascadeSeries(tk, angle, v, torque), CascadeSettings(VEHICLE))
    chain = Chain(ChainSettings(vehicle=VEHICLE, curves=TyreCurves.from_tire(PARAMS.tire)))
    for k in range(n):
        out = chain.update(float(tk[k]), angle[k], float(v[k]), torque[k])
        assert out.estimates.slope == offline.slope[k]
        assert out.estimates.slope_valid == offline.slope_valid[k]


def _replayed_slope(folder: Path, sim: SimResult, keep: np.ndarray) -> tuple[np.ndarray, ...]:
    """(stamp indexes, slope [rad], valid) of `vd replay` of the run's bag with only the
    stamps `keep` on every sensor topic."""
    stamp_ns = np.round(sim.t * 1e9).astype(np.int64)
    topics = sim_topics(sim)
    for topic in SENSORS:
        topics[topic] = {name: values[keep] for name, values in topics[topic].items()}
    write_topic_arrays_bag(
        folder / 'in', stamp_ns, topics, stamps={topic: stamp_ns[keep] for topic in SENSORS}
    )
    replay_bag(folder / 'in', folder / 'out', progress=False)
    arrays = BagReader(folder / 'out').topic_arrays([ESTIMATES_SLOPE])[ESTIMATES_SLOPE]
    batch = decode_batch('vd_msgs/msg/Slope', arrays.datas)
    index = np.round(batch.stamp_ns * 1e-6).astype(np.int64)  # 1 kHz stamps
    return index, batch.values['angle'], batch.values['valid'].astype(bool)


@pytest.mark.slow
def test_a_bag_with_200_ms_gaps_replays_within_1_5_times_the_lossless_slope_error(
    tmp_path: Path,
) -> None:
    # scripts/eval_loss.py's case gap200: paper_table1 (launch, shifts, slope steps) at 1 kHz
    # with a 96 counts/rev encoder and 0.05 m/s speed noise (seeded), 200 ms of every second
    # lost on every topic; slope RMS where valid, away from the slope steps and shifts
    scenario = load_scenario(PAPER_TABLE1)
    scenario = dataclasses.replace(
        scenario,
        duration=30.0,
        sensors=dataclasses.replace(
            scenario.sensors, encoder_counts_per_rev=96, speed_noise_std=0.05
        ),
    )
    sim = simulate(PARAMS, scenario, rate_hz=1000.0)
    mask = sim.t >= 1.0
    for stamp, text in sim.events:
        if 'slope' in text or 'shift' in text:
            mask &= np.abs(sim.t - stamp) > 0.5
    k = np.arange(sim.t.size)
    figures = {}
    for name, keep in (('lossless', k >= 0), ('gap200', k % 1000 >= 200)):
        (tmp_path / name).mkdir()
        index, angle, valid = _replayed_slope(tmp_path / name, sim, keep)
        assert index.size == keep.sum()  # every stamp estimated
        take = valid & mask[index]
        rms = float(np.sqrt(np.mean((angle[take] - sim.slope[index[take]]) ** 2)))
        figures[name] = (np.degrees(rms), float(valid.mean()))
    (lossless, lossless_valid), (gapped, gapped_valid) = figures['lossless'], figures['gap200']
    assert lossless < 0.3  # docs/performance.md: 0.249 deg
    # measured 1.00x (0.2490 deg against 0.2494); the target was 1.5x
    assert gapped <= 1.05 * lossless, figures
    # the slope settles after the gaps that hid a transient (launch, clutch, wheel spin,
    # shift): valid on 68 % of the stamps against 72 % without loss
    assert gapped_valid >= 0.9 * lossless_valid, figures
