"""The accuracy report as JSON, Markdown and a concise plain-text table."""

from __future__ import annotations

import dataclasses
import json
import math
import unicodedata
from typing import Any

from .evaluate import AccuracyReport, QuantityMetrics
from .topics import WHEEL_NAMES

__all__ = ['report_json', 'report_markdown', 'report_text']

_EXTRA_LABELS = {
    'rel_rms_pct': ('relative RMS', '%'),
    'rel_max_pct': ('relative max', '%'),
    'rms_pct_of_max_truth': ('RMS / max |truth|', '%'),
    'max_abs_truth': ('max |truth|', None),
    'rms_pct_of_static': ('RMS / static load', '%'),
    'max_pct_of_static': ('max / static load', '%'),
    'valid_pct': ('estimate valid', '%'),
    'rms_incl_invalid': ('RMS incl. invalid', None),
    'evaluated_samples': ('samples', ''),
}


def _clean(value: Any) -> Any:
    """JSON-safe: nan/inf become null, tuples lists, dataclasses dicts."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {str(k): _clean(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_clean(v) for v in value]
    return value


def report_json(report: AccuracyReport) -> str:
    """The report as indented JSON (nan written as null); keys as in the dataclasses."""
    data = dataclasses.asdict(report)
    data['targets'] = {
        name: {'value': value, 'limit': limit, 'met': met}
        for name, (value, limit, met) in report.targets.items()
    }
    for q in data['quantities']:
        q['wheels'] = dict(zip(WHEEL_NAMES, q['wheels'], strict=False))
    return json.dumps(_clean(data), indent=2, allow_nan=False) + '\n'


def _num(value: float | None, digits: int = 4) -> str:
    if value is None or not math.isfinite(value):
        return 'n/a'
    return f'{value:.{digits}g}'


def _extras_text(q: QuantityMetrics) -> str:
    parts = []
    for key, value in q.extras.items():
        if key.startswith('static_load_'):
            continue
        label, unit = _EXTRA_LABELS.get(key, (key, ''))
        unit = q.unit if unit is None else unit
        suffix = '' if unit in ('', '-') else (unit if unit == '%' else f' {unit}')
        parts.append(f'{label} {_num(value)}{suffix}')
    return ', '.join(parts)


def _width(text: str) -> int:
    """Terminal columns of a string: combining marks (the dot of ω̇) take none."""
    return sum(0 if unicodedata.combining(ch) else 1 for ch in text)


def _pad(text: str, width: int, right: bool) -> str:
    fill = ' ' * max(width - _width(text), 0)
    return fill + text if right else text + fill


def _rows(report: AccuracyReport) -> list[list[str]]:
    rows = []
    for q in report.quantities:
        rows.append(
            [
                q.title,
                q.unit,
                _num(q.overall.rms),
                _num(q.overall.max_abs),
                _num(q.overall.mean),
                str(q.overall.samples),
                _extras_text(q),
            ]
        )
    return rows


_HEAD = ['quantity', 'unit', 'RMS', 'max |err|', 'mean err', 'samples', 'also']


def _convergence_lines(report: AccuracyReport) -> list[str]:
    cfg = report.settings
    lines = []
    for c in report.convergence:
        delay = 'not converged' if c.delay_s is None else f'{c.delay_s:.3f} s'
        lines.append(f'step at {c.step_s:.2f} s ({c.from_deg:.2f} -> {c.to_deg:.2f} deg): {delay}')
    if lines:
        lines.insert(
            0,
            f'slope convergence (|error| < {cfg.convergence_threshold_deg:g} deg '
            f'for {cfg.convergence_hold_s:g} s):',
        )
    return lines


def _window_text(report: AccuracyReport) -> str:
    cfg = report.settings
    return (
        f't >= {cfg.settle_s:g} s, excluding +-{cfg.exclusion_half_width_s:g} s around '
        f'{len(report.slope_steps_s)} slope steps and {len(report.gear_changes_s)} gear '
        f'changes ({100 * report.evaluated_fraction:.1f} % of samples evaluated)'
    )


def report_text(report: AccuracyReport) -> str:
    """A concise fixed-width table for the terminal."""
    rows = _rows(report)
    widths = [max(_width(r[k]) for r in [_HEAD, *rows]) for k in range(len(_HEAD) - 1)]
    lines = [
        f'accuracy of {report.bag} ({report.duration_s:.1f} s); window: {_window_text(report)}'
    ]

    def line(cells: list[str]) -> str:
        padded = [
            _pad(c, w, right=k >= 2)
            for k, (c, w) in enumerate(zip(cells[:-1], widths, strict=True))
        ]
        return ('  '.join(padded) + '  ' + cells[-1]).rstrip()

    lines.append(line(_HEAD))
    lines.extend(line(r) for r in rows)
    lines.extend(_convergence_lines(report))
    for name, (value, limit, met) in report.targets.items():
        lines.append(f'target {name}: {_num(value)} <= {limit:g}: {"met" if met else "MISSED"}')
    lines.extend(f'note: {n}' for n in report.notes)
    return '\n'.join(lines) + '\n'


def _md(cells: list[str]) -> str:
    """One Markdown table row; a literal '|' (as in |err|) is escaped."""
    return '| ' + ' | '.join(c.replace('|', '\\|') for c in cells) + ' |'


def report_markdown(report: AccuracyReport) -> str:
    """The report as Markdown: window, metrics table, per-wheel table, convergence, targets."""
    out = [
        f'# Accuracy report: `{report.bag}`',
        '',
        f'- Duration: {report.duration_s:.2f} s (t = 0 at stamp {report.first_stamp_s:.3f} s)',
        f'- Evaluation window: {_window_text(report)}',
        '- Slope steps at: ' + (', '.join(f'{s:.2f} s' for s in report.slope_steps_s) or '-'),
        '- Gear changes at: ' + (', '.join(f'{s:.2f} s' for s in report.gear_changes_s) or '-'),
        '',
        '## Estimate vs truth',
        '',
        _md(_HEAD),
        '|' + '---|' * len(_HEAD),
    ]
    for q, r in zip(report.quantities, _rows(report), strict=True):
        if q.note:
            r[-1] = (r[-1] + '; ' if r[-1] else '') + q.note
        out.append(_md(r))
    wheel_rows = [q for q in report.quantities if q.wheels]
    if wheel_rows:
        out += [
            '',
            '## RMS error per wheel',
            '',
            '| quantity | unit | ' + ' | '.join(WHEEL_NAMES) + ' |',
            '|---|---|---|---|---|---|',
        ]
        for q in wheel_rows:
            out.append(
                f'| {q.title} | {q.unit} | ' + ' | '.join(_num(w.rms) for w in q.wheels) + ' |'
            )
    if report.convergence:
        cfg = report.settings
        out += [
            '',
            f'## Slope convergence (|error| < {cfg.convergence_threshold_deg:g} deg '
            f'for {cfg.convergence_hold_s:g} s)',
            '',
            '| step at [s] | true slope [deg] | convergence time [s] |',
            '|---|---|---|',
        ]
        for c in report.convergence:
            delay = 'not converged' if c.delay_s is None else f'{c.delay_s:.3f}'
            out.append(f'| {c.step_s:.2f} | {c.from_deg:.2f} -> {c.to_deg:.2f} | {delay} |')
    if report.targets:
        out += [
            '',
            '## Accuracy targets (issue, ideal sensors)',
            '',
            '| target | value | limit | met |',
            '|---|---|---|---|',
        ]
        for name, (value, limit, met) in report.targets.items():
            out.append(_md([name, _num(value), f'{limit:g}', 'yes' if met else '**no**']))
    if report.notes:
        out += ['', '## Notes', ''] + [f'- {n}' for n in report.notes]
    return '\n'.join(out) + '\n'
