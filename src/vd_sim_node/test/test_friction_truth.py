"""True friction potential: the tabulated MF peak against a brute-force search of the curve.

The table itself, its road classes and axle means are tested with vd_common (test_friction.py).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from vd_common.vehicle.friction import friction_table
from vd_common.vehicle.params import TireParams, load_vehicle
from vd_common.vehicle.tire import magic_formula_fx
from vd_sim_node.vehicle.friction_truth import true_friction_potential
from vd_sim_node.vehicle.scenario import load_scenario
from vd_sim_node.vehicle.simulation import Simulator, simulate

CONFIG = Path(__file__).resolve().parents[1] / 'config'
VEHICLE_FILE = Path(__file__).resolve().parents[2] / 'vd_common' / 'config' / 'clio_rl_1_1.yaml'
TP = load_vehicle(VEHICLE_FILE).tire
TABLE = friction_table(TP)
FINE = np.linspace(0.0, 1.0, 100_001)  # [-] slip grid of the brute-force search, step 1e-5
# [-] per unit road_mu: the table's slip step 1e-4 plus the linear interpolation of the
# (curved) peak slip between its 100 N rows, < 5e-5 over the Clio's loads (1000..5000 N)
SLIP_TOL = 1.5e-4
MU_TOL = 1e-6  # the peak mu is linear in the load and flat at the peak


def brute_peak(
    fz: float, driving: bool, road_mu: float, tire: TireParams = TP
) -> tuple[float, float]:
    """(peak |mu|, |slip| at it) of the simulator's own MF, by search on a fine slip grid."""
    sign = 1.0 if driving else -1.0
    mu = sign * magic_formula_fx(sign * FINE, fz, road_mu, tire) / fz
    k = int(np.argmax(mu))
    return float(mu[k]), float(FINE[k])


def test_matches_brute_force_on_random_wheels() -> None:
    rng = np.random.default_rng(7)
    n = 60
    fz = rng.uniform(1000.0, 5000.0, (n, 4))
    fx = rng.normal(0.0, 1000.0, (n, 4))
    road = rng.uniform(0.1, 1.5, n)
    truth = true_friction_potential(TABLE, fz, fx, road)
    assert truth.mu_max.shape == (n, 4) and truth.axle_mu_max.shape == (n, 2)
    for i in range(n):
        for w in range(4):
            mu, slip = brute_peak(float(fz[i, w]), bool(fx[i, w] >= 0.0), float(road[i]))
            assert truth.mu_max[i, w] == pytest.approx(mu, abs=MU_TOL)
            assert truth.slip_peak[i, w] == pytest.approx(slip, abs=SLIP_TOL * road[i])


def test_light_wheels_are_coarser_but_close() -> None:
    """Below 700 N (a wheel nearly lifting) the peak slip bends faster than the rows: 1e-3."""
    loads = np.array([250.0, 330.0, 450.0, 650.0])
    truth = true_friction_potential(TABLE, loads, np.ones(4), 1.0)
    for w, load in enumerate(loads):
        mu, slip = brute_peak(float(load), True, 1.0)
        assert truth.mu_max[w] == pytest.approx(mu, abs=MU_TOL)
        assert truth.slip_peak[w] == pytest.approx(slip, abs=1e-3)


def test_documented_peaks_scale_with_road_mu() -> None:
    """1.05 at slip 0.148 on dry at 2500 N; 0.315 at 0.044 at road_mu 0.3 (docs/alerts.md)."""
    dry = true_friction_potential(TABLE, np.full(4, 2500.0), np.ones(4), 1.0)
    wet = true_friction_potential(TABLE, np.full(4, 2500.0), np.ones(4), 0.3)
    assert dry.mu_max[0] == pytest.approx(1.05, abs=1e-4)
    assert dry.slip_peak[0] == pytest.approx(0.148, abs=1e-3)
    assert wet.mu_max[0] == pytest.approx(0.315, abs=1e-4)
    assert wet.slip_peak[0] == pytest.approx(0.0444, abs=5e-4)
    mu, slip = brute_peak(2500.0, True, 0.3)
    assert wet.mu_max[0] == pytest.approx(mu, abs=MU_TOL)
    assert wet.slip_peak[0] == pytest.approx(slip, abs=SLIP_TOL * 0.3)


def test_side_follows_the_sign_of_fx() -> None:
    # The Clio's pEx4 (0.0017) makes the sides differ by only 3e-5 in slip: exaggerate the
    # asymmetry so that picking the wrong side would fail the test.
    tire = dataclasses.replace(TP, pEx4=0.5)
    table = friction_table(tire)
    fz = np.full(4, 3000.0)
    truth = true_friction_potential(table, fz, np.array([1.0, 0.0, -1.0, -5.0]), 1.0)
    drive = brute_peak(3000.0, True, 1.0, tire)
    brake = brute_peak(3000.0, False, 1.0, tire)
    assert abs(drive[1] - brake[1]) > 10 * SLIP_TOL
    for w, expect in enumerate((drive, drive, brake, brake)):
        assert truth.slip_peak[w] == pytest.approx(expect[1], abs=SLIP_TOL)


def test_zero_road_gives_zero_potential_and_axles_are_wheel_means() -> None:
    fz = np.array([[2000.0, 3000.0, 1500.0, 1700.0]])
    truth = true_friction_potential(TABLE, fz, np.ones((1, 4)), np.array([0.0]))
    assert np.all(truth.mu_max == 0.0) and np.all(truth.slip_peak == 0.0)
    truth = true_friction_potential(TABLE, fz, np.ones((1, 4)), np.array([0.8]))
    np.testing.assert_allclose(
        truth.axle_mu_max[0],
        [truth.mu_max[0, :2].mean(), truth.mu_max[0, 2:].mean()],
        rtol=0,
        atol=1e-15,
    )


def test_simulator_reports_the_potential_and_the_tyre_never_exceeds_it() -> None:
    """launch_low_mu at 200 Hz: spin-up on the mu 0.25 patch, then dry road again."""
    scenario = load_scenario(CONFIG / 'scenarios' / 'launch_low_mu.yaml')
    vehicle = load_vehicle(VEHICLE_FILE)
    sim = simulate(vehicle, scenario, rate_hz=200.0)
    expect = true_friction_potential(TABLE, sim.fz, sim.fx, sim.road_mu)
    np.testing.assert_array_equal(sim.peak_mu, expect.mu_max)
    np.testing.assert_array_equal(sim.peak_slip, expect.slip_peak)
    # the simulated force is the same MF: |mu| stays below its peak (up to the table's 1e-6)
    assert np.all(np.abs(sim.mu) <= sim.peak_mu + MU_TOL)
    # and the launch on the patch does reach it (the truth is not vacuous)
    patch = (sim.t > 6.0) & (sim.t < 9.0)
    assert np.max(np.abs(sim.mu[patch, 0]) / sim.peak_mu[patch, 0]) > 0.99
    on_patch = true_friction_potential(TABLE, sim.fz[patch], sim.fx[patch], 0.25).mu_max
    np.testing.assert_allclose(sim.peak_mu[patch], on_patch, rtol=0, atol=1e-12)
    # the stepping simulator hands out the same truth frame by frame
    stepper = Simulator(vehicle, scenario, rate_hz=200.0)
    frames = [stepper.step() for _ in range(1300)]
    np.testing.assert_allclose(
        np.array([f.peak_mu for f in frames]), sim.peak_mu[:1300], rtol=1e-9, atol=1e-9
    )
