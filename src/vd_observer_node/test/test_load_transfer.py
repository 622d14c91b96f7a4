"""The axle loads through the chassis's vertical dynamics (`axle_loads`): the settled transfer
against the moment balance's closed form, the integration against scipy's exact response of
the same linear model, and the estimated wheel loads against the simulator's bond graph (the
independent oracle of the model's matrices) with and without it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy import signal
from vd_common.vehicle.params import load_vehicle
from vd_observer_node.estimation.axle_loads import (
    VerticalModel,
    axle_transfer_step,
    load_model_params,
)
from vd_observer_node.estimation.cascade import CascadeSeries, CascadeSettings, run_cascade
from vd_observer_node.estimation.observer import ObserverConfig
from vd_observer_node.estimation.vehicle import load_estimator_vehicle

ROOT = Path(__file__).resolve().parents[2]
VEHICLE_FILE = ROOT / 'vd_common' / 'config' / 'clio_rl_1_1.yaml'
SCENARIOS = ROOT / 'vd_sim_node' / 'config' / 'scenarios'
MODEL = VerticalModel.from_params(load_vehicle(VEHICLE_FILE))


def _run(ground: np.ndarray, dt: float) -> np.ndarray:
    """The axle transfers [N] (front, rear) of the step at a fixed rate, started settled."""
    p = load_model_params(MODEL)
    pos, vel = np.full(4, np.nan), np.zeros(4)
    out = np.empty((ground.size, 2))
    for k, g in enumerate(ground):
        axle_transfer_step(p, pos, vel, dt if k else 0.0, float(g), out[k])
    return out


def test_settled_transfer_is_the_moment_balance() -> None:
    """A held ground force settles to -+ h G / L on the axles (formulas.wheel_loads)."""
    g = 3000.0
    out = _run(np.full(20000, g), 1e-3)
    expected = MODEL.cg_height * g / MODEL.wheelbase
    np.testing.assert_allclose(out[0], [-expected, expected], rtol=1e-12)  # started settled
    np.testing.assert_allclose(out[-1], [-expected, expected], rtol=1e-6)


@pytest.mark.parametrize('dt', [1e-3, 1e-2])
def test_integration_follows_the_exact_response(dt: float) -> None:
    """A braking step of 6 kN then a release, at 1 kHz and at 100 Hz (sub-steps of 1 ms):
    within 1.5 % of the step's settled transfer of scipy's exact response of the same linear
    system (measured 0.6 % at both)."""
    t = np.arange(0.0, 3.0, dt)
    ground = np.where((t >= 0.5) & (t < 1.5), -6000.0, 0.0)
    p = load_model_params(MODEL)
    a = np.block([[np.zeros((4, 4)), np.eye(4)], [p.kp, p.kv]])
    b = np.concatenate([np.zeros(4), p.b])[:, None]
    c = np.hstack([p.cp, p.cv])
    # the step holds the NEW stamp's force over the step that ends at it: scipy's zero-order
    # hold of the force one sample later
    held = np.append(ground[1:], ground[-1])
    _, exact, _ = signal.lsim((a, b, c, np.zeros((2, 1))), held, t, interp=False)
    got = _run(ground, dt)
    settled = MODEL.cg_height * 6000.0 / MODEL.wheelbase
    assert np.max(np.abs(got - exact)) < 0.015 * settled


def _load_errors(scenario: str, rigid: bool) -> float:
    """RMS |Fz error| [N] over t > 1 s of the cascade on the simulator's ideal sensors, with
    the Clio file's vertical model or as a rigid body."""
    from vd_sim_node.vehicle.scenario import load_scenario
    from vd_sim_node.vehicle.simulation import simulate

    sim = simulate(load_vehicle(VEHICLE_FILE), load_scenario(SCENARIOS / f'{scenario}.yaml'))
    vehicle = load_estimator_vehicle(VEHICLE_FILE)
    if rigid:
        vehicle = vehicle.with_vertical(None)
    est = run_cascade(
        CascadeSeries(sim.t, sim.wheel_angle, sim.body_speed, sim.wheel_torque),
        CascadeSettings(
            vehicle, observer=ObserverConfig(wheel_lipschitz=10000.0, speed_lipschitz=2000.0)
        ),
    )
    err = (est.fz - sim.fz)[sim.t > 1.0]
    return float(np.sqrt(np.mean(err**2)))


@pytest.mark.parametrize('scenario', ['braking_low_mu_hard', 'launch_low_mu'])
def test_loads_follow_the_simulator(scenario: str) -> None:
    """A braking onto a dry road and a launch: the axle loads swing through the chassis's
    heave and pitch, which the quasi-static balance misses. With the vertical model the
    wheel loads are within a few newtons of the bond graph's (measured 2.4 and 1.7 N RMS;
    rigid 80 and 58 N)."""
    assert _load_errors(scenario, rigid=False) < 5.0
    assert _load_errors(scenario, rigid=True) > 50.0
