"""First-order Levant differentiator on samples of f' (wheel speeds instead of wheel angles)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from vd_observer_node.errors import ConfigurationError
from vd_observer_node.estimation.differentiator import (
    DISCRETIZATIONS,
    INIT_POLICIES,
    DifferentiatorSettings,
    LevantDifferentiator,
    levant_params,
)
from vd_observer_node.estimation.faults import OBSERVER_FAULTS
from vd_observer_node.estimation.levant_step import (
    STATE_DTYPE,
    first_order_euler_step,
    first_order_implicit_step,
    levant_reset,
    levant_step,
    levant_update,
    new_channels,
)
from vd_observer_node.estimation.observer import ObserverConfig, WheelObserver
from vd_observer_node.kernel._jit import new_record


def _run(disc: str, t: np.ndarray, g: np.ndarray, lip: float, init: str = 'first_sample'):
    diff = LevantDifferentiator(
        lip,
        n_channels=1,
        input_derivative=1,
        settings=DifferentiatorSettings(discretization=disc, init=init),
    )
    out = np.array([diff.update(tk, gk)[:3] for tk, gk in zip(t, g, strict=True)])
    return out[:, :, 0]


def _cosine_errors(disc: str, tau: float) -> np.ndarray:
    """Max errors of (f', f'') after convergence on g = f' = cos(t) (|g''| <= 1), L = 1.5."""
    t = np.arange(0.0, 8.0, tau)
    out = _run(disc, t, np.cos(t), 1.5)
    keep = t > 3.0
    truth = np.stack((np.cos(t), -np.sin(t)), axis=1)
    return np.abs(out[keep, 1:] - truth[keep]).max(axis=0)


@pytest.mark.parametrize(('disc', 'max_dot_error'), [('euler_taylor', 6e-3), ('implicit', 6e-4)])
def test_accuracy_scales_like_levant_law_for_first_order(disc: str, max_dot_error: float) -> None:
    # Levant, n = 1: |z1 - g| ~ L tau^2, |z2 - g'| ~ L tau. The implicit step reproduces g
    # exactly (error 0) and its g' error is the backward difference's tau/2 * |g''|.
    taus = [4e-3, 2e-3, 1e-3]
    errors = np.array([_cosine_errors(disc, tau) for tau in taus])
    slope = np.polyfit(np.log(taus), np.log(errors[:, 1]), 1)[0]
    assert slope == pytest.approx(1.0, abs=0.3)
    assert errors[-1, 1] < max_dot_error
    assert errors[-1, 0] < 1e-5


def test_implicit_step_is_dead_beat_on_a_linear_speed() -> None:
    # g = 3 + 2 t, started with slope 0: once the error is inside the band the step is the
    # backward difference, exact for a linear g (a few steps here, then exact for ever).
    t = np.arange(0.0, 1.0, 0.01)
    out = _run('implicit', t, 3.0 + 2.0 * t, 50.0)
    np.testing.assert_allclose(out[6:, 1], 3.0 + 2.0 * t[6:], rtol=0, atol=1e-12)
    np.testing.assert_allclose(out[6:, 2], 2.0, rtol=0, atol=1e-9)
    assert abs(out[1, 2] - 2.0) > 0.1  # the start was wrong


def test_converges_in_finite_time_from_a_wrong_state() -> None:
    t = np.arange(0.0, 8.0, 1e-3)
    g = 20.0 + 4.0 * np.sin(t)
    out = _run('implicit', t, g, 20.0, init='zero')
    late = t > 5.0
    np.testing.assert_allclose(out[late, 1], g[late], atol=1e-9)
    np.testing.assert_allclose(out[late, 2], 4.0 * np.cos(t[late]), atol=5e-3)


def test_row_zero_integrates_the_speed() -> None:
    t = np.arange(0.0, 5.0, 1e-3)
    g = 30.0 + 5.0 * np.sin(2.0 * t)
    out = _run('implicit', t, g, 300.0, init='finite_difference')[1:]  # active from sample 1
    t = t[1:]
    trapezoid = np.concatenate(([0.0], np.cumsum(0.5 * np.diff(t) * (out[1:, 1] + out[:-1, 1]))))
    np.testing.assert_allclose(out[:, 0], trapezoid, rtol=1e-12, atol=1e-9)
    f = 30.0 * t + 2.5 * (1.0 - np.cos(2.0 * t))
    np.testing.assert_allclose(out[:, 0], f - f[0], atol=1e-4)


def _params(disc: str) -> np.record:
    return levant_params(
        DifferentiatorSettings(discretization=disc, init='first_sample'), math.inf, 1
    )


def test_step_dispatches_the_first_order_steps() -> None:
    # levant_step gets the sample its scheme corrects with: g0 (start) explicit, g1 (end)
    z = np.array([0.5, 10.0, 1.0])
    g0, g1, tau, lip = 10.2, 10.1, 0.01, 300.0
    implicit = _params('implicit')
    assert levant_step(implicit, z, g1, tau, lip) == first_order_implicit_step(
        implicit, z, g1, tau, lip
    )
    euler = _params('euler')
    plain = first_order_euler_step(euler, z, g0, tau, lip, False)
    assert levant_step(euler, z, g0, tau, lip) == plain
    taylor = levant_step(_params('euler_taylor'), z, g0, tau, lip)
    assert taylor[1] == pytest.approx(plain[1] + 5e-5)


def test_refuses_an_unknown_input_derivative() -> None:
    with pytest.raises(ConfigurationError, match='input_derivative'):
        LevantDifferentiator(1.0, n_channels=1, input_derivative=2)
    with pytest.raises(ConfigurationError, match='wheel_input'):
        ObserverConfig(wheel_input='pulses')


def _faulty_speeds(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    n = 900
    t = np.arange(n) * 0.002 + rng.normal(0.0, 1e-4, n)
    g = (
        25.0
        + 3.0 * np.sin(np.arange(n)[:, None] * 0.01 * np.arange(1, 5))
        + rng.normal(0.0, 0.02, (n, 4))
    )
    g[100, 2] = math.nan  # one channel missing
    t[200] = t[199]  # duplicate
    t[300] = math.nan  # non-finite stamp
    t[400:] += 1.0  # gap
    t[600:] -= 3.0  # jump back
    g[700] = 1e300  # overflow
    return t, g


@pytest.mark.parametrize('init', INIT_POLICIES)
@pytest.mark.parametrize('disc', DISCRETIZATIONS)
def test_the_update_on_records_is_the_wrapper_and_counts_every_fault(disc: str, init: str) -> None:
    # levant_update driven on its own records (as the fused kernels do) against the wrapper,
    # on speeds with one fault of each kind injected
    t, g = _faulty_speeds(np.random.default_rng(7))
    settings = DifferentiatorSettings(
        discretization=disc, init=init, max_gap=0.5, init_baseline=0.01
    )
    wrapper = LevantDifferentiator(300.0, n_channels=4, input_derivative=1, settings=settings)
    p = levant_params(settings, 0.5, 1)
    lip, s, channels = np.full(4, 300.0), new_record(STATE_DTYPE), new_channels(4)
    levant_reset(p, s, channels)
    out, valid = np.zeros((3, 4)), np.zeros(4, dtype=np.bool_)
    for tk, gk in zip(t, g, strict=True):
        est = wrapper.update(float(tk), gk)
        levant_update(p, lip, s, channels, float(tk), gk, out, valid)
        np.testing.assert_array_equal(np.stack(est[:3]), out)
        np.testing.assert_array_equal(est.valid, valid)
    counts = wrapper.faults.counts
    assert counts == {kind: int(s[kind]) for kind in OBSERVER_FAULTS}
    injected = ('non_finite_stamp', 'non_finite_value', 'duplicate_stamp', 'gap', 'time_jump_back')
    assert all(counts[kind] >= 1 for kind in injected)
    assert wrapper.rejected_count == s.rejected == 2  # the duplicate and the nan stamp


@pytest.mark.parametrize('noise', [0.0, 0.01])
def test_wheel_observer_on_speeds_gives_omega_and_omega_dot(noise: float) -> None:
    rng = np.random.default_rng(3)
    tau = 0.01  # 100 Hz ABS wheel speeds
    t = np.arange(0.0, 6.0, tau)
    gain = np.array([1.0, 1.01, 0.99, 1.0])
    omega = 40.0 + 8.0 * np.sin(0.5 * t)[:, None] * gain
    measured = omega + rng.normal(0.0, noise, omega.shape)
    observer = WheelObserver(ObserverConfig(wheel_input='speed'))
    states = [observer.update(tk, wk) for tk, wk in zip(t, measured, strict=True)]
    late = t > 2.0
    est_omega = np.array([s.omega for s in states])[late]
    est_dot = np.array([s.omega_dot for s in states])[late]
    true_dot = 4.0 * np.cos(0.5 * t)[:, None] * gain
    rms_omega = np.sqrt(np.mean((est_omega - omega[late]) ** 2))
    rms_dot = np.sqrt(np.mean((est_dot - true_dot[late]) ** 2))
    # noise-free: tau/2 * |omega''| <= 0.01 rad/s^2; with noise the default L = 300 keeps the
    # noise inside the band, where omega_dot is the backward difference: sqrt(2) sigma / tau
    assert rms_omega <= max(1e-9, 1.1 * noise)
    assert rms_dot <= max(0.02, 1.1 * math.sqrt(2.0) * noise / tau)
    assert all(s.valid.all() for s in states[10:])
