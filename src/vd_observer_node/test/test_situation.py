"""SituationMonitor: the composition the node and replay run, against its parts."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from vd_common.vehicle.params import load_vehicle
from vd_common.vehicle.tire import slip_ratio
from vd_observer_node.errors import ConfigurationError
from vd_observer_node.estimation.observer import ObserverConfig, WheelObserver
from vd_observer_node.situation.alerts import AlertMonitor, slip_velocity
from vd_observer_node.situation.friction_potential import FrictionPotentialEstimator, TyreCurves
from vd_observer_node.situation.monitor import SituationConfig, SituationMonitor

VEHICLE_FILE = Path(__file__).resolve().parents[2] / 'vd_common' / 'config' / 'clio_rl_1_1.yaml'
RADIUS = 0.29  # [m]
STATIC = np.array([3300.0, 2400.0])  # [N]


def drive(n: int, rng: np.random.Generator) -> list[tuple[float, ...]]:
    """Synthetic stamps: a wheel spinning up under drive torque, then braking to a lock."""
    rows = []
    angle = np.zeros(4)
    for k in range(n):
        t = k * 0.001
        v = 10.0 + 2.0 * t
        slip = (
            np.array([0.3, 0.3, 0.01, 0.01]) * min(1.0, t / 0.2) if t < 0.5 else np.full(4, -0.4)
        )
        omega = v * (1.0 + slip) / RADIUS
        angle = angle + omega * 0.001
        torque = np.where(slip > 0, 600.0, -900.0) * (np.arange(4) < 2 if t < 0.5 else 1.0)
        mu = np.clip(8.0 * slip, -0.3, 0.3) + rng.normal(0.0, 0.01, 4)
        rows.append((t, angle.copy(), v, torque, omega, mu, np.full(4, 3000.0)))
    return rows


def test_monitor_equals_its_parts() -> None:
    curves = TyreCurves.from_tire(load_vehicle(VEHICLE_FILE).tire)
    config = SituationConfig(alert_wheel_lipschitz=5000.0)
    monitor = SituationMonitor(curves, STATIC, RADIUS, situation=config)
    fast = WheelObserver(ObserverConfig(wheel_lipschitz=5000.0))
    friction = FrictionPotentialEstimator(curves, STATIC)
    alerts = AlertMonitor()
    rng = np.random.default_rng(2)
    raised = False
    for t, angle, v, torque, omega, mu, load in drive(1000, rng):
        valid = np.ones(4, dtype=bool)
        out = monitor.update(t, angle, v, torque, omega, mu, valid, load)
        state = fast.update(t, angle)
        sv = np.where(state.valid, slip_velocity(state.omega, v, RADIUS), 0.0)
        slip = slip_ratio(sv, v, config.slip_floor_speed)
        pot = friction.update(t, slip_velocity(omega, v, RADIUS), v, mu, valid, load)
        ref = alerts.update(
            t, slip, sv, torque, mu, valid, pot.wheel_mu_max(), pot.wheel_slip_peak()
        )
        np.testing.assert_array_equal(out.slip, slip)
        np.testing.assert_array_equal(out.potential.mu_max, pot.mu_max)
        assert [(a.kind, a.wheel, a.level) for a in out.alerts] == [
            (a.kind, a.wheel, a.level) for a in ref
        ]
        np.testing.assert_array_equal(  # nan == nan here: inactive alerts have no onset
            [(a.onset, a.detected) for a in out.alerts], [(a.onset, a.detected) for a in ref]
        )
        raised |= any(a.active for a in out.alerts)
    assert raised  # the spin-up and the lock did raise alerts


def test_a_looped_bag_starts_again() -> None:
    curves = TyreCurves.from_tire(load_vehicle(VEHICLE_FILE).tire)
    monitor = SituationMonitor(curves, STATIC, RADIUS)
    rows = drive(800, np.random.default_rng(3))
    for t, angle, v, torque, omega, mu, load in rows:
        first = monitor.update(t, angle, v, torque, omega, mu, np.ones(4, bool), load)
    assert any(a.active for a in first.alerts)
    # the bag starts again at t = 0: everything is reset, not frozen on the old stamps
    t, angle, v, torque, omega, mu, load = rows[0]
    again = monitor.update(t, angle, v, torque, omega, mu, np.ones(4, bool), load)
    assert again.t == 0.0
    assert not any(a.active for a in again.alerts)
    assert np.all(again.potential.confidence == 0.0)


def test_bad_inputs_give_finite_outputs() -> None:
    curves = TyreCurves.from_tire(load_vehicle(VEHICLE_FILE).tire)
    monitor = SituationMonitor(curves, STATIC, RADIUS)
    nan4 = np.full(4, math.nan)
    for k in range(50):
        t = k * 0.001
        out = monitor.update(
            t, np.full(4, k * 0.03), math.nan, nan4, nan4, nan4, np.ones(4, bool), nan4
        )
        assert np.all(np.isfinite(out.potential.mu_max))
        assert np.all(np.isfinite(out.potential.confidence))
        assert not any(a.active for a in out.alerts)


def test_config_errors() -> None:
    with pytest.raises(ConfigurationError, match='alert_wheel_lipschitz'):
        SituationConfig(alert_wheel_lipschitz=0.0)
    with pytest.raises(ConfigurationError, match='unknown'):
        SituationConfig.from_mapping({'nope': 1.0})


def test_observer_disagreement_gate_keeps_lagging_pairs_out_of_the_fit() -> None:
    curves = TyreCurves.from_tire(load_vehicle(VEHICLE_FILE).tire)
    rows = drive(300, np.random.default_rng(4))
    counts = []
    for gate in (0.0, 0.5):
        monitor = SituationMonitor(
            curves, STATIC, RADIUS, situation=SituationConfig(max_observer_disagreement=gate)
        )
        for t, angle, v, torque, omega, mu, load in rows:
            lagging = omega * 0.9  # the cascade 10 % behind the wheel: off by > 1 m/s
            monitor.update(t, angle, v, torque, lagging, mu, np.ones(4, bool), load)
        counts.append(float(monitor.friction.state.count.sum()))
    assert counts[0] > 0.0
    assert counts[1] == 0.0
