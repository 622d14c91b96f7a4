"""The ``vd`` command: bag inspection, repair and offline replay (ROS-free).

    vd bag info BAG [--recover]
    vd bag repair BAG [--no-backup]
    vd replay IN_BAG OUT_BAG [--vehicle FILE] [--config FILE] [--mapping FILE]
              [--torque-source {measured,engine,none}] [--no-progress]
    vd report BAG [--out DIR] ...
    vd fleet BAGS... --out DIR [--workers N] [--engine local|dask] [--baseline OLD] ...
    vd calibrate BAGS... --out FILE.yaml [--mapping FILE] [--vehicle BASE] [--report DIR]

Errors (missing paths, corrupt bags, bad vehicle files) print one line on stderr and exit
with status 2; no traceback.
"""

from __future__ import annotations

import argparse
import gc
import sys
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

from vd_common.errors import VdError
from vd_common.topics import SENSORS_NAMESPACE

from vd_observer_node.tools.calibrate.cli import add_calibrate_parser
from vd_observer_node.tools.fleet.cli import add_fleet_parser
from vd_observer_node.tools.report.cli import add_report_parser

__all__ = ['main']

EXIT_OK = 0
EXIT_ERROR = 2


def _format_ns(ns: int) -> str:
    return f'{ns * 1e-9:.3f} s'


def _info(args: argparse.Namespace) -> int:
    from vd_observer_node.bag.reader import BagReader

    reader = BagReader(args.bag, recover=args.recover)
    counts: dict[str, int] = {}
    first: int | None = None
    last = 0
    for msg in reader.raw_messages():
        counts[msg.topic] = counts.get(msg.topic, 0) + 1
        first = msg.log_time_ns if first is None else min(first, msg.log_time_ns)
        last = max(last, msg.log_time_ns)
    topics = reader.topics
    print(f'Bag:       {reader.path}')
    print(f'Files:     {", ".join(str(f.name) for f in reader.files)}')
    print('Storage:   mcap (rosbag2 metadata version 9)')
    print(f'Messages:  {sum(counts.values())}')
    if first is not None:
        print(f'Start:     {_format_ns(first)}')
        print(f'Duration:  {_format_ns(last - first)}')
    print('Topics:')
    width = max((len(name) for name in topics), default=0)
    for name, info in sorted(topics.items()):
        print(f'  {name:<{width}}  {counts.get(name, 0):>9}  {info.msgtype}')
    for problem in reader.problems:
        print(f'Damage:    {problem}')
    if reader.problems:
        print(f'Run `vd bag repair {args.bag}` to rebuild a readable bag.')
    return EXIT_OK


def _repair(args: argparse.Namespace) -> int:
    from vd_observer_node.bag.repair import repair_bag

    report = repair_bag(args.bag, keep_backup=not args.no_backup)
    for problem in report.problems:
        print(f'damage: {problem}')
    print(f'recovered {report.messages_recovered} messages into {report.mcap_file}')
    for topic, count in sorted(report.topic_counts.items()):
        print(f'  {topic}: {count}')
    if report.backup is not None:
        print(f'original kept as {report.backup}')
    return EXIT_OK


def _replay(args: argparse.Namespace) -> int:
    from vd_common.settings_log import settings_line

    from vd_observer_node.inputs.mapping import default_mapping, load_input_mapping
    from vd_observer_node.inputs.mount_learner import unstated_mounting_note
    from vd_observer_node.tools.replay import replay_bag
    from vd_observer_node.tools.settings_file import SettingsFile, load_settings_file

    config = load_settings_file(args.config) if args.config else SettingsFile()
    mapping = load_input_mapping(args.mapping) if args.mapping else default_mapping()
    if args.mapping and args.vehicle is None:
        from vd_observer_node.estimation.vehicle import mapped_without_vehicle_warning

        print(mapped_without_vehicle_warning(), file=sys.stderr)
    if args.torque_source is not None:
        mapping = replace(mapping, torque_source=args.torque_source)
    report = replay_bag(
        args.in_bag,
        args.out_bag,
        # the estimator vehicle, the tyre and the drivetrain, from one read of the file
        config.settings(mapping, args.vehicle),
        mapping=mapping,
        progress=not args.no_progress,
    )
    # the torque is known where the clutch (or the converter's turbine) is engaged and
    # settled, and not while a brake switch is on
    known = f'{100 * report.torque_valid_fraction:.1f} % of samples with the torque known'
    path = {
        'measured': 'measured wheel torques'
        + (f' ({known})' if report.torque_valid_fraction < 1.0 else ''),
        'engine': f'engine torque and gear ({known})',
        'none': 'none (Fx, mu and slope invalid)',
    }[report.torque_source]
    print(
        f'replayed {report.samples} samples ({report.sensor_messages} sensor messages, '
        f'{report.unmatched} unmatched) of {report.bag_duration_s:.1f} s in '
        f'{report.wall_time_s:.2f} s: {report.real_time_factor:.0f}x real time, '
        f'{report.samples_per_second:.0f} sensor messages/s (alerts and friction potential '
        f'{report.situation_us_per_sample:.0f} us per sample); wrote '
        f'{report.messages_written} messages to {args.out_bag}'
    )
    for stats in report.inputs:
        print(f'  input {stats.text()}')
    print(f'torque path: {path}')
    if report.imu:
        print(f'imu: {report.imu}')
        note = unstated_mounting_note(mapping.imu)
        if note:
            print(f'  {note}')
    print(f'vehicle: {report.vehicle}')
    # the IMU fusion's are named as the mapping names them (imu.fusion.*)
    derived = {
        k if k.startswith('imu.') else f'estimator.{k}': v for k, v in report.rate_settings.items()
    }
    origin = Path(config.source).name if config.source else ''
    print(f'settings: {settings_line(config.given, origin, derived, report.input_rate_hz)}')
    for note in report.notes:
        print(f'note: {note}')
    return EXIT_OK


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog='vd', description='vd vehicle-dynamics tools')
    commands = parser.add_subparsers(dest='command', required=True)
    bag = commands.add_parser('bag', help='inspect or repair rosbag2 MCAP bags')
    bag_commands = bag.add_subparsers(dest='bag_command', required=True)
    info = bag_commands.add_parser('info', help='topics, counts and time span of a bag')
    info.add_argument('bag', type=Path, help='bag folder or .mcap file')
    info.add_argument('--recover', action='store_true', help='report damage and read on')
    info.set_defaults(run=_info)
    repair = bag_commands.add_parser('repair', help='rebuild summary and metadata.yaml')
    repair.add_argument('bag', type=Path, help='bag folder or .mcap file')
    repair.add_argument('--no-backup', action='store_true', help='delete the damaged file')
    repair.set_defaults(run=_repair)
    replay = commands.add_parser('replay', help='run the estimator cascade over a bag offline')
    replay.add_argument(
        'in_bag',
        type=Path,
        help=f'input bag with the {SENSORS_NAMESPACE}* topics, or the topics of --mapping',
    )
    replay.add_argument('out_bag', type=Path, help='output bag folder to create')
    replay.add_argument('--vehicle', type=Path, help='vehicle YAML (default: the Clio file)')
    replay.add_argument(
        '--config',
        type=Path,
        help='settings YAML: observer / estimator / cascade / alerts / friction_potential / '
        'situation sections (default: the defaults; docs/replay.md)',
    )
    replay.add_argument(
        '--mapping',
        type=Path,
        help='input mapping YAML: your topics, types, joints and units (docs/input_mapping.md)',
    )
    replay.add_argument(
        '--torque-source',
        choices=('measured', 'engine', 'none'),
        default=None,
        help='wheel torques: measured, from the engine torque and gear (engine), or none; '
        "default: the mapping's torque_source (measured)",
    )
    replay.add_argument('--no-progress', action='store_true', help='no progress bar')
    replay.set_defaults(run=_replay)
    add_report_parser(commands)
    add_fleet_parser(commands)
    add_calibrate_parser(commands)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``vd`` command; returns the exit status (0 ok, 2 error)."""
    args = _parser().parse_args(argv)
    try:
        status: int = args.run(args)
    except VdError as exc:  # every bag, vehicle, mapping and configuration error
        hint = ''
        if type(exc).__name__ == 'BagCorruptError':
            hint = ' (see `vd bag info --recover`, fix with `vd bag repair`)'
        print(f'vd: error: {exc}{hint}', file=sys.stderr)
        return EXIT_ERROR
    except OSError as exc:  # e.g. an unreadable vehicle file
        print(f'vd: error: {exc}', file=sys.stderr)
        return EXIT_ERROR
    except KeyboardInterrupt:
        print('vd: interrupted', file=sys.stderr)
        return 130
    return status


def command() -> int:
    """The ``vd`` console script: `main`, then what it made kept out of the exit's collection.

    At exit the interpreter's last garbage collection walks every object the command made
    (numba's and LLVM's, the typestore's classes): 0.2 s of a short `vd replay`'s 1.3 s. The
    process ends right after and the command has written and closed all it writes, so they
    are frozen (`gc.freeze`: left to the process's end). Not in `main`, which tests call in
    their own long-lived process.
    """
    status = main()
    gc.freeze()
    return status


if __name__ == '__main__':
    sys.exit(command())
