"""Online mass inside the estimator (issue 16): Fz, mu, rolling and slope use `mass_used`."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from adaptation_setup import VEHICLE as CLIO
from adaptation_setup import G, model_drive, replay_estimator_config, series
from numpy.typing import NDArray
from vd_observer_node.errors import ConfigurationError
from vd_observer_node.estimation.drivetrain import TORQUE_ENGINE, TORQUE_MEASURED, TORQUE_NONE
from vd_observer_node.estimation.estimator import Estimates, Estimator, EstimatorConfig
from vd_observer_node.estimation.mass_grade import MassGradeConfig

#: rigid, as the model drive's car is (its loads sum to the weight at every stamp)
VEHICLE = CLIO.with_vertical(None)
M0 = VEHICLE.mass
FloatArray = NDArray[np.float64]
Drive = tuple[FloatArray, FloatArray, FloatArray, FloatArray]


def _inputs(drive: Drive) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """Estimator inputs of a `model_drive`: t (N,), omega (N, 4), omega_dot (N, 4), v (N,) and
    torque (N, 4), the wheels rolling without slip and the torques equal, so that the
    estimator's sum Fx is the drive's."""
    t, fx, v, _ = drive
    r = VEHICLE.effective_radius
    accel = np.gradient(v, t)
    omega = np.repeat((v / r)[:, None], 4, axis=1)
    omega_dot = np.repeat((accel / r)[:, None], 4, axis=1)
    inertia = np.array([VEHICLE.inertia_front] * 2 + [VEHICLE.inertia_rear] * 2)
    # Fx_i = (T_i - J_i omega_dot_i) / R = sum Fx / 4
    torque = (fx[:, None] / 4.0) * r + inertia * omega_dot
    return t, omega, omega_dot, v, torque


def _run(drive: Drive, config: EstimatorConfig, source: int = TORQUE_MEASURED) -> list[Estimates]:
    t, omega, omega_dot, v, torque = _inputs(drive)
    accel = np.gradient(v, t)
    est = Estimator(VEHICLE, config, source)
    return [
        est.update(float(t[k]), omega[k], omega_dot[k], float(v[k]), float(accel[k]), torque[k])
        for k in range(t.size)
    ]


ON = EstimatorConfig(mass_adaptation=True)
OFF = EstimatorConfig(mass_adaptation=False)


def test_adaptation_off_publishes_the_files_mass() -> None:
    out = _run(model_drive(M0 + 125.0, duration=3.0), OFF)
    np.testing.assert_array_equal(series(out, 'mass'), M0)
    np.testing.assert_array_equal(series(out, 'mass_used'), M0)
    np.testing.assert_array_equal(series(out, 'mass_std'), 0.0)
    assert not any(e.mass_converged or e.mass_excited for e in out)


@pytest.mark.slow
def test_a_loaded_car_converges_and_fz_mu_slope_use_the_estimated_mass() -> None:
    m_true = M0 + 125.0
    drive = model_drive(m_true, duration=40.0)
    t, slope_true = drive[0], drive[3]
    on, off = _run(drive, ON), _run(drive, OFF)
    converged = series(on, 'mass_converged').astype(bool)
    assert converged[-1] and not converged[0]
    k0 = int(np.argmax(converged))
    mass, used = series(on, 'mass'), series(on, 'mass_used')
    # mass_used: the file's until the estimate's deviation is within use_std_ratio (before
    # convergence), the estimate after
    k_use = int(np.argmax(used != M0))
    assert 0 < k_use <= k0
    np.testing.assert_array_equal(used[:k_use], M0)
    np.testing.assert_array_equal(used[k_use:], mass[k_use:])
    assert np.max(np.abs(mass[k0:] - m_true)) <= 0.02 * m_true
    assert series(on, 'mass_excited')[:k0].any()
    # Before it is used the estimator is today's, bit for bit.
    for name in ('fz', 'mu', 'slope', 'rolling'):
        np.testing.assert_array_equal(
            np.array([getattr(e, name) for e in on[:k_use]]),
            np.array([getattr(e, name) for e in off[:k_use]]),
            err_msg=name,
        )
    # After: the loads carry the estimated weight (sum Fz = m g cos(alpha_prev), 4 wheels).
    late = slice(k_use + 1, None)
    fz_sum = np.array([e.fz.sum() for e in on])[late]
    cos_prev = np.cos(series(on, 'slope'))[k_use:-1]
    np.testing.assert_allclose(fz_sum, used[late] * G * cos_prev, rtol=1e-12)
    # ... and the slope is far better than with the file's mass.
    sel = t >= t[k0] + 1.0
    err_on = np.degrees(series(on, 'slope')[sel] - slope_true[sel])
    err_off = np.degrees(series(off, 'slope')[sel] - slope_true[sel])
    rms_on, rms_off = np.sqrt(np.mean(err_on**2)), np.sqrt(np.mean(err_off**2))
    assert rms_on < 0.15 and rms_off > 4.0 * rms_on


def test_a_drive_that_never_accelerates_keeps_the_nominal_mass_and_says_so() -> None:
    drive = model_drive(M0 + 400.0, duration=30.0, force_steps=False)
    on, off = _run(drive, ON), _run(drive, OFF)
    assert not any(e.mass_converged or e.mass_excited for e in on)
    np.testing.assert_allclose(series(on, 'mass'), M0, rtol=1e-12)
    assert on[-1].mass_std == pytest.approx(0.3 * M0, rel=1e-12)  # the prior, unchanged
    for name in ('fz', 'mu', 'slope', 'rolling', 'fx'):
        np.testing.assert_array_equal(
            np.array([getattr(e, name) for e in on]),
            np.array([getattr(e, name) for e in off]),
            err_msg=name,
        )


def test_a_wrong_mass_is_bounded_and_counted_as_an_estimator_fault() -> None:
    drive = model_drive(5.0 * M0, duration=30.0)
    est = Estimator(VEHICLE, ON)
    t, omega, omega_dot, v, torque = _inputs(drive)
    accel = np.gradient(v, t)
    masses = [
        est.update(float(t[k]), omega[k], omega_dot[k], float(v[k]), float(accel[k]), torque[k])
        for k in range(t.size)
    ]
    mass = series(masses, 'mass')
    assert np.all(np.isfinite(mass))
    assert np.max(mass) <= ON.mass.mass_max_ratio * M0 * (1.0 + 1e-12)
    assert est.faults.counts['mass_clamped'] > 0
    report = est.faults.report()
    assert 'mass_clamped' in report.active


def test_a_time_jump_restarts_the_mass_at_the_files_value() -> None:
    drive = model_drive(M0 + 300.0, duration=40.0)
    t, omega, omega_dot, v, torque = _inputs(drive)
    accel = np.gradient(v, t)
    est = Estimator(VEHICLE, ON)
    for k in range(t.size):
        out = est.update(
            float(t[k]), omega[k], omega_dot[k], float(v[k]), float(accel[k]), torque[k]
        )
    assert out.mass_converged and out.mass_used > M0 + 200.0
    back = est.update(float(t[0]), omega[0], omega_dot[0], float(v[0]), float(accel[0]), torque[0])
    assert est.faults.counts['time_jump_back'] == 1
    assert back.mass == pytest.approx(M0, rel=1e-12) and back.mass_used == M0
    assert not back.mass_converged


def test_held_inputs_and_untrusted_torque_do_not_update_the_mass() -> None:
    drive = model_drive(M0 + 300.0, duration=12.0)
    t, omega, omega_dot, v, torque = _inputs(drive)
    accel = np.gradient(v, t)
    est = Estimator(VEHICLE, ON)
    on_bad, on_good = 0, 0
    for k in range(t.size):
        row = torque[k].copy()
        held = k % 2 == 1  # a non-finite torque: the estimator holds the last one
        trusted = k % 3 != 0  # torque_ok False (the engine path's clutch slipping)
        if held:
            row[1] = math.nan
        e = est.update(
            float(t[k]), omega[k], omega_dot[k], float(v[k]), float(accel[k]), row, trusted
        )
        if held or not trusted:
            on_bad += e.mass_excited
        else:
            on_good += e.mass_excited
    assert on_bad == 0 and on_good > 0


@pytest.mark.parametrize('source', [TORQUE_ENGINE, TORQUE_NONE])
def test_no_adaptation_without_measured_torques(source: int) -> None:
    out = _run(model_drive(M0 + 300.0, duration=15.0), ON, source)
    np.testing.assert_array_equal(series(out, 'mass_used'), M0)
    assert not any(e.mass_excited for e in out)


def test_mass_settings_from_a_flat_or_nested_mapping() -> None:
    flat = EstimatorConfig.from_mapping({'mass_adaptation': True, 'mass.min_speed': 4.0})
    nested = EstimatorConfig.from_mapping({'mass_adaptation': True, 'mass': {'min_speed': 4.0}})
    assert (
        flat
        == nested
        == EstimatorConfig(mass_adaptation=True, mass=MassGradeConfig(min_speed=4.0))
    )
    assert (
        'mass.grade_tau' in EstimatorConfig.setting_keys()
        and 'mass' not in EstimatorConfig.setting_keys()
    )
    with pytest.raises(ConfigurationError, match=r'mass\.nope'):
        EstimatorConfig.from_mapping({'mass.nope': 1.0})
    with pytest.raises(ConfigurationError, match='mass_min_ratio'):
        EstimatorConfig.from_mapping({'mass.mass_min_ratio': 1.5})


def test_vd_replay_config_takes_the_mass_settings(tmp_path: Path) -> None:
    config = replay_estimator_config(
        tmp_path,
        'estimator:\n  mass_adaptation: true\n  mass:\n    min_speed: 2.0\n'
        '  mass.grade_tau: 0.4\n',
    )
    assert config == EstimatorConfig(
        mass_adaptation=True, mass=MassGradeConfig(min_speed=2.0, grade_tau=0.4)
    )
    with pytest.raises(ConfigurationError, match='min_speeed'):
        replay_estimator_config(tmp_path, 'estimator:\n  mass:\n    min_speeed: 2.0\n')
