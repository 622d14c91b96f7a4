#!/usr/bin/env python3
"""`make demo`: the whole graph on a scenario, recorded to an MCAP bag, then the report.

Starts recorder_node, pipeline_node and sim_node as separate processes over the real
middleware, the simulator publishing its IMU and the pipeline mapping it
(``config/input_mapping_sim_imu.yaml``): the slope is the IMU's grade fused with the force
balance (docs/estimation.md, IMU fusion). ``--no-imu`` runs the graph of
`launch/demo.launch.py` instead (observer_node, estimator_node, alerts_node: the force
balance's slope, no IMU). Shows the simulation's progress, stops every process cleanly with
SIGINT, keeps the bag and runs `vd report` on it. Run inside the workspace environment (`make
demo` sources env.sh).

By default the simulator runs in lockstep with the estimator, the alerts node and the recorder
(it waits for their progress, at most 0.5 s of sample time ahead, the real-time factor a cap):
nothing is lost on a slow machine, so the figures are the same on every machine and every run.
``--real-time`` paces it by the wall clock alone, as a car does: a machine that cannot keep up
then loses messages, and the diagnostics and the report say so.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import sys
import time
from pathlib import Path

from tqdm import tqdm
from vd_common.topics import ESTIMATES_ALERTS, ESTIMATES_SLOPE, STATUS_RECORDER_PROGRESS
from vd_observer_node.testing.launcher import GraphLauncher, NodeSpec

ROOT = Path(__file__).resolve().parents[1]
_PROGRESS = re.compile(r'progress t=([0-9.]+)/([0-9.]+) s')


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--scenario', default='paper_table1', help='installed name or YAML path')
    parser.add_argument('--rate-hz', type=float, default=1000.0, help='sensor rate [Hz]')
    parser.add_argument(
        '--real-time-factor', type=float, default=1.0, help='simulated s per wall s'
    )
    parser.add_argument(
        '--real-time',
        action='store_true',
        help='pace the simulator by the wall clock alone (no lockstep: a slow machine loses data)',
    )
    parser.add_argument(
        '--lockstep-topics',
        default=f'{ESTIMATES_SLOPE},{ESTIMATES_ALERTS},{STATUS_RECORDER_PROGRESS}',
        help='comma-separated topics the simulator waits for in lockstep',
    )
    parser.add_argument(
        '--lockstep-window', type=float, default=0.5, help='lockstep window [s of sample time]'
    )
    parser.add_argument('--out', type=Path, default=ROOT / 'out' / 'demo', help='output folder')
    parser.add_argument('--encoder-counts', type=int, default=-1, help='-1: scenario setting')
    parser.add_argument('--speed-noise', type=float, default=-1.0, help='-1: scenario setting')
    parser.add_argument(
        '--imu-noise', type=float, default=0.05, help="the IMU's noise per axis [m/s^2]"
    )
    parser.add_argument(
        '--gyro-noise',
        type=float,
        default=0.004,
        help="the IMU's pitch-rate noise [rad/s] (a consumer MEMS gyro's at 1 kHz)",
    )
    parser.add_argument(
        '--no-imu',
        action='store_true',
        help='no IMU: the split observer, estimator and alerts nodes (launch/demo.launch.py)',
    )
    parser.add_argument('--no-report', action='store_true', help='skip vd report')
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    bag = args.out / 'bag'
    if args.out.exists():
        shutil.rmtree(args.out)
    args.out.mkdir(parents=True)
    pacing = 'real time' if args.real_time else 'lockstep with estimator, alerts and recorder'
    print(
        f'demo: scenario {args.scenario} at {args.rate_hz:g} Hz, {pacing}, real-time factor '
        f'{args.real_time_factor:g}; logs and bag in {args.out}',
        flush=True,
    )
    lockstep = (
        {}
        if args.real_time
        else {
            'lockstep_topics': args.lockstep_topics,
            'lockstep_window': args.lockstep_window,
        }
    )
    if lockstep and 'FASTDDS_DEFAULT_PROFILES_FILE' not in os.environ:
        # a heartbeat every 50 ms: a message lost in a pause of the stream is repaired then,
        # not after Fast DDS's default 3 s (config/fastdds_lockstep.xml says why)
        from ament_index_python.packages import get_package_share_directory

        share = Path(get_package_share_directory('vd_observer_node'))
        os.environ['FASTDDS_DEFAULT_PROFILES_FILE'] = str(
            share / 'config' / 'fastdds_lockstep.xml'
        )
    from ament_index_python.packages import get_package_share_directory

    share = Path(get_package_share_directory('vd_observer_node'))
    if args.no_imu:
        estimation = [
            NodeSpec('vd_observer_node', 'observer_node', 'observer'),
            NodeSpec('vd_observer_node', 'estimator_node', 'estimator'),
            NodeSpec('vd_observer_node', 'alerts_node', 'alerts'),
        ]
    else:
        mapping = share / 'config' / 'input_mapping_sim_imu.yaml'
        estimation = [
            NodeSpec(
                'vd_observer_node', 'pipeline_node', 'pipeline', {'input_mapping': str(mapping)}
            )
        ]
    started = time.monotonic()
    with GraphLauncher(args.out / 'logs') as graph:
        graph.start_all(
            [
                NodeSpec('vd_observer_node', 'recorder_node', 'recorder', {'output': str(bag)}),
                *estimation,
            ],
            settle_s=3.0,
        )
        dead = graph.dead()
        if dead:
            print(f'demo: {dead[0].spec.name} failed to start:\n{dead[0].log_tail()}')
            return 1
        sim = graph.start(
            NodeSpec(
                'vd_sim_node',
                'sim_node',
                'sim',
                {
                    'scenario_file': args.scenario,
                    'rate_hz': args.rate_hz,
                    'real_time_factor': args.real_time_factor,
                    'encoder_counts_per_rev': args.encoder_counts,
                    'speed_noise_std': args.speed_noise,
                    'imu_noise_std': -1.0 if args.no_imu else args.imu_noise,
                    'imu_gyro_noise_std': -1.0 if args.no_imu else args.gyro_noise,
                    'progress_period': 1.0,
                    **lockstep,
                },
            )
        )
        with tqdm(
            total=1.0,
            unit='s sim',
            desc='simulating',
            dynamic_ncols=True,
            bar_format='{desc}: {percentage:3.0f}%|{bar}| {n:.0f}/{total:.0f} s '
            '[{elapsed}<{remaining}]',
        ) as bar:
            while sim.running:
                time.sleep(0.5)
                found = _PROGRESS.findall(sim.log_tail(400))
                if found:
                    done, total = (float(v) for v in found[-1])
                    bar.total = total
                    bar.update(done - bar.n)
                broken = [n for n in graph.dead() if n is not sim]
                if broken:
                    print(f'demo: {broken[0].spec.name} died:\n{broken[0].log_tail()}')
                    return 1
        if sim.popen.returncode != 0:
            print(f'demo: the simulator failed:\n{sim.log_tail()}')
            return 1
        # in lockstep the simulator ended once its consumers had the last sample; in real time
        # give the last samples time to go through observer and estimator to the recorder
        time.sleep(0.5 if lockstep else 2.0)
        codes = graph.stop_all()
    print(f'demo: graph ran {time.monotonic() - started:.0f} s', flush=True)
    if any(codes.values()):
        print(f'demo: exit codes {codes}; logs in {args.out / "logs"}')
    from vd_observer_node.tools.cli import main as vd

    print(f'\ndemo: bag {bag}', flush=True)
    vd(['bag', 'info', str(bag)])
    if args.no_report:
        return 0
    return vd(['report', str(bag), '--out', str(args.out / 'report')])


if __name__ == '__main__':
    sys.exit(main())
