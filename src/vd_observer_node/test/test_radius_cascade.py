"""The online rolling radius through the whole cascade on simulated cars (issue 16).

The robustness cases of the estimator (test_radius_estimator.py), held through `run_cascade`
and the per-stamp chain the nodes run: tyres 3 % smaller converge and correct Fx and the slip;
a drive without free rolling keeps the file's radius and says so; a radius beyond its bounds
is clamped and reported on the diagnostics; a jump back in time restarts at the file's radius.
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

R0 = VEHICLE.effective_radius
ON = EstimatorConfig(radius_adaptation=True)
OFF = EstimatorConfig()


def _drive(scale: float, duration: float) -> SimResult:
    """The first `duration` s of mass_drive on tyres `scale` times the file's radius."""
    return simulated_mass_drive(VehicleVariant(tyre_radius_scale=scale), duration)


def test_smaller_tyres_converge_through_the_cascade_and_fx_follows() -> None:
    r_true = 0.97 * R0
    sim = _drive(0.97, 90.0)
    on, off = cascade(sim, ON), cascade(sim, OFF)
    assert on.radius_converged[-1]
    k0 = int(np.argmax(on.radius_converged))
    assert abs(on.radius[-1] / r_true - 1.0) < 3e-3
    np.testing.assert_array_equal(on.radius_used[:k0], R0)
    np.testing.assert_array_equal(on.radius_used[k0:], on.radius[k0:])
    late = (sim.t >= sim.t[k0] + 1.0) & (np.abs(sim.body_speed) > 5.0)
    # Fx is proportional to 1/R: its gain on the true force is 0.97 with the file's radius
    truth = sim.fx[late].sum(axis=1)
    gain_on = np.dot(on.fx[late].sum(axis=1), truth) / np.dot(truth, truth)
    gain_off = np.dot(off.fx[late].sum(axis=1), truth) / np.dot(truth, truth)
    assert abs(gain_off - 0.97) < 0.01
    assert abs(gain_on - 1.0) < 0.3 * abs(gain_off - 1.0)
    rear = late[:, None] & np.array([False, False, True, True])
    slip_on = np.mean(np.abs((on.slip - sim.slip)[rear]))
    slip_off = np.mean(np.abs((off.slip - sim.slip)[rear]))
    assert slip_on < 0.3 * slip_off  # the rest is the encoder noise on omega (0.0064)
    assert on.faults['estimator.radius_clamped'] == 0


def test_a_drive_without_free_rolling_keeps_the_files_radius_and_says_so() -> None:
    # a crawl in first gear below radius.min_speed (5 m/s): no wheel is ever used
    sim = steady_drive(
        'crawl', 20.0, throttle=0.02, gear=1, speed=3.0, car=VehicleVariant(tyre_radius_scale=0.97)
    )
    assert np.max(np.abs(sim.body_speed)) < ON.radius.min_speed
    on, off = cascade(sim, ON), cascade(sim, OFF)
    assert not (on.radius_free_wheels > 0).any() and not on.radius_converged.any()
    np.testing.assert_array_equal(on.radius, R0)
    np.testing.assert_array_equal(on.radius_used, R0)
    assert on.radius_std[-1] == pytest.approx(ON.radius.initial_std_ratio * R0, rel=1e-12)
    for name in ('fx', 'fz', 'mu', 'slip', 'slope'):
        np.testing.assert_array_equal(getattr(on, name), getattr(off, name), err_msg=name)


def test_a_radius_beyond_its_bounds_is_clamped_and_reported_on_the_diagnostics() -> None:
    sim = _drive(0.85, 40.0)  # beyond scale_min (0.9)
    radius, reports = chain_run(sim, ON, 'radius_used')
    assert np.all(np.isfinite(radius))
    assert np.min(radius) >= ON.radius.scale_min * R0 * (1.0 - 1e-12)
    assert radius[-1] == pytest.approx(ON.radius.scale_min * R0, rel=1e-9)
    flagged = [r for r in reports if 'estimator.radius_clamped' in r.active]
    assert flagged and all(r.level >= WARN for r in flagged)


def test_a_jump_back_in_time_restarts_the_radius_at_the_files_value() -> None:
    sim = _drive(0.97, 60.0)
    # a looped bag: its first 5 s again at the end
    res = run_cascade(looped_record(sim, 5.0), CascadeSettings(VEHICLE, estimator=ON))
    n = sim.t.size
    assert res.radius_converged[n - 1] and res.radius_used[n - 1] < 0.98 * R0
    assert res.faults['estimator.time_jump_back'] == 1
    assert not res.radius_converged[n:].any()
    np.testing.assert_array_equal(res.radius_used[n:], R0)
    assert res.radius[n] == pytest.approx(R0, rel=1e-12)
