"""Paper-style PNG figures of estimate vs truth (matplotlib, Agg backend, no display needed).

One figure per quantity (4-wheel quantities as 2x2 subplots), plus ``summary.png``. Long
records are reduced to a min/max envelope per pixel-sized bucket before plotting, so the
chattering of a differentiator stays visible while a 150 s, 1 kHz drive plots in about a
second. Grey bands mark what the metrics leave out (start-up, slope steps, gear changes).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use('Agg')  # before pyplot: files only, never a window

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.axes import Axes  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from numpy.typing import NDArray  # noqa: E402

from .evaluate import AccuracyReport, Comparison  # noqa: E402
from .metrics import error_stats  # noqa: E402
from .topics import WHEEL_NAMES  # noqa: E402

__all__ = ['DPI', 'envelope', 'write_figures']

FloatArray = NDArray[np.float64]

DPI = 110
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


def envelope(t: FloatArray, y: FloatArray, buckets: int = _BUCKETS) -> tuple[FloatArray, FloatArray]:
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
    with np.errstate(invalid='ignore'), _quiet():
        lo, hi = np.nanmin(yp, axis=1), np.nanmax(yp, axis=1)
    return np.repeat(tb, 2), np.column_stack([lo, hi]).ravel()


class _quiet:  # noqa: N801 (used like a function)
    """Silence numpy's all-nan slice warnings (a gap is expected, e.g. invalid mu)."""

    def __enter__(self) -> None:
        import warnings

        self._ctx = warnings.catch_warnings()
        self._ctx.__enter__()
        warnings.simplefilter('ignore', RuntimeWarning)

    def __exit__(self, *exc: object) -> None:
        self._ctx.__exit__(*exc)


def _shade(ax: Axes, report: AccuracyReport, t_end: float) -> None:
    cfg = report.settings
    ax.axvspan(0.0, cfg.settle_s, color='0.9', lw=0, zorder=0)
    for event in (*report.slope_steps_s, *report.gear_changes_s):
        w = cfg.exclusion_half_width_s
        ax.axvspan(event - w, event + w, color='0.9', lw=0, zorder=0)
    ax.set_xlim(0.0, t_end)


def _series(c: Comparison, column: int | None) -> tuple[FloatArray | None, FloatArray | None]:
    def pick(a: FloatArray | None) -> FloatArray | None:
        if a is None:
            return None
        return a[:, column] if column is not None else a

    est = pick(c.estimate)
    if c.key == 'mu' and est is not None:
        # An invalid mu is a placeholder 0, not an estimate: leave a gap instead.
        valid = c.mask if c.mask.ndim == 1 else c.mask[:, column]
        est = np.where(valid, est, np.nan)
    return est, pick(c.truth)


def _plot_axis(ax: Axes, c: Comparison, report: AccuracyReport, column: int | None,
               title: str) -> None:
    est, truth = _series(c, column)
    t_end = float(c.t[-1]) if c.t.size else 1.0
    _shade(ax, report, t_end)
    if truth is not None:
        ax.plot(*envelope(c.t, truth), color=_TRUTH_COLOR, lw=1.0, label=c.truth_label)
    if est is not None:
        ax.plot(*envelope(c.t, est), color=_EST_COLOR, lw=0.8, alpha=0.85,
                label=c.estimate_label)
    if est is not None and truth is not None:
        mask = c.mask if c.mask.ndim == 1 else c.mask[:, column]
        stats = error_stats(est, truth, mask)
        if stats.samples:
            title += f'  (RMS error {stats.rms:.3g} {c.unit})'
    ax.set_title(title, fontsize=10)
    ax.set_xlabel('time [s]')
    ax.set_ylabel(f'{c.title.split(" ", 1)[-1] if c.per_wheel else c.title} [{c.unit}]'
                  if c.unit != '-' else f'{c.title} [-]')
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
    elif c.key == 'slope' and c.estimate is not None and c.truth is not None:
        fig, (ax, ax_err) = plt.subplots(2, 1, figsize=(11, 7), sharex=True,
                                         height_ratios=(2, 1))
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
        ax_err.set_title(f'estimate - truth (dashed: ±{limit:g} deg convergence band)',
                         fontsize=10)
        fig.suptitle('Road slope: estimate vs true slope', fontsize=12)
    else:
        fig, ax = plt.subplots(figsize=(11, 4.5))
        _plot_axis(ax, c, report, None, c.title)
        ax.legend(loc='best', fontsize=9)
    fig.tight_layout()
    return fig


def _summary_figure(comparisons: Sequence[Comparison], report: AccuracyReport) -> Figure:
    by_key = {c.key: c for c in comparisons}
    panels = [('speed', None), ('slope', None), ('omega', 0), ('fx', 0), ('fz', 0), ('mu', 0)]
    present = [(by_key[k], col) for k, col in panels if k in by_key]
    fig, axes = plt.subplots(3, 2, figsize=(13, 10), sharex=True)
    flat = axes.ravel()
    for ax, (c, col) in zip(flat, present, strict=False):
        title = c.title + (f' ({WHEEL_NAMES[col]})' if c.per_wheel and col is not None else '')
        _plot_axis(ax, c, report, col if c.per_wheel else None, title)
        ax.legend(loc='best', fontsize=8)
    for ax in flat[len(present):]:
        ax.axis('off')
    lines = [f'{name}: {value:.3g} (target {limit:g}) {"met" if met else "MISSED"}'
             for name, (value, limit, met) in report.targets.items()]
    if lines:
        fig.text(0.5, 0.005, '   |   '.join(lines), ha='center', va='bottom', fontsize=8.5)
    fig.suptitle(f'Summary: {Path(report.bag).name} (grey: not evaluated)', fontsize=12)
    fig.tight_layout(rect=(0, 0.03, 1, 1))
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
