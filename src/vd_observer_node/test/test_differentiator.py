"""Levant differentiator: discretizations, accuracy laws, convergence, invalid input."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from vd_observer_node.errors import ConfigurationError, InputShapeError
from vd_observer_node.estimation.differentiator import (
    DEFAULT_GAINS,
    DISCRETIZATIONS,
    DifferentiatorSettings,
    LevantDifferentiator,
    LevantGains,
    levant_params,
)
from vd_observer_node.estimation.levant_step import euler_step, implicit_step, levant_step

ACCURATE = ('euler_taylor', 'implicit')


def _params(disc: str = 'implicit', gains: LevantGains = DEFAULT_GAINS) -> np.record:
    """The parameter record the step functions read (only the gains and names matter)."""
    return levant_params(
        DifferentiatorSettings(gains, discretization=disc, init='first_sample'), math.inf
    )


def _run(disc: str, t: np.ndarray, f: np.ndarray, lip: float, init: str = 'finite_difference'):
    diff = LevantDifferentiator(
        lip, n_channels=1, settings=DifferentiatorSettings(discretization=disc, init=init)
    )
    out = np.array([diff.update(tk, fk)[:3] for tk, fk in zip(t, f, strict=True)])
    return out[:, :, 0]


def _sine_errors(disc: str, tau: float, jitter: float = 0.0, seed: int = 0):
    """Max errors of (f, f', f'') after convergence on f = sin(t) (|f'''| <= 1), L = 1.5."""
    rng = np.random.default_rng(seed)
    steps = tau * (1.0 + jitter * rng.uniform(-1.0, 1.0, int(8.0 / tau)))
    t = np.concatenate(([0.0], np.cumsum(steps)))
    out = _run(disc, t, np.sin(t), 1.5)
    keep = t > 3.0
    truth = np.stack((np.sin(t), np.cos(t), -np.sin(t)), axis=1)
    return np.abs(out[keep] - truth[keep]).max(axis=0)


def _order(values: list[float], taus: list[float]) -> float:
    return float(np.polyfit(np.log(taus), np.log(values), 1)[0])


@pytest.mark.parametrize('disc', ACCURATE)
def test_accuracy_scales_like_levant_law_with_step(disc: str) -> None:
    # Levant: |z_i - f^(i)| ~ L * tau^(3 - i): f' error ~ tau^2, f'' error ~ tau.
    taus = [4e-3, 2e-3, 1e-3]
    errors = np.array([_sine_errors(disc, tau) for tau in taus])
    assert _order(list(errors[:, 1]), taus) == pytest.approx(2.0, abs=0.3)
    assert _order(list(errors[:, 2]), taus) == pytest.approx(1.0, abs=0.3)
    assert errors[-1, 2] < 0.01


def test_plain_euler_first_derivative_is_only_first_order() -> None:
    # Documented weakness of plain explicit Euler: the f' error only falls like tau.
    taus = [4e-3, 2e-3, 1e-3]
    errors = np.array([_sine_errors('euler', tau) for tau in taus])
    assert _order(list(errors[:, 1]), taus) == pytest.approx(1.0, abs=0.3)
    assert _order(list(errors[:, 2]), taus) == pytest.approx(1.0, abs=0.3)


@pytest.mark.parametrize('disc', ACCURATE)
def test_irregular_jittery_steps_keep_accuracy(disc: str) -> None:
    # Steps uniform in [0.5, 1.5] ms: the errors must stay within the tau^k law evaluated at
    # the largest step (1.5 ms), with a margin of 1.5 for the irregularity itself.
    largest_regular = _sine_errors(disc, 1.5e-3)
    jittery = _sine_errors(disc, 1e-3, jitter=0.5, seed=3)
    assert np.all(jittery[1:] <= 1.5 * largest_regular[1:])


def test_irregular_steps_make_explicit_euler_chatter_more() -> None:
    # Documented weakness: with jitter the explicit-Euler f'' error grows well beyond the
    # regular-step law, which is why the implicit scheme is the default.
    largest_regular = _sine_errors('euler', 1.5e-3)
    jittery = _sine_errors('euler', 1e-3, jitter=0.5, seed=3)
    assert jittery[2] > 1.5 * largest_regular[2]
    assert jittery[2] < 0.05


@pytest.mark.parametrize('disc', ACCURATE)
def test_noise_error_scales_like_cube_root_of_noise(disc: str) -> None:
    # Homogeneity: a noise eps*sin(Omega*t) with Omega = (L/eps)^(1/3) is the worst-case
    # noise shape scaled in time, so the f'' error must scale exactly like L^(2/3)*eps^(1/3)
    # (as long as tau << 1/Omega).
    tau = 5e-4
    lip = 1.5
    t = np.arange(0.0, 4.0, tau)
    epsilons = [1e-3, 1e-4, 1e-5]
    errors = []
    for eps in epsilons:
        omega_noise = (lip / eps) ** (1.0 / 3.0)
        noisy = np.sin(t) + eps * np.sin(omega_noise * t)
        out = _run(disc, t, noisy, lip)
        keep = t > 2.0
        errors.append(float(np.abs(out[keep, 2] + np.sin(t[keep])).max()))
    assert _order(errors, epsilons) == pytest.approx(1.0 / 3.0, abs=0.08)


@pytest.mark.parametrize('disc', ACCURATE)
def test_random_bounded_noise_error_within_cube_root_bound(disc: str) -> None:
    # Levant's bound |z2 - f''| <= mu2 * L^(2/3) * eps^(1/3). Measured constants with these
    # gains: ~1.0 for the sinusoid above, ~1.6 for uniform random noise; allow mu2 = 3.
    rng = np.random.default_rng(7)
    tau = 5e-4
    lip = 1.5
    t = np.arange(0.0, 4.0, tau)
    for eps in (1e-3, 1e-5):
        noisy = np.sin(t) + eps * rng.uniform(-1.0, 1.0, t.size)
        out = _run(disc, t, noisy, lip)
        keep = t > 2.0
        error = float(np.abs(out[keep, 2] + np.sin(t[keep])).max())
        assert error < 3.0 * lip ** (2 / 3) * eps ** (1 / 3)


@pytest.mark.parametrize('disc', DISCRETIZATIONS)
def test_finite_time_convergence_from_wrong_initial_state(disc: str) -> None:
    # Quadratic-plus-cubic signal, state starts at zero far from (f, f', f'') = (5, 3, 1).
    tau = 1e-3
    t = np.arange(0.0, 5.0, tau)
    f = 5.0 + 3.0 * t + 0.5 * t**2 + 0.1 * np.sin(t)
    lip = 20.0
    out = _run(disc, t, f, lip, init='zero')
    d1 = 3.0 + t + 0.1 * np.cos(t)
    d2 = 1.0 - 0.1 * np.sin(t)
    early = t < 0.05
    late = t > 4.0
    assert np.abs(out[early, 1] - d1[early]).max() > 1.0
    assert np.abs(out[late, 1] - d1[late]).max() < 1e-3
    assert np.abs(out[late, 2] - d2[late]).max() < 0.1


def test_implicit_is_exact_for_quadratic_signals_without_chattering() -> None:
    tau = 1e-3
    t = np.arange(0.0, 5.0, tau)
    f = -2.0 + 4.0 * t - 1.5 * t**2
    out = _run('implicit', t, f, 20.0, init='zero')
    late = t > 3.0
    # Exact up to round-off, which the 1/tau^2 of the f'' update amplifies to ~1e-8.
    assert np.abs(out[late, 1] - (4.0 - 3.0 * t[late])).max() < 1e-8
    assert np.abs(out[late, 2] + 3.0).max() < 1e-6
    euler = _run('euler', t, f, 20.0, init='zero')
    # Explicit Euler keeps chattering by about l2 * L * tau around f''.
    assert np.abs(euler[late, 2] + 3.0).max() > 1e-4


@pytest.mark.parametrize('disc', DISCRETIZATIONS)
def test_wrapper_matches_pure_steps(disc: str) -> None:
    # the per-channel step driven by hand (explicit schemes correct with the sample at the
    # start of the step, the implicit one with the sample at its end) against the wrapper
    rng = np.random.default_rng(11)
    t = np.concatenate(([0.0], np.cumsum(rng.uniform(5e-4, 2e-3, 400))))
    f = np.stack((np.sin(3 * t), np.cos(2 * t), t**2, np.exp(-t)), axis=1)
    lip = np.array([30.0, 10.0, 1.0, 2.0])
    diff = LevantDifferentiator(
        lip,
        n_channels=4,
        settings=DifferentiatorSettings(discretization=disc, init='first_sample'),
    )
    p = _params(disc)
    z = np.zeros((4, 3))  # a row per channel: (f, f', f'')
    z[:, 0] = f[0]
    diff.update(t[0], f[0])
    for k in range(1, t.size):
        used = f[k] if disc == 'implicit' else f[k - 1]
        for i in range(4):
            z[i] = levant_step(p, z[i], used[i], t[k] - t[k - 1], lip[i])
        est = diff.update(t[k], f[k])
        np.testing.assert_allclose(np.stack(est[:3]), z.T, rtol=0, atol=1e-12)


@settings(max_examples=200, deadline=None)
@given(
    z=st.lists(st.floats(-100, 100), min_size=3, max_size=3),
    f=st.floats(-100, 100),
    tau=st.floats(1e-5, 1e-1),
    lip=st.floats(1e-2, 1e4),
)
def test_implicit_step_solves_its_implicit_equations(
    z: list[float], f: float, tau: float, lip: float
) -> None:
    k0, k1, k2 = DEFAULT_GAINS.nonrecursive()
    z_old = np.array(z)[:, None]
    new = np.array(implicit_step(_params(), z_old[:, 0].copy(), f, tau, lip))
    e = new[0] - f
    sign_value = (z_old[2, 0] - new[2]) / (tau * k2 * lip)
    # Round-off of z2 (magnitude up to ~100) relative to the size of its sign step.
    sign_tol = 1e-9 + 1e-13 * (1.0 + abs(z_old[2, 0])) / (tau * k2 * lip)
    assert -1.0 - sign_tol <= sign_value <= 1.0 + sign_tol
    if abs(e) > 1e-9 * max(1.0, abs(f)):
        assert sign_value == pytest.approx(math.copysign(1.0, e), abs=sign_tol)
    phi13 = math.copysign(abs(e) ** (1 / 3), e)
    phi23 = math.copysign(abs(e) ** (2 / 3), e)
    w = z_old[0, 0] + tau * z_old[1, 0] + 0.5 * tau**2 * z_old[2, 0] - f
    w_expected = (
        e
        + tau * k0 * lip ** (1 / 3) * phi23
        + tau**2 * k1 * lip ** (2 / 3) * phi13
        + tau**3 * k2 * lip * sign_value
    )
    z1_expected = (
        z_old[1, 0]
        + tau * z_old[2, 0]
        - 1.5 * tau**2 * k2 * lip * sign_value
        - tau * k1 * lip ** (2 / 3) * phi13
    )
    scale = 1.0 + abs(z_old).max() + abs(new).max()
    assert w == pytest.approx(w_expected, abs=1e-9 * scale)
    assert new[1] == pytest.approx(z1_expected, abs=1e-9 * scale)


def test_euler_step_is_the_recursive_form() -> None:
    z = np.array([1.0, 2.0, 3.0])
    out = np.array(
        euler_step(_params('euler', LevantGains(2.0, 1.5, 1.1)), z, 0.5, 0.01, 8.0, False)
    )
    v0 = 2.0 - 2.0 * 8.0 ** (1 / 3) * 0.5 ** (2 / 3)
    v1 = 3.0 - 1.5 * 8.0**0.5 * math.copysign(abs(2.0 - v0) ** 0.5, 2.0 - v0)
    dz2 = -1.1 * 8.0 * math.copysign(1.0, 3.0 - v1)
    np.testing.assert_allclose(out, [1.0 + 0.01 * v0, 2.0 + 0.01 * v1, 3.0 + 0.01 * dz2])


@pytest.mark.parametrize('disc', DISCRETIZATIONS)
def test_invalid_samples_do_not_poison_the_state(disc: str) -> None:
    diff = LevantDifferentiator(
        1.0, n_channels=2, settings=DifferentiatorSettings(discretization=disc)
    )
    t = np.arange(0.0, 3.0, 1e-3)
    for tk in t[:1500]:
        diff.update(tk, [np.sin(tk), 2.0 * tk])
    before = diff.state
    rejected = diff.update(t[1499], [0.0, 0.0])  # repeated stamp
    np.testing.assert_array_equal(diff.state, before)
    assert not rejected.valid.any()
    diff.update(float('nan'), [0.0, 0.0])
    assert diff.rejected_count == 2
    est = diff.update(t[1500], [np.nan, 2.0 * t[1500]])
    assert list(est.valid) == [False, True]
    assert np.all(np.isfinite(diff.state))
    for tk in t[1501:]:
        est = diff.update(tk, [np.sin(tk), 2.0 * tk])
    assert est.valid.all()
    assert est.first == pytest.approx([np.cos(t[-1]), 2.0], abs=1e-3)


def test_finite_difference_initialisation_starts_close() -> None:
    diff = LevantDifferentiator(
        10.0, n_channels=1, settings=DifferentiatorSettings(discretization='implicit')
    )
    first = diff.update(0.0, 100.0)
    assert not first.valid[0]
    second = diff.update(0.001, 100.08)
    assert second.valid[0]
    assert second.first[0] == pytest.approx(80.0)


def test_long_gap_reinitialises() -> None:
    diff = LevantDifferentiator(10.0, n_channels=1, settings=DifferentiatorSettings(max_gap=0.1))
    for k in range(100):
        diff.update(k * 1e-3, 1.0 * k * 1e-3)
    est = diff.update(5.0, 123.0)
    assert est.value[0] == 123.0
    assert not est.valid[0]


def test_configuration_errors() -> None:
    with pytest.raises(ConfigurationError):
        LevantDifferentiator(
            1.0, n_channels=1, settings=DifferentiatorSettings(discretization='rk4')
        )
    with pytest.raises(ConfigurationError):
        LevantDifferentiator(0.0, n_channels=1)
    with pytest.raises(ConfigurationError):
        LevantDifferentiator(1.0, n_channels=1, settings=DifferentiatorSettings(init='guess'))
    with pytest.raises(ConfigurationError):
        LevantGains(l2=0.9)
    with pytest.raises(InputShapeError):
        LevantDifferentiator(1.0, n_channels=4).update(0.0, [1.0, 2.0])


def test_default_gains_nonrecursive_table() -> None:
    k0, k1, k2 = DEFAULT_GAINS.nonrecursive()
    assert (k0, round(k1, 2), k2) == (2.0, 2.12, 1.1)
