#!/usr/bin/env python3
"""The compiled kernel against the Python reference: cost per 4-wheel sample, start-up time.

Prints, side by side in one run (issue 14's targets: <= 20 us per sample for cascade +
monitor, node start-up <= 3 s with a warm compile cache):

1. offline blocks (what `vd replay` runs): `run_cascade` + `run_situation` against their
   compiled twins, on the first 30 s of paper_table1 and of launch_low_mu at 1 kHz with the
   96-count encoder and speed noise;
2. per stamp (what the live nodes run, N = 1 per call): `chain.PythonChain.update` against
   `kernel.chain.CompiledChain.update`;
3. start-up of pipeline_node and observer_node with each kernel: from the process start to
   its 'ready' log line (median of 3; the numba cache is warm after the first).

Run inside ``. ./env.sh``; about a minute.
"""

from __future__ import annotations

import dataclasses
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from vd_common.vehicle.params import default_vehicle_file, load_vehicle
from vd_observer_node.chain import ChainSettings, PythonChain
from vd_observer_node.estimation.cascade import run_cascade
from vd_observer_node.estimation.vehicle import load_estimator_vehicle
from vd_observer_node.kernel.chain import (
    CompiledChain,
    compiled_monitor,
    run_cascade_compiled,
    run_situation_compiled,
    warm_up,
)
from vd_observer_node.situation.friction_potential import TyreCurves
from vd_observer_node.situation.monitor import SituationMonitor, run_situation
from vd_observer_node.testing.launcher import NodeSpec
from vd_sim_node.vehicle.scenario import SensorSettings, load_scenario
from vd_sim_node.vehicle.simulation import simulate

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = ROOT / 'src' / 'vd_sim_node' / 'config' / 'scenarios'
ENCODER = SensorSettings(rate_hz=1000.0, seed=2, encoder_counts_per_rev=96, speed_noise_std=0.05)


def record(name: str, duration: float) -> tuple[np.ndarray, ...]:
    scenario = load_scenario(SCENARIOS / f'{name}.yaml')
    short = dataclasses.replace(
        scenario, duration=min(duration, scenario.duration), sensors=ENCODER
    )
    sim = simulate(load_vehicle(default_vehicle_file()), short)
    return sim.t, sim.wheel_angle, sim.body_speed, sim.wheel_torque


def blocks(name: str, vehicle: object, curves: TyreCurves) -> None:
    t, angle, speed, torque = record(name, 30.0)
    n = len(t)
    loads = vehicle.static_wheel_loads[[0, 2]]  # type: ignore[attr-defined]
    radius = vehicle.effective_radius  # type: ignore[attr-defined]
    start = time.process_time()
    cascade = run_cascade(t, angle, speed, torque, vehicle)
    mid = time.process_time()
    run_situation(SituationMonitor(curves, loads, radius), angle, speed, torque, cascade)
    end = time.process_time()
    py = ((mid - start) / n * 1e6, (end - mid) / n * 1e6)
    runs = []
    for _ in range(5):
        monitor = compiled_monitor(curves, loads, radius)
        start = time.process_time()
        compiled = run_cascade_compiled(t, angle, speed, torque, vehicle)
        mid = time.process_time()
        run_situation_compiled(monitor, angle, speed, torque, compiled)
        end = time.process_time()
        runs.append(((mid - start) / n * 1e6, (end - mid) / n * 1e6))
    cc = statistics.median(r[0] for r in runs)
    cs = statistics.median(r[1] for r in runs)
    print(
        f'  {name:14s} ({n} samples, mu valid {cascade.mu_valid.mean():.0%}): python '
        f'{py[0]:6.1f} + {py[1]:6.1f} = {sum(py):6.1f} us   compiled {cc:5.2f} + {cs:5.2f} = '
        f'{cc + cs:5.2f} us   ratio {sum(py) / (cc + cs):5.0f}x'
    )


def per_stamp(vehicle: object, curves: TyreCurves) -> None:
    t, angle, speed, torque = record('launch_low_mu', 5.0)
    settings = ChainSettings(vehicle=vehicle, curves=curves)  # type: ignore[arg-type]
    for label, chain in (('python', PythonChain(settings)), ('compiled', CompiledChain(settings))):
        start = time.process_time()
        for k in range(len(t)):
            chain.update(float(t[k]), angle[k], float(speed[k]), torque[k])
        cost = (time.process_time() - start) / len(t) * 1e6
        print(f'  {label:8s} chain.update: {cost:7.1f} us per stamp (N = 1, outputs as objects)')


def startup(executable: str, kernel: str, env: dict[str, str]) -> float:
    """Median wall time [s] from spawn to the node's 'ready' line, over 3 starts."""
    times = []
    for _ in range(3):
        argv = NodeSpec('vd_observer_node', executable, executable, {'kernel': kernel}).argv()
        with tempfile.TemporaryFile() as log:
            start = time.monotonic()
            proc = subprocess.Popen(argv, stdout=log, stderr=subprocess.STDOUT, env=env)
            while time.monotonic() - start < 60.0:
                log.seek(0)
                if b'ready' in log.read():
                    break
                time.sleep(0.01)
            times.append(time.monotonic() - start)
            proc.terminate()
            proc.wait(20)
    return statistics.median(times)


def main() -> int:
    print(f'load average {os.getloadavg()[0]:.2f} (figures taken above ~1.5 are not figures)')
    vehicle = load_estimator_vehicle(default_vehicle_file())
    curves = TyreCurves.from_tire(load_vehicle(default_vehicle_file()).tire)
    warm_up(curves)
    print('== cascade + situation monitor per 4-wheel sample (CPU time), offline blocks')
    for name in ('paper_table1', 'launch_low_mu'):
        blocks(name, vehicle, curves)
    print('== per stamp, as the live pipeline node')
    per_stamp(vehicle, curves)
    print('== node start-up to "ready" (warm numba cache), median of 3')
    env = dict(os.environ)
    env['ROS_DOMAIN_ID'] = str(60 + os.getpid() % 30)
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    for executable in ('pipeline_node', 'observer_node', 'alerts_node'):
        line = ', '.join(
            f'{kernel} {startup(executable, kernel, env):.2f} s'
            for kernel in ('compiled', 'python')
        )
        print(f'  {executable:14s} {line}')
    print(f'load average {os.getloadavg()[0]:.2f}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
