"""Online effective rolling radius (estimation.rolling_radius)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from adaptation_setup import DT, VEHICLE
from numpy.typing import NDArray
from vd_observer_node.errors import ConfigurationError, InputShapeError
from vd_observer_node.estimation.rolling_radius import (
    ROLLING_RADIUS_FAULTS,
    RollingRadiusConfig,
    RollingRadiusEstimator,
    run_rolling_radius,
)

R0 = VEHICLE.effective_radius

FloatArray = NDArray[np.float64]


def _cruise(
    radius: float, duration: float = 40.0, seed: int = 0, front_slip: float = 0.05
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """(t, omega, torque, speed): speed 10-25 m/s; rear wheels free, front wheels driven
    with ``front_slip`` and 80 N m; 0.05 m/s noise on the speed, 0.2 rad/s on omega."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration, DT)
    v = 17.5 + 7.5 * np.sin(2.0 * math.pi * t / 60.0)
    omega = np.empty((t.size, 4))
    omega[:, 2:] = (v / radius)[:, None]
    omega[:, :2] = (v * (1.0 + front_slip) / radius)[:, None]
    omega += 0.2 * rng.standard_normal(omega.shape)
    torque = np.zeros((t.size, 4))
    torque[:, :2] = 80.0
    return t, omega, torque, v + 0.05 * rng.standard_normal(t.size)


@pytest.mark.parametrize('scale', [0.97, 1.0, 1.01])
def test_the_radius_converges_from_the_free_wheels_only(scale: float) -> None:
    t, omega, torque, v = _cruise(scale * R0)
    track = run_rolling_radius(t, omega, torque, v, VEHICLE)
    assert track['converged'][-1]
    assert np.all(track['free_wheels'] == np.where(t > 0.0, 2, 0))  # the rear wheels
    # Issue 16's goal is <= 0.3 % after 60 s of cruise; here 40 s of free rolling.
    assert track['radius'][-1] == pytest.approx(scale * R0, rel=1e-3)
    assert abs(track['radius'][-1] - scale * R0) <= 3.0 * track['radius_std'][-1]
    first = np.argmax(track['converged'])
    assert np.all(np.abs(track['radius'][first:] / (scale * R0) - 1.0) <= 3e-3)
    np.testing.assert_array_equal(track['radius_used'][:first], R0)
    assert track.faults == dict.fromkeys(ROLLING_RADIUS_FAULTS, 0)


def test_no_free_wheel_or_no_speed_keeps_the_file_radius() -> None:
    t, omega, torque, v = _cruise(0.97 * R0, duration=5.0)
    torque[:, 2:] = -50.0  # braked all along
    track = run_rolling_radius(t, omega, torque, v, VEHICLE)
    assert not track['converged'].any() and np.all(track['free_wheels'] == 0)
    np.testing.assert_array_equal(track['radius'], R0)
    slow = run_rolling_radius(t, omega, np.zeros_like(torque), 0.1 * v, VEHICLE)
    np.testing.assert_array_equal(slow['radius'], R0)


def test_the_radius_is_bounded_and_counted() -> None:
    cfg = RollingRadiusConfig()
    t, omega, torque, v = _cruise(1.5 * R0, duration=20.0)
    track = run_rolling_radius(t, omega, torque, v, VEHICLE, cfg)
    assert np.max(track['radius']) <= cfg.scale_max * R0 * (1.0 + 1e-12)
    assert track['radius'][-1] == pytest.approx(cfg.scale_max * R0, rel=1e-12)
    assert track.faults['radius_clamped'] > 0


def test_time_jump_resets_and_bad_inputs_are_counted() -> None:
    t, omega, torque, v = _cruise(0.97 * R0, duration=20.0)
    est = RollingRadiusEstimator(VEHICLE)
    for k in range(t.size):
        out = est.update(float(t[k]), omega[k], torque[k], float(v[k]))
    assert out.converged
    assert est.update(0.0, omega[0], torque[0], float(v[0])).radius == R0
    assert est.faults['time_jump_back'] == 1
    same = est.update(0.0, omega[0], torque[0], float(v[0]))
    assert est.update(0.001, omega[1], torque[1], math.nan) is same
    assert est.update(math.inf, omega[1], torque[1], 1.0) is same
    assert est.faults['duplicate_stamp'] == 1
    assert est.faults['non_finite_value'] == 1 and est.faults['non_finite_stamp'] == 1
    assert est.update(5.0, omega[1], torque[1], float(v[1])).free_time == 0.0
    assert est.faults['gap'] == 1
    with pytest.raises(InputShapeError, match='shape'):
        est.update(5.001, omega[1][:3], torque[1], 1.0)
    with pytest.raises(InputShapeError, match='shape'):
        run_rolling_radius(t, omega[:, :3], torque, v, VEHICLE)


def test_config_is_checked() -> None:
    with pytest.raises(ConfigurationError, match='scale_min'):
        RollingRadiusConfig(scale_min=1.2)
    with pytest.raises(ConfigurationError, match='tau'):
        RollingRadiusConfig(tau=0.0)
    with pytest.raises(ConfigurationError, match='finite'):
        RollingRadiusConfig(min_speed=math.inf)
    with pytest.raises(ConfigurationError, match='unknown'):
        RollingRadiusConfig.from_mapping({'taux': 1.0})
