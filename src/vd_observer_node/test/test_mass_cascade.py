"""The online mass through the whole cascade on simulated cars that are not the file (issue 16).

The robustness cases of the standalone estimator (test_mass_grade.py) and of the estimator
(test_mass_estimator.py), held through `run_cascade` and the per-stamp chain that the nodes
run: no excitation keeps the file's mass and says so, a far wrong mass is bounded and
reported as a fault, a jump back in time restarts at the file's mass, and a loaded car
converges and corrects the slope.
"""

from __future__ import annotations

import numpy as np
import pytest
from adaptation_setup import (
    VEHICLE,
    cascade,
    chain_run,
    looped_record,
    simulated_mass_drive,
    steady_drive,
)
from vd_observer_node.estimation.cascade import CascadeSettings, run_cascade
from vd_observer_node.estimation.estimator import EstimatorConfig
from vd_observer_node.estimation.faults import WARN
from vd_sim_node.vehicle.scenario import VehicleVariant
from vd_sim_node.vehicle.simulation import SimResult

M0 = VEHICLE.mass
ON = EstimatorConfig(mass_adaptation=True)
OFF = EstimatorConfig(mass_adaptation=False)


def _drive(extra_kg: float, duration: float) -> SimResult:
    """The first `duration` s of mass_drive with `extra_kg` on board, encoder and speed noise."""
    return simulated_mass_drive(VehicleVariant(extra_mass_kg=extra_kg), duration)


def test_a_loaded_car_converges_through_the_cascade_and_the_slope_follows() -> None:
    m_true = M0 + 300.0
    sim = _drive(300.0, 60.0)
    on, off = cascade(sim, ON), cascade(sim, OFF)
    assert on.mass_converged[-1]
    k0 = int(np.argmax(on.mass_converged))
    assert np.max(np.abs(on.mass[k0:] - m_true)) <= 0.03 * m_true
    # the estimate is used from the stamp its deviation is within use_std_ratio, before
    # it has converged; the file's mass before that
    k_use = int(np.argmax(on.mass_used != M0))
    assert 0 < k_use <= k0
    assert on.mass_std[k_use] <= ON.mass.use_std_ratio * on.mass[k_use]
    np.testing.assert_array_equal(on.mass_used[:k_use], M0)
    np.testing.assert_array_equal(on.mass_used[k_use:], on.mass[k_use:])
    late = (sim.t >= sim.t[k0] + 1.0) & (np.abs(sim.body_speed) > 1.0)
    rms_on = np.sqrt(np.mean((on.slope - sim.slope)[late] ** 2))
    rms_off = np.sqrt(np.mean((off.slope - sim.slope)[late] ** 2))
    assert rms_on < 0.4 * rms_off
    # the total load is the estimated weight, not the file's
    assert np.mean(np.abs(on.fz[late].sum(axis=1) - sim.fz[late].sum(axis=1))) < 0.4 * np.mean(
        np.abs(off.fz[late].sum(axis=1) - sim.fz[late].sum(axis=1))
    )
    assert on.faults['estimator.mass_clamped'] == 0


def test_a_cruise_that_never_accelerates_keeps_the_files_mass_and_says_so() -> None:
    # 3rd gear at 15 m/s, constant part throttle on a flat road: the force never steps
    sim = steady_drive(
        'cruise', 30.0, throttle=0.15, gear=3, speed=15.0, car=VehicleVariant(extra_mass_kg=400.0)
    )
    on, off = cascade(sim, ON), cascade(sim, OFF)
    assert not on.mass_excited.any() and not on.mass_converged.any()
    np.testing.assert_allclose(on.mass, M0, rtol=1e-12)
    np.testing.assert_array_equal(on.mass_used, M0)
    assert on.mass_std[-1] == pytest.approx(ON.mass.initial_mass_std_ratio * M0, rel=1e-12)
    for name in ('fx', 'fz', 'mu', 'slope', 'rolling'):
        np.testing.assert_array_equal(getattr(on, name), getattr(off, name), err_msg=name)


def test_a_far_wrong_mass_is_bounded_and_reported_on_the_diagnostics() -> None:
    sim = _drive(1500.0, 40.0)  # 2.7 times the file: beyond mass_max_ratio (2)
    mass, reports = chain_run(sim, ON, 'mass')
    assert np.all(np.isfinite(mass))
    assert np.max(mass) <= ON.mass.mass_max_ratio * M0 * (1.0 + 1e-12)
    assert mass[-1] == pytest.approx(ON.mass.mass_max_ratio * M0, rel=1e-9)
    flagged = [r for r in reports if 'estimator.mass_clamped' in r.active]
    assert flagged and all(r.level >= WARN for r in flagged)


def test_a_jump_back_in_time_restarts_the_mass_at_the_files_value() -> None:
    sim = _drive(300.0, 45.0)
    # a looped bag: its first 5 s again at the end
    res = run_cascade(looped_record(sim, 5.0), CascadeSettings(VEHICLE, estimator=ON))
    n = sim.t.size
    assert res.mass_converged[n - 1] and res.mass_used[n - 1] > M0 + 150.0
    assert res.faults['estimator.time_jump_back'] == 1
    assert not res.mass_converged[n:].any()
    np.testing.assert_array_equal(res.mass_used[n:], M0)
    assert res.mass[n] == pytest.approx(M0, rel=1e-12)
