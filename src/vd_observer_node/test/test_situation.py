"""SituationMonitor: the composition the node and replay run, against its parts."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

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
    # the monitor's fast observer keeps its L (it does not follow the angles' resolution)
    fast = WheelObserver(ObserverConfig(wheel_lipschitz=5000.0, follow_resolution=False))
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


def _cascade_of(rows: list[tuple[float, ...]]) -> tuple[np.ndarray, ...]:
    """The drive's rows as record arrays, and a CascadeResult-like object of its omega, mu."""
    t = np.array([r[0] for r in rows])
    angle = np.array([r[1] for r in rows])
    speed = np.array([r[2] for r in rows])
    torque = np.array([r[3] for r in rows])
    return t, angle, speed, torque


def test_run_situation_equals_the_stamp_by_stamp_monitor() -> None:
    """run_situation (the block) against `update` per stamp (the same block on one stamp),
    across a looped record (the second half starts again at t = 0)."""
    from types import SimpleNamespace

    from vd_observer_node.situation.monitor import run_situation

    curves = TyreCurves.from_tire(load_vehicle(VEHICLE_FILE).tire)
    rows = drive(600, np.random.default_rng(5))
    rows = rows + rows  # looped
    t, angle, speed, torque = _cascade_of(rows)
    omega = np.array([r[4] for r in rows])
    mu = np.array([r[5] for r in rows])
    cascade: Any = SimpleNamespace(
        t=t, omega=omega, mu=mu, mu_valid=np.ones((t.size, 4), bool), fz=np.full((t.size, 4), 3e3)
    )
    config = SituationConfig(max_observer_disagreement=0.5)
    for make, run in ((SituationMonitor, run_situation),):
        stepped = make(curves, STATIC, RADIUS, situation=config)
        whole = make(curves, STATIC, RADIUS, situation=config)
        # in two blocks: the state carries across them
        halves = [slice(0, 900), slice(900, t.size)]
        parts = [
            run(
                whole,
                angle[h],
                speed[h],
                torque[h],
                SimpleNamespace(**{k: v[h] for k, v in vars(cascade).items()}),
            )
            for h in halves
        ]
        for k in range(t.size):
            out = stepped.update(
                t[k], angle[k], speed[k], torque[k], omega[k], mu[k], [1] * 4, [3e3] * 4
            )
            part, i = (parts[0], k) if k < 900 else (parts[1], k - 900)
            np.testing.assert_array_equal(part.mu_max[i], out.potential.mu_max)
            np.testing.assert_array_equal(part.confidence[i], out.potential.confidence)
            np.testing.assert_array_equal(part.road_class[i], out.potential.road_class)
            assert part.vehicle_road_class[i] == out.potential.vehicle_road_class()
            assert part.level[i].ravel().tolist() == [a.level for a in out.alerts]
            np.testing.assert_array_equal(part.onset[i].ravel(), [a.onset for a in out.alerts])
            np.testing.assert_array_equal(
                part.detected[i].ravel(), [a.detected for a in out.alerts]
            )
        assert parts[1].level.any()
        # the wrapped parts' results follow the records after a block
        np.testing.assert_array_equal(  # nan == nan here
            [(a.level, a.onset, a.detected) for a in whole.monitor.last],
            [(a.level, a.onset, a.detected) for a in stepped.monitor.last],
        )
        np.testing.assert_array_equal(whole.friction.last.mu_max, stepped.friction.last.mu_max)
