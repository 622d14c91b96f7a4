#!/usr/bin/env python3
"""Fleet replay throughput and memory per worker; prints figures, asserts nothing.

    python scripts/bench_fleet.py [--bags 8] [--duration 20] [--rate 1000] [--workers 1,2]
                                  [--dask] [--memory-durations 1,30,60,120] [--skip-memory]
                                  [--replay-durations 60,300,1200] [--replay-only]
                                  [--memory-only]

1. Throughput: a fleet of ``--bags`` recording-like bags (20 topics at ``--rate`` Hz, the
   layout of a live demo recording) replayed and evaluated by ``vd fleet``'s engine with 1
   and 2 local worker processes (and a 2-worker Dask LocalCluster with ``--dask``): samples/s,
   bag-hours per hour, and the speed-up of 2 workers over 1 (the issue's goal: >= 1.7x on a
   2-core machine). Also the bags in flight on average (sum of the bags' wall times over the
   run's) and, for the local pool, samples per CPU-second of the workers (start-up
   included), which a busy machine disturbs less than wall time. The load average is printed
   with every figure: on a shared machine the figures are not final.
2. Memory per worker: the peak RSS of one process that runs the per-bag function on one bag,
   for bags of ``--memory-durations`` seconds, a straight-line fit over those of 30 s and more,
   and its extrapolation to a 2 h bag at ``--rate`` Hz (the issue's goal: <= 500 MiB; flat
   when memory is bounded). Both halves are streamed (the replay in blocks of stamps, the
   evaluation in blocks of messages); pass 7200 to measure the 2 h bag itself
   (``--memory-only --memory-durations 60,300,1200,7200``: about 15 min and 8 GiB of
   temporary disk).
3. Replay memory: the peak RSS of one process that only replays (``vd replay``'s
   `replay_bag`, streamed) one recording-like bag, for bags of ``--replay-durations``
   seconds (7200: the issue's 2 h bag; about 1 GiB of disk per 10 min at 1 kHz, deleted
   after), against the same process's RSS after its imports: flat in the bag length when the
   replay's memory is bounded by its block size.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'src' / 'vd_observer_node'))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'src' / 'vd_sim_node'))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'src' / 'vd_common'))

from vd_observer_node.testing.fleet_bags import write_recording_like_bag
from vd_observer_node.tools.fleet import FleetEngine, FleetSettings, process_bag, run_fleet

_HWM = """
def hwm():  # [KiB] this process's peak RSS: VmHWM starts at exec, ru_maxrss would
    # inherit the parent's high-water mark across fork + exec
    for line in open('/proc/self/status'):
        if line.startswith('VmHWM:'):
            return int(line.split()[1])
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
"""
_RSS_PROBE = (
    """
import json, resource, sys
sys.path[:0] = json.loads(sys.argv[2])
from vd_observer_node.tools.fleet import FleetSettings, process_bag
"""
    + _HWM
    + """
record = process_bag(sys.argv[1], FleetSettings())
peak = hwm()
print(json.dumps({'status': record['row']['status'], 'error': record['row']['error'],
                  'peak_kib': peak, 'timing': record['timing']}))
"""
)


_REPLAY_PROBE = (
    """
import json, resource, sys, time
sys.path[:0] = json.loads(sys.argv[3])
"""
    + _HWM
    + """
from vd_observer_node.tools.replay import replay_bag
from vd_observer_node.chain import warm_up
from vd_observer_node.situation.friction_potential import TyreCurves
from vd_observer_node.estimation.vehicle import load_vehicle_params, vehicle_tire
warm_up(TyreCurves.from_tire(vehicle_tire(load_vehicle_params())))
base = hwm()
started = time.perf_counter()
report = replay_bag(sys.argv[1], sys.argv[2], progress=False)
peak = hwm()
print(json.dumps({'base_kib': base, 'peak_kib': peak, 'wall_s': time.perf_counter() - started,
                  'samples': report.samples, 'written': report.messages_written}))
"""
)


def _load() -> str:
    return ' '.join(f'{x:.2f}' for x in os.getloadavg())


def _children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _throughput(bags: list[str], root: Path, engine: str, workers: int) -> dict[str, float]:
    out = root / f'out-{engine}-{workers}'
    cpu = _children_cpu()
    run = run_fleet(
        bags, out, FleetSettings(), engine=FleetEngine(engine, workers=workers), progress=False
    )
    # the pool's workers have exited: their CPU time is in RUSAGE_CHILDREN (Dask's workers
    # are the nanny's children, not ours: no figure)
    cpu = _children_cpu() - cpu
    failed = [r['row']['error'] for r in run.records if r['row']['status'] != 'ok']
    if failed:
        print(f'  failed bags: {failed}')
    wall = run.wall_time_s
    busy = sum(r['timing'].get('wall_s', 0.0) for r in run.records)
    return {
        'wall_s': wall,
        'samples_per_s': run.samples_processed / wall,
        'bag_hours_per_hour': run.hours_processed * 3600.0 / wall,
        'in_flight': busy / wall,
        'samples_per_cpu_s': run.samples_processed / cpu if cpu > 0 and engine == 'local' else 0,
    }


def _memory(root: Path, durations: list[float], rate: float) -> None:
    print(f'\n== memory per worker (peak RSS of one process, one bag, {rate:.0f} Hz, 20 topics)')
    xs, ys = [], []
    for duration in durations:
        bag = root / f'mem_{duration:g}s'
        messages = write_recording_like_bag(bag, duration, rate)
        size = sum(p.stat().st_size for p in bag.iterdir())
        probe = subprocess.run(
            [sys.executable, '-c', _RSS_PROBE, str(bag), json.dumps(sys.path)],
            capture_output=True,
            text=True,
            check=True,
        )
        result = json.loads(probe.stdout.strip().splitlines()[-1])
        peak = result['peak_kib'] / 1024.0
        print(
            f'  {duration:6.0f} s bag: {messages} messages, {size / 2**20:6.1f} MiB on disk; '
            f'peak RSS {peak:7.1f} MiB, {result["timing"]["wall_s"]:.1f} s, '
            f'{result["status"]} {result["error"]}'
        )
        if duration >= 30.0:  # shorter bags sit on the fixed cost (imports, numba, buffers)
            xs.append(duration)
            ys.append(peak)
        bag_files = list(bag.iterdir())
        for path in bag_files:
            path.unlink()
        bag.rmdir()
    if len(xs) >= 2:
        slope, intercept = np.polyfit(xs, ys, 1)
        two_hours = intercept + slope * 7200.0
        print(
            f'  fit: {intercept:.0f} MiB + {slope:.2f} MiB per second of drive '
            f'({slope * 60:.0f} MiB per minute); a 2 h bag at {rate:.0f} Hz: '
            f'~{two_hours / 1024:.1f} GiB per worker (extrapolated; goal <= 500 MiB: '
            f'{"met" if two_hours <= 500 else "NOT met"})'
        )


def _replay_memory(root: Path, durations: list[float], rate: float) -> None:
    print(
        f'\n== replay memory (peak RSS of one process replaying one bag, {rate:.0f} Hz, '
        '20 topics; streamed)'
    )
    for duration in durations:
        bag = root / f'replay_{duration:g}s'
        out = root / f'replay_{duration:g}s_out'
        started = time.perf_counter()
        messages = write_recording_like_bag(bag, duration, rate)
        made = time.perf_counter() - started
        size = sum(p.stat().st_size for p in bag.iterdir())
        try:
            probe = subprocess.run(
                [sys.executable, '-c', _REPLAY_PROBE, str(bag), str(out), json.dumps(sys.path)],
                capture_output=True,
                text=True,
                check=True,
            )
            result = json.loads(probe.stdout.strip().splitlines()[-1])
            print(
                f'  {duration:6.0f} s bag: {messages} messages, {size / 2**20:7.1f} MiB on disk '
                f'(made in {made:.0f} s); replay peak RSS {result["peak_kib"] / 1024:6.1f} MiB '
                f'(after imports {result["base_kib"] / 1024:.1f} MiB), '
                f'{result["samples"]} samples, {result["written"]} messages written in '
                f'{result["wall_s"]:.1f} s; load {_load()}'
            )
        finally:
            for folder in (bag, out):
                if folder.exists():
                    for path in folder.iterdir():
                        path.unlink()
                    folder.rmdir()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--bags', type=int, default=8)
    parser.add_argument('--duration', type=float, default=20.0, help='[s] per bag')
    parser.add_argument('--rate', type=float, default=1000.0, help='[Hz]')
    parser.add_argument('--workers', default='1,2', help='comma-separated worker counts')
    parser.add_argument('--dask', action='store_true', help='also a Dask LocalCluster')
    parser.add_argument(
        '--memory-durations',
        default='1,30,60,120',
        help='[s], comma-separated; those >= 30 s make the straight-line fit',
    )
    parser.add_argument('--skip-memory', action='store_true')
    parser.add_argument(
        '--replay-durations',
        default='60,300,1200',
        help='[s], comma-separated: bags of the replay-only memory figure (7200: 2 h)',
    )
    parser.add_argument('--replay-only', action='store_true', help='only the replay memory figure')
    parser.add_argument(
        '--memory-only', action='store_true', help='only the per-bag memory figure'
    )
    args = parser.parse_args()
    replay_durations = [float(d) for d in args.replay_durations.split(',') if d]
    if args.memory_only:
        with tempfile.TemporaryDirectory(prefix='vd-bench-memory-') as tmp:
            _memory(Path(tmp), [float(d) for d in args.memory_durations.split(',')], args.rate)
        return
    if args.replay_only:
        with tempfile.TemporaryDirectory(prefix='vd-bench-replay-') as tmp:
            _replay_memory(Path(tmp), replay_durations, args.rate)
        return
    counts = [int(w) for w in args.workers.split(',')]
    print(
        f'fleet bench: {args.bags} bags x {args.duration:g} s at {args.rate:g} Hz, '
        f'{os.cpu_count()} cores; load average {_load()} (figures are not final unless '
        'the machine is quiet)'
    )
    with tempfile.TemporaryDirectory(prefix='vd-bench-fleet-') as tmp:
        root = Path(tmp)
        bags = []
        for k in range(args.bags):
            bag = root / 'bags' / f'drive_{k:02d}'
            write_recording_like_bag(bag, args.duration, args.rate, seed=k)
            bags.append(str(bag))
        # numba compiles once here and caches on disk: workers load the cache, and no
        # worker count is charged the compilation
        process_bag(bags[0], FleetSettings())
        print('\n== throughput (replay + report per bag)')
        results: dict[str, dict[str, float]] = {}
        runs = [('local', w) for w in counts] + ([('dask', 2)] if args.dask else [])
        for engine, workers in runs:
            started = time.perf_counter()
            figures = _throughput(bags, root, engine, workers)
            results[f'{engine}-{workers}'] = figures
            per_cpu = figures['samples_per_cpu_s']
            print(
                f'  {engine:5s} {workers} worker(s): {figures["wall_s"]:6.1f} s, '
                f'{figures["samples_per_s"]:9.0f} samples/s, '
                f'{figures["bag_hours_per_hour"]:6.1f} bag-hours per hour; '
                f'bags in flight {figures["in_flight"]:.2f} on average; '
                + (f'{per_cpu:.0f} samples per worker CPU-second; ' if per_cpu else '')
                + f'load {_load()} ({time.perf_counter() - started:.1f} s with start-up)'
            )
        if 'local-1' in results and 'local-2' in results:
            speedup = results['local-2']['samples_per_s'] / results['local-1']['samples_per_s']
            print(f'  2 workers vs 1: {speedup:.2f}x (goal >= 1.7x on 2 cores)')
        if not args.skip_memory:
            durations = [float(d) for d in args.memory_durations.split(',')]
            _memory(root, durations, args.rate)
        if replay_durations:
            _replay_memory(root, replay_durations, args.rate)
    print(f'\nload average at the end {_load()}')


if __name__ == '__main__':
    main()
