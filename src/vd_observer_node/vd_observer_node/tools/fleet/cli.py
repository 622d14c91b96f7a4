"""``vd fleet``: replay and evaluate many bags in parallel, one fleet report (ROS-free).

    vd fleet BAG_OR_FOLDER_OR_PATTERN... [--list FILE] --out DIR [--workers N]
             [--engine local|dask] [--scheduler ADDRESS] [--baseline OLD_REPORT]
             [--no-replay] [--keep-bags] [--retry-failed] [--vehicle FILE] [--config FILE]
             [--mapping FILE] [--no-figures] [--no-progress]
             [--fail-on-regression]

Exit status: 0 every bag processed; 1 some bags failed (listed in the report and on
stderr), a worker died, or (with --fail-on-regression) regressions against the baseline;
2 nothing to do or a bad setting (one line on stderr); 130 interrupted.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

__all__ = ['EXIT_BAGS_FAILED', 'add_fleet_parser', 'run_fleet_command']

EXIT_OK = 0
EXIT_BAGS_FAILED = 1
EXIT_ERROR = 2


def add_fleet_parser(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add the ``fleet`` sub-command to the ``vd`` command's sub-parsers."""
    parser = subparsers.add_parser(
        'fleet',
        help='replay and evaluate many bags in parallel (local processes or Dask), one report',
        description='Run `vd replay` and the `vd report` metrics over many bags in parallel '
        'and write one fleet report (fleet.csv, fleet.md, fleet.png) into --out. Results are '
        'stored per bag in OUT/bags/: running again with the same --out resumes, skipping '
        'the bags already done.',
    )
    parser.add_argument(
        'bags',
        nargs='*',
        help='bag folders, .mcap files, folders of bags, or glob patterns (quoted, ** recursive)',
    )
    parser.add_argument(
        '--list',
        dest='lists',
        action='append',
        type=Path,
        default=[],
        help='text file with one bag, folder or pattern per line (repeatable)',
    )
    parser.add_argument('--out', type=Path, required=True, help='output folder (resumable)')
    parser.add_argument(
        '--workers', type=int, default=None, help='worker processes (default: the cores)'
    )
    parser.add_argument(
        '--engine',
        choices=('local', 'dask'),
        default=None,
        help='local process pool (default) or Dask distributed (default with --scheduler)',
    )
    parser.add_argument(
        '--scheduler',
        default=None,
        help='address of a running Dask scheduler, e.g. tcp://head:8786 (workers must see '
        'the bags and have vd installed); without it, --engine dask starts a local cluster',
    )
    parser.add_argument(
        '--baseline', type=Path, default=None, help='earlier fleet report (folder or fleet.csv)'
    )
    parser.add_argument(
        '--fail-on-regression',
        action='store_true',
        help='exit with 1 when the baseline comparison finds regressions',
    )
    parser.add_argument(
        '--no-replay',
        action='store_true',
        help='judge the estimates recorded in the bags (as `vd report`), no replay',
    )
    parser.add_argument(
        '--keep-bags', action='store_true', help='keep the replayed bags in OUT/replayed/'
    )
    parser.add_argument(
        '--retry-failed', action='store_true', help='process again bags that failed before'
    )
    parser.add_argument('--vehicle', type=Path, help='vehicle YAML (default: the Clio file)')
    parser.add_argument('--config', type=Path, help='replay settings YAML (see vd replay)')
    parser.add_argument('--mapping', type=Path, help='input mapping YAML (see vd replay)')
    parser.add_argument('--no-figures', action='store_true', help='no fleet.png')
    parser.add_argument('--no-progress', action='store_true', help='no progress bar')
    parser.set_defaults(run=run_fleet_command)


def run_fleet_command(args: argparse.Namespace) -> int:
    """Run ``vd fleet`` with parsed arguments; returns the exit status."""
    from vd_observer_node.tools.fleet.bags import find_bags
    from vd_observer_node.tools.fleet.errors import FleetInputError
    from vd_observer_node.tools.fleet.process import FleetSettings
    from vd_observer_node.tools.fleet.report import read_fleet_csv, write_fleet_report
    from vd_observer_node.tools.fleet.run import FleetEngine, run_fleet

    if args.baseline is not None:
        read_fleet_csv(args.baseline)  # a bad baseline stops the run before hours of work
    out: Path = args.out
    # the output folder may sit among the bags: its kept replays are no input
    inside = Path(os.path.normpath(out.absolute()))
    bags = [b for b in find_bags(args.bags, args.lists) if not b.is_relative_to(inside)]
    if not bags:
        raise FleetInputError('no bags found in ' + ', '.join(map(str, [*args.bags, *args.lists])))
    for name in ('vehicle', 'config', 'mapping'):
        path = getattr(args, name)
        if path is not None and not path.is_file():
            raise FleetInputError(f'--{name} {path}: no such file')
    engine = args.engine or ('dask' if args.scheduler else 'local')
    if args.scheduler and engine != 'dask':
        raise FleetInputError('--scheduler needs --engine dask')
    settings = FleetSettings(
        replay=not args.no_replay,
        vehicle_file=str(args.vehicle.absolute()) if args.vehicle else None,
        config_file=str(args.config.absolute()) if args.config else None,
        mapping_file=str(args.mapping.absolute()) if args.mapping else None,
        keep_dir=str((out / 'replayed').absolute()) if args.keep_bags else None,
    )
    run = run_fleet(
        [str(b) for b in bags],
        out,
        settings,
        engine=FleetEngine(engine, args.workers, args.scheduler),
        retry_failed=args.retry_failed,
        progress=not args.no_progress,
    )
    report = write_fleet_report(
        run.records, out, baseline=args.baseline, figures=not args.no_figures
    )
    wall = max(run.wall_time_s, 1e-9)
    print(
        f'fleet: {len(bags)} bags, {run.processed} processed now, {run.skipped} done before, '
        f'{run.failed} failed; {run.samples_processed} samples in {wall:.1f} s '
        f'({run.samples_processed / wall:.0f} samples/s, '
        f'{run.hours_processed * 3600.0 / wall:.1f} bag-hours per hour) with {run.workers} '
        f'{run.engine} workers'
    )
    for row in report.rows:
        if row['status'] != 'ok':
            print(f'vd: failed: {row["bag"]}: {row["error"]}', file=sys.stderr)
    for bag in run.lost:
        print(f'vd: lost (a worker died; run again to retry): {bag}', file=sys.stderr)
    if report.regressions:
        print(f'{len(report.regressions)} regressions against {args.baseline} (fleet.md)')
    print('wrote ' + ', '.join(str(p) for p in report.files))
    if run.failed or run.lost:
        return EXIT_BAGS_FAILED
    if args.fail_on_regression and report.regressions:
        return EXIT_BAGS_FAILED
    return EXIT_OK
