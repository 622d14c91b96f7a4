"""The report's accuracy metrics as running sums: the one implementation `vd report` and
`vd fleet` share.

`QuantityAccumulator` takes one estimated quantity's compared samples in stamp order, all at
once (`evaluation.evaluate`, the whole record that `vd report` also plots) or block by block
(`stream.evaluate_bag`, which `vd fleet` runs on bags it does not hold in memory), and gives
its `QuantityMetrics`: the error statistics overall and per wheel and the quantity's own
figures (ω's relative RMS, Fx against its peak, Fz against the static loads, the slope's
valid share); `ConvergenceAccumulator` the slope's convergence after each true step. How the
samples are paired and selected (the evaluation window, the
excitation, a reference interpolated onto the estimates) is each caller's; what is computed
from them is here.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from vd_observer_node.tools.report.metrics import ErrorStats, selected_errors
from vd_observer_node.tools.report.results import (
    EvaluationSettings,
    QuantityMetrics,
    SlopeConvergence,
)

__all__ = ['ConvergenceAccumulator', 'QuantityAccumulator', 'StatsSum', 'quantity_note']

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

_WHEELS = ('FL', 'FR', 'RL', 'RR')


class StatsSum:
    """Running `ErrorStats` of the selected finite elements (`metrics.error_stats`)."""

    def __init__(self) -> None:
        self.squares = 0.0
        self.total = 0.0
        self.max_abs = -math.inf
        self.samples = 0

    def add(self, error: FloatArray, mask: BoolArray | None) -> None:
        """Add the finite elements of `error` where `mask` holds (`metrics.selected_errors`)."""
        values = selected_errors(error, mask)
        if values.size:
            self.squares += float(np.sum(np.square(values)))
            self.total += float(np.sum(values))
            self.max_abs = max(self.max_abs, float(np.max(np.abs(values))))
            self.samples += int(values.size)

    def result(self) -> ErrorStats:
        """The statistics so far (nan with 0 samples when nothing was selected)."""
        if self.samples == 0:
            return ErrorStats(math.nan, math.nan, math.nan, 0)
        n = self.samples
        return ErrorStats(math.sqrt(self.squares / n), self.max_abs, self.total / n, n)


def quantity_note(key: str, cfg: EvaluationSettings, samples: int) -> str:
    """The caveat printed with a quantity's metrics ('' for none).

    Args:
        key: the quantity ('mu', 'slope', ...).
        cfg: evaluation settings.
        samples: elements its overall statistics were taken over.
    """
    note = ''
    if key == 'mu':
        note = f'|Fx_true| > {cfg.mu_excitation:g} Fz_true and estimate valid'
    elif key == 'slope':
        note = 'where the estimate is valid'
    if samples == 0:
        note = (note + '; ' if note else '') + 'no sample in the evaluation window'
    return note


class QuantityAccumulator:
    """One quantity's metrics over its compared samples, fed in stamp order."""

    def __init__(self, key: str, title: str, unit: str, settings: EvaluationSettings) -> None:
        """Args:
        key: the quantity ('omega', 'fx', 'fz', 'slope', ...; `results.Comparison`).
        title: its human name.
        unit: the unit of its errors.
        settings: the evaluation's (``omega_min``).
        """
        self.key, self.title, self.unit, self.settings = key, title, unit, settings
        self.overall = StatsSum()
        self.wheels = [StatsSum() for _ in _WHEELS]
        self.per_wheel = False
        self.relative = StatsSum()  # omega: |error| / |truth|; fz: error / static load
        self.spinning_error = StatsSum()  # omega: the error where the wheel spins
        self.spinning_truth = StatsSum()  # omega: the truth on the same samples
        self.peak = -math.inf  # fx: max |true Fx| over the selected samples
        self.peak_seen = False
        self.window = StatsSum()  # slope: every sample of the window, valid or not
        self.window_count = 0
        self.selected_count = 0
        self.static_loads: FloatArray | None = None

    def add(
        self,
        estimate: FloatArray,
        truth: FloatArray,
        mask: BoolArray,
        *,
        window: BoolArray | None = None,
        static_loads: FloatArray | None = None,
    ) -> None:
        """Add compared samples.

        Args:
            estimate: shape (N,) or (N, 4) (per wheel, order FL, FR, RL, RR), in the unit.
            truth: the same shape.
            mask: shape (N,) or like `estimate`: the samples the metrics count.
            window: shape (N,), the slope's evaluation window with its invalid samples too
                (the valid share and the RMS including them); the slope's only.
            static_loads: shape (4,), [N]: Fz's errors are also taken relative to these.
        """
        self.per_wheel = estimate.ndim == 2
        error = estimate - truth
        self.overall.add(error, mask)
        if self.per_wheel:
            for k, wheel in enumerate(self.wheels):
                wheel.add(error[:, k], mask if mask.ndim == 1 else mask[:, k])
        rows = np.broadcast_to(mask if mask.ndim == truth.ndim else mask[:, None], truth.shape)
        if self.key == 'omega':
            # the RMS of the error over the RMS of the truth, on the same spinning samples (the
            # standard relative RMS; the mean of per-sample ratios weighted slow wheels 3x more)
            spinning = rows & (np.abs(truth) > self.settings.omega_min) & np.isfinite(error)
            with np.errstate(divide='ignore', invalid='ignore'):
                ratio = np.abs(error) / np.abs(truth)
            self.relative.add(ratio, spinning)
            self.spinning_error.add(error, spinning)
            self.spinning_truth.add(truth, spinning)
        elif self.key == 'fx' and rows.any():
            self.peak = float(np.maximum(self.peak, np.abs(truth[rows]).max()))
            self.peak_seen = True
        elif self.key == 'fz' and static_loads is not None:
            self.static_loads = static_loads
            with np.errstate(divide='ignore', invalid='ignore'):
                ratio = error / static_loads[None, :]
            self.relative.add(ratio, rows)
        if window is not None:
            self.window.add(error, window)
            self.window_count += int(window.sum())
            self.selected_count += int(mask.sum())

    def result(self) -> QuantityMetrics:
        """The metrics of every sample added so far, with their caveat (`quantity_note`)."""
        overall = self.overall.result()
        wheels = tuple(w.result() for w in self.wheels) if self.per_wheel else ()
        extras: dict[str, float] = {}
        if self.key == 'omega':
            extras['rel_rms_pct'] = (
                100.0 * self.spinning_error.result().rms / self.spinning_truth.result().rms
            )
            extras['rel_max_pct'] = 100.0 * self.relative.result().max_abs
        elif self.key == 'fx':
            peak = self.peak if self.peak_seen else math.nan
            extras['max_abs_truth'] = peak
            # a drive that never pulls (true Fx zero in the window) has no percentage
            extras['rms_pct_of_max_truth'] = 100.0 * overall.rms / peak if peak > 0 else math.nan
        elif self.key == 'fz' and self.static_loads is not None:
            rel = self.relative.result()
            extras['rms_pct_of_static'] = 100.0 * rel.rms
            extras['max_pct_of_static'] = 100.0 * rel.max_abs
            for name, load in zip(_WHEELS, self.static_loads.tolist(), strict=True):
                extras[f'static_load_{name}'] = load
        if self.key == 'slope':
            extras['valid_pct'] = 100.0 * float(self.selected_count) / max(self.window_count, 1)
            extras['rms_incl_invalid'] = self.window.result().rms
        note = quantity_note(self.key, self.settings, overall.samples)
        return QuantityMetrics(self.key, self.title, self.unit, overall, wheels, extras, note)


class ConvergenceAccumulator:
    """The slope's convergence after each true step, from the compared samples in stamp order.

    After a step, the delay is the time to the first sample of the first stretch of samples
    whose |error| stays below ``convergence_threshold_deg`` for ``convergence_hold_s``,
    looked for up to the next step (or the end); a non-finite error breaks a stretch. Steps
    may be learnt as the samples come, each before any sample after it (the streamed
    evaluation finds them in the true slope as it reads).
    """

    def __init__(self, settings: EvaluationSettings) -> None:
        self.settings = settings
        self.steps: list[float] = []
        self.delays: list[float | None] = []
        self._open: list[float | None] = []  # start of a good stretch still going on
        self._before: list[float | None] = []
        self._after: list[float | None] = []
        self._first: float | None = None
        self._last: float | None = None

    def feed(
        self, t: FloatArray, estimate: FloatArray, truth: FloatArray, steps: FloatArray
    ) -> None:
        """Add samples.

        Args:
            t: shape (N,), [s], increasing, after every sample fed before.
            estimate: shape (N,), [deg].
            truth: shape (N,), [deg].
            steps: shape (K,), [s], the true steps known so far (those fed before first).
        """
        for step in steps.tolist()[len(self.steps) :]:
            self.steps.append(step)
            self.delays.append(None)
            self._open.append(None)
            self._before.append(self._last)
            self._after.append(None)
        if t.size == 0:
            return
        if self._first is None:
            self._first = float(truth[0])
        if not self.steps:
            self._last = float(truth[-1])
            return
        ok = np.abs(estimate - truth) < self.settings.convergence_threshold_deg
        stops = [*self.steps[1:], math.inf]
        for i, (start, stop) in enumerate(zip(self.steps, stops, strict=True)):
            k = int(np.searchsorted(t, start))  # first sample at or after the step
            if k > 0:
                self._before[i] = float(truth[k - 1])
            if k < t.size and self._after[i] is None:
                self._after[i] = float(truth[k])
            if self.delays[i] is not None:
                continue
            window = (t >= start) & (t < stop)
            if window.any():
                self._stretches(i, start, t[window], ok[window])
        self._last = float(truth[-1])

    def _stretches(self, i: int, start: float, tw: FloatArray, ok: BoolArray) -> None:
        edges = np.diff(np.concatenate(([0], ok.astype(np.int8), [0])))
        firsts = np.flatnonzero(edges == 1)
        lasts = np.flatnonzero(edges == -1) - 1
        begin = tw[firsts]
        if firsts.size and firsts[0] == 0 and self._open[i] is not None:
            begin[0] = self._open[i]  # the stretch goes on from the previous samples
        long_enough = tw[lasts] - begin >= self.settings.convergence_hold_s - 1e-9
        if long_enough.any():
            self.delays[i] = float(begin[np.argmax(long_enough)] - start)
        open_at_end = lasts.size > 0 and lasts[-1] == tw.size - 1
        self._open[i] = float(begin[-1]) if open_at_end else None

    def result(self) -> list[SlopeConvergence]:
        """Per step: the true slope before and after it and the delay (None: not converged)."""
        out = []
        for i, step in enumerate(self.steps):
            before = self._before[i] if self._before[i] is not None else self._first
            after = self._after[i] if self._after[i] is not None else self._last
            assert before is not None and after is not None
            out.append(SlopeConvergence(step, before, after, self.delays[i]))
        return out
