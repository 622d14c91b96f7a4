"""``vd report BAG [--out DIR] [--mapping FILE]``: argparse wiring of the ``vd`` command.

The ``vd`` command adds the sub-command with :func:`add_report_parser`; the parsed
arguments carry ``run=run_report``. Errors print one line on stderr and give exit status 2.

With ``--mapping`` (a user's bag with its own topics and standard types, docs/input_mapping.md) the
report summarises each mapped input (messages, longest gap, gaps longer than ``max_gap``);
a bag without estimates is first replayed with the mapping (``vd replay``, into a temporary
folder) so that there is something to compare with the truth.

A bag without reference (no ``/vd/truth/*`` topic) gives an estimates-only report (each
estimate's values and validity, no accuracy); the command says so before it reads or replays
the bag. The output folder is checked first too (:func:`prepare_out_dir`): the files a
previous ``vd report`` wrote there (listed in its manifest, :data:`MANIFEST`) are removed
before the new ones are written, and a non-empty folder that is not a report is refused.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path
from typing import TYPE_CHECKING

from vd_common.topics import (
    ESTIMATES_NAMESPACE,
    OBSERVER_NAMESPACE,
    TRUTH_FRICTION_POTENTIAL,
    TRUTH_NAMESPACE,
)

from vd_observer_node.errors import ObserverError
from vd_observer_node.tools.report.errors import ReportOutputError

if TYPE_CHECKING:
    from vd_observer_node.tools.report.load import BagSeries

__all__ = [
    'MANIFEST',
    'REPORT_FILES',
    'add_report_parser',
    'clear_previous_report',
    'default_out_dir',
    'prepare_out_dir',
    'run_report',
]

EXIT_OK = 0
EXIT_ERROR = 2

#: The list of the files ``vd report`` wrote into its folder (JSON: {"files": [names]}).
MANIFEST = '.vd_report_files.json'
#: The names ``vd report`` writes: a folder's old report without a manifest (written before
#: the manifest existed) is recognised by its metrics.json and cleared of these names only.
REPORT_FILES = (
    'metrics.json',
    'metrics.md',
    'summary.png',
    'wheel_speed.png',
    'wheel_accel.png',
    'body_accel.png',
    'body_speed.png',
    'tire_fx.png',
    'tire_fz.png',
    'friction_mu.png',
    'slip.png',
    'rolling_resistance.png',
    'aero_drag.png',
    'slope.png',
    'alerts.png',
    'friction_potential.png',
)


def _previous_files(out: Path) -> list[str] | None:
    """Names of the files a previous report wrote into ``out`` (None: no report there)."""
    manifest = out / MANIFEST
    if manifest.is_file():
        try:
            names = json.loads(manifest.read_text(encoding='utf-8'))['files']
        except (ValueError, KeyError, TypeError, OSError):
            names = None
        if isinstance(names, list) and all(isinstance(n, str) for n in names):
            # names only: a manifest never reaches outside its folder
            return [n for n in names if n and Path(n).name == n] + [MANIFEST]
    metrics = out / 'metrics.json'
    try:
        data = json.loads(metrics.read_text(encoding='utf-8'))
    except (OSError, ValueError):
        return None
    if isinstance(data, dict) and {'bag', 'settings', 'quantities'} <= data.keys():
        return list(REPORT_FILES)  # a report from before the manifest
    return None


def prepare_out_dir(out: Path) -> list[str]:
    """Check that ``vd report`` may write into ``out``; returns the old report's files there.

    Args:
        out: the output folder (need not exist).

    Returns:
        Names of files a previous ``vd report`` wrote there (to remove before writing).

    Raises:
        ReportOutputError: ``out`` is a file, or a non-empty folder without a previous report
            (vd report never removes files it did not write).
    """
    if out.exists() and not out.is_dir():
        raise ReportOutputError(f'--out {out} is a file, not a folder')
    if not out.is_dir() or not any(out.iterdir()):
        return []
    previous = _previous_files(out)
    if previous is None:
        raise ReportOutputError(
            f'--out {out} is not empty and holds no vd report: give a new or empty folder '
            '(vd report removes only the files of its own previous report)'
        )
    return previous


def clear_previous_report(out: Path, names: list[str]) -> int:
    """Remove the previous report's files ``names`` from ``out``; returns how many."""
    removed = 0
    for name in names:
        path = out / name
        if path.is_file() and not path.is_symlink():
            path.unlink()
            removed += 1
    return removed


def default_out_dir(bag: Path) -> Path:
    """``<bag>_report`` next to the bag (for a .mcap file: next to the file, without suffix)."""
    bag = Path(bag)
    base = bag.with_suffix('') if bag.suffix == '.mcap' else bag
    return base.parent / f'{base.name.rstrip("/")}_report'


def add_report_parser(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add the ``report`` sub-command to the ``vd`` command's sub-parsers."""
    parser = subparsers.add_parser(
        'report',
        help='accuracy of the estimates against the truth in a bag (metrics + figures)',
        description=f'Compare {OBSERVER_NAMESPACE}* and {ESTIMATES_NAMESPACE}* with '
        f'{TRUTH_NAMESPACE}* (paired by header stamp); judge the alerts and the friction '
        f'potential against {TRUTH_FRICTION_POTENTIAL}; write metrics.json, metrics.md and '
        'PNG figures.',
    )
    parser.add_argument('bag', type=Path, help='bag folder or .mcap file with truth topics')
    parser.add_argument(
        '--out',
        type=Path,
        default=None,
        help='output directory (default: <bag>_report next to the bag); the files of a '
        'previous report there are replaced, a non-empty folder that is not a report is '
        'refused',
    )
    parser.add_argument(
        '--vehicle',
        type=Path,
        default=None,
        help='vehicle YAML: static wheel loads for the Fz percentage (default: '
        'median true Fz over the first second), and the vehicle of the replay of a bag '
        'without estimates (default: the Clio file)',
    )
    parser.add_argument(
        '--mapping',
        type=Path,
        default=None,
        help='input mapping YAML of a bag with your own topics and types (docs/input_mapping.md): '
        'its inputs are summarised, and a bag without estimates is replayed with it first',
    )
    parser.add_argument(
        '--config',
        type=Path,
        default=None,
        help='replay settings YAML (as vd replay --config) for the replay of a bag without '
        'estimates',
    )
    parser.add_argument('--no-figures', action='store_true', help='metrics only')
    parser.add_argument('--no-progress', action='store_true', help='no progress bar')
    parser.set_defaults(run=run_report)


def run_report(args: argparse.Namespace) -> int:
    """Run ``vd report`` with parsed arguments; returns the exit status (0 ok, 2 error)."""
    try:
        return _run(args)
    except ObserverError as exc:  # bag, vehicle and report input errors: one line
        print(f'vd: error: {exc}', file=sys.stderr)
        return EXIT_ERROR
    except OSError as exc:
        print(f'vd: error: {exc}', file=sys.stderr)
        return EXIT_ERROR


def _load_mapped(
    bag: Path,
    mapping_file: Path,
    scratch: Path,
    progress: bool,
    vehicle_file: Path | None,
    config_file: Path | None,
) -> BagSeries:
    """The report's series of a user's bag: replayed with the mapping first if it has no
    estimates (the replay copies the mapped inputs and the truth to its output), with the
    vehicle file and replay settings given (else the defaults)."""
    from vd_common.settings_log import settings_line

    from vd_observer_node.bag.reader import BagReader
    from vd_observer_node.inputs.mapping import load_input_mapping
    from vd_observer_node.tools.replay import ESTIMATE_TOPICS, replay_bag
    from vd_observer_node.tools.report.load import load_bag_series
    from vd_observer_node.tools.settings_file import SettingsFile, load_settings_file

    mapping = load_input_mapping(mapping_file)
    config = load_settings_file(config_file) if config_file else SettingsFile()
    settings = config.settings(mapping, vehicle_file)
    source = bag
    if not any(topic in ESTIMATE_TOPICS for topic in BagReader(bag).topics):
        source = scratch / 'replayed'
        replayed = replay_bag(bag, source, settings, mapping=mapping, progress=progress)
        # the IMU fusion's are named as the mapping names them (imu.fusion.*)
        derived = {
            k if k.startswith('imu.') else f'estimator.{k}': v
            for k, v in replayed.rate_settings.items()
        }
        origin = Path(config.source).name if config.source else ''
        print(f'{bag} has no estimates: replayed it with {mapping_file} first')
        print(f'  vehicle: {replayed.vehicle}')
        line = settings_line(config.given, origin, derived, replayed.input_rate_hz)
        print(f'  settings: {line}')
        for note in replayed.notes:
            print(f'  note: {note}')
    return load_bag_series(
        source,
        progress=progress,
        mapping=mapping,
        max_gap_s=settings.observer.max_gap,
        radius=settings.vehicle.effective_radius,
    )


def _reference_first(bag: Path) -> bool:
    """Whether the bag holds a reference; says at once when it does not (before a replay)."""
    from vd_observer_node.bag.reader import BagReader
    from vd_observer_node.tools.report.evaluation import has_reference
    from vd_observer_node.tools.report.results import NO_REFERENCE_HINT

    if has_reference(BagReader(bag).topics):
        return True
    print(
        f'{bag} has no reference (no {TRUTH_NAMESPACE}* topic): an estimates-only report '
        f'(every estimate and its validity, no accuracy); {NO_REFERENCE_HINT}'
    )
    return False


def _run(args: argparse.Namespace) -> int:
    from vd_observer_node.tools.report.evaluation import evaluate, evaluate_estimates
    from vd_observer_node.tools.report.format import report_json, report_markdown, report_text
    from vd_observer_node.tools.report.load import load_bag_series

    started = time.perf_counter()
    out = args.out if args.out is not None else default_out_dir(args.bag)
    previous = prepare_out_dir(out)
    reference = _reference_first(args.bag)
    static = None
    if getattr(args, 'vehicle', None):
        from vd_observer_node.estimation.vehicle import load_estimator_vehicle

        static = load_estimator_vehicle(args.vehicle).static_wheel_loads
    progress = not getattr(args, 'no_progress', False)
    mapping_file = getattr(args, 'mapping', None)
    if mapping_file is None:
        series = load_bag_series(args.bag, progress=progress)
    else:
        if not getattr(args, 'vehicle', None):
            from vd_observer_node.estimation.vehicle import mapped_without_vehicle_warning

            print(mapped_without_vehicle_warning(), file=sys.stderr)
        with tempfile.TemporaryDirectory(prefix='vd-report-') as scratch:
            series = _load_mapped(
                args.bag,
                Path(mapping_file),
                Path(scratch),
                progress,
                getattr(args, 'vehicle', None),
                getattr(args, 'config', None),
            )
        series.path = args.bag
    if reference:
        report, comparisons = evaluate(series, static_loads=static)
    else:
        report, comparisons = evaluate_estimates(series)
    out.mkdir(parents=True, exist_ok=True)
    removed = clear_previous_report(out, previous)
    (out / 'metrics.json').write_text(report_json(report))
    (out / 'metrics.md').write_text(report_markdown(report))
    figures: list[Path] = []
    if not getattr(args, 'no_figures', False):
        from vd_observer_node.tools.report.figures import write_figures

        figures = write_figures(comparisons, report, out)
        if report.alerts is not None:
            from vd_observer_node.tools.report.alert_data import alert_data
            from vd_observer_node.tools.report.figures import write_alert_figures

            data, _ = alert_data(series)
            if data is not None:
                figures += write_alert_figures(data, report.alerts, out)
    names = ['metrics.json', 'metrics.md', *(f.name for f in figures)]
    (out / MANIFEST).write_text(json.dumps({'files': names}, indent=1) + '\n')
    sys.stdout.write(report_text(report))
    if removed:
        print(f'replaced the previous report in {out} ({removed} files)')
    print(
        f'wrote metrics.json, metrics.md and {len(figures)} figures to {out} '
        f'(read {series.message_count} messages in {series.read_time_s:.1f} s, '
        f'total {time.perf_counter() - started:.1f} s)'
    )
    return EXIT_OK
