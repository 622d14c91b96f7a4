"""Low-pass filter, observer wrappers and the offline cascade on synthetic data."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy import signal
from vd_observer_node.errors import ConfigurationError, InputShapeError
from vd_observer_node.estimation.cascade import CascadeSeries, CascadeSettings, run_cascade
from vd_observer_node.estimation.estimator import EstimatorConfig
from vd_observer_node.estimation.filters import LowPass, mode_step
from vd_observer_node.estimation.observer import Observer, ObserverConfig
from vd_observer_node.estimation.vehicle import load_estimator_vehicle
from vd_observer_node.testing.synthetic import synthetic_trajectory

VEHICLE_FILE = Path(__file__).resolve().parents[2] / 'vd_common' / 'config' / 'clio_rl_1_1.yaml'
#: rigid, as the synthetic trajectory's loads are
VEHICLE = load_estimator_vehicle(VEHICLE_FILE).with_vertical(None)


def test_lowpass_step_response_and_derivative() -> None:
    tau = 0.1
    lp = LowPass(tau, order=1)
    lp.update(0.0, 0.0)
    out = 0.0
    for _ in range(100):
        out = float(lp.update(1e-3, 1.0))
    assert out == pytest.approx(1.0 - math.exp(-1.0), rel=1e-9)
    # The output's rate over the last step: (y_k - y_(k-1)) / dt.
    previous = 1.0 - math.exp(-0.099 / tau)
    assert float(lp.derivative()) == pytest.approx((out - previous) / 1e-3, rel=1e-6)


@pytest.mark.parametrize(('frequency', 'zeta'), [(1.57, 0.45), (1.0, 0.1), (3.0, 1.2)])
def test_mode_step_follows_the_second_order_step_response(frequency: float, zeta: float) -> None:
    """x'' = w^2 (u - x) - 2 zeta w x' (the body pitch of `gyro_grade`) for a unit step of u
    at 1 kHz: scipy's exact response of w^2 / (s^2 + 2 zeta w s + w^2) and its rate."""
    w = 2.0 * math.pi * frequency
    dt = 1e-3
    t = np.arange(0.0, 4.0, dt)
    x, rate = 0.0, 0.0
    xs, rates = [], []
    for _ in t:
        xs.append(x)
        rates.append(rate)
        x, rate = mode_step(w, zeta, dt, 1.0, x, rate)
    system = signal.lti([w * w], [1.0, 2.0 * zeta * w, w * w])
    _, exact = signal.step(system, T=t)
    _, exact_rate = signal.impulse(system, T=t)
    # first order in w dt: measured 0.003-0.005 of the step, 0.1-1 % of the peak rate
    assert np.max(np.abs(np.asarray(xs) - exact)) < 0.01
    np.testing.assert_allclose(rates, exact_rate, atol=0.02 * np.max(np.abs(exact_rate)))


def test_lowpass_derivative_of_a_ramp_is_its_slope() -> None:
    lp = LowPass(0.05, order=2)
    t = np.arange(0.0, 2.0, 1e-3)
    for tk in t:
        lp.update(1e-3, 3.0 * tk)
    assert float(lp.derivative()) == pytest.approx(3.0, rel=1e-9)


def test_lowpass_passthrough_and_errors() -> None:
    assert float(LowPass(0.0).update(0.1, 5.0)) == 5.0
    with pytest.raises(ConfigurationError):
        LowPass(-1.0)
    with pytest.raises(ConfigurationError):
        LowPass(0.1, order=0)


def test_observer_config_from_mapping() -> None:
    cfg = ObserverConfig.from_mapping(
        {'l0': 3.0, 'wheel_lipschitz': 50.0, 'discretization': 'euler'}
    )
    assert cfg.gains.l0 == 3.0 and cfg.wheel_lipschitz == 50.0
    with pytest.raises(ConfigurationError):
        ObserverConfig.from_mapping({'bogus': 1})
    with pytest.raises(ConfigurationError):
        ObserverConfig(discretization='rk4')
    with pytest.raises(ConfigurationError):
        ObserverConfig(speed_lipschitz=0.0)


def test_observer_tracks_synthetic_wheels_and_speed() -> None:
    t = np.arange(0.0, 3.0, 1e-3)
    traj = synthetic_trajectory(t, VEHICLE)
    observer = Observer(ObserverConfig(wheel_lipschitz=1000.0, speed_lipschitz=100.0))
    for k in range(t.size):
        out = observer.update(t[k], traj.angle[k], traj.speed[k])
    np.testing.assert_allclose(out.omega, traj.omega[-1], rtol=1e-4)
    np.testing.assert_allclose(out.omega_dot, traj.omega_dot[-1], atol=0.05)
    assert out.accel == pytest.approx(traj.accel[-1], abs=0.01)
    with pytest.raises(InputShapeError):
        observer.wheels.update(10.0, np.zeros(3))


def test_cascade_on_synthetic_sensors_with_jittery_stamps() -> None:
    rng = np.random.default_rng(5)
    t = np.concatenate(([0.0], np.cumsum(rng.uniform(0.7e-3, 1.3e-3, 4000))))
    traj = synthetic_trajectory(t, VEHICLE)
    est = run_cascade(
        CascadeSeries(t, traj.angle, traj.speed, traj.torque),
        CascadeSettings(
            VEHICLE,
            observer=ObserverConfig(wheel_lipschitz=1000.0, speed_lipschitz=100.0),
            estimator=EstimatorConfig(slope_filter_tau=0.02),
        ),
    )
    late = t > 1.0
    # The slope filter (2 stages of 20 ms) delays the slowly varying slope by ~40 ms.
    slope_err = np.degrees(np.abs(est.slope - traj.slope)[late])
    assert slope_err.max() < 0.1
    fx_err = np.abs(est.fx - traj.fx)[late]
    assert fx_err.max() < 0.01 * np.abs(traj.fx).max()
    np.testing.assert_allclose(est.fz[late], traj.fz[late], rtol=2e-3)
    assert est.slope_valid[late].all()
    # Wheels clearly excited (|Fx| > 5 % Fz) must be flagged valid, mu close to the truth.
    excited = late[:, None] & (np.abs(traj.fx) > 0.05 * traj.fz)
    assert excited.sum() > 1000
    assert est.mu_valid[excited].all()
    assert np.abs(est.mu - traj.fx / traj.fz)[excited].max() < 0.005


def test_cascade_rejects_bad_shapes() -> None:
    with pytest.raises(InputShapeError):
        run_cascade(
            CascadeSeries(np.zeros(3), np.zeros((3, 4)), np.zeros(2), np.zeros((3, 4))),
            CascadeSettings(VEHICLE),
        )
    with pytest.raises(ConfigurationError):
        run_cascade(
            CascadeSeries(np.zeros(1), np.zeros((1, 4)), np.zeros(1), np.zeros((1, 4))),
            CascadeSettings(VEHICLE, estimator_speed='guess'),
        )
