#!/usr/bin/env python3
"""The chain's one implementation: cost per 4-wheel sample in blocks and per stamp, start-up.

Prints (issue 14's targets: <= 20 us per sample for cascade + monitor, node start-up <= 3 s
with a warm compile cache):

1. offline blocks (what `vd replay` runs): `run_cascade` + `run_situation` on the first 30 s
   of paper_table1 and of launch_low_mu at 1 kHz with the 96-count encoder and speed noise;
   the same source uncompiled (``VD_JIT=0``, a child process) on the first 2 s, for scale;
2. per stamp (what the live pipeline node runs, N = 1 per call): `chain.Chain.update`;
3. start-up of pipeline_node, observer_node and alerts_node: from the process start to its
   'ready' log line (median of 3; the numba cache is warm).

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
from vd_observer_node.chain import Chain, warm_up
from vd_observer_node.estimation.cascade import CascadeSeries, CascadeSettings, run_cascade
from vd_observer_node.estimation.vehicle import load_estimator_vehicle
from vd_observer_node.kernel._jit import JIT_ENABLED
from vd_observer_node.situation.chain_settings import ChainSettings
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


def _block_cost(
    name: str, seconds: float, vehicle: object, curves: TyreCurves
) -> tuple[float, ...]:
    """(cascade, monitor) CPU [us] per sample, median of 5 (1 uncompiled), and N."""
    t, angle, speed, torque = record(name, seconds)
    n = len(t)
    loads = vehicle.static_wheel_loads[[0, 2]]  # type: ignore[attr-defined]
    radius = vehicle.effective_radius  # type: ignore[attr-defined]
    runs = []
    for _ in range(5 if JIT_ENABLED else 1):
        monitor = SituationMonitor(curves, loads, radius)
        start = time.process_time()
        cascade = run_cascade(CascadeSeries(t, angle, speed, torque), CascadeSettings(vehicle))
        mid = time.process_time()
        run_situation(monitor, angle, speed, torque, cascade)
        end = time.process_time()
        runs.append(((mid - start) / n * 1e6, (end - mid) / n * 1e6))
    return statistics.median(r[0] for r in runs), statistics.median(r[1] for r in runs), n


def blocks(name: str, vehicle: object, curves: TyreCurves) -> None:
    cc, cs, n = _block_cost(name, 30.0, vehicle, curves)
    code = (
        'import sys; sys.argv = ["x"]; import runpy; '
        f'm = runpy.run_path({str(Path(__file__))!r}); '
        f'print(*m["uncompiled"]({name!r}))'
    )
    env = dict(os.environ, VD_JIT='0')
    out = subprocess.run(
        [sys.executable, '-c', code], env=env, capture_output=True, text=True, check=True
    )
    pc, ps = (float(v) for v in out.stdout.split()[-2:])
    print(
        f'  {name:14s} ({n} samples): compiled {cc:5.2f} + {cs:5.2f} = {cc + cs:5.2f} us   '
        f'uncompiled (VD_JIT=0, 2 s) {pc:7.1f} + {ps:7.1f} = {pc + ps:7.1f} us   '
        f'ratio {(pc + ps) / (cc + cs):5.0f}x'
    )


def uncompiled(name: str) -> tuple[float, float]:
    """The block cost with ``VD_JIT=0`` (called in a child process)."""
    vehicle = load_estimator_vehicle(default_vehicle_file())
    curves = TyreCurves.from_tire(load_vehicle(default_vehicle_file()).tire)
    cc, cs, _ = _block_cost(name, 2.0, vehicle, curves)
    return cc, cs


def imu_cost(vehicle: object) -> None:
    """The cascade's CPU per sample without an IMU, with its specific force, and with its
    pitch rate too (issue 36's budget: the whole IMU within 3 us of today's fusion)."""
    scenario = load_scenario(SCENARIOS / 'paper_table1.yaml')
    sensors = dataclasses.replace(ENCODER, imu=True, imu_noise_std=0.05, imu_gyro_noise_std=0.004)
    sim = simulate(
        load_vehicle(default_vehicle_file()),
        dataclasses.replace(scenario, duration=30.0, sensors=sensors),
    )
    n = len(sim.t)
    inputs = {
        'no IMU': None,
        'specific force': np.column_stack([sim.t, sim.imu[:, 0]]),
        'whole IMU': np.column_stack([sim.t, sim.imu[:, 0], sim.gyro]),
    }
    settings = CascadeSettings(vehicle)
    costs = {}
    for name, imu in inputs.items():
        runs = []
        for _ in range(5):
            start = time.process_time()
            series = CascadeSeries(
                sim.t, sim.wheel_angle, sim.body_speed, sim.wheel_torque, imu=imu
            )
            run_cascade(series, settings)
            runs.append((time.process_time() - start) / n * 1e6)
        costs[name] = statistics.median(runs)
    print(
        '  paper_table1 30 s: '
        + ', '.join(f'{name} {cost:5.2f} us' for name, cost in costs.items())
        + f'; the pitch rate adds {costs["whole IMU"] - costs["specific force"]:+5.2f} us'
    )


def per_stamp(vehicle: object, curves: TyreCurves) -> None:
    t, angle, speed, torque = record('launch_low_mu', 5.0)
    chain = Chain(ChainSettings(vehicle=vehicle, curves=curves))  # type: ignore[arg-type]
    start = time.process_time()
    for k in range(len(t)):
        chain.update(float(t[k]), angle[k], float(speed[k]), torque[k])
    cost = (time.process_time() - start) / len(t) * 1e6
    print(f'  Chain.update: {cost:7.1f} us per stamp (N = 1, outputs as objects)')


def startup(executable: str, env: dict[str, str]) -> float:
    """Median wall time [s] from spawn to the node's 'ready' line, over 3 starts."""
    times = []
    for _ in range(3):
        argv = NodeSpec('vd_observer_node', executable, executable, {}).argv()
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
    print('== the IMU fusion: cascade CPU per sample, median of 5')
    imu_cost(vehicle)
    print('== per stamp, as the live pipeline node')
    per_stamp(vehicle, curves)
    print('== node start-up to "ready" (warm numba cache), median of 3')
    env = dict(os.environ)
    env['ROS_DOMAIN_ID'] = str(60 + os.getpid() % 30)
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    for executable in ('pipeline_node', 'observer_node', 'alerts_node'):
        print(f'  {executable:14s} {startup(executable, env):.2f} s')
    print(f'load average {os.getloadavg()[0]:.2f}')
    return 0


if __name__ == '__main__' and sys.argv[1:2] != ['x']:
    sys.exit(main())
