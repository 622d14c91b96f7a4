#!/usr/bin/env python3
"""Does a 100 Hz IMU help the slope of a car logged on standard types? (issue 41, item 3)

Each drive is simulated once at 1 kHz with ideal sensors and written as a car logs it
(:mod:`vd_observer_node.testing.standard_bags`: ABS wheel speeds at 100 Hz, odometry at
50 Hz, CAN torques at 100 Hz, each with noise and on its own clock) plus an accelerometer on
``/imu`` (``sensor_msgs/Imu``) at ``--imu-rate`` with ``--imu-noise`` white noise and a bias
drawn per drive within +-``--imu-bias``. The bag is replayed as a user would, with no settings
file (the slope filter follows the input rate), once with the standard mapping (the force
balance's slope) and once with the IMU mapped (the fusion, `estimation.imu_grade`), and the
slope RMS [deg] against the simulator's road is printed for both (t >= 1 s, speed > 1 m/s,
not within 0.5 s of a slope step or a shift).

Drives: ``table1:SEED`` is paper_table1 (150 s) with the sensors' noise seeded SEED;
``everyday:SEED`` is drive SEED of ``vd_sim_node.vehicle.everyday`` (120 s; its true car
differs from the nominal file the replay uses). The fusion's settings were chosen on
table1:0-1 and everyday:0-4; report on others (table1:2-5, everyday:100-109).

``--set KEY=VALUE`` overrides an `ImuGradeConfig` field (a tuning run); the default is what
`imu_grade_config` gives a mapping without ``imu.fusion`` settings.

Usage:
    python scripts/eval_imu_rate.py [--drives table1:2,table1:3,everyday:100] [--imu-rate 100]
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'scripts'))
sys.path.insert(0, str(ROOT / 'src' / 'vd_observer_node'))
sys.path.insert(0, str(ROOT / 'src' / 'vd_sim_node'))
sys.path.insert(0, str(ROOT / 'src' / 'vd_common'))

from eval_estimators import SCENARIO_FILE, VEHICLE_FILE, evaluation_mask  # noqa: E402
from vd_common.topics import ESTIMATES_SLOPE  # noqa: E402
from vd_observer_node.bag import BagReader  # noqa: E402
from vd_observer_node.bag.cdr_batch import decode_batch  # noqa: E402
from vd_observer_node.inputs.mapping import mapping_from_dict  # noqa: E402
from vd_observer_node.testing.standard_bags import (  # noqa: E402
    IMU_MAPPING,
    STANDARD_MAPPING,
    CarSensors,
    write_standard_bag,
)
from vd_observer_node.tools.replay import ESTIMATE_TOPICS, replay_bag  # noqa: E402

REPORTED = 'table1:2,table1:3,table1:4,table1:5,' + ','.join(
    f'everyday:{s}' for s in range(100, 110)
)


def simulate_drive(name: str) -> Any:
    """The 1 kHz ideal-sensor run of drive ``name`` (module docstring)."""
    from vd_common.vehicle.params import load_vehicle
    from vd_sim_node.vehicle.everyday import EverydaySettings, everyday_scenario
    from vd_sim_node.vehicle.scenario import load_scenario
    from vd_sim_node.vehicle.simulation import simulate

    kind, seed = name.split(':')
    params = load_vehicle(VEHICLE_FILE)
    if kind == 'table1':
        return simulate(params, load_scenario(SCENARIO_FILE))
    if kind == 'everyday':
        return simulate(params, everyday_scenario(int(seed), params, EverydaySettings()))
    raise SystemExit(f'unknown drive {name!r} (table1:SEED or everyday:SEED)')


def slope_rms_deg(bag: Path, sim: Any) -> float:
    """Slope RMS [deg] of a replayed bag against the simulator's road (module docstring)."""
    arrays = BagReader(bag).topic_arrays([ESTIMATES_SLOPE])[ESTIMATES_SLOPE]
    fields = decode_batch(ESTIMATE_TOPICS[ESTIMATES_SLOPE], arrays.datas)
    t = fields.stamp_ns * 1e-9
    mask = evaluation_mask(t, sim.events) & (np.interp(t, sim.t, sim.speed_true) > 1.0)
    error = fields.values['angle'] - np.interp(t, sim.t, sim.slope)
    return math.degrees(float(np.sqrt(np.mean(error[mask] ** 2))))


def _load(cache: Path | None, name: str) -> SimpleNamespace:
    """The arrays of drive ``name`` the bag needs, from ``cache`` or simulated (and cached)."""
    keep = ('t', 'angle_true', 'speed_true', 'wheel_torque', 'imu_true', 'slope')
    # the table's drive is one simulation whatever the sensors' seed
    stem = 'table1' if name.startswith('table1:') else name.replace(':', '_')
    path = cache / f'{stem}.npz' if cache is not None else None
    if path is not None and path.exists():
        with np.load(path) as data:
            arrays = {k: data[k] for k in (*keep, 'event_t')}
            labels = [str(x) for x in np.load(path)['event_text']]
    else:
        run = simulate_drive(name)
        arrays = {k: getattr(run, k) for k in keep}
        arrays['event_t'] = np.array([e[0] for e in run.events], dtype=np.float64)
        labels = [e[1] for e in run.events]
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
            np.savez(path, **arrays, event_text=np.array(labels, dtype=str))
    events = tuple(zip(arrays.pop('event_t').tolist(), labels, strict=True))
    return SimpleNamespace(**arrays, events=events)


def main(argv: list[str] | None = None) -> int:
    """Simulate, write, replay with and without the IMU, print the slope figures."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--drives', default=REPORTED, help='comma-separated kind:seed')
    parser.add_argument('--imu-rate', type=float, default=100.0, help='[Hz]')
    parser.add_argument('--imu-noise', type=float, default=0.05, help='[m/s^2]')
    parser.add_argument('--imu-bias', type=float, default=0.1, help='largest |bias| [m/s^2]')
    parser.add_argument('--set', action='append', default=[], metavar='KEY=VALUE')
    parser.add_argument('--cache', type=Path, default=None, help='folder for the simulations')
    args = parser.parse_args(argv)
    changes = tuple((k, float(v)) for k, v in (item.split('=', 1) for item in args.set))
    imu_mapping = dict(IMU_MAPPING)
    if changes:
        imu_mapping['imu'] = {**IMU_MAPPING['imu'], 'fusion': dict(changes)}
    plain_map = mapping_from_dict(STANDARD_MAPPING)
    imu_map = mapping_from_dict(imu_mapping)
    print(
        f'standard types + IMU {args.imu_rate:g} Hz, noise {args.imu_noise:g} m/s^2, bias <= '
        f'{args.imu_bias:g} m/s^2; fusion settings: {dict(changes) or "defaults"}',
        flush=True,
    )
    rows: list[tuple[str, float, float]] = []
    start = time.perf_counter()
    for name in args.drives.split(','):
        sim = _load(args.cache, name)
        seed = int(name.split(':')[1])
        rng = np.random.default_rng(1000 + seed)
        bias = float(rng.uniform(-args.imu_bias, args.imu_bias))
        sensors = CarSensors(
            seed=seed, imu_rate_hz=args.imu_rate, imu_noise_std=args.imu_noise, imu_bias=bias
        )
        with tempfile.TemporaryDirectory() as tmp:
            bag = Path(tmp) / 'car'
            write_standard_bag(bag, sim, sensors)
            replay_bag(bag, Path(tmp) / 'force', progress=False, mapping=plain_map)
            replay_bag(bag, Path(tmp) / 'fused', progress=False, mapping=imu_map)
            force = slope_rms_deg(Path(tmp) / 'force', sim)
            fused = slope_rms_deg(Path(tmp) / 'fused', sim)
        rows.append((name, force, fused))
        print(
            f'  {name:<13} bias {bias:+.3f}  slope RMS [deg]: force balance {force:.3f}, '
            f'fused {fused:.3f}  ({fused / force:.2f}x)',
            flush=True,
        )
    ratios = [fused / force for _, force, fused in rows]
    print(
        f'fused / force balance: median {np.median(ratios):.2f}x, worst {max(ratios):.2f}x '
        f'({sum(r > 1.0 for r in ratios)} of {len(rows)} drives worse); '
        f'{time.perf_counter() - start:.0f} s'
    )
    return 0


if __name__ == '__main__':
    sys.exit(main())
