"""The fleet report: one table of every bag (CSV, Markdown, Parquet if pyarrow is there), a
summary figure, and the regressions against an earlier fleet report.

Rows come from :func:`~.process.process_bag`. The report holds no wall times, so the same
bags under the same settings give the same files, whichever engine ran them and however
often the run was interrupted. Bags are listed worst first: failed bags, then by the number
of accuracy targets failed, then by missed alerts plus false alarms, then by the worst
target's value over its limit.
"""

from __future__ import annotations

import csv
import importlib.util
import io
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from vd_observer_node.tools.fleet.errors import FleetInputError
from vd_observer_node.tools.fleet.process import ROW_COLUMNS, TARGET_COLUMNS, TEXT_COLUMNS
from vd_observer_node.tools.report.alerts import ALERT_KINDS

__all__ = [
    'LOWER_IS_BETTER',
    'REPORT_COLUMNS',
    'FleetReport',
    'Regression',
    'compare_baseline',
    'fleet_csv',
    'fleet_markdown',
    'read_fleet_csv',
    'sort_worst_first',
    'target_ratio',
    'write_fleet_report',
]

#: Columns of fleet.csv: the row's, plus the worst target's value / limit.
REPORT_COLUMNS: tuple[str, ...] = (*ROW_COLUMNS, 'worst_target_ratio')

_INT_COLUMNS = frozenset(
    {
        'samples',
        'unmatched',
        'targets_met',
        'targets_failed',
        *(f'alerts_{kind}' for kind in ALERT_KINDS),
        'episodes',
        'detected',
        'missed',
        'false_alarms',
        'mu_max_segments',
        'faults_total',
    }
)
_FLOAT_COLUMNS = frozenset(
    {
        'duration_s',
        'distance_m',
        *TARGET_COLUMNS.values(),
        'mu_max_rms_worst',
        'mu_max_max_abs_worst',
        'worst_target_ratio',
    }
)

#: Columns where a larger value than the baseline's is a regression.
LOWER_IS_BETTER: tuple[str, ...] = (
    *TARGET_COLUMNS.values(),
    'targets_failed',
    'missed',
    'false_alarms',
    'mu_max_rms_worst',
    'mu_max_max_abs_worst',
    'faults_total',
    'unmatched',
)
#: Columns where a smaller value than the baseline's is a regression.
HIGHER_IS_BETTER: tuple[str, ...] = ('targets_met', 'detected')


def _limits() -> dict[str, float]:
    from vd_observer_node.tools.report.results import TARGETS

    return {column: TARGETS[name][2] for name, column in TARGET_COLUMNS.items()}


def target_ratio(row: dict[str, Any]) -> float | None:
    """The worst accuracy figure over its target limit (> 1: a target failed); None: none, or
    a bag the simulator's ideal-sensor targets do not judge (a car's reference)."""
    if row.get('targets_met') is None:
        return None
    ratios = [
        row[column] / limit
        for column, limit in _limits().items()
        if row.get(column) is not None and limit > 0
    ]
    return float(f'{max(ratios):.6g}') if ratios else None


def _badness(row: dict[str, Any]) -> tuple[int, int, int, float, str]:
    ratio = row.get('worst_target_ratio')
    return (
        0 if row['status'] != 'ok' else 1,
        -(row.get('targets_failed') or 0),
        -((row.get('missed') or 0) + (row.get('false_alarms') or 0)),
        -(ratio if ratio is not None else -math.inf),
        str(row['bag']),
    )


def sort_worst_first(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Rows with ``worst_target_ratio`` added, worst bag first (ties: by bag path)."""
    full = [{**row, 'worst_target_ratio': target_ratio(row)} for row in rows]
    return sorted(full, key=_badness)


def _cell(value: Any) -> str:
    if value is None:
        return ''
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, float):
        return f'{value:.9g}'
    return str(value)


def fleet_csv(rows: Sequence[dict[str, Any]]) -> str:
    """CSV text of sorted rows (:data:`REPORT_COLUMNS`; empty cell = no figure)."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator='\n')
    writer.writerow(REPORT_COLUMNS)
    for row in rows:
        writer.writerow([_cell(row.get(name)) for name in REPORT_COLUMNS])
    return buffer.getvalue()


def _parse(name: str, text: str) -> Any:
    if name in TEXT_COLUMNS or name not in REPORT_COLUMNS:
        return text
    if text == '':
        return None
    if name in _INT_COLUMNS:
        return int(text)
    if name in _FLOAT_COLUMNS:
        return float(text)
    return text == 'true'  # has_truth, the one flag


def read_fleet_csv(path: str | os.PathLike[str]) -> list[dict[str, Any]]:
    """Rows of a fleet.csv (or of the fleet.csv in a report folder).

    Raises:
        FleetInputError: unreadable, or not a fleet report.
    """
    source = Path(path)
    if source.is_dir():
        source = source / 'fleet.csv'
    try:
        text = source.read_text(encoding='utf-8')
    except (OSError, UnicodeDecodeError) as exc:
        raise FleetInputError(f'{source}: cannot read the baseline report: {exc}') from exc
    reader = csv.DictReader(io.StringIO(text))
    if reader.fieldnames is None or not {'bag', 'status'} <= set(reader.fieldnames):
        raise FleetInputError(f'{source}: not a fleet report (no bag and status columns)')
    try:
        return [
            {k: _parse(k, v or '') for k, v in line.items() if k is not None} for line in reader
        ]
    except ValueError as exc:
        raise FleetInputError(f'{source}: not a fleet report: {exc}') from exc


@dataclass(frozen=True)
class Regression:
    """A figure of one bag that got worse than in the baseline.

    Attributes:
        bag: the bag path.
        column: the report column (or 'status', or 'bag' for a bag no longer in the run).
        old: the baseline's value.
        new: this run's value.
    """

    bag: str
    column: str
    old: Any
    new: Any


def compare_baseline(
    rows: Sequence[dict[str, Any]],
    baseline: Sequence[dict[str, Any]],
    *,
    rel_tol: float = 0.1,
    abs_tol: float = 1e-9,
) -> list[Regression]:
    """What got worse from ``baseline`` to ``rows``.

    Bags are matched by path; when no path matches at all (the fleet was copied or mounted
    elsewhere), by their path below the folder each report's bags share.

    A regression is: a bag that was ok and now fails or is missing from the run; a
    :data:`LOWER_IS_BETTER` figure above ``old * (1 + rel_tol) + abs_tol`` (or present
    before and missing now); a :data:`HIGHER_IS_BETTER` count below the old one.
    Counts (alerts missed, false alarms, faults) regress on any increase.

    Returns:
        Regressions in the order of ``rows`` (then the missing bags).
    """
    old_by_bag = {str(r['bag']): r for r in baseline}
    key = {str(r['bag']): str(r['bag']) for r in rows}
    if not set(key) & set(old_by_bag):
        old_names, new_names = _names(baseline), _names(rows)
        old_by_bag = {old_names[bag]: r for bag, r in old_by_bag.items()}
        key = {bag: new_names[bag] for bag in key}
    new_bags = set(key.values())
    out: list[Regression] = []
    for row in rows:
        old = old_by_bag.get(key[str(row['bag'])])
        if old is None:
            continue
        if old.get('status') == 'ok' and row['status'] != 'ok':
            out.append(Regression(row['bag'], 'status', 'ok', row['error']))
            continue
        for column in LOWER_IS_BETTER:
            before, now = old.get(column), row.get(column)
            if before is None:
                continue
            if now is None:
                if row['status'] == 'ok':
                    out.append(Regression(row['bag'], column, before, None))
                continue
            slack = 0.0 if column in _INT_COLUMNS else rel_tol * abs(before) + abs_tol
            if now > before + slack:
                out.append(Regression(row['bag'], column, before, now))
        for column in HIGHER_IS_BETTER:
            before, now = old.get(column), row.get(column)
            if before is not None and now is not None and now < before:
                out.append(Regression(row['bag'], column, before, now))
    for bag, old in old_by_bag.items():
        if bag not in new_bags and old.get('status') == 'ok':
            out.append(Regression(bag, 'bag', 'present', 'absent from this run'))
    return out


def _fmt(value: Any, digits: int = 3) -> str:
    if value is None:
        return '–'
    if isinstance(value, float):
        return f'{value:.{digits}g}'
    return str(value)


def _names(rows: Sequence[dict[str, Any]]) -> dict[str, str]:
    """Bag paths shortened to their part below the folder all bags share."""
    paths = [str(r['bag']) for r in rows]
    if len(paths) < 2:
        return {p: Path(p).name for p in paths}
    try:
        common = os.path.commonpath(paths)
    except ValueError:
        return {p: p for p in paths}
    return {p: os.path.relpath(p, common) if p != common else Path(p).name for p in paths}


def _summary_lines(rows: Sequence[dict[str, Any]]) -> list[str]:
    ok = [r for r in rows if r['status'] == 'ok']
    hours = sum(r['duration_s'] or 0.0 for r in ok) / 3600.0
    km = sum(r['distance_m'] or 0.0 for r in ok) / 1000.0
    truth = [r for r in ok if r.get('has_truth')]
    simulated = [r for r in truth if r.get('targets_met') is not None]
    met = sum(r.get('targets_met') or 0 for r in truth)
    total = met + sum(r.get('targets_failed') or 0 for r in truth)
    alerts = {k: sum(r.get(f'alerts_{k}') or 0 for r in ok) for k in ALERT_KINDS}
    missed = sum(r.get('missed') or 0 for r in truth)
    false = sum(r.get('false_alarms') or 0 for r in truth)
    episodes = sum(r.get('episodes') or 0 for r in truth)
    faults = sum(r.get('faults_total') or 0 for r in ok)
    return [
        f'- **{len(rows)} bags**: {len(ok)} processed, {len(rows) - len(ok)} failed',
        f'- drive time {hours:.2f} h, distance {km:.1f} km (processed bags)',
        f'- {len(truth)} bags with a reference ({len(simulated)} from the simulator, '
        f"{len(truth) - len(simulated)} a car's), {len(ok) - len(truth)} without "
        '(estimates only: no accuracy)',
        f"- the simulator's ideal-sensor targets (simulator bags only): met {met} of {total}; "
        f'alert episodes {episodes}, missed {missed}, false alarms {false}',
        '- alert activations: ' + ', '.join(f'{kind} {count}' for kind, count in alerts.items()),
        f'- faults counted by the estimator cascade: {faults}',
    ]


_TABLE: tuple[tuple[str, str, int], ...] = (
    # column, header, significant digits
    ('status', 'status', 0),
    ('reference', 'reference', 0),
    ('duration_s', 'duration [s]', 4),
    ('distance_m', 'distance [m]', 4),
    ('slope_rms_deg', 'slope RMS [deg]', 3),
    ('mu_rms', 'μ RMS', 3),
    ('fx_rms_pct', 'Fx RMS [%]', 3),
    ('fz_rms_pct', 'Fz RMS [%]', 3),
    ('omega_rel_rms_pct', 'ω RMS [%]', 3),
    ('worst_target_ratio', 'worst / limit', 3),
    ('targets_met', 'targets met', 0),
    ('missed', 'missed', 0),
    ('false_alarms', 'false alarms', 0),
    ('mu_max_rms_worst', 'μ_max RMS (worst segment)', 3),
    ('faults_total', 'faults', 0),
)


def _reference(row: dict[str, Any]) -> str:
    """'simulator', 'car' (a car's reference: figures, no targets) or 'none' (estimates only)."""
    if row['status'] != 'ok':
        return ''
    if not row.get('has_truth'):
        return 'none'
    return 'simulator' if row.get('targets_met') is not None else 'car'


def fleet_markdown(
    rows: Sequence[dict[str, Any]],
    regressions: Sequence[Regression] | None = None,
    baseline_name: str | None = None,
) -> str:
    """Markdown of sorted rows: a summary, one table line per bag, failures, regressions."""
    names = _names(rows)
    lines = ['# Fleet report', '', *_summary_lines(rows), '', '## Bags, worst first', '']
    header = ['#', 'bag', *(h for _, h, _ in _TABLE), 'alerts T/L/LF']
    lines.append('| ' + ' | '.join(header) + ' |')
    lines.append('|' + '|'.join('---' for _ in header) + '|')
    for k, row in enumerate(rows, 1):
        targets = row.get('targets_met')
        cells = [str(k), f'`{names[str(row["bag"])]}`']
        for column, _, digits in _TABLE:
            if column == 'reference':
                cells.append(_reference(row))
            elif column == 'targets_met' and targets is not None:
                cells.append(f'{targets}/{targets + (row.get("targets_failed") or 0)}')
            else:
                cells.append(_fmt(row.get(column), digits or 3))
        counts = [row.get(f'alerts_{kind}') for kind in ALERT_KINDS]
        cells.append(
            '/'.join(_fmt(c) for c in counts) if any(c is not None for c in counts) else '–'
        )
        lines.append('| ' + ' | '.join(cells) + ' |')
    failed = [r for r in rows if r['status'] != 'ok']
    if failed:
        lines += ['', '## Failed bags', '']
        lines += [f'- `{r["bag"]}`: {r["error"]}' for r in failed]
    faulty = [r for r in rows if r.get('faults')]
    if faulty:
        lines += ['', '## Faults counted', '']
        lines += [f'- `{names[str(r["bag"])]}`: {r["faults"]}' for r in faulty]
    if regressions is not None:
        lines += ['', f'## Regressions against {baseline_name or "the baseline"}', '']
        if not regressions:
            lines.append('None.')
        for reg in regressions:
            lines.append(f'- `{reg.bag}`: {reg.column} {_fmt(reg.old, 4)} → {_fmt(reg.new, 4)}')
    return '\n'.join(lines) + '\n'


def _write_parquet(rows: Sequence[dict[str, Any]], path: Path) -> bool:
    if importlib.util.find_spec('pyarrow') is None:
        return False
    import pyarrow as pa  # optional: only when it is installed anyway
    import pyarrow.parquet as pq

    table = pa.Table.from_pylist([{k: r.get(k) for k in REPORT_COLUMNS} for r in rows])
    pq.write_table(table, path)
    return True


def _write_figure(rows: Sequence[dict[str, Any]], path: Path) -> None:
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    import numpy as np

    fig, axes = plt.subplots(2, 2, figsize=(12, 8), constrained_layout=True)
    ok = [r for r in rows if r['status'] == 'ok']
    limits = _limits()
    ax = axes[0, 0]
    judged = [r for r in ok if r.get('targets_met') is not None]  # simulator bags only
    for x, column in enumerate(limits):
        values = [r[column] / limits[column] for r in judged if r.get(column) is not None]
        if values:
            ax.scatter(np.full(len(values), x), values, s=14, alpha=0.7)
    ax.axhline(1.0, color='tab:red', lw=1, ls='--', label='target limit')
    ax.set_xticks(range(len(limits)), [c.replace('_', ' ') for c in limits], rotation=20)
    ax.set_yscale('log')
    ax.set_ylabel('figure / target limit')
    ax.set_title("Accuracy against the simulator's ideal-sensor targets (each dot a bag)")
    ax.legend(loc='best')
    if not any(r.get('worst_target_ratio') is not None for r in ok):
        # rows of cars' references or without one: nothing judged, which must not look empty
        ax.text(0.5, 0.5, 'no simulator bag (no valid samples)', transform=ax.transAxes,
                ha='center', va='center', color='0.35')  # fmt: skip
    ax = axes[0, 1]
    worst = rows[:30]
    ratios = [r.get('worst_target_ratio') or 0.0 for r in worst]
    reach = max([*ratios, 1.0])
    for k, row in enumerate(worst):
        if row['status'] != 'ok':  # no figure: a full-width red bar says "failed"
            ax.barh(k, reach, color='tab:red', alpha=0.35)
            ax.text(reach * 0.02, k, 'failed', va='center', fontsize=7, color='tab:red')
        elif row.get('worst_target_ratio') is None:
            why = 'no reference' if not row.get('has_truth') else "a car's reference"
            ax.text(reach * 0.02, k, f'{why}: no targets', va='center', fontsize=7, color='0.35')
        else:
            ax.barh(k, ratios[k], color='tab:blue')
    ax.set_yticks(range(len(worst)), [Path(str(r['bag'])).name[:28] for r in worst], fontsize=7)
    ax.invert_yaxis()
    ax.axvline(1.0, color='tab:red', lw=1, ls='--')
    ax.set_xlabel('worst accuracy figure / its target limit (> 1: a target failed)')
    ax.set_title(f'Worst bags first ({len(worst)} of {len(rows)})')
    ax = axes[1, 0]
    minutes = [r['duration_s'] / 60.0 for r in ok if r.get('duration_s') is not None]
    ax.hist(minutes, bins=min(30, max(len(minutes), 1)), color='tab:gray')
    ax.set_xlabel('bag duration [min]')
    ax.set_ylabel('bags')
    ax.set_title('Durations (processed bags)')
    ax = axes[1, 1]
    ranked = [(k + 1, r) for k, r in enumerate(rows) if r['status'] == 'ok'][:30]
    bottom = np.zeros(len(ranked))
    for kind in ALERT_KINDS:
        per_hour = np.array(
            [
                (r.get(f'alerts_{kind}') or 0) * 3600.0 / r['duration_s']
                if r.get('duration_s')
                else 0.0
                for _, r in ranked
            ]
        )
        ax.bar(range(len(ranked)), per_hour, bottom=bottom, label=kind)
        bottom += per_hour
    if not bottom.any():
        ax.text(0.5, 0.5, 'no alert activation', transform=ax.transAxes, ha='center')
    ax.set_xticks(range(len(ranked)), [str(rank) for rank, _ in ranked], fontsize=7)
    ax.set_xlabel('bag (its rank in the table)')
    ax.set_ylabel('alert activations per hour')
    ax.set_title('Alerts')
    ax.legend(loc='upper right')
    fig.savefig(path, dpi=100)
    plt.close(fig)


@dataclass(frozen=True)
class FleetReport:
    """Files written and what the report found.

    Attributes:
        rows: sorted rows, worst first.
        files: paths written.
        regressions: against the baseline (None without one).
    """

    rows: list[dict[str, Any]]
    files: list[Path]
    regressions: list[Regression] | None


def write_fleet_report(
    records: Sequence[dict[str, Any]],
    out_dir: str | os.PathLike[str],
    *,
    baseline: str | os.PathLike[str] | None = None,
    figures: bool = True,
) -> FleetReport:
    """Write fleet.csv, fleet.md, fleet.png (and fleet.parquet with pyarrow) to ``out_dir``.

    Args:
        records: per-bag records (:func:`~.process.process_bag`).
        out_dir: existing folder.
        baseline: an earlier fleet.csv or its folder; its regressions are listed in fleet.md
            and regressions.csv.
        figures: write fleet.png.

    Raises:
        FleetInputError: the baseline cannot be read.
    """
    from vd_observer_node.tools.fleet.run import write_atomic

    out = Path(out_dir)
    old = read_fleet_csv(baseline) if baseline is not None else None
    rows = sort_worst_first([r['row'] for r in records])
    regressions = compare_baseline(rows, old) if old is not None else None
    files = [out / 'fleet.csv', out / 'fleet.md']
    write_atomic(files[0], fleet_csv(rows))
    write_atomic(files[1], fleet_markdown(rows, regressions, str(baseline) if baseline else None))
    if regressions is not None:
        buffer = io.StringIO()
        writer = csv.writer(buffer, lineterminator='\n')
        writer.writerow(['bag', 'column', 'old', 'new'])
        for reg in regressions:
            writer.writerow([reg.bag, reg.column, _cell(reg.old), _cell(reg.new)])
        files.append(out / 'regressions.csv')
        write_atomic(files[-1], buffer.getvalue())
    if _write_parquet(rows, out / '.fleet.parquet.tmp'):
        os.replace(out / '.fleet.parquet.tmp', out / 'fleet.parquet')
        files.append(out / 'fleet.parquet')
    if figures and rows:
        tmp = out / '.fleet.png.tmp.png'
        _write_figure(rows, tmp)
        os.replace(tmp, out / 'fleet.png')
        files.append(out / 'fleet.png')
    return FleetReport(rows, files, regressions)
