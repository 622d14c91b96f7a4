"""Paper-style PNG figures of estimate vs truth (matplotlib, Agg backend, no display needed).

One figure per quantity (4-wheel quantities as 2x2 subplots), plus ``summary.png``. Long
records are reduced to a min/max envelope per pixel-sized bucket before plotting, so the
chattering of a differentiator stays visible while a 150 s, 1 kHz drive plots in about a
second. Grey bands mark what the metrics leave out (start-up, slope steps, gear changes).
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use('Agg')  # before pyplot: files only, never a window

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from numpy.typing import NDArray

from .evaluate import AccuracyReport, Comparison
from .metrics import error_stats
from .topics import WHEEL_NAMES

__all__ = ['DPI', 'envelope', 'write_figures']

FloatArray = NDArray[np.float64]

DPI = 110
_ESTIMATE_PERCENTILES = (0.5, 99.5)  # [%] of the estimate kept inside the y range
_BUCKETS = 1500  # min/max pairs per line: finer than the ~800 px wide axes
_EST_COLOR = 'tab:blue'
_TRUTH_COLOR = 'black'
_FILES = {
    'omega': 'wheel_speed.png',
    'omega_dot': 'wheel_accel.png',
    'accel': 'body_accel.png',
    'speed': 'body_speed.png',
    'fx': 'tire_fx.png',
    'fz': 'tire_fz.png',
    'mu': 'friction_mu.png',
    'slip': 'slip.png',
    'rolling': 'rolling_resistance.png',
    'aero': 'aero_drag.png',
    'slope': 'slope.png',
}


def envelope(
    t: FloatArray, y: FloatArray, buckets: int = _BUCKETS
) -> tuple[FloatArray, FloatArray]:
    """Min/max envelope of a long series for plotting.

    Args:
        t: shape (N,), [s].
        y: shape (N,); nan marks gaps (kept as gaps when a whole bucket is nan).
        buckets: number of buckets; series shorter than 2 * buckets are returned as is.

    Returns:
        (t, y) of shape (2 * K,), K <= buckets: each bucket's min then max, at its first time.
    """
    n = t.shape[0]
    if n <= 2 * buckets:
        return t, y
    size = -(-n // buckets)
    count = -(-n // size)  # buckets actually filled (the last one may be partial)
    pad = size * count - n
    yp = np.concatenate([y, np.full(pad, np.nan)]).reshape(count, size)
    tb = t[::size]
    with warnings.catch_warnings():
        # An all-nan bucket is an expected gap (e.g. invalid mu), not a problem.
        warnings.simplefilter('ignore', RuntimeWarning)
        lo, hi = np.nanmin(yp, axis=1), np.nanmax(yp, axis=1)
    return np.repeat(tb, 2), np.column_stack([lo, hi]).ravel()


def _shade(ax: Axes, report: AccuracyReport, t_end: float) -> None:
    cfg = report.settings
    ax.axvspan(0.0, cfg.settle_s, color='0.9', lw=0, zorder=0)
    for event in (*report.slope_steps_s, *report.gear_changes_s):
        w = cfg.exclusion_half_width_s
        ax.axvspan(event - w, event + w, color='0.9', lw=0, zorder=0)
    ax.set_xlim(0.0, t_end)


def _series(c: Comparison, column: int | None) -> tuple[FloatArray | None, FloatArray | None]:
    def pick(a: np.ndarray | None) -> np.ndarray | None:
        if a is None:
            return None
        return a[:, column] if column is not None and a.ndim == 2 else a

    est = pick(c.estimate)
    valid = pick(c.estimate_valid)
    if c.key == 'mu' and est is not None and valid is not None:
        # An invalid mu is a placeholder 0, not an estimate: leave a gap instead.
        est = np.where(valid, est, np.nan)
    return est, pick(c.truth)


def _robust_ylim(ax: Axes, est: FloatArray | None, truth: FloatArray | None) -> None:
    """Show all of the truth and 99 % of the estimate: rare transient spikes of an estimate
    (launch, gear shifts) would otherwise flatten the whole record into a line."""
    parts = []
    if truth is not None and np.isfinite(truth).any():
        parts += [float(np.nanmin(truth)), float(np.nanmax(truth))]
    if est is not None and np.isfinite(est).any():
        parts += [float(v) for v in np.nanpercentile(est, _ESTIMATE_PERCENTILES)]
    if not parts:
        return
    lo, hi = min(parts), max(parts)
    pad = 0.08 * (hi - lo) if hi > lo else max(abs(hi), 1.0) * 0.1
    ax.set_ylim(lo - pad, hi + pad)


def _plot_axis(
    ax: Axes, c: Comparison, report: AccuracyReport, column: int | None, title: str
) -> None:
    est, truth = _series(c, column)
    t_end = float(c.t[-1]) if c.t.size else 1.0
    _shade(ax, report, t_end)
    if truth is not None:
        ax.plot(*envelope(c.t, truth), color=_TRUTH_COLOR, lw=1.0, label=c.truth_label)
    if est is not None:
        ax.plot(*envelope(c.t, est), color=_EST_COLOR, lw=0.8, alpha=0.85, label=c.estimate_label)
    if est is not None and truth is not None:
        mask = c.mask if c.mask.ndim == 1 else c.mask[:, column]
        stats = error_stats(est, truth, mask)
        if stats.samples:
            unit = '' if c.unit == '-' else f' {c.unit}'
            title += f'  (RMS error {stats.rms:.3g}{unit})'
    _robust_ylim(ax, est, truth)
    ax.set_title(title, fontsize=10)
    ax.set_xlabel('time [s]')
    ax.set_ylabel(f'{c.symbol or c.title} [{c.unit}]')
    ax.grid(True, lw=0.3)


def _quantity_figure(c: Comparison, report: AccuracyReport) -> Figure:
    if c.per_wheel:
        fig, axes = plt.subplots(2, 2, figsize=(12, 7.5), sharex=True)
        for k, ax in enumerate(axes.ravel()):
            _plot_axis(ax, c, report, k, WHEEL_NAMES[k])
            if k < 2:
                ax.set_xlabel('')
        axes[0, 0].legend(loc='best', fontsize=9)
        fig.suptitle(f'{c.title} per wheel: estimate vs truth', fontsize=12)
        fig.subplots_adjust(left=0.07, right=0.98, bottom=0.07, top=0.91, hspace=0.18, wspace=0.15)
    elif c.key == 'slope' and c.estimate is not None and c.truth is not None:
        fig, (ax, ax_err) = plt.subplots(2, 1, figsize=(11, 7), sharex=True, height_ratios=(2, 1))
        _plot_axis(ax, c, report, None, c.title)
        ax.set_xlabel('')
        ax.legend(loc='best', fontsize=9)
        _shade(ax_err, report, float(c.t[-1]))
        ax_err.plot(*envelope(c.t, c.estimate - c.truth), color='tab:red', lw=0.8)
        limit = report.settings.convergence_threshold_deg
        for y in (-limit, limit):
            ax_err.axhline(y, color='0.4', lw=0.8, ls='--')
        ax_err.set_ylim(-4 * limit, 4 * limit)
        ax_err.set_ylabel('error [deg]')
        ax_err.set_xlabel('time [s]')
        ax_err.grid(True, lw=0.3)
        ax_err.set_title(
            f'estimate - truth (dashed: ±{limit:g} deg convergence band)', fontsize=10
        )
        fig.suptitle('Road slope: estimate vs true slope', fontsize=12)
        fig.subplots_adjust(left=0.08, right=0.98, bottom=0.08, top=0.91, hspace=0.2)
    else:
        fig, ax = plt.subplots(figsize=(11, 4.5))
        _plot_axis(ax, c, report, None, c.title)
        ax.legend(loc='best', fontsize=9)
        fig.subplots_adjust(left=0.08, right=0.98, bottom=0.12, top=0.92)
    return fig


def _summary_figure(comparisons: Sequence[Comparison], report: AccuracyReport) -> Figure:
    by_key = {c.key: c for c in comparisons}
    panels = [('speed', None), ('slope', None), ('omega', 0), ('fx', 0), ('fz', 0), ('mu', 0)]
    if 'speed' not in by_key:
        panels[0] = ('accel', None)
    present = [(by_key[k], col) for k, col in panels if k in by_key]
    fig, axes = plt.subplots(3, 2, figsize=(13, 10.5), sharex=True)
    flat = axes.ravel()
    for k, (ax, (c, col)) in enumerate(zip(flat, present, strict=False)):
        title = c.title + (f' ({WHEEL_NAMES[col]})' if c.per_wheel and col is not None else '')
        _plot_axis(ax, c, report, col if c.per_wheel else None, title)
        ax.legend(loc='best', fontsize=8)
        if k < len(flat) - 2:
            ax.set_xlabel('')
    for ax in flat[len(present) :]:
        ax.axis('off')
    lines = [
        f'{name}: {value:.3g} (limit {limit:g}, {"met" if met else "MISSED"})'
        for name, (value, limit, met) in report.targets.items()
    ]
    if lines:
        half = (len(lines) + 1) // 2
        text = '   |   '.join(lines[:half]) + '\n' + '   |   '.join(lines[half:])
        fig.text(0.5, 0.008, 'targets: ' + text, ha='center', va='bottom', fontsize=9)
    fig.suptitle(f'Summary: {Path(report.bag).name} (grey: not evaluated)', fontsize=12)
    fig.subplots_adjust(left=0.07, right=0.98, bottom=0.1, top=0.94, hspace=0.22, wspace=0.15)
    return fig


def write_figures(
    comparisons: Sequence[Comparison],
    report: AccuracyReport,
    out_dir: str | os.PathLike[str],
) -> list[Path]:
    """Write one PNG per quantity and ``summary.png`` into ``out_dir``.

    Args:
        comparisons: from :func:`~vd_observer_node.report.evaluate.evaluate`.
        report: the metrics (for excluded windows and titles).
        out_dir: existing directory.

    Returns:
        The files written.
    """
    out = Path(out_dir)
    written: list[Path] = []
    for c in comparisons:
        if c.t.size == 0:
            continue
        fig = _quantity_figure(c, report)
        path = out / _FILES.get(c.key, f'{c.key}.png')
        fig.savefig(path, dpi=DPI)
        plt.close(fig)
        written.append(path)
    if comparisons:
        fig = _summary_figure(comparisons, report)
        path = out / 'summary.png'
        fig.savefig(path, dpi=DPI)
        plt.close(fig)
        written.append(path)
    return written
