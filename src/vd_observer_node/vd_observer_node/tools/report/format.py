"""The accuracy report as JSON, Markdown and a concise plain-text table."""

from __future__ import annotations

import dataclasses
import json
import math
import unicodedata
from typing import Any

from vd_common.topics import TRUTH_NAMESPACE

from vd_observer_node.tools.report.alerts import AXLE_NAMES, AlertsSection, road_name
from vd_observer_node.tools.report.results import (
    NO_REFERENCE_HINT,
    TARGETS_TITLE,
    AccuracyReport,
    EstimateStats,
    QuantityMetrics,
)
from vd_observer_node.tools.report.topics import TRUE_POTENTIAL_TOPIC, WHEEL_NAMES

__all__ = ['report_json', 'report_markdown', 'report_text']

_EXTRA_LABELS = {
    'rel_rms_pct': ('relative RMS (RMS error / RMS truth)', '%'),
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
    for q in data['quantities'] + data['estimates']:
        q['wheels'] = dict(zip(WHEEL_NAMES, q['wheels'], strict=False))
    if report.alerts is not None:
        data['alerts']['targets'] = {
            name: {'value': value, 'limit': limit, 'met': met}
            for name, (value, limit, met) in report.alerts.targets.items()
        }
        for e in data['alerts']['episodes'] + data['alerts']['false_alarms']:
            e['wheel'] = WHEEL_NAMES[e['wheel']]
        for m in data['alerts']['mu_max']:
            m['axle'] = AXLE_NAMES[m['axle']]
            m['true_road_class'] = road_name(m['true_road_class'])
            m['road_class'] = road_name(m['road_class'])
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


_EST_HEAD = ['estimate', 'unit', 'samples', 'valid %', 'min', 'mean', 'max', 'valid means']


def _estimate_rows(report: AccuracyReport) -> list[list[str]]:
    rows = []
    for e in report.estimates:
        o = e.overall
        rows.append(
            [
                e.title,
                e.unit,
                str(o.samples),
                _num(o.valid_pct, 3),
                _num(o.minimum),
                _num(o.mean),
                _num(o.maximum),
                e.note,
            ]
        )
    return rows


def _wheel_cell(e: EstimateStats, k: int) -> str:
    w = e.wheels[k]
    if not w.valid:
        return 'no valid samples'
    return f'{_num(w.minimum)} / {_num(w.mean)} / {_num(w.maximum)} ({_num(w.valid_pct, 3)} %)'


def _table(head: list[str], rows: list[list[str]]) -> list[str]:
    """A fixed-width table: text columns left, the rest right; the last one free."""
    widths = [max(_width(r[k]) for r in [head, *rows]) for k in range(len(head) - 1)]

    def line(cells: list[str]) -> str:
        padded = [
            _pad(c, w, right=k >= 2)
            for k, (c, w) in enumerate(zip(cells[:-1], widths, strict=True))
        ]
        return ('  '.join(padded) + '  ' + cells[-1]).rstrip()

    return [line(head), *(line(r) for r in rows)]


def _estimates_text(report: AccuracyReport) -> str:
    lines = [
        f'estimates of {report.bag} ({report.duration_s:.1f} s): no reference in the bag, '
        'no accuracy computed; valid samples of every estimate over the whole bag:'
    ]
    lines += _table(_EST_HEAD, _estimate_rows(report))
    lines.extend(f'note: {n}' for n in report.notes[1:])  # the first: the line above
    return '\n'.join(lines) + '\n'


def _estimates_markdown(report: AccuracyReport) -> str:
    out = [
        f'# Estimates report: `{report.bag}`',
        '',
        f'- Duration: {report.duration_s:.2f} s (t = 0 at stamp {report.first_stamp_s:.3f} s)',
        '- Gear changes at: ' + (', '.join(f'{s:.2f} s' for s in report.gear_changes_s) or '-'),
        '',
        f'**This bag has no reference** (no `{TRUTH_NAMESPACE}*` topic), so no accuracy is '
        'computed: '
        "the tables give each estimate's own values. How to add one: " + NO_REFERENCE_HINT + '.',
        '',
        '## Estimates (valid samples, whole bag)',
        '',
        _md(_EST_HEAD),
        '|' + '---|' * len(_EST_HEAD),
    ]
    out += [_md(r) for r in _estimate_rows(report)]
    wheel_rows = [e for e in report.estimates if e.wheels]
    if wheel_rows:
        out += [
            '',
            '## Per wheel: min / mean / max (valid %)',
            '',
            '| estimate | unit | ' + ' | '.join(WHEEL_NAMES) + ' |',
            '|---|---|---|---|---|---|',
        ]
        for e in wheel_rows:
            cells = [_wheel_cell(e, k) for k in range(len(e.wheels))]
            out.append(_md([e.title, e.unit, *cells]))
    notes = report.notes[1:] if report.notes else ()
    if notes:
        out += ['', '## Notes', ''] + [f'- {n}' for n in notes]
    return '\n'.join(out) + '\n'


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


def _ms(seconds: float | None) -> str:
    return 'n/a' if seconds is None else f'{1e3 * seconds:.0f} ms'


def _alert_summary(section: AlertsSection) -> str:
    c = section.counts
    goal = section.settings.delay_goal_s
    return (
        f'{c["episodes"]} truth episodes: {c["met"]} detected within {1e3 * goal:.0f} ms, '
        f'{c["late"]} later, {c["missed"]} missed; {c["false_alarms"]} false alarms'
    )


def _episode_text(e: Any) -> str:
    wheel = WHEEL_NAMES[e.wheel]
    if e.delay_s is None:
        return f'{e.kind} {wheel}: true onset {e.true_onset_s:.3f} s, NOT DETECTED'
    if e.already_active:
        return f'{e.kind} {wheel}: true onset {e.true_onset_s:.3f} s, already active ({e.status})'
    return (
        f'{e.kind} {wheel}: true onset {e.true_onset_s:.3f} s, delay {_ms(e.delay_s)} ({e.status})'
    )


def _segment_text(m: Any) -> str:
    recent = (
        f'while excited rms {m.recent_rms:.3f}, {m.recent_within_pct:.0f} % within 0.1 '
        f'({_num(m.recent_unknown_pct, 3)} % class unknown, '
        f'{_num(m.recent_known_wrong_pct, 3)} % known and wrong); '
        if m.recent_samples
        else 'never excited for long, '
    )
    return (
        f'mu_max {AXLE_NAMES[m.axle]} [{m.start_s:.2f}, {m.end_s:.2f}] s, true '
        f'{m.true_mu_max:.3f} ({road_name(m.true_road_class)}): {recent}'
        f'all after excitation rms {m.rms:.3f}, class {road_name(m.road_class)}'
    )


_TEXT_EPISODES = 8  # episode lines in the terminal table; the rest is in metrics.md


def _alerts_text(section: AlertsSection) -> list[str]:
    lines = [f'alerts ({section.samples} samples): {_alert_summary(section)}']
    shown = [e for e in section.episodes if e.status != 'met'] + [
        e for e in section.episodes if e.status == 'met'
    ]
    lines += ['  ' + _episode_text(e) for e in shown[:_TEXT_EPISODES]]
    if len(shown) > _TEXT_EPISODES:
        lines.append(f'  ... {len(shown) - _TEXT_EPISODES} more episodes in metrics.md')
    if section.false_alarms:
        stamps = ', '.join(
            f'{a.kind} {WHEEL_NAMES[a.wheel]} {a.t_s:.2f} s' for a in section.false_alarms[:4]
        )
        more = len(section.false_alarms) - 4
        lines.append(f'  false alarms at {stamps}' + (f' (+{more})' if more > 0 else ''))
    lines += ['  ' + _segment_text(m) for m in section.mu_max]
    for name, (value, limit, met) in section.targets.items():
        verdict = 'met' if met else 'MISSED'
        lines.append(f'  goal {name}: {_num(value)} (goal {limit:g}): {verdict}')
    lines += [f'  note: {n}' for n in section.notes]
    return lines


def report_text(report: AccuracyReport) -> str:
    """A concise fixed-width table for the terminal."""
    if report.reference == 'none':
        return _estimates_text(report)
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
        verdict = 'met' if met else 'MISSED'
        lines.append(
            f'simulator ideal-sensor target {name}: {_num(value)} <= {limit:g}: {verdict}'
        )
    if report.alerts is not None:
        lines.extend(_alerts_text(report.alerts))
    lines.extend(f'note: {n}' for n in report.notes)
    return '\n'.join(lines) + '\n'


def _md(cells: list[str]) -> str:
    """One Markdown table row; a literal '|' (as in |err|) is escaped."""
    return '| ' + ' | '.join(c.replace('|', '\\|') for c in cells) + ' |'


def report_markdown(report: AccuracyReport) -> str:
    """The report as Markdown: window, metrics table, per-wheel table, convergence, targets
    (only for the simulator's bags); without reference, the estimates' own statistics."""
    if report.reference == 'none':
        return _estimates_markdown(report)
    against = 'truth' if report.reference == 'simulator' else 'reference'
    out = [
        f'# Accuracy report: `{report.bag}`',
        '',
        f'- Duration: {report.duration_s:.2f} s (t = 0 at stamp {report.first_stamp_s:.3f} s)',
        f'- Evaluation window: {_window_text(report)}',
        '- Slope steps at: ' + (', '.join(f'{s:.2f} s' for s in report.slope_steps_s) or '-'),
        '- Gear changes at: ' + (', '.join(f'{s:.2f} s' for s in report.gear_changes_s) or '-'),
        '',
        f'## Estimate vs {against}',
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
            f'## {TARGETS_TITLE}',
            '',
            '| target | value | limit | met |',
            '|---|---|---|---|',
        ]
        for name, (value, limit, met) in report.targets.items():
            out.append(_md([name, _num(value), f'{limit:g}', 'yes' if met else '**no**']))
    if report.alerts is not None:
        out += _alerts_markdown(report.alerts)
    if report.notes:
        out += ['', '## Notes', ''] + [f'- {n}' for n in report.notes]
    return '\n'.join(out) + '\n'


def _opt(value: float | None, digits: int = 3) -> str:
    return '-' if value is None else f'{value:.{digits}f}'


def _alerts_markdown(section: AlertsSection) -> list[str]:
    cfg = section.settings
    out = [
        '',
        '## Alerts: detection delay and false alarms',
        '',
        f'Truth (docs/alerts.md 4.1): traction at true slip >= the MF peak slip, lock at '
        f'slip <= -peak slip, low_friction at |mu| >= {cfg.low_friction_ratio:g} x peak mu '
        f'(peak at the true load and road mu, {TRUE_POTENTIAL_TOPIC}); onsets from '
        f'{cfg.settle_s:g} s, merged within {cfg.merge_s:g} s; an activation up to '
        f'{cfg.early_s:g} s early counts; false alarm: no relaxed truth '
        f'({cfg.relaxed_scale:g} x thresholds) within [-{cfg.false_before_s:g}, '
        f'+{cfg.false_after_s:g}] s. {section.samples} samples.',
        '',
        f'**{_alert_summary(section)}.**',
    ]
    if section.episodes:
        out += [
            '',
            '| kind | wheel | true onset [s] | detected [s] | delay [ms] | status '
            '| reported onset [s] |',
            '|---|---|---|---|---|---|---|',
        ]
        for e in section.episodes:
            delay = '-' if e.delay_s is None else f'{1e3 * e.delay_s:.1f}'
            if e.already_active:
                delay = 'already active'
            status = e.status if e.status == 'met' else f'**{e.status}**'
            out.append(
                f'| {e.kind} | {WHEEL_NAMES[e.wheel]} | {e.true_onset_s:.3f} | '
                f'{_opt(e.detected_s)} | {delay} | {status} | {_opt(e.reported_onset_s)} |'
            )
    if section.false_alarms:
        out += ['', '| false alarm: kind | wheel | at [s] |', '|---|---|---|']
        out += [
            f'| {a.kind} | {WHEEL_NAMES[a.wheel]} | {a.t_s:.3f} |' for a in section.false_alarms
        ]
    if section.mu_max:
        out += [
            '',
            f'## Friction potential: mu_max error (goal |err| <= {cfg.mu_max_goal:g})',
            '',
            f'(a) while the axle was excited (true utilisation >= {cfg.excitation_ratio:g}) '
            f'within the last {cfg.excitation_window_s:g} s, from '
            f'{cfg.excitation_start_s:g} s after the first excitation; (b) every sample after '
            'the first excitation of the constant-road segment.',
            '',
            '| axle | segment [s] | excited at [s] | true mu_max | true class | (a) samples '
            '| (a) RMS | (a) within 0.1 | (a) class unknown | (a) known and wrong '
            '| (b) mean estimate | (b) RMS | (b) max err '
            '| (b) within 0.1 | last miss after [s] | confidence | class |',
            '|' + '---|' * 17,
        ]
        for m in section.mu_max:
            out.append(
                _md(
                    [
                        AXLE_NAMES[m.axle],
                        f'{m.start_s:.2f} - {m.end_s:.2f}',
                        f'{m.excited_s:.3f}',
                        f'{m.true_mu_max:.3f}',
                        road_name(m.true_road_class),
                        str(m.recent_samples),
                        _num(m.recent_rms, 3),
                        f'{_num(m.recent_within_pct, 3)} %',
                        f'{_num(m.recent_unknown_pct, 3)} %',
                        f'{_num(m.recent_known_wrong_pct, 3)} %',
                        f'{m.estimate_mean:.3f}',
                        f'{m.rms:.3f}',
                        f'{m.max_abs:.3f}',
                        f'{m.within_pct:.1f} %',
                        f'{m.last_miss_s:.3f}',
                        _num(m.confidence_mean, 2),
                        road_name(m.road_class),
                    ]
                )
            )
    if section.targets:
        out += ['', '| goal | value | limit | met |', '|---|---|---|---|']
        for name, (value, limit, met) in section.targets.items():
            out.append(_md([name, _num(value), f'{limit:g}', 'yes' if met else '**no**']))
    if section.notes:
        out += [''] + [f'- {n}' for n in section.notes]
    return out
