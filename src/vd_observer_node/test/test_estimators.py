"""Estimator formulas and the online estimator on exact synthetic trajectories."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from vd_observer_node.errors import ConfigurationError, InputShapeError
from vd_observer_node.estimation import formulas as phys
from vd_observer_node.estimation.estimator import Estimator, EstimatorConfig
from vd_observer_node.estimation.vehicle import load_estimator_vehicle
from vd_observer_node.testing.synthetic import TrajectoryShape, synthetic_trajectory

VEHICLE_FILE = Path(__file__).resolve().parents[2] / 'vd_common' / 'config' / 'clio_rl_1_1.yaml'
#: rigid, as the synthetic trajectory's loads are (the vertical model's: test_load_transfer)
VEHICLE = load_estimator_vehicle(VEHICLE_FILE).with_vertical(None)
NO_FILTER = EstimatorConfig(slope_filter_tau=0.0, force_filter_tau=0.0)


def test_fx_inverts_the_wheel_spin_balance() -> None:
    rng = np.random.default_rng(0)
    fx = rng.normal(0.0, 2000.0, (50, 4))
    omega_dot = rng.normal(0.0, 30.0, (50, 4))
    torque = VEHICLE.wheel_inertia * omega_dot + VEHICLE.effective_radius * fx
    np.testing.assert_allclose(phys.tire_longitudinal_force(torque, omega_dot, VEHICLE), fx)


@settings(max_examples=100, deadline=None)
@given(
    ground=st.floats(-8000.0, 8000.0),
    alpha=st.floats(-0.3, 0.3),
)
def test_wheel_loads_balance_weight_and_pitch_moment(ground: float, alpha: float) -> None:
    fz = phys.wheel_loads(ground, math.cos(alpha), VEHICLE)
    if np.all(fz > 0.0):
        weight = VEHICLE.mass * VEHICLE.gravity * math.cos(alpha)
        assert fz.sum() == pytest.approx(weight, rel=1e-12)
        # Moment about the CG: front load * a - rear load * b = -G * h.
        front, rear = fz[0] + fz[1], fz[2] + fz[3]
        moment = front * VEHICLE.cg_to_front_axle - rear * VEHICLE.cg_to_rear_axle
        assert moment == pytest.approx(-ground * VEHICLE.cg_height, abs=1e-9 * weight)
    assert np.all(fz >= 0.0)


def test_resistances_follow_paper_eq7_and_drag() -> None:
    fz = np.array([2700.0, 2700.0, 1700.0, 1700.0])
    v = 25.0
    expected = 0.01 * (1.0 + 3.6 * 25.0 / 160.0) * fz
    np.testing.assert_allclose(phys.rolling_resistance(v, fz, VEHICLE), expected)
    assert phys.aero_drag(v, VEHICLE) == pytest.approx(0.5 * 1.225 * 0.33 * 1.85 * 625.0)
    assert phys.aero_drag(-v, VEHICLE) == pytest.approx(phys.aero_drag(v, VEHICLE))


def test_friction_flags_unloaded_and_unexcited_wheels() -> None:
    fx = np.array([500.0, 10.0, 500.0, -800.0])
    fz = np.array([2500.0, 2500.0, 50.0, 2000.0])
    mu, valid = phys.utilised_friction(fx, fz, min_load=170.0, min_excitation_ratio=0.02)
    assert list(valid) == [True, False, False, True]
    np.testing.assert_allclose(mu, [0.2, 0.0, 0.0, -0.4])


def test_slip_ratio_sign_and_standstill() -> None:
    r = VEHICLE.effective_radius
    slip = phys.slip_ratio(np.array([11.0, 10.0, 9.0, 0.0]) / r, 10.0, VEHICLE)
    np.testing.assert_allclose(slip, [1.0 / 11.0, 0.0, -0.1, -1.0])
    assert np.all(np.isfinite(phys.slip_ratio(np.zeros(4), 0.0, VEHICLE)))


def test_slope_is_clamped_and_flagged() -> None:
    weight = VEHICLE.mass * VEHICLE.gravity
    alpha, valid = phys.slope_from_forces(np.array([0.1 * weight, 2.0 * weight]), VEHICLE, 0.5)
    assert alpha[0] == pytest.approx(math.asin(0.1))
    assert alpha[1] == pytest.approx(0.5)
    assert list(valid) == [True, False]


@pytest.mark.parametrize('source', ['tire_forces', 'acceleration'])
def test_online_estimator_recovers_exact_synthetic_truth(source: str) -> None:
    t = np.arange(0.0, 6.0, 1e-3)
    traj = synthetic_trajectory(t, VEHICLE)
    config = EstimatorConfig(slope_filter_tau=0.0, load_transfer_source=source)
    estimator = Estimator(VEHICLE, config)
    slopes, fz, fx = [], [], []
    for k in range(t.size):
        est = estimator.update(
            t[k], traj.omega[k], traj.omega_dot[k], traj.speed[k], traj.accel[k], traj.torque[k]
        )
        assert est.slope_valid
        slopes.append(est.slope)
        fz.append(est.fz)
        fx.append(est.fx)
    np.testing.assert_allclose(np.array(fx), traj.fx, atol=1e-6)
    # The slope is exact once a previous slope exists (the rolling sum uses its cosine) ...
    np.testing.assert_allclose(slopes[1:], traj.slope[1:], atol=1e-6)
    # ... and Fz uses the previous stamp's slope: a lag of one step of a slowly varying angle.
    np.testing.assert_allclose(np.array(fz)[1:], traj.fz[1:], rtol=1e-4)


def test_slope_filter_delays_but_keeps_a_constant_slope() -> None:
    t = np.arange(0.0, 3.0, 1e-3)
    traj = synthetic_trajectory(
        t, VEHICLE, TrajectoryShape(slope_amplitude=0.0, accel_amplitude=0.0)
    )
    estimator = Estimator(VEHICLE, EstimatorConfig(slope_filter_tau=0.05))
    for k in range(t.size):
        est = estimator.update(
            t[k], traj.omega[k], traj.omega_dot[k], traj.speed[k], traj.accel[k], traj.torque[k]
        )
    assert est.slope == pytest.approx(traj.slope[-1], abs=1e-9)


def test_invalid_inputs_give_finite_flagged_outputs() -> None:
    t = np.arange(0.0, 1.0, 1e-3)
    traj = synthetic_trajectory(t, VEHICLE)
    estimator = Estimator(VEHICLE, NO_FILTER)
    for k in range(500):
        estimator.update(
            t[k], traj.omega[k], traj.omega_dot[k], traj.speed[k], traj.accel[k], traj.torque[k]
        )
    good = estimator.last
    assert good is not None
    omega_dot = traj.omega_dot[500].copy()
    omega_dot[1] = np.nan
    est = estimator.update(t[500], traj.omega[500], omega_dot, np.inf, np.nan, traj.torque[500])
    for value in (est.fx, est.fz, est.mu, est.slip, est.rolling, est.aero, est.slope):
        assert np.all(np.isfinite(value))
    assert not est.mu_valid.any()
    assert not est.slope_valid
    assert est.slope == good.slope
    repeated = estimator.update(
        t[500], traj.omega[500], traj.omega_dot[500], 10.0, 0.0, traj.torque[500]
    )
    assert repeated is est
    assert estimator.rejected_count == 1
    for k in range(501, t.size):
        est = estimator.update(
            t[k], traj.omega[k], traj.omega_dot[k], traj.speed[k], traj.accel[k], traj.torque[k]
        )
    assert est.slope_valid
    assert est.slope == pytest.approx(traj.slope[-1], abs=1e-6)


def test_slope_held_at_standstill() -> None:
    estimator = Estimator(VEHICLE, NO_FILTER)
    est = estimator.update(0.0, np.zeros(4), np.zeros(4), 0.0, 0.0, np.full(4, 300.0))
    assert not est.slope_valid
    assert est.slope == 0.0


def test_estimator_input_and_config_errors() -> None:
    estimator = Estimator(VEHICLE)
    with pytest.raises(InputShapeError):
        estimator.update(0.0, np.zeros(3), np.zeros(4), 1.0, 0.0, np.zeros(4))
    with pytest.raises(ConfigurationError):
        EstimatorConfig(load_transfer_source='magic')
    with pytest.raises(ConfigurationError):
        EstimatorConfig(slope_filter_tau=-1.0)
    with pytest.raises(ConfigurationError):
        EstimatorConfig.from_mapping({'unknown': 1})
    assert EstimatorConfig.from_mapping({'min_speed': 1.0}).min_speed == 1.0
