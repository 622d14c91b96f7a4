"""The online mass without an IMU on drives nobody designed (issue 27 item 3).

Simulator truth as the oracle: an everyday drive (`vd_sim_node.vehicle.everyday`, a tuning
seed of scripts/eval_everyday.py) whose car carries 374 kg more than its file, and the
designed mass_drive with tyres 3 % smaller than the file's, both through the compiled
cascade with mass and radius adaptation on.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from adaptation_setup import PARAMS, VEHICLE, cascade, simulated_mass_drive
from vd_observer_node.estimation.estimator import EstimatorConfig
from vd_sim_node.vehicle.everyday import everyday_scenario
from vd_sim_node.vehicle.scenario import VehicleVariant
from vd_sim_node.vehicle.simulation import simulate

M0 = VEHICLE.mass
ON = EstimatorConfig(mass_adaptation=True, radius_adaptation=True)
OFF = EstimatorConfig()


def test_an_ordinary_drive_excites_the_mass_at_its_first_braking_and_the_slope_uses_it() -> None:
    # seed 4: +374 kg; part throttle on a constant grade, then a braking at 11.72 s
    scenario = everyday_scenario(4, PARAMS)
    sim = simulate(PARAMS, scenario)
    on, off = cascade(sim, ON), cascade(sim, OFF)
    m_true = M0 + scenario.true_vehicle.extra_mass_kg
    first_action = scenario.throttle.times[1]
    assert scenario.brake.values[1] > 0.0 and first_action > 10.0
    t = sim.t
    # the gate rejects the steady part throttle before it (constant force: 1/m unobservable)
    cruise = t < first_action
    assert not on.mass_excited[cruise].any()
    np.testing.assert_array_equal(on.mass_used[cruise], M0)
    # ... and accepts the ordinary braking, within the 2 filter stages of 0.1 s
    k_first = int(np.argmax(on.mass_excited))
    assert first_action < t[k_first] <= first_action + 0.3
    # used from then on, within 2 % of the true mass 1 s later (the file's is 29 % off)
    k = int(np.searchsorted(t, first_action + 1.0))
    assert on.mass_used[k] != M0
    assert abs(on.mass_used[k] - m_true) <= 0.02 * m_true
    # converged means within 2 % (two standard deviations)
    assert on.mass_converged[-1]
    converged = on.mass_converged
    assert np.max(np.abs(on.mass[converged] - m_true)) <= 0.02 * m_true
    # the slope over the whole drive: the file's mass reads the 4.5 deg hill 1.3 deg off
    moving = (t >= 1.0) & (sim.speed_true > 1.0)
    rms_on = math.degrees(float(np.sqrt(np.mean((on.slope - sim.slope)[moving] ** 2))))
    rms_off = math.degrees(float(np.sqrt(np.mean((off.slope - sim.slope)[moving] ** 2))))
    assert rms_off > 1.5
    assert rms_on < 0.2 * rms_off


def test_the_mass_does_not_converge_on_forces_of_a_radius_not_known_yet() -> None:
    # Fx = T/R_file is 3 % high on tyres 3 % small: so is the mass learnt from it until the
    # radius converges (then rescaled). Its deviation includes the radius's error, so even
    # issue 16's criterion (1 sigma within 2 %, which converged at 20.6 s with a 3.3 % error)
    # waits for the radius.
    sim = simulated_mass_drive(VehicleVariant(tyre_radius_scale=0.97), 60.0)
    mass_config = dataclasses.replace(ON.mass, converged_std_ratio=0.02, min_excited_time=5.0)
    for config in (ON, dataclasses.replace(ON, mass=mass_config)):
        on = cascade(sim, config)
        assert on.radius_converged[-1] and on.mass_converged[-1]
        k_radius = int(np.argmax(on.radius_converged))
        assert not on.mass_converged[:k_radius].any()
        # closed form: var(m)/m^2 >= ((R_used - R_hat)^2 + var(R_hat)) / R_used^2
        radius_error = np.hypot(on.radius_used - on.radius, on.radius_std) / on.radius_used
        assert np.all(on.mass_std >= on.mass * radius_error * (1.0 - 1e-9))
        converged = on.mass_converged
        assert np.max(np.abs(on.mass[converged] - M0)) <= 0.02 * M0
