#!/usr/bin/env python3
"""The real drive's figures (issue 26): the RAV4 segment replayed as docs/real_car.md says.

Imports ``../shared/realdata/comma2k19-rav4-seg40`` (scripts/import_comma2k19.py), replays
it with ``input_mapping_comma2k19.yaml`` (engine torque through the torque converter, brake
switch), the RAV4's estimation-only vehicle file and the 100 Hz settings, and prints, against
the pose (an independent reference: comma's fused GNSS/IMU/vision):

* slope RMS against the pose's grade (40 m window) over the valid estimates, and the share of
  the moving samples that are valid (braking included: with a switch only, braking is
  invalid);
* the force balance: sum(Fx) - rolling - aero against m (a + g sin(theta_ref)), a the pose
  speed's derivative (Savitzky-Golay, 1 s), RMS over the samples whose slope is valid and
  rests on the force balance (Slope.sources SOURCE_FORCE; with an IMU fused, the stamps its
  grade covers alone, e.g. braking on a switch, are left out).

Without the segment it says so and exits 0 (``make bench`` runs everywhere).

Usage:
    python scripts/eval_realdata.py [--segment DIR] [--config FILE] [--mapping FILE]
        [--vehicle FILE]
"""

from __future__ import annotations

import argparse
import importlib.util
import math
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / 'src' / 'vd_observer_node' / 'config'
VEHICLE = ROOT / 'src' / 'vd_common' / 'config' / 'toyota_rav4_2017_estimation.yaml'


def _importer() -> Any:
    spec = importlib.util.spec_from_file_location(
        'import_comma2k19', ROOT / 'scripts' / 'import_comma2k19.py'
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def evaluate(
    segment: Path,
    config: Path | None,
    work: Path,
    mapping: Path | None = None,
    vehicle: Path = VEHICLE,
) -> dict[str, float]:
    """Replay the segment and measure it (see the module docstring); the figures by name."""
    from scipy.signal import savgol_filter
    from vd_common.topics import ESTIMATES_RESISTANCES, ESTIMATES_SLOPE, ESTIMATES_TIRE_FORCES
    from vd_observer_node.bag import BagReader
    from vd_observer_node.bag.cdr_batch import decode_batch
    from vd_observer_node.estimation.vehicle import load_vehicle_params
    from vd_observer_node.inputs.mapping import load_input_mapping
    from vd_observer_node.tools.replay import ESTIMATE_TOPICS, replay_bag
    from vd_observer_node.tools.report.metrics import error_stats
    from vd_observer_node.tools.settings_file import SettingsFile, load_settings_file

    importer = _importer()
    bag = work / 'bag'
    importer.import_segment(segment, bag)
    settings = load_settings_file(config) if config is not None else SettingsFile()
    inputs = load_input_mapping(mapping or CONFIG / 'input_mapping_comma2k19.yaml')
    chain = settings.settings(inputs, vehicle)
    report = replay_bag(bag, work / 'out', chain, mapping=inputs, progress=False)
    out = BagReader(work / 'out')
    topics = [ESTIMATES_SLOPE, ESTIMATES_TIRE_FORCES, ESTIMATES_RESISTANCES]
    arrays = out.topic_arrays(topics)
    d = {}
    for topic in topics:
        fields = decode_batch(ESTIMATE_TOPICS[topic], arrays[topic].datas)
        d[topic] = {'t': fields.stamp_ns * 1e-9, **fields.values}
    slope = d[ESTIMATES_SLOPE]
    t = np.asarray(slope['t'])
    pose = segment / 'global_pose'
    pose_t = np.load(pose / 'frame_times')
    pose_v = np.linalg.norm(np.load(pose / 'frame_velocities'), axis=1)
    grade, grade_ok = importer.reference_grade(np.load(pose / 'frame_positions'), 40.0)
    inside = (t >= pose_t[0]) & (t <= pose_t[-1])
    ref_ok = inside & (np.interp(t, pose_t, grade_ok.astype(float)) > 0.999)
    theta = np.interp(t, pose_t, grade)
    speed = np.interp(t, pose_t, pose_v)
    moving = ref_ok & (speed >= 0.5)
    valid = moving & np.asarray(slope['valid'], dtype=bool)
    params = load_vehicle_params(vehicle)
    mass, g = params.chassis.mass, params.environment.gravity
    dt = float(np.median(np.diff(pose_t)))
    accel = np.interp(t, pose_t, savgol_filter(pose_v, 21, 2, deriv=1, delta=dt))
    forces = d[ESTIMATES_TIRE_FORCES]
    resist = d[ESTIMATES_RESISTANCES]
    net = (
        np.asarray(forces['fx']).sum(axis=1)
        - np.asarray(resist['rolling']).sum(axis=1)
        - np.asarray(resist['aero'])
    )
    need = mass * (accel + g * np.sin(theta))
    # the force balance where it held (its slope valid: SOURCE_FORCE), not where the IMU's
    # grade alone covered a braking
    sources = np.asarray(slope.get('sources', np.ones(t.size, dtype=np.uint8)))
    balanced = valid & ((sources & 1) != 0)
    # (nan where nothing is valid: said, not warned about)
    slope_error = error_stats(np.asarray(slope['angle']), theta, valid)
    force_error = error_stats(net, need, balanced)
    return {
        'samples': float(report.samples),
        'torque_valid': report.torque_valid_fraction,
        'slope_rms_deg': math.degrees(slope_error.rms),
        'slope_bias_deg': math.degrees(slope_error.mean),
        'slope_valid_share': float(valid.sum() / max(moving.sum(), 1)),
        'force_rms_n': force_error.rms,
        'force_bias_n': force_error.mean,
    }


def main(argv: list[str] | None = None) -> int:
    """Command line; exit code 0."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    importer = _importer()
    parser.add_argument('--segment', type=Path, default=importer.DEFAULT_SEGMENT)
    parser.add_argument('--config', type=Path, default=CONFIG / 'replay_100hz_example.yaml')
    parser.add_argument(
        '--mapping',
        type=Path,
        default=CONFIG / 'input_mapping_comma2k19.yaml',
        help='input mapping (input_mapping_comma2k19_imu.yaml: with the IMU fused)',
    )
    parser.add_argument(
        '--vehicle',
        type=Path,
        default=VEHICLE,
        help='vehicle file (e.g. one vd calibrate wrote; default: the hand-built RAV4 file)',
    )
    args = parser.parse_args(argv)
    if not (args.segment / 'processed_log').is_dir():
        print(f'eval_realdata: the real drive is not at {args.segment}: skipped')
        return 0
    with tempfile.TemporaryDirectory() as tmp:
        f = evaluate(args.segment, args.config, Path(tmp), args.mapping, args.vehicle)
    print(
        f'RAV4 segment ({int(f["samples"])} samples, torque path valid '
        f'{100 * f["torque_valid"]:.1f} %):\n'
        f'  slope vs pose grade: RMS {f["slope_rms_deg"]:.2f} deg (bias '
        f'{f["slope_bias_deg"]:+.2f}) over {100 * f["slope_valid_share"]:.1f} % of the moving '
        'samples (goal <= 0.4 deg over >= 90 %)\n'
        f'  sum(Fx) - rolling - aero vs m (a + g sin theta_ref): RMS {f["force_rms_n"]:.0f} N '
        f'(bias {f["force_bias_n"]:+.0f} N) where the force balance held (goal <= 250 N)'
    )
    return 0


if __name__ == '__main__':
    sys.exit(main())
