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

from vd_observer_node.tools.report.alert_data import AlertData
from vd_observer_node.tools.report.alerts import (
    ALERT_KINDS,
    AXLE_NAMES,
    AlertsSection,
    truth_conditions,
)
from vd_observer_node.tools.report.metrics import error_stats
from vd_observer_node.tools.report.mu_max import (
    axle_utilisation,
)
from vd_observer_node.tools.report.results import TARGETS_TITLE, AccuracyReport, Comparison
from vd_observer_node.tools.report.topics import WHEEL_NAMES

__all__ = ['DPI', 'NO_VALID_SAMPLES', 'envelope', 'write_alert_figures', 'write_figures']

FloatArray = NDArray[np.float64]

DPI = 110
_ESTIMATE_PERCENTILES = (0.5, 99.5)  # [%] of the estimate kept inside the y range
_BUCKETS = 1500  # min/max pairs per line: finer than the ~800 px wide axes
_EST_COLOR = 'tab:blue'
_TRUTH_COLOR = 'black'
_INVALID_COLOR = 'tab:red'
#: The text of a panel with nothing valid to draw (instead of an empty frame).
NO_VALID_SAMPLES = 'no valid samples'
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
    ax.set_xlim(0.0, t_end)
    if report.reference == 'none':  # no accuracy, so no evaluation window to grey out
        return
    cfg = report.settings
    ax.axvspan(0.0, cfg.settle_s, color='0.9', lw=0, zorder=0)
    for event in (*report.slope_steps_s, *report.gear_changes_s):
        w = cfg.exclusion_half_width_s
        ax.axvspan(event - w, event + w, color='0.9', lw=0, zorder=0)


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


def _against(report: AccuracyReport) -> str:
    """'truth' (the simulator's), 'reference' (a car's) or '' (none) for the titles."""
    return {'simulator': 'truth', 'reference': 'reference'}.get(report.reference, '')


def _vs(report: AccuracyReport) -> str:
    against = _against(report)
    return f'estimate vs {against}' if against else 'estimate (no reference in the bag)'


def _mark_invalid(ax: Axes, c: Comparison, column: int | None) -> None:
    """A band along the bottom of the axes where the estimator flags its estimate invalid
    (mu's and the slope's ``valid``): a reader sees what the statistics leave out."""
    if c.estimate_valid is None or c.t.size == 0:
        return
    valid = np.asarray(c.estimate_valid, dtype=bool)
    if valid.ndim == 2:
        valid = valid[:, column] if column is not None else np.all(valid, axis=1)
    runs = _runs(np.logical_not(valid), c.t)
    if runs:
        ax.broken_barh(
            runs,
            (0.0, 0.04),
            facecolors=_INVALID_COLOR,
            alpha=0.5,
            lw=0,
            transform=ax.get_xaxis_transform(),
            label='estimate invalid',
        )


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
        _mark_invalid(ax, c, column)
    if not _has_valid(est, c, column):
        # an empty frame reads as a plotting bug: say why nothing (of the estimate) is drawn
        text = NO_VALID_SAMPLES if est is not None else 'no estimate'
        ax.text(0.5, 0.5, text, transform=ax.transAxes, ha='center', va='center',
                fontsize=12, color='0.35')  # fmt: skip
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


def _has_valid(est: FloatArray | None, c: Comparison, column: int | None) -> bool:
    """Whether the estimate has one finite sample its estimator flags valid."""
    if est is None:
        return False
    ok = np.isfinite(est)
    if c.estimate_valid is not None:
        valid = np.asarray(c.estimate_valid, dtype=bool)
        if column is not None and valid.ndim == 2:
            valid = valid[:, column]
        if valid.shape == ok.shape:
            ok = ok & valid
    return bool(ok.any())


def _quantity_figure(c: Comparison, report: AccuracyReport) -> Figure:
    if c.per_wheel:
        fig, axes = plt.subplots(2, 2, figsize=(12, 7.5), sharex=True)
        for k, ax in enumerate(axes.ravel()):
            _plot_axis(ax, c, report, k, WHEEL_NAMES[k])
            if k < 2:
                ax.set_xlabel('')
        axes[0, 0].legend(loc='best', fontsize=9)
        fig.suptitle(f'{c.title} per wheel: {_vs(report)}', fontsize=12)
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
            f'estimate - {_against(report)} (dashed: ±{limit:g} deg convergence band)',
            fontsize=10,
        )
        fig.suptitle(f'Road slope: {_vs(report)}', fontsize=12)
        fig.subplots_adjust(left=0.08, right=0.98, bottom=0.08, top=0.91, hspace=0.2)
    else:
        fig, ax = plt.subplots(figsize=(11, 4.5))
        _plot_axis(ax, c, report, None, c.title)
        ax.legend(loc='best', fontsize=9)
        fig.suptitle(f'{c.title}: {_vs(report)}', fontsize=12)
        fig.subplots_adjust(left=0.08, right=0.98, bottom=0.12, top=0.9)
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
        fig.text(0.5, 0.008, f'{TARGETS_TITLE}: ' + text, ha='center', va='bottom', fontsize=9)
    grey = 'grey: not evaluated' if report.reference != 'none' else 'no reference in the bag'
    fig.suptitle(f'Summary: {Path(report.bag).name} ({grey})', fontsize=12)
    fig.subplots_adjust(left=0.07, right=0.98, bottom=0.1, top=0.94, hspace=0.22, wspace=0.15)
    return fig


def write_figures(
    comparisons: Sequence[Comparison],
    report: AccuracyReport,
    out_dir: str | os.PathLike[str],
) -> list[Path]:
    """Write one PNG per quantity and ``summary.png`` into ``out_dir``.

    Args:
        comparisons: from :func:`~vd_observer_node.tools.report.evaluation.evaluate`.
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


_KIND_COLORS = ('tab:orange', 'tab:purple', 'tab:green')
_LANE = 3.0  # y distance between the kinds' lanes (levels 0..2 within a lane)


def _runs(mask: np.ndarray, t: FloatArray) -> list[tuple[float, float]]:
    """(start, width) [s] of each run of a bool series, for ``broken_barh``."""
    m = np.concatenate([[False], mask.astype(bool), [False]])
    edges = np.flatnonzero(np.diff(m.astype(np.int8)))
    starts, stops = edges[0::2], edges[1::2] - 1
    dt = float(np.median(np.diff(t))) if t.size > 1 else 0.0
    return [(float(t[a]), float(t[b] - t[a]) + dt) for a, b in zip(starts, stops, strict=True)]


def _steps(t: FloatArray, y: np.ndarray) -> tuple[FloatArray, np.ndarray]:
    """Only the change points of a piecewise-constant series (plotted as steps-post)."""
    keep = np.concatenate([[True], np.diff(y) != 0, [True]])[: t.size]
    keep[-1] = True
    return t[keep], y[keep]


def _alerts_figure(data: AlertData, section: AlertsSection) -> Figure:
    assert data.level is not None
    cfg = section.settings
    truth = truth_conditions(
        data.slip, data.mu, data.peak_slip, data.peak_mu, low_friction_ratio=cfg.low_friction_ratio
    )
    fig, axes = plt.subplots(2, 2, figsize=(13, 7.5), sharex=True, sharey=True)
    t_end = float(data.t[-1]) if data.t.size else 1.0
    for wheel, ax in enumerate(axes.ravel()):
        for kind, name in enumerate(ALERT_KINDS):
            base = _LANE * kind
            color = _KIND_COLORS[kind]
            ax.broken_barh(
                _runs(truth[:, kind, wheel], data.t),
                (base - 0.2, 2.4),
                facecolors=color,
                alpha=0.18,
                lw=0,
            )
            ts, lv = _steps(data.t, data.level[:, kind, wheel])
            ax.plot(ts, base + lv, drawstyle='steps-post', color=color, lw=1.2, label=name)
        for e in section.episodes:
            if e.wheel == wheel and e.status == 'missed':
                y = _LANE * ALERT_KINDS.index(e.kind) + 1.0
                ax.plot(e.true_onset_s, y, 'kv', ms=7)
        for a in section.false_alarms:
            if a.wheel == wheel:
                ax.plot(a.t_s, _LANE * ALERT_KINDS.index(a.kind) + 1.0, 'rx', ms=9, mew=2)
        ax.set_title(WHEEL_NAMES[wheel], fontsize=10)
        ax.set_xlim(0.0, t_end)
        ax.set_yticks(
            [_LANE * k + v for k in range(3) for v in (0, 1, 2)],
            [f'{n} {lv}' for n in ('traction', 'lock', 'low μ') for lv in ('ok', 'warn', 'crit')],
            fontsize=7,
        )
        ax.grid(True, lw=0.3)
        if wheel >= 2:
            ax.set_xlabel('time [s]')
    axes[0, 0].legend(loc='upper left', fontsize=8)
    c = section.counts
    fig.suptitle(
        f'Alert levels per wheel; shaded: true condition (MF peak at the true road mu); '
        f'x: false alarm, v: missed onset\n{c["met"]} of {c["episodes"]} episodes within '
        f'{1e3 * cfg.delay_goal_s:.0f} ms, {c["late"]} later, {c["missed"]} missed, '
        f'{c["false_alarms"]} false alarms',
        fontsize=11,
    )
    fig.subplots_adjust(left=0.09, right=0.98, bottom=0.08, top=0.88, hspace=0.2, wspace=0.12)
    return fig


def _potential_figure(data: AlertData, section: AlertsSection) -> Figure:
    assert data.mu_max is not None
    cfg = section.settings
    util = axle_utilisation(data.mu, data.peak_mu)
    fig, axes = plt.subplots(2, 1, figsize=(12, 7.5), sharex=True)
    t_end = float(data.t[-1]) if data.t.size else 1.0
    for axle, ax in enumerate(axes):
        ax.broken_barh(
            _runs(util[:, axle] >= cfg.excitation_ratio, data.t),
            (0.0, 10.0),
            facecolors='0.85',
            lw=0,
            zorder=0,
        )
        ax.plot(
            *envelope(data.t, data.true_mu_max[:, axle]),
            color=_TRUTH_COLOR,
            lw=1.2,
            label='true μ_max (MF peak)',
        )
        ax.plot(
            *envelope(data.t, data.mu_max[:, axle]),
            color=_EST_COLOR,
            lw=1.0,
            label='estimated μ_max',
        )
        top = max(1.3, float(np.nanmax(data.true_mu_max[:, axle])) * 1.25)
        ax.set_ylim(0.0, top)
        ax.set_xlim(0.0, t_end)
        ax.set_ylabel('μ_max [-]')
        ax.grid(True, lw=0.3)
        parts = [
            f'{m.recent_rms:.3f} RMS, {m.recent_within_pct:.0f} % within {cfg.mu_max_goal:g} '
            f'({m.start_s:.1f}-{m.end_s:.1f} s)'
            for m in section.mu_max
            if m.axle == axle and m.recent_samples
        ]
        ax.set_title(
            f'{AXLE_NAMES[axle]} axle; grey: excited (true utilisation >= '
            f'{cfg.excitation_ratio:g}); while excited: ' + ('; '.join(parts) or 'never'),
            fontsize=9,
        )
        if data.confidence is not None:
            twin = ax.twinx()
            twin.plot(
                *envelope(data.t, data.confidence[:, axle]),
                color='tab:green',
                lw=0.8,
                alpha=0.7,
                label='confidence',
            )
            twin.set_ylim(0.0, 1.05)
            twin.set_ylabel('confidence [-]', color='tab:green')
            if axle == 0:
                twin.legend(loc='upper right', fontsize=8)
        if axle == 0:
            ax.legend(loc='upper left', fontsize=8)
    axes[-1].set_xlabel('time [s]')
    fig.suptitle("Road-friction potential: estimate vs the simulated tyre's peak", fontsize=12)
    fig.subplots_adjust(left=0.07, right=0.93, bottom=0.07, top=0.9, hspace=0.25)
    return fig


def write_alert_figures(
    data: AlertData, section: AlertsSection, out_dir: str | os.PathLike[str]
) -> list[Path]:
    """Write ``alerts.png`` and ``friction_potential.png`` (each only if its estimate exists).

    Args:
        data: paired arrays from :func:`~vd_observer_node.tools.report.alerts.alert_data`.
        section: the metrics of the same data.
        out_dir: existing directory.

    Returns:
        The files written.
    """
    out = Path(out_dir)
    written: list[Path] = []
    figures = []
    if data.level is not None and data.t.size:
        figures.append(('alerts.png', _alerts_figure(data, section)))
    if data.mu_max is not None and data.t.size:
        figures.append(('friction_potential.png', _potential_figure(data, section)))
    for name, fig in figures:
        path = out / name
        fig.savefig(path, dpi=DPI)
        plt.close(fig)
        written.append(path)
    return written
