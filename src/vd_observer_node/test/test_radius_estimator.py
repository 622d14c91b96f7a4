"""The online rolling radius inside `Estimator` (issue 16).

Drives: `adaptation_setup.model_drive` on a front-wheel-drive car whose tyres roll with a radius
that is not the file's (the rear wheels report no torque, so they roll freely whenever the
car does not accelerate hard).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from adaptation_setup import VEHICLE, model_drive, replay_estimator_config, series
from numpy.typing import NDArray
from vd_observer_node.errors import ConfigurationError
from vd_observer_node.estimation.drivetrain import TORQUE_ENGINE, TORQUE_MEASURED
from vd_observer_node.estimation.estimator import Estimates, Estimator, EstimatorConfig
from vd_observer_node.estimation.rolling_radius import RollingRadiusConfig

FloatArray = NDArray[np.float64]
R0 = VEHICLE.effective_radius
M0 = VEHICLE.mass
ON = EstimatorConfig(radius_adaptation=True)
BOTH = EstimatorConfig(radius_adaptation=True, mass_adaptation=True, mass_waits_for_radius=True)
EAGER = dataclasses.replace(BOTH, mass_waits_for_radius=False)


def _fwd_inputs(
    mass: float, radius: float, duration: float, **drive: float | bool
) -> tuple[FloatArray, ...]:
    """(t, omega, omega_dot, v, accel, torque) of a FWD car with tyres of ``radius`` [m]."""
    t, fx, v, _ = model_drive(mass, duration=duration, **drive)  # type: ignore[arg-type]
    accel = np.gradient(v, t)
    omega = np.repeat((v / radius)[:, None], 4, axis=1)
    omega_dot = np.repeat((accel / radius)[:, None], 4, axis=1)
    torque = np.zeros((t.size, 4))
    # the front wheels carry the whole force plus every wheel's spin inertia; the rear roll
    inertia = VEHICLE.inertia_front + VEHICLE.inertia_rear
    torque[:, :2] = (fx[:, None] / 2.0) * radius + inertia * omega_dot[:, :2]
    return t, omega, omega_dot, v, accel, torque


def _run(
    config: EstimatorConfig, inputs: tuple[FloatArray, ...], source: int = TORQUE_MEASURED
) -> tuple[Estimator, list[Estimates]]:
    t, omega, omega_dot, v, accel, torque = inputs
    est = Estimator(VEHICLE, config, source)
    out = [
        est.update(float(t[k]), omega[k], omega_dot[k], float(v[k]), float(accel[k]), torque[k])
        for k in range(t.size)
    ]
    return est, out


@pytest.mark.slow
def test_the_radius_converges_and_fx_uses_it() -> None:
    r_true = 0.97 * R0
    inputs = _fwd_inputs(M0, r_true, 60.0)
    _, out = _run(ON, inputs)
    _, off = _run(EstimatorConfig(), inputs)
    conv = series(out, 'radius_converged').astype(bool)
    assert conv.any() and not conv[0]
    k0 = int(np.argmax(conv))
    assert abs(out[-1].radius / r_true - 1.0) < 1e-3
    # before convergence the file's radius, after it the estimate, in Fx and the slip
    assert all(e.radius_used == R0 for e in out[:k0])
    assert all(e.radius_used == e.radius for e in out[k0:])
    assert {e.radius_free_wheels for e in out} >= {0, 2}  # the rear wheels at least
    # Fx sum with the adapted radius is the drive's force (within the radius's error),
    # with the file's it is 3 % short
    _, fx_true, _, _ = model_drive(M0, duration=60.0)
    late = slice(k0 + 100, None)
    err_on = np.abs(_series_sum(out, 'fx')[late] - fx_true[late])
    err_off = np.abs(_series_sum(off, 'fx')[late] - fx_true[late])
    assert np.max(err_on) < 0.2 * np.max(err_off)
    # the slip of rolling wheels is ~0 with the adapted radius, -3 % with the file's
    assert abs(out[-1].slip[2]) < 2e-3 < abs(off[-1].slip[2])


def _series_sum(out: list[Estimates], name: str) -> FloatArray:
    return np.array([float(np.sum(getattr(e, name))) for e in out])


def test_adaptation_off_is_todays_estimator_bit_for_bit() -> None:
    inputs = _fwd_inputs(M0, 0.97 * R0, 5.0)
    _, off = _run(EstimatorConfig(), inputs)
    for e in off:
        assert e.radius == e.radius_used == R0 and e.radius_std == 0.0
        assert not e.radius_converged and e.radius_free_wheels == 0


@pytest.mark.slow
def test_the_mass_waits_for_the_radius_and_then_learns_the_true_mass() -> None:
    r_true, m_true = 0.97 * R0, M0 + 125.0
    inputs = _fwd_inputs(m_true, r_true, 120.0)
    _, out = _run(BOTH, inputs)
    conv = series(out, 'radius_converged').astype(bool)
    k0 = int(np.argmax(conv))
    assert conv.any()
    assert not series(out, 'mass_excited')[:k0].any()
    assert all(e.mass == pytest.approx(M0, rel=1e-12) for e in out[:k0])
    _, eager = _run(dataclasses.replace(BOTH, mass_waits_for_radius=False), inputs)
    assert series(eager, 'mass_excited')[:k0].any()  # the eager one learns on the file's R
    assert out[-1].mass_converged
    assert abs(out[-1].mass / m_true - 1.0) < 0.02


@pytest.mark.slow
def test_without_the_wait_the_early_mass_is_rescaled_when_the_radius_converges() -> None:
    r_true, m_true = 0.97 * R0, M0 + 125.0
    _, out = _run(EAGER, _fwd_inputs(m_true, r_true, 120.0))
    conv = series(out, 'radius_converged').astype(bool)
    k0 = int(np.argmax(conv))
    assert conv.any() and series(out, 'mass_excited')[:k0].sum() > 1000  # it learnt first
    # learnt on Fx = T/R_file, the early mass is the true one times R_true/R_file ...
    assert out[k0 - 1].mass == pytest.approx(m_true * r_true / R0, rel=0.015)
    # ... and is rescaled by R_file/R at the stamp the radius is first used
    jump = out[k0].mass / out[k0 - 1].mass
    assert jump == pytest.approx(R0 / out[k0].radius_used, rel=2e-3)
    assert abs(out[-1].mass / m_true - 1.0) < 0.01


def test_no_free_rolling_keeps_the_files_radius_and_says_so() -> None:
    # every wheel reports a drive torque above max_wheel_torque: never a free wheel
    inputs = list(_fwd_inputs(M0, 0.97 * R0, 20.0))
    inputs[5] = np.full_like(inputs[5], 3.0 * ON.radius.max_wheel_torque)
    _, out = _run(ON, tuple(inputs))
    assert all(e.radius_free_wheels == 0 and not e.radius_converged for e in out)
    assert all(e.radius == e.radius_used == R0 for e in out)
    assert out[-1].radius_std == pytest.approx(ON.radius.initial_std_ratio * R0, rel=1e-12)


def test_a_radius_beyond_its_bound_is_clamped_and_counted() -> None:
    config = dataclasses.replace(ON, radius=RollingRadiusConfig(scale_min=0.99, scale_max=1.01))
    est, out = _run(config, _fwd_inputs(M0, 0.95 * R0, 30.0))
    assert est.faults.counts['radius_clamped'] > 0
    assert min(e.radius for e in out) == pytest.approx(0.99 * R0, rel=1e-12)
    assert all(0.99 * R0 - 1e-15 <= e.radius_used <= 1.01 * R0 + 1e-15 for e in out)


def test_a_time_jump_restarts_at_the_files_radius() -> None:
    t, *rest = _fwd_inputs(M0, 0.97 * R0, 40.0)
    k = 2000
    looped = (np.concatenate([t, t[:k]]), *(np.concatenate([x, x[:k]]) for x in rest))
    est, out = _run(ON, looped)
    assert est.faults.counts['time_jump_back'] == 1
    assert out[t.size - 1].radius_converged
    assert not out[t.size].radius_converged and out[t.size].radius == R0


def test_settings_nested_and_flat_and_a_bad_one() -> None:
    flat = EstimatorConfig.from_mapping({'radius_adaptation': True, 'radius.tau': 100.0})
    nested = EstimatorConfig.from_mapping({'radius_adaptation': True, 'radius': {'tau': 100.0}})
    assert flat == nested and flat.radius.tau == 100.0
    assert 'radius.min_free_time' in EstimatorConfig.setting_keys()
    with pytest.raises(ConfigurationError, match='radius'):
        EstimatorConfig.from_mapping({'radius.bogus': 1.0})


# -- held inputs, a looped record, the clamp and the engine path -------------------------


@pytest.mark.slow
def test_held_inputs_and_a_looped_record_with_both_adaptations() -> None:
    t, omega, omega_dot, v, accel, torque = _fwd_inputs(M0 + 125.0, 0.97 * R0, 60.0)
    torque = torque.copy()
    torque[20000:20100:3, 2] = math.nan  # held inputs: no update there
    k = 2000  # and a looped record
    looped = tuple(np.concatenate([x, x[:k]]) for x in (t, omega, omega_dot, v, accel, torque))
    waiting, out = _run(BOTH, looped)
    assert waiting.faults.counts['time_jump_back'] == 1
    assert waiting.faults.counts['non_finite_value'] == 34
    held = out[20000:20100:3]
    assert all(e.radius_free_wheels == 0 and not e.mass_excited for e in held)
    eager, _ = _run(dataclasses.replace(BOTH, mass_waits_for_radius=False), looped)
    assert eager.last is not None and eager.last.radius_converged is False


def test_the_clamp_is_counted_by_the_estimator() -> None:
    config = dataclasses.replace(ON, radius=RollingRadiusConfig(scale_min=0.99, scale_max=1.01))
    est, _ = _run(config, _fwd_inputs(M0, 0.95 * R0, 20.0))
    assert est.faults.counts['radius_clamped'] > 0


def test_the_engine_path_keeps_the_files_radius() -> None:
    est, out = _run(BOTH, _fwd_inputs(M0, 0.97 * R0, 15.0), source=TORQUE_ENGINE)
    assert not est.radius_adaptation and not est.mass_adaptation
    assert est.last is not None and est.last.radius_used == R0
    assert all(e.radius == e.radius_used == R0 and e.radius_free_wheels == 0 for e in out)


def test_vd_replay_config_takes_the_radius_settings(tmp_path: Path) -> None:
    config = replay_estimator_config(
        tmp_path,
        'estimator:\n  radius_adaptation: true\n  radius:\n    min_speed: 2.0\n'
        '  radius.tau: 100.0\n  mass_waits_for_radius: false\n',
    )
    assert config == EstimatorConfig(
        radius_adaptation=True,
        radius=RollingRadiusConfig(min_speed=2.0, tau=100.0),
        mass_waits_for_radius=False,
    )
    with pytest.raises(ConfigurationError, match='min_speeed'):
        replay_estimator_config(tmp_path, 'estimator:\n  radius:\n    min_speeed: 2.0\n')
