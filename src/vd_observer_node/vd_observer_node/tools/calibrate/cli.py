"""``vd calibrate BAGS... --out FILE.yaml [--mapping] [--vehicle] [--report DIR] [--level-road]``.

Reads each drive (:mod:`.drive`), fits what they determine (:mod:`.calibration`), writes the
estimation-only vehicle file (:mod:`.vehicle_file`) and, with ``--report``, the figures and
tables (:mod:`.report`). Errors print one line and exit with status 2; nothing is written
then.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

from vd_common.topics import TRUTH_NAMESPACE

__all__ = ['add_calibrate_parser', 'run_calibrate']


def add_calibrate_parser(commands: Any) -> None:
    """Add the ``calibrate`` sub-command to the ``vd`` parser's sub-parsers."""
    parser = commands.add_parser(
        'calibrate', help='fit an estimation-only vehicle file from recorded drives'
    )
    parser.add_argument('bags', type=Path, nargs='+', help='bag folders or .mcap files')
    parser.add_argument('--out', type=Path, required=True, help='vehicle YAML to write')
    parser.add_argument(
        '--mapping',
        type=Path,
        help='input mapping YAML (its reference section: the speed '
        f'and grade reference where the bag has no {TRUTH_NAMESPACE}* topics)',
    )
    parser.add_argument(
        '--vehicle',
        type=Path,
        help="base vehicle YAML: what the drive does not determine (default: vd's Clio file)",
    )
    parser.add_argument('--report', type=Path, help='folder for the figures and tables')
    parser.add_argument(
        '--level-road',
        action='store_true',
        help='the drives are on level road (coast-downs on a test track): grade 0 where the '
        'bag has no grade reference',
    )
    parser.set_defaults(run=run_calibrate)


def run_calibrate(args: argparse.Namespace) -> int:
    """Run ``vd calibrate``; returns the exit status."""
    import yaml
    from vd_common.vehicle.estimation import parse_estimation_vehicle
    from vd_common.vehicle.params import default_vehicle_file

    from vd_observer_node.inputs.mapping import load_input_mapping
    from vd_observer_node.tools.calibrate.calibration import calibrate
    from vd_observer_node.tools.calibrate.drive import concatenated, read_drive
    from vd_observer_node.tools.calibrate.errors import CalibrationError
    from vd_observer_node.tools.calibrate.report import mounting_line
    from vd_observer_node.tools.calibrate.vehicle_file import (
        vehicle_file_text,
        write_vehicle_file,
    )

    started = time.perf_counter()
    base_path = args.vehicle or default_vehicle_file()
    try:
        base_data = yaml.safe_load(Path(base_path).read_text(encoding='utf-8'))
    except (OSError, yaml.YAMLError) as error:
        raise CalibrationError(
            f'cannot read the base vehicle file {base_path}: {error}'
        ) from error
    base = parse_estimation_vehicle(base_data, source=str(base_path))
    base_name = (
        f'the base file {Path(base_path).name}'
        if args.vehicle
        else f"vd's default car file {Path(base_path).name} (no --vehicle given)"
    )
    mapping = load_input_mapping(args.mapping) if args.mapping else None
    radius = base.wheel.effective_radius
    drives = [read_drive(bag, mapping, radius, level_road=args.level_road) for bag in args.bags]
    calibration = calibrate(concatenated(drives), base)
    if not calibration.fits and calibration.mounting is None:
        reasons = '; '.join(f'{k}: {v}' for k, v in calibration.not_determined.items())
        raise CalibrationError(f'the drive determines nothing ({reasons})')
    sources = ', '.join(Path(b).name for b in args.bags)
    text = vehicle_file_text(calibration, base_data, base_name, sources)
    if args.report is not None:
        from vd_observer_node.tools.calibrate.report import write_report

        write_report(args.report, calibration, sources)
    write_vehicle_file(args.out, text)
    wall = time.perf_counter() - started
    print(
        f'calibrated on {calibration.drive_seconds:.0f} s of drive ({len(drives)} bag'
        f'{"s" if len(drives) > 1 else ""}) in {wall:.1f} s; wrote {args.out}'
    )
    for fit in calibration.fits.values():
        spread = f' ± {fit.std:.3g}' if isinstance(fit.std, float) else ''
        value = f'{fit.value:.6g}' if isinstance(fit.value, float) else str(fit.value)
        print(f'  fitted {fit.key}: {value}{spread} ({fit.samples} samples)')
    if calibration.mounting is not None:
        print(f'  fitted {mounting_line(calibration.mounting)} (for the input mapping)')
    for key, reason in calibration.not_determined.items():
        print(f'  not determined {key}: {reason}')
    for note in calibration.notes:
        print(f'  note: {note}')
    if args.report is not None:
        print(f'report: {args.report}')
    return 0
