#!/usr/bin/env python3
"""Benchmark of the ROS-free vehicle simulator: simulated seconds per wall-clock second.

Runs a scenario (default ``paper_table1``, 150 s) with 1 kHz sensor output several times
and prints the best and median speed-up over real time, both in wall-clock and in process
CPU time (the latter is less sensitive to other processes sharing the machine), plus the
integration cost (right-hand-side evaluations). Goal: >= 200x real time on one core.

Usage::

    python scripts/bench_simulator.py [--scenario NAME_OR_PATH] [--rate 1000] [--repeat 5]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'src' / 'vd_sim_node'))
sys.path.insert(0, str(ROOT / 'src' / 'vd_common'))

from vd_common.vehicle.params import default_vehicle_file, load_vehicle  # noqa: E402
from vd_sim_node.vehicle.model import VehicleModel  # noqa: E402
from vd_sim_node.vehicle.scenario import load_scenario  # noqa: E402
from vd_sim_node.vehicle.simulation import Simulator  # noqa: E402

CONFIG = ROOT / 'src' / 'vd_sim_node' / 'config'


def main() -> None:
    """Parse arguments, run the benchmark, print the figures."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--scenario', default='paper_table1')
    ap.add_argument('--rate', type=float, default=1000.0, help='sensor rate [Hz]')
    ap.add_argument('--repeat', type=int, default=5)
    args = ap.parse_args()
    path = Path(args.scenario)
    if not path.exists():
        path = CONFIG / 'scenarios' / f'{args.scenario}.yaml'
    scenario = load_scenario(path)

    t0 = time.perf_counter()
    model = VehicleModel(load_vehicle(default_vehicle_file()))
    build = time.perf_counter() - t0

    walls, cpus = [], []
    nfev = samples = 0
    for _ in range(args.repeat):
        sim = Simulator(model, scenario, rate_hz=args.rate)
        w0, c0 = time.perf_counter(), time.process_time()
        result = sim.run()
        walls.append(time.perf_counter() - w0)
        cpus.append(time.process_time() - c0)
        nfev, samples = sim.nfev, len(result.t)

    d = scenario.duration
    print(
        f'scenario            : {scenario.name} ({d:g} s simulated, {samples} samples at '
        f'{args.rate:g} Hz)'
    )
    print(f'model build/compile : {build * 1e3:.0f} ms (once per process)')
    print(f'RHS evaluations     : {nfev}')
    print(
        f'wall time  best/med : {min(walls):.3f} / {statistics.median(walls):.3f} s  ->  '
        f'{d / min(walls):.0f}x / {d / statistics.median(walls):.0f}x real time'
    )
    print(
        f'CPU time   best/med : {min(cpus):.3f} / {statistics.median(cpus):.3f} s  ->  '
        f'{d / min(cpus):.0f}x / {d / statistics.median(cpus):.0f}x real time'
    )
    load = os.getloadavg()[0] if hasattr(os, 'getloadavg') else float('nan')
    print(f'machine load (1 min): {load:.2f} on {os.cpu_count()} cores')


if __name__ == '__main__':
    main()
