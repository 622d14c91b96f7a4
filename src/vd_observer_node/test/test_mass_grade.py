"""Online mass and grade estimation (estimation.mass_grade): the RLS step, the estimator."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from adaptation_setup import DT, VEHICLE, G, model_drive
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from numpy.typing import NDArray
from scipy.signal import lfilter
from vd_observer_node.errors import ConfigurationError, InputShapeError
from vd_observer_node.estimation.mass_grade import (
    MASS_GRADE_FAULTS,
    MassGradeConfig,
    MassGradeEstimator,
    forgetting_factor,
    rls_step,
    run_mass_grade,
    slope_with_mass,
)

M0 = VEHICLE.mass

FloatArray = NDArray[np.float64]


# -- the pure RLS step ------------------------------------------------------------------


def _batch_ls(
    theta0: FloatArray,
    cov0: FloatArray,
    phis: FloatArray,
    ys: FloatArray,
    noise_var: float,
    lam: float,
) -> FloatArray:
    """Exponentially weighted least squares with a prior, solved in one go."""
    n = ys.size
    weights = np.power(lam, np.arange(n - 1, -1, -1, dtype=np.float64))  # newest: weight 1
    info = lam**n * np.linalg.inv(cov0) + (phis.T * weights) @ phis / noise_var
    rhs = lam**n * np.linalg.solve(cov0, theta0) + (phis.T * weights) @ ys / noise_var
    return np.asarray(np.linalg.solve(info, rhs), dtype=np.float64)


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    n=st.integers(2, 60),
    lam=st.sampled_from([1.0, 0.99, 0.9]),
)
def test_rls_equals_weighted_batch_least_squares(seed: int, n: int, lam: float) -> None:
    rng = np.random.default_rng(seed)
    theta0 = rng.normal(size=2)
    cov0 = np.diag(rng.uniform(0.5, 2.0, size=2))
    phis = rng.normal(size=(n, 2))
    ys = rng.normal(size=n)
    theta, cov = theta0, cov0
    for k in range(n):
        theta, cov = rls_step(theta, cov, phis[k], float(ys[k]), (lam, lam), 0.3, (True, True))
    expected = _batch_ls(theta0, cov0, phis, ys, 0.3, lam)
    np.testing.assert_allclose(theta, expected, rtol=1e-8, atol=1e-10)


def test_vector_forgetting_scales_each_parameter_and_no_update_keeps_theta() -> None:
    cov = np.array([[4.0, 1.0], [1.0, 2.0]])
    theta, out = rls_step((1.0, 2.0), cov, (1.0, 1.0), 5.0, (0.25, 1.0), 1.0, (False, False))
    np.testing.assert_array_equal(theta, (1.0, 2.0))
    # D P D with D = diag(1/sqrt(0.25), 1) = diag(2, 1)
    np.testing.assert_allclose(out, [[16.0, 2.0], [2.0, 2.0]])


@settings(max_examples=60, deadline=None)
@given(
    phi=arrays(np.float64, 2, elements=st.floats(-1e3, 1e3)),
    y=st.floats(-1e3, 1e3),
    update=st.tuples(st.booleans(), st.booleans()),
    lam=st.tuples(st.floats(0.5, 1.0), st.floats(0.5, 1.0)),
)
def test_a_step_keeps_the_covariance_symmetric_positive_definite_and_held_parameters(
    phi: FloatArray, y: float, update: tuple[bool, bool], lam: tuple[float, float]
) -> None:
    cov0 = np.array([[2.0, 0.5], [0.5, 1.0]])
    theta, cov = rls_step((0.1, -0.2), cov0, phi, y, lam, 0.5, update)
    np.testing.assert_allclose(cov, cov.T, rtol=0, atol=1e-12 * np.abs(cov).max())
    assert np.all(np.linalg.eigvalsh(cov) > 0.0)
    for i, selected in enumerate(update):
        if not selected:
            assert theta[i] == (0.1, -0.2)[i]
    # A measurement never increases the uncertainty of what it updates (after forgetting).
    forgotten = cov0 / np.sqrt(np.outer(lam, lam))
    for i, selected in enumerate(update):
        if selected:
            assert cov[i, i] <= forgotten[i, i] * (1.0 + 1e-12)


def test_forgetting_factor() -> None:
    assert forgetting_factor(1e-3, math.inf) == 1.0
    assert forgetting_factor(0.0, 2.0) == 1.0
    assert forgetting_factor(0.5, 2.0) == pytest.approx(math.exp(-0.25), rel=1e-15)


# -- synthetic drives -------------------------------------------------------------------


def test_the_mass_converges_on_a_drive_with_force_steps_and_a_changing_grade() -> None:
    m_true = M0 + 125.0
    t, fx, v, slope = model_drive(m_true)
    # issue 16's criterion (one standard deviation within 2 %, after 5 s of excitation); the
    # default's (two within 2 %) is tested below
    track = run_mass_grade(
        t, fx, v, VEHICLE, MassGradeConfig(converged_std_ratio=0.02, min_excited_time=5.0)
    )
    assert track['converged'][-1]
    first = t[np.argmax(track['excited'])]
    converged_at = t[np.argmax(track['converged'])]
    # One force step every 3 s: converged within 20 s of the first excitation (issue 16's
    # 15 s goal is measured on the simulator's mass_drive by scripts/eval_mass_adaptation.py).
    assert converged_at - first <= 20.0
    after = track['converged']
    assert np.max(np.abs(track['mass'][after] - m_true)) <= 0.02 * m_true
    assert abs(track['mass'][-1] - m_true) <= 0.005 * m_true
    # Reported uncertainty covers the error at the end.
    assert abs(track['mass'][-1] - m_true) <= 3.0 * track['mass_std'][-1]
    # The slope uses the adapted mass once converged: error far below the nominal one.
    late = t >= converged_at + 1.0
    err = np.degrees(track['slope'][late] - slope[late])
    nominal_err = np.degrees(
        slope_with_mass(track['slope'][late], fx[late], m_true, M0, G) - slope[late]
    )
    # 0.15 deg: the two-stage filter's 0.2 s lag on the grade sine alone is ~0.07 deg RMS.
    assert np.sqrt(np.mean(err**2)) < 0.15
    assert np.sqrt(np.mean(nominal_err**2)) > 4.0 * np.sqrt(np.mean(err**2))
    assert track.faults == dict.fromkeys(MASS_GRADE_FAULTS, 0)


@pytest.mark.parametrize('extra', [125.0, 400.0, -50.0])
def test_the_estimate_is_used_from_its_first_excitation_and_converged_means_within_2_percent(
    extra: float,
) -> None:
    m_true = M0 + extra
    t, fx, v, _ = model_drive(m_true)
    track = run_mass_grade(t, fx, v, VEHICLE)
    cfg = MassGradeConfig()
    first = int(np.argmax(track['excited']))
    used = track['mass_used'] != M0
    # used once its deviation is within use_std_ratio: the prior's 30 % shrinks below 10 %
    # within the first force step (one per 3 s here), long before it converges
    first_used = int(np.argmax(used))
    assert used[first_used:].all()
    assert t[first_used] - t[first] <= 1.0
    assert track['mass_std'][first_used] <= cfg.use_std_ratio * track['mass'][first_used]
    assert not track['converged'][first_used]
    # the posterior mean of the nominal prior and the data: closer than the nominal mass
    # at every stamp from then on
    assert np.all(np.abs(track['mass_used'][used] - m_true) < abs(M0 - m_true))
    # converged: two standard deviations within 2 %, so the error is
    assert track['converged'][-1]
    conv = track['converged']
    assert np.max(np.abs(track['mass'][conv] - m_true)) <= 0.02 * m_true
    assert np.all(
        track['mass_std'][conv] <= cfg.converged_std_ratio * track['mass'][conv] * 1.0001
    )


def test_without_use_std_ratio_the_nominal_mass_is_used_until_convergence() -> None:
    t, fx, v, _ = model_drive(M0 + 125.0)
    track = run_mass_grade(t, fx, v, VEHICLE, MassGradeConfig(use_std_ratio=0.0))
    np.testing.assert_array_equal(track['mass_used'] == M0, ~track['converged'])


def test_a_drive_without_excitation_keeps_the_nominal_mass_and_says_so() -> None:
    # Constant speed on a changing grade: the force follows the grade slowly, never steps.
    t, fx, v, _ = model_drive(M0 + 400.0, duration=30.0, force_steps=False)
    track = run_mass_grade(t, fx, v, VEHICLE)
    assert not track['excited'].any()
    assert not track['converged'].any()
    np.testing.assert_allclose(track['mass'], M0, rtol=1e-12)
    np.testing.assert_array_equal(track['mass_used'], M0)
    assert track['mass_std'][-1] == pytest.approx(0.3 * M0, rel=1e-12)  # the prior, unchanged


def test_a_wrong_mass_is_bounded_and_counted() -> None:
    # A car five times heavier than the file: the estimate stops at mass_max_ratio.
    cfg = MassGradeConfig()
    t, fx, v, _ = model_drive(5.0 * M0, duration=30.0)
    track = run_mass_grade(t, fx, v, VEHICLE, cfg)
    assert np.all(np.isfinite(track['mass']))
    assert np.max(track['mass']) <= cfg.mass_max_ratio * M0 * (1.0 + 1e-12)
    assert track['mass'][-1] == pytest.approx(cfg.mass_max_ratio * M0, rel=1e-9)
    assert track.faults['mass_clamped'] > 0


@settings(max_examples=25, deadline=None)
@given(
    fx=arrays(np.float64, 400, elements=st.floats(-2e4, 2e4)),
    v=arrays(np.float64, 400, elements=st.floats(-60.0, 60.0)),
)
def test_any_finite_input_gives_a_finite_bounded_estimate(fx: FloatArray, v: FloatArray) -> None:
    cfg = MassGradeConfig(min_excited_time=0.0)
    t = np.arange(fx.size) * DT
    track = run_mass_grade(t, fx, v, VEHICLE, cfg)
    for name in ('mass', 'mass_std', 'mass_used', 'slope'):
        assert np.all(np.isfinite(track[name])), name
    assert np.all(track['mass'] >= cfg.mass_min_ratio * M0 * (1.0 - 1e-12))
    assert np.all(track['mass'] <= cfg.mass_max_ratio * M0 * (1.0 + 1e-12))
    assert np.all(np.abs(track['slope']) <= cfg.max_slope + 1e-12)


def test_the_wrapper_equals_filters_and_rls_steps_computed_apart() -> None:
    """The estimator's regression is the pure step on the filtered signals (filterpy style)."""
    cfg = MassGradeConfig(
        min_speed=0.0, min_accel=0.0, min_force_ratio=0.0, min_force_change_ratio=0.0,
        max_force_rate=math.inf, min_excited_time=0.0, mass_max_ratio=100.0,
        mass_min_ratio=0.01,
    )  # fmt: skip
    # Flat road: a grade that changes within grade_tau leaks into the mass (module doc).
    t, fx, v, _ = model_drive(M0 + 200.0, duration=8.0, seed=3, grade_deg=0.0)
    est = MassGradeEstimator(VEHICLE, cfg)
    masses = np.array(
        [est.update(float(a), float(b), float(c)).mass for a, b, c in zip(t, fx, v, strict=True)]
    )
    # The same chain, vectorised: two low-pass stages, backward difference, high-pass.
    w = -math.expm1(-DT / cfg.filter_tau)
    force = fx - VEHICLE.drag_factor * v * v

    def lowpass(x: FloatArray, weight: float) -> FloatArray:
        out, _ = lfilter([weight], [1.0, weight - 1.0], x, zi=[(1.0 - weight) * x[0]])
        return np.asarray(out)

    f_lp = lowpass(lowpass(force, w), w)
    v_lp = lowpass(lowpass(v, w), w)
    accel = np.concatenate(([0.0], np.diff(v_lp) / DT))
    c_r = VEHICLE.rolling_c0 * (1.0 + VEHICLE.rolling_c1 * np.abs(v_lp) / 160.0)
    # cos(slope) of the previous stamp's published slope: take it from the wrapper's run.
    est2 = MassGradeEstimator(VEHICLE, cfg)
    slopes = np.array(
        [est2.update(float(a), float(b), float(c)).slope for a, b, c in zip(t, fx, v, strict=True)]
    )
    prev_cos = np.cos(np.concatenate(([0.0], slopes[:-1])))
    y = accel + G * c_r * prev_cos
    w_slow = -math.expm1(-DT / cfg.grade_tau)
    f_hp = f_lp - lowpass(f_lp, w_slow)
    y_hp = y - lowpass(y, w_slow)
    theta = np.array([1.0 / M0])
    cov = np.array([[(0.3 / M0) ** 2]])
    expected = np.empty_like(t)
    expected[0] = M0
    lam = forgetting_factor(DT, cfg.mass_tau)
    for k in range(1, t.size):
        if t[k] < est.warmup - 1e-9:
            expected[k] = M0
            continue
        theta, cov = rls_step(
            theta, cov, (f_hp[k],), float(y_hp[k]), (lam,), cfg.accel_noise_density**2 / DT,
            (True,),
        )  # fmt: skip
        expected[k] = 1.0 / theta[0]
    np.testing.assert_allclose(masses, expected, rtol=1e-9)
    assert masses[-1] == pytest.approx(M0 + 200.0, rel=0.01)


# -- robustness of the stamps and inputs ------------------------------------------------


def test_time_jump_back_and_gap_reset_to_the_nominal_mass() -> None:
    t, fx, v, _ = model_drive(M0 + 300.0, duration=40.0)
    est = MassGradeEstimator(VEHICLE)
    for a, b, c in zip(t, fx, v, strict=True):
        out = est.update(float(a), float(b), float(c))
    assert out.converged and out.mass > M0 + 200.0
    back = est.update(float(t[0]), float(fx[0]), float(v[0]))  # a looped bag
    assert (
        back.mass == pytest.approx(M0, rel=1e-12)
        and not back.converged
        and back.excited_time == 0.0
    )
    assert est.faults['time_jump_back'] == 1
    for a, b, c in zip(t[:20000], fx[:20000], v[:20000], strict=True):
        est.update(float(a), float(b), float(c))
    gap = est.update(float(t[20000]) + 5.0, float(fx[20000]), float(v[20000]))
    assert gap.mass == pytest.approx(M0, rel=1e-12) and est.faults['gap'] == 1


def test_bad_stamps_and_values_are_rejected_and_counted() -> None:
    est = MassGradeEstimator(VEHICLE)
    first = est.update(0.0, 1000.0, 10.0)
    assert est.update(0.0, 1000.0, 10.0) is first
    assert est.update(math.nan, 1000.0, 10.0) is first
    assert est.update(0.001, math.inf, 10.0) is first
    assert est.update(0.002, 1000.0, math.nan) is first
    second = est.update(0.003, 1000.0, 10.0)
    assert est.update(0.0025, 1000.0, 10.0) is second  # slightly older: dropped
    assert est.faults['duplicate_stamp'] == 1
    assert est.faults['non_finite_stamp'] == 1
    assert est.faults['non_finite_value'] == 2
    assert est.faults['out_of_order'] == 1
    assert math.isfinite(second.slope)


def test_config_is_checked() -> None:
    with pytest.raises(ConfigurationError, match='grade_tau'):
        MassGradeConfig(grade_tau=0.0)
    with pytest.raises(ConfigurationError, match='min_speed'):
        MassGradeConfig(min_speed=-1.0)
    with pytest.raises(ConfigurationError, match='finite'):
        MassGradeConfig(grade_tau=math.inf)
    with pytest.raises(ConfigurationError, match='mass_min_ratio'):
        MassGradeConfig(mass_min_ratio=1.5)
    with pytest.raises(ConfigurationError, match='max_slope'):
        MassGradeConfig(max_slope=2.0)
    with pytest.raises(ConfigurationError, match='unknown'):
        MassGradeConfig.from_mapping({'mass_tua': 3.0})
    assert MassGradeConfig.from_mapping({'mass_tau': math.inf}).mass_tau == math.inf
    assert dataclasses.replace(MassGradeConfig(), max_gap=1.0).max_gap == 1.0


def test_run_mass_grade_checks_shapes() -> None:
    with pytest.raises(InputShapeError, match='shape'):
        run_mass_grade(np.zeros(3), np.zeros(4), np.zeros(3), VEHICLE)


@settings(max_examples=50, deadline=None)
@given(
    slope=st.floats(-0.3, 0.3),
    force=st.floats(-5e3, 5e3),
    mass=st.floats(0.8 * M0, 1.5 * M0),
)
def test_slope_with_mass_round_trips_and_is_identity_at_the_nominal_mass(
    slope: float, force: float, mass: float
) -> None:
    same = slope_with_mass(slope, force, M0, M0, G)
    assert float(same) == pytest.approx(slope, abs=1e-12)
    there = slope_with_mass(slope, force, M0, mass, G, max_slope=1.5)
    back = slope_with_mass(there, force, mass, M0, G, max_slope=1.5)
    assert float(back) == pytest.approx(slope, abs=1e-9)


def test_the_track_records_every_field_of_the_estimate() -> None:
    """One recorder (`estimation.track`): each field of the estimate dataclass is a series
    of one row per stamp; a record without stamps gives empty series."""
    import dataclasses

    from vd_observer_node.estimation.mass_grade import MassGradeEstimate

    t = np.arange(5) * 0.01
    track = run_mass_grade(t, np.full(5, 100.0), np.full(5, 10.0), VEHICLE)
    names = {f.name for f in dataclasses.fields(MassGradeEstimate)}
    assert set(track.series) == names
    assert all(track[name].shape == (5,) for name in names)
    assert track['converged'].dtype == np.bool_
    empty = run_mass_grade(np.zeros(0), np.zeros(0), np.zeros(0), VEHICLE)
    assert all(empty[name].shape == (0,) for name in names)
