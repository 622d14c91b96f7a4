"""Pure accuracy metrics of vd report on synthetic arrays with known answers."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from vd_observer_node.tools.report.accumulate import ConvergenceAccumulator
from vd_observer_node.tools.report.metrics import (
    change_times,
    error_stats,
    evaluation_mask,
    relative_error_stats,
    step_times,
)
from vd_observer_node.tools.report.results import EvaluationSettings

RATE = 1000.0  # [Hz]


def _time(duration: float) -> np.ndarray:
    return np.arange(round(duration * RATE) + 1) / RATE


def _delays(
    t: np.ndarray, error: np.ndarray, steps: list[float], blocks: int = 1
) -> list[float | None]:
    """Convergence delays [s] after `steps` of a slope error (truth 0, threshold 0.5, hold
    1 s), the samples fed in `blocks` equal parts."""
    acc = ConvergenceAccumulator(
        EvaluationSettings(convergence_threshold_deg=0.5, convergence_hold_s=1.0)
    )
    for part in np.array_split(np.arange(t.size), blocks):
        acc.feed(t[part], error[part], np.zeros(part.size), np.asarray(steps))
    return [c.delay_s for c in acc.result()]


def test_constant_offset_gives_known_rms_max_and_mean() -> None:
    rng = np.random.default_rng(1)
    truth = rng.normal(0.0, 100.0, size=(500, 4))
    stats = error_stats(truth - 2.5, truth)
    assert stats.rms == pytest.approx(2.5, rel=1e-12)
    assert stats.max_abs == pytest.approx(2.5, rel=1e-12)
    assert stats.mean == pytest.approx(-2.5, rel=1e-12)
    assert stats.samples == 2000


def test_alternating_error_rms_and_max() -> None:
    # Errors +-3 and +-4 in equal numbers: RMS = sqrt((9 + 16) / 2), mean 0, max 4.
    error = np.array([3.0, -3.0, 4.0, -4.0] * 25)
    stats = error_stats(error, np.zeros_like(error))
    assert stats.rms == pytest.approx(math.sqrt(12.5), rel=1e-12)
    assert stats.max_abs == 4.0
    assert stats.mean == pytest.approx(0.0, abs=1e-12)


def test_row_mask_selects_rows_of_per_wheel_arrays() -> None:
    truth = np.zeros((4, 4))
    estimate = np.array([[1.0] * 4, [100.0] * 4, [1.0] * 4, [100.0] * 4])
    stats = error_stats(estimate, truth, np.array([True, False, True, False]))
    assert stats.rms == 1.0
    assert stats.samples == 8


def test_elementwise_mask_and_non_finite_errors_are_left_out() -> None:
    truth = np.zeros((3, 2))
    estimate = np.array([[1.0, 50.0], [np.nan, 1.0], [1.0, np.inf]])
    mask = np.array([[True, False], [True, True], [True, True]])
    stats = error_stats(estimate, truth, mask)
    assert (stats.rms, stats.max_abs, stats.samples) == (1.0, 1.0, 3)


def test_empty_selection_is_nan_with_zero_samples() -> None:
    stats = error_stats(np.ones(5), np.zeros(5), np.zeros(5, dtype=bool))
    assert stats.samples == 0
    assert math.isnan(stats.rms) and math.isnan(stats.max_abs)


def test_relative_error_against_static_load() -> None:
    static = np.array([3000.0, 3000.0, 2000.0, 2000.0])
    truth = np.tile(static, (10, 1))
    estimate = truth + np.array([30.0, -30.0, 20.0, -20.0])
    stats = relative_error_stats(estimate, truth, static[None, :])
    assert 100.0 * stats.rms == pytest.approx(1.0, rel=1e-12)


@settings(max_examples=60, deadline=None)
@given(
    offset=st.floats(-1e3, 1e3, allow_nan=False),
    n=st.integers(1, 200),
    seed=st.integers(0, 2**32 - 1),
)
def test_offset_property(offset: float, n: int, seed: int) -> None:
    truth = np.random.default_rng(seed).normal(0.0, 10.0, size=n)
    stats = error_stats(truth + offset, truth)
    assert stats.rms == pytest.approx(abs(offset), rel=1e-9, abs=1e-9)
    assert stats.max_abs == pytest.approx(abs(offset), rel=1e-9, abs=1e-9)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 300))
def test_rms_lies_between_mean_abs_and_max(seed: int, n: int) -> None:
    rng = np.random.default_rng(seed)
    error = rng.standard_cauchy(n)
    stats = error_stats(error, np.zeros(n))
    assert abs(stats.mean) <= stats.rms * (1 + 1e-12)
    assert stats.rms <= stats.max_abs * (1 + 1e-12)
    permuted = error_stats(rng.permutation(error), np.zeros(n))
    assert permuted.rms == pytest.approx(stats.rms, rel=1e-12)


def test_step_times_of_a_staircase() -> None:
    t = _time(60.0)
    slope = np.radians(np.select([t < 10, t < 20, t < 50], [0.0, 5.0, 10.0], 3.0))
    steps = step_times(t, slope, np.radians(0.1))
    np.testing.assert_allclose(steps, [10.0, 20.0, 50.0], atol=1e-12)


def test_step_spread_over_samples_is_one_step_and_ramps_are_not_steps() -> None:
    t = _time(10.0)
    signal = np.where(t < 2.0, 0.0, 1.0) + np.where(t < 2.002, 0.0, 1.0)  # two-sample step
    signal = signal + 0.0005 * t  # a slow ramp: 5e-7 per sample
    assert step_times(t, signal, 0.1).tolist() == pytest.approx([2.0])


def test_gear_changes_including_neutral_during_a_shift() -> None:
    t = _time(5.0)
    gear = np.select([t < 1.0, t < 1.25, t < 3.0], [1, 0, 2], 3)
    np.testing.assert_allclose(change_times(t, gear), [1.0, 1.25, 3.0], atol=1e-12)
    np.testing.assert_allclose(change_times(t, gear, merge_s=0.5), [1.0, 3.0], atol=1e-12)
    assert change_times(t, np.full(t.size, 2)).size == 0


def test_evaluation_mask_start_and_exclusion_windows() -> None:
    t = _time(10.0)
    mask = evaluation_mask(t, start=1.0, events=[3.0, 7.0], half_width=0.5)
    # Evaluated: [1, 2.5) and (3.5, 6.5) and (7.5, 10]; the window edges are excluded.
    expected = (t >= 1.0) & (np.abs(t - 3.0) > 0.5) & (np.abs(t - 7.0) > 0.5)
    np.testing.assert_array_equal(mask, expected)
    assert not mask[np.searchsorted(t, 2.5)] and mask[np.searchsorted(t, 2.499)]
    assert mask.sum() == 1000 * 9 + 1 - 2 * 1001  # 9 s evaluated minus two 1 s windows


def test_convergence_time_of_a_decaying_error() -> None:
    t = _time(10.0)
    # Error 2 deg decaying with tau 0.5 s after a step at 2 s: below 0.5 deg from
    # 2 + 0.5 ln(4) s on, and it stays there.
    error = np.where(t < 2.0, 0.0, 2.0 * np.exp(-(t - 2.0) / 0.5))
    delay = _delays(t, error, [2.0])[0]
    assert delay == pytest.approx(0.5 * math.log(4.0), abs=1.5 / RATE)


def test_convergence_needs_the_error_to_stay_below_for_the_hold_time() -> None:
    t = _time(10.0)
    error = np.full(t.size, 2.0)
    error[(t >= 3.0) & (t < 3.8)] = 0.1  # 0.8 s below: too short
    error[t >= 5.0] = 0.1  # from here on it stays
    assert _delays(t, error, [2.0])[0] == pytest.approx(3.0)
    error[(t >= 3.0) & (t < 3.8)] = 2.0
    error[(t >= 3.0) & (t < 4.2)] = 0.1  # 1.2 s below, then diverges again
    assert _delays(t, error, [2.0])[0] == pytest.approx(1.0)


def test_convergence_not_reached_before_next_step_or_end() -> None:
    t = _time(10.0)
    error = np.where(t < 9.5, 3.0, 0.0)  # below only for the last 0.5 s
    assert _delays(t, error, [2.0])[0] is None
    error = np.where(t < 6.0, 3.0, 0.0)
    delays = _delays(t, error, [2.0, 5.0])
    assert delays[0] is None  # converged only after the next step
    assert delays[1] == pytest.approx(1.0)


@settings(max_examples=25, deadline=None)
@given(blocks=st.integers(min_value=2, max_value=40), seed=st.integers(0, 2**16))
def test_convergence_is_the_same_block_by_block(blocks: int, seed: int) -> None:
    """The streamed evaluation feeds blocks, the whole-record one everything at once: a
    stretch that goes on across blocks, and a step's window across them, give the same
    delays (the closed-form cases above fix what they are)."""
    rng = np.random.default_rng(seed)
    t = _time(12.0)
    error = np.where(rng.random(t.size) < 0.002, 3.0, 0.1)  # rare spikes break stretches
    error[(t > 4.0) & (t < 4.5)] = 2.0
    steps = [2.0, 4.2, 8.0]
    assert _delays(t, error, steps, blocks) == _delays(t, error, steps)


def test_nan_error_breaks_a_stretch() -> None:
    t = _time(6.0)
    error = np.zeros(t.size)
    error[np.searchsorted(t, 1.5)] = np.nan
    assert _delays(t, error, [1.0])[0] == pytest.approx(0.501, abs=1e-9)
