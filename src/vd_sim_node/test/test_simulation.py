"""End-to-end simulator tests: paper scenario, physics checks, sensors, stepping API."""

from __future__ import annotations

import math
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from vd_common.vehicle.params import load_vehicle
from vd_common.vehicle.tire import magic_formula_fx
from vd_sim_node.errors import SimulationError
from vd_sim_node.vehicle.model import VehicleModel
from vd_sim_node.vehicle.scenario import Scenario, load_scenario, parse_scenario
from vd_sim_node.vehicle.simulation import SimResult, Simulator, simulate

ROOT = Path(__file__).resolve().parents[1]
VP = load_vehicle(ROOT.parent / 'vd_common' / 'config' / 'clio_rl_1_1.yaml')
PAPER = load_scenario(ROOT / 'config' / 'scenarios' / 'paper_table1.yaml')
BRAKING = load_scenario(ROOT / 'config' / 'scenarios' / 'braking_low_mu.yaml')
G = VP.environment.gravity
R = VP.wheel.effective_radius
M = VP.chassis.mass


@lru_cache(maxsize=1)
def model() -> VehicleModel:
    return VehicleModel(VP)


@lru_cache(maxsize=1)
def paper_run() -> SimResult:
    return simulate(model(), PAPER)


def _scenario(**kw: Any) -> Scenario:
    return parse_scenario(kw)


def test_paper_scenario_runs_end_to_end_without_nan() -> None:
    r = paper_run()
    n = 150001
    assert r.t.shape == (n,)
    np.testing.assert_allclose(np.diff(r.t), 1e-3, rtol=1e-9)
    for name in SimResult.__dataclass_fields__:
        value = getattr(r, name)
        if isinstance(value, np.ndarray):
            assert value.shape[0] == n, name
            assert np.all(np.isfinite(value)), name
    for name in ('omega', 'omega_dot', 'fx', 'fz', 'mu', 'slip', 'wheel_angle', 'rolling'):
        assert getattr(r, name).shape == (n, 4)
    assert r.gear.dtype.kind == 'i'
    descriptions = [d for _, d in r.events]
    assert 'upshift 1->2' in descriptions and 'throttle 0 -> 1' in descriptions


def test_paper_car_idles_still_until_the_throttle() -> None:
    r = paper_run()
    before = r.t < 8.0
    assert np.max(np.abs(r.speed_true[before])) < 1e-6
    assert np.max(np.abs(r.omega[before])) < 1e-5
    idle = r.engine_speed[before]
    assert np.all((idle > 70.0) & (idle < 90.0))  # ~800 rpm
    after = (r.t > 9.0) & (r.t < 100.0)
    assert np.all(r.speed_true[after] > 1.0)
    assert r.speed_true[np.searchsorted(r.t, 60.0)] > 20.0


def test_paper_run_obeys_the_shared_conventions_exactly() -> None:
    r = paper_run()
    inertia = model().inertia
    # Fx_i = (T_i - J omega_dot_i) / R_eff (wheel torque sensors are ideal in this scenario)
    fx_from_torque = (r.wheel_torque - inertia * r.omega_dot) / R
    np.testing.assert_allclose(fx_from_torque, r.fx, atol=1e-7 * np.max(np.abs(r.fx)))
    # m v_dot = sum Fx - sum F_r - F_aero - m g sin(alpha) (magnitudes signed by motion)
    sign = np.tanh(r.speed_true / VP.rolling_resistance.regularisation_speed)
    rhs = (
        r.fx.sum(axis=1)
        - r.rolling.sum(axis=1) * np.sign(sign)
        - r.aero * np.sign(r.speed_true)
        - M * G * np.sin(r.slope)
    )
    np.testing.assert_allclose(M * r.accel_true, rhs, atol=1e-7 * M * G)
    # utilised friction and slip definitions
    np.testing.assert_allclose(r.mu, r.fx / r.fz, rtol=1e-12)
    wr = r.omega * R
    den = np.maximum(np.maximum(np.abs(wr), np.abs(r.speed_true)[:, None]), 1.0)
    np.testing.assert_allclose(r.slip, (wr - r.speed_true[:, None]) / den, rtol=1e-12)
    # the tyre force is the Magic Formula of exactly this slip (no hidden slip definition)
    mf = magic_formula_fx(r.slip, r.fz, r.road_mu[:, None], VP.tire)
    np.testing.assert_allclose(r.fx, mf, rtol=1e-9, atol=1e-9)
    # ideal sensors are the truth
    np.testing.assert_array_equal(r.wheel_angle, r.angle_true)
    np.testing.assert_array_equal(r.body_speed, r.speed_true)


def test_omega_dot_is_the_derivative_of_omega() -> None:
    r = paper_run()
    # The integral of the exact omega_dot over 1 s windows reproduces the change of omega
    # (a finite difference of omega would only measure the solver's interpolation noise).
    for start in (30.0, 40.0, 60.0, 110.0):
        idx = np.flatnonzero((r.t >= start) & (r.t <= start + 1.0))
        for w in range(4):
            change = r.omega[idx[-1], w] - r.omega[idx[0], w]
            integral = np.trapezoid(r.omega_dot[idx, w], r.t[idx])
            assert integral == pytest.approx(change, abs=1e-5 * (1.0 + abs(r.omega[idx[0], w])))
    # and the wheel angle integrates omega (trapezoid over 15 s)
    idx = np.flatnonzero((r.t > 30.0) & (r.t < 45.0))
    integral = np.trapezoid(r.omega[idx, 0], r.t[idx])
    assert r.angle_true[idx[-1], 0] - r.angle_true[idx[0], 0] == pytest.approx(integral, rel=1e-6)


def test_coasting_in_neutral_decelerates_by_aero_and_rolling_only() -> None:
    r = simulate(model(), _scenario(duration=4.0, initial_speed=25.0, neutral=True), rate_hz=100)
    k = slice(100, None)  # after the initial settling of the suspension
    # wheel spin inertia adds sum(J)/R^2 to the mass that the resistances decelerate
    m_eff = M + model().inertia.sum() / R**2
    expected = -(r.aero[k] + r.rolling[k].sum(axis=1)) / m_eff
    np.testing.assert_allclose(r.accel_true[k], expected, rtol=2e-3)
    assert np.all(r.engine_torque[k] >= -1e-9)  # engine idles, decoupled
    assert r.speed_true[-1] < 25.0


def test_steady_cruise_on_a_slope_needs_grade_plus_resistances() -> None:
    # Full throttle in 4th on a 3 deg grade: the engine runs past its torque peak, so the
    # speed settles (time constant ~20 s) where drive force = grade + resistances.
    alpha_deg = 3.0
    sc = _scenario(
        duration=110.0,
        initial_speed=32.0,
        initial_gear=4,
        signals={'throttle': [[0, 1.0]], 'slope_deg': [[0, alpha_deg]]},
    )
    r = simulate(model(), sc, rate_hz=20)
    i = -1
    alpha = alpha_deg * math.pi / 180.0
    assert r.gear[i] == 4
    assert abs(r.accel_true[i]) < 5e-4  # settled
    resist = M * G * math.sin(alpha) + r.rolling[i].sum() + r.aero[i]
    assert r.fx[i].sum() == pytest.approx(resist, rel=1e-3)
    # the wheels need the engine torque through the gearbox (steady, clutch locked)
    ratio = VP.gearbox.ratios[3] * VP.gearbox.final_drive
    assert r.wheel_torque[i].sum() == pytest.approx(r.engine_torque[i] * ratio, rel=1e-3)
    # quasi-static axle loads follow the whole-vehicle moment balance
    L, a, h = VP.chassis.wheelbase, VP.chassis.cg_to_front_axle, VP.chassis.cg_height
    push = M * r.accel_true[i] + M * G * math.sin(alpha) + r.aero[i]
    front = (M * G * math.cos(alpha) * (L - a) - push * h) / L
    rear = (M * G * math.cos(alpha) * a + push * h) / L
    assert 2 * r.fz[i, 0] == pytest.approx(front, rel=1e-3)
    assert 2 * r.fz[i, 2] == pytest.approx(rear, rel=1e-3)


def test_acceleration_and_top_speed_of_a_clio_1_1() -> None:
    sc = _scenario(duration=120.0, signals={'throttle': [[0, 0.0], [1.0, 1.0]]})
    r = simulate(model(), sc, rate_hz=20)
    t100 = r.t[np.argmax(r.speed_true >= 100.0 / 3.6)] - 1.0
    assert 14.0 <= t100 <= 16.0
    v_max = r.speed_true[-1] * 3.6
    assert 145.0 <= v_max <= 155.0
    assert abs(r.accel_true[-1]) < 0.02  # at (or very near) the top speed


def test_energy_balance_of_the_whole_model() -> None:
    r = simulate(model(), BRAKING, rate_hz=1000)
    dE = np.diff(r.energy_stored)
    net = r.power_sources - r.power_dissipated
    trap = 0.5 * (net[1:] + net[:-1]) * np.diff(r.t)
    # intervals that straddle an input jump (scenario step, shift) are not smooth: skip them
    jumps = np.zeros(len(dE), dtype=bool)
    for t_event, _ in r.events:
        k = round(t_event * 1000.0)
        jumps[max(k - 1, 0) : k + 1] = True
    smooth = ~jumps
    total = np.sum(np.abs(trap[smooth]))
    assert total > 1e5  # a real test: the run moves hundreds of kJ
    assert np.sum(np.abs(dE[smooth] - trap[smooth])) < 1e-4 * total


def test_locked_wheels_on_the_low_mu_patch() -> None:
    r = simulate(model(), BRAKING, rate_hz=200)
    on_patch = (r.t > 15.5) & (r.t < 17.0)
    assert np.all(r.slip[on_patch, :2] < -0.5)  # front wheels locked (no ABS)
    assert np.all(np.abs(r.mu[on_patch]) <= 0.3 * VP.tire.pDx1 * 1.2)
    after = (r.t > 17.3) & (r.t < 17.8)
    assert np.all(r.slip[after, :2] > -0.2)  # they spin up again on dry road
    assert abs(r.speed_true[-1]) < 0.05  # stopped and held


def test_step_matches_simulate_including_noise_and_quantisation() -> None:
    sc = _scenario(
        duration=3.0,
        signals={'throttle': [[0, 0.0], [0.5, 1.0]], 'road_mu': [[0, 1.0], [2.0, 0.5]]},
        sensors={'seed': 3, 'encoder_counts_per_rev': 48, 'speed_noise_std': 0.1},
    )
    whole = simulate(model(), sc)
    sim = Simulator(model(), sc)
    frames = []
    while not sim.done:
        assert sim.t == pytest.approx(len(frames) / 1000.0)
        frames.append(sim.step())
    assert len(frames) == len(whole.t)
    for name in ('wheel_angle', 'body_speed', 'omega', 'omega_dot', 'fx', 'fz', 'gear'):
        stacked = np.array([getattr(f, name) for f in frames])
        np.testing.assert_array_equal(stacked, getattr(whole, name), err_msg=name)
    with pytest.raises(SimulationError):
        sim.step()


def test_sensor_noise_is_seeded_and_encoder_quantised() -> None:
    sc = _scenario(
        duration=2.0,
        initial_speed=10.0,
        neutral=True,
        sensors={'seed': 5, 'encoder_counts_per_rev': 96, 'speed_noise_std': 0.2},
    )
    a = simulate(model(), sc)
    b = simulate(model(), sc)
    c = simulate(model(), sc, seed=6)
    np.testing.assert_array_equal(a.body_speed, b.body_speed)
    assert not np.array_equal(a.body_speed, c.body_speed)
    noise = a.body_speed - a.speed_true
    assert np.std(noise) == pytest.approx(0.2, rel=0.05)
    assert abs(np.mean(noise)) < 0.02
    step = 2.0 * math.pi / 96
    counts = a.wheel_angle / step
    np.testing.assert_allclose(counts, np.round(counts), atol=1e-9)
    assert np.all(a.wheel_angle <= a.angle_true + 1e-12)
    assert np.all(a.angle_true - a.wheel_angle < step)


def test_integration_accuracy_against_tight_reference() -> None:
    sc = _scenario(duration=14.0, signals={'throttle': [[0, 0.0], [1.0, 1.0]]})
    fast = simulate(model(), sc, rate_hz=200)
    tight = simulate(model(), sc, rate_hz=200, rtol=1e-10, atol_scale=1e-2)
    assert [e for e in fast.events] == [e for e in tight.events]
    err = np.abs(fast.omega - tight.omega) / np.maximum(np.abs(tight.omega), 1.0)
    assert np.max(err) < 1e-4


def test_run_only_on_fresh_simulator_and_bad_rate() -> None:
    sim = Simulator(model(), _scenario(duration=0.01))
    sim.step()
    with pytest.raises(SimulationError):
        sim.run()
    with pytest.raises(SimulationError):
        Simulator(model(), _scenario(duration=1.0), rate_hz=-1.0)
