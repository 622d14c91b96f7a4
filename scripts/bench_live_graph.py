#!/usr/bin/env python3
"""The live graph over the real middleware: message loss, latency, CPU and memory (prints figures).

Runs sim_node (real-time factor 1.0, the first `--duration` s of the paper scenario) with the
estimation nodes of each layout (``nodes``: observer_node, estimator_node and alerts_node;
``pipeline``: pipeline_node), with and without
recorder_node, each node its
own process (GraphLauncher, like ``ros2 run``), plus a probe process
(scripts/latency_probe.py) that notes the wall-clock reception time of every message.
Stamps are simulation time, so the latency of a sample is the probe's reception time of
``/vd/estimates/slope`` minus its reception time of ``/vd/sensors/wheel_angles`` for the same
stamp (both clocks are the probe's CLOCK_MONOTONIC). It includes the probe's own queueing,
and when the probe falls behind on the angles it is biased low (even negative), so the
script also prints the slope estimate's lateness against the real-time schedule: reception
minus (stamp + the smallest reception-minus-stamp offset seen on the angles).

Figures per run:
* lost per topic: samples the simulator published minus distinct stamps the probe received
  (and, with the recorder, minus the bag's message count);
* latency p50 / p99 / max, wheel angles -> slope estimate [ms];
* CPU per node: utime + stime from /proc/<pid>/stat over the run window, as % of one core;
  RSS at the end and its peak (VmHWM) [MiB];
* the real-time factor the simulator achieved (from its log).
Then a sweep of sensor rates with shorter runs: the highest rate with no loss on any
watched topic and the simulator keeping real time. Finally one short run with the old
``VD_ROS_EXECUTOR=single_threaded`` on the estimation nodes (the EventsExecutor is the
default), for comparison.

Every run uses its own ROS_DOMAIN_ID and localhost-only discovery, so graphs started by
tests or other people on the same machine do not mix in.

Usage (inside env.sh; `make bench` runs it without arguments):
    python scripts/bench_live_graph.py [--quick] [--repeat 3] [--duration 60] [--rate 1000]
"""

from __future__ import annotations

import argparse
import contextlib
import os
import re
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml
from vd_common.topics import (
    ESTIMATES_ALERTS,
    ESTIMATES_SLOPE,
    ESTIMATES_TIRE_FORCES,
    OBSERVER_BODY_ACCEL,
    OBSERVER_WHEEL_STATES,
    SENSORS_BODY_VELOCITY,
    SENSORS_WHEEL_ANGLES,
    SENSORS_WHEEL_TORQUES,
    TRUTH_NAMESPACE,
)
from vd_observer_node.testing.launcher import GraphLauncher, NodeProcess, NodeSpec

__all__ = ['RunResult', 'main', 'run_graph']

ROOT = Path(__file__).resolve().parents[1]
PROBE = ROOT / 'scripts' / 'latency_probe.py'
SCENARIO = ROOT / 'src' / 'vd_sim_node' / 'config' / 'scenarios' / 'paper_table1.yaml'
SENSOR_TOPICS = [
    SENSORS_WHEEL_ANGLES,
    SENSORS_BODY_VELOCITY,
    SENSORS_WHEEL_TORQUES,
]
DERIVED_TOPICS = [
    OBSERVER_WHEEL_STATES,
    OBSERVER_BODY_ACCEL,
    ESTIMATES_TIRE_FORCES,
    ESTIMATES_SLOPE,
    ESTIMATES_ALERTS,
]
#: The estimation nodes of each layout: (executable, name, text it logs when ready).
LAYOUTS = {
    'nodes': (
        ('observer_node', 'observer', 'observer ready'),
        ('estimator_node', 'estimator', 'estimator ready'),
        ('alerts_node', 'alerts', 'alerts ready'),
    ),
    'pipeline': (('pipeline_node', 'pipeline', 'pipeline ready'),),
    # the same, pinned: pipeline_node alone on the last CPU, the simulator and the probe on
    # the others (as `ros2 run --prefix 'taskset -c 1' ...` does; docs/performance.md)
    'pipeline-pinned': (('pipeline_node', 'pipeline', 'pipeline ready'),),
}
#: layouts whose estimation processes get a CPU of their own
PINNED = {'pipeline-pinned'}
WATCHED = SENSOR_TOPICS + DERIVED_TOPICS
_FINISHED = re.compile(r'scenario finished: (\d+) samples, ([0-9.]+) s simulated in ([0-9.]+) s')
_TICK = os.sysconf('SC_CLK_TCK')
_PAGE = os.sysconf('SC_PAGE_SIZE')


@dataclass
class ProcStats:
    """CPU time [s] and memory [MiB] of one process, sampled from /proc."""

    cpu_s: float = 0.0
    rss_mib: float = 0.0
    hwm_mib: float = 0.0


def proc_stats(pid: int) -> ProcStats | None:
    """utime + stime [s], VmRSS and VmHWM [MiB] of `pid`; None once it has exited."""
    try:
        stat = Path(f'/proc/{pid}/stat').read_text()
        status = Path(f'/proc/{pid}/status').read_text()
    except OSError:
        return None
    # fields after the parenthesised command name; utime and stime are fields 14 and 15
    fields = stat[stat.rindex(')') + 2 :].split()
    cpu = (int(fields[11]) + int(fields[12])) / _TICK
    mem = {
        line.split(':')[0]: int(line.split()[1]) / 1024.0
        for line in status.splitlines()
        if line.startswith(('VmRSS', 'VmHWM'))
    }
    return ProcStats(cpu, mem.get('VmRSS', float('nan')), mem.get('VmHWM', float('nan')))


@dataclass
class RunResult:
    """Figures of one graph run."""

    rate_hz: float
    duration_s: float
    recorder: bool
    published: int = 0
    achieved_rtf: float = float('nan')
    received: dict[str, int] = field(default_factory=dict)
    in_bag: dict[str, int] = field(default_factory=dict)
    latency_ms: dict[str, float] = field(default_factory=dict)
    cpu_pct: dict[str, float] = field(default_factory=dict)
    rss_mib: dict[str, float] = field(default_factory=dict)
    hwm_mib: dict[str, float] = field(default_factory=dict)
    exit_codes: dict[str, int] = field(default_factory=dict)
    error: str = ''

    def lost(self) -> dict[str, int]:
        """Published minus received per watched topic (probe)."""
        return {t: self.published - n for t, n in self.received.items()}

    def lossless(self) -> bool:
        """No loss on any watched topic and the simulator kept (95 % of) real time."""
        return (
            not self.error
            and self.published > 0
            and all(v == 0 for v in self.lost().values())
            and self.achieved_rtf >= 0.95
        )


def _scenario_file(folder: Path, duration: float) -> Path:
    data = yaml.safe_load(SCENARIO.read_text())
    data['name'] = f'paper_table1_first_{duration:g}s'
    data['duration'] = float(duration)
    path = folder / 'bench_scenario.yaml'
    path.write_text(yaml.safe_dump(data))
    return path


def _wait_for(
    proc_log: Path, text: str, alive: Sequence[subprocess.Popen[bytes]], t: float
) -> bool:
    deadline = time.monotonic() + t
    while time.monotonic() < deadline:
        if proc_log.exists() and text in proc_log.read_text(errors='replace'):
            return True
        if any(p.poll() is not None for p in alive):
            return False
        time.sleep(0.05)
    return False


class _Probe:
    """The latency probe as a child process (not a ROS package executable)."""

    def __init__(self, out: Path, log_dir: Path, env: Mapping[str, str]) -> None:
        self.out = out
        self.log_path = log_dir / 'probe.log'
        self._log = self.log_path.open('wb')
        self.popen = subprocess.Popen(
            [sys.executable, str(PROBE), '--out', str(out), *WATCHED],
            stdout=self._log,
            stderr=subprocess.STDOUT,
            env=dict(env),
            start_new_session=True,
        )

    def stop(self) -> None:
        if self.popen.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self.popen.pid, signal.SIGINT)
            try:
                self.popen.wait(20.0)
            except subprocess.TimeoutExpired:
                os.killpg(self.popen.pid, signal.SIGKILL)
                self.popen.wait(5.0)
        self._log.close()


def _pin(pid: int, cpus: set[int]) -> None:
    """Pin every thread of process ``pid`` to ``cpus`` (threads it starts later inherit)."""
    for task in Path(f'/proc/{pid}/task').glob('*'):
        with contextlib.suppress(OSError):
            os.sched_setaffinity(int(task.name), cpus)


def _domain_id(salt: int) -> str:
    # 0..101 are safe on Linux; stay clear of 0 (the default) and of small numbers people use
    return str(20 + (os.getpid() + salt) % 80)


def _analyse_probe(result: RunResult, npz: Path) -> None:
    data = np.load(npz)
    topics = [str(t) for t in data['topics']]
    rec = data['records']
    first: dict[str, dict[int, int]] = {}
    for i, topic in enumerate(topics):
        sel = rec[rec[:, 0] == i]
        stamps, idx = np.unique(sel[:, 1], return_index=True)
        result.received[topic] = len(stamps)
        first[topic] = dict(zip(stamps.tolist(), sel[idx, 2].tolist(), strict=True))
    src, dst = first[SENSORS_WHEEL_ANGLES], first[ESTIMATES_SLOPE]
    common = sorted(set(src) & set(dst))
    if common:
        lat = np.array([dst[s] - src[s] for s in common], dtype=float) / 1e6
        result.latency_ms = {
            'p50': float(np.percentile(lat, 50)),
            'p99': float(np.percentile(lat, 99)),
            'max': float(lat.max()),
            'n': float(len(lat)),
            'negative': float(np.mean(lat < 0.0)),
        }
    if src and dst:
        # When the probe itself falls behind, it reads wheel angles late and the difference
        # above can even turn negative. Lateness against the real-time schedule does not
        # depend on the probe's angle queue: the fastest angle delivery fixes the schedule
        # (stamp + offset); a slope estimate's lateness is its reception minus that.
        offset = min(t - s for s, t in src.items())
        late = np.array([t - s - offset for s, t in dst.items()], dtype=float) / 1e6
        result.latency_ms |= {
            'sched_p50': float(np.percentile(late, 50)),
            'sched_p99': float(np.percentile(late, 99)),
            'sched_max': float(late.max()),
        }


def run_graph(
    rate_hz: float,
    duration_s: float,
    *,
    recorder: bool,
    publish_truth: bool,
    work: Path,
    executor: str = '',
    salt: int = 0,
    timeout_s: float | None = None,
    layout: str = 'nodes',
) -> RunResult:
    """Run the graph once and measure it.

    Args:
        rate_hz: sensor rate [Hz].
        duration_s: simulated time [s], run at real-time factor 1.0.
        recorder: also run recorder_node (bag in `work`).
        publish_truth: the simulator also publishes /vd/truth/*.
        work: scratch folder (logs, probe file, bag).
        executor: value of VD_ROS_EXECUTOR for the estimation nodes ('' = default).
        salt: varies the ROS_DOMAIN_ID between runs.
        timeout_s: give up on the simulator after this wall time [s] (default 3x duration
            + 30 s).
        layout: 'nodes' (observer, estimator and alerts nodes) or 'pipeline' (pipeline_node).
    """
    result = RunResult(rate_hz, duration_s, recorder)
    work.mkdir(parents=True, exist_ok=True)
    logs = work / 'logs'
    env = dict(os.environ)
    env['ROS_DOMAIN_ID'] = _domain_id(salt)
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    env.pop('VD_ROS_EXECUTOR', None)
    scenario = _scenario_file(work, duration_s)
    npz = work / 'probe.npz'
    bag = work / 'bag'
    timeout = timeout_s if timeout_s is not None else 3.0 * duration_s + 30.0
    with GraphLauncher(logs, env) as graph:
        probe = _Probe(npz, logs, env)
        try:
            node_env = dict(graph.env)
            if executor:
                node_env['VD_ROS_EXECUTOR'] = executor
            ready: list[tuple[NodeProcess, str]] = []
            if recorder:
                rec = graph.start(
                    NodeSpec('vd_observer_node', 'recorder_node', 'recorder', {'output': str(bag)})
                )
                ready.append((rec, 'recording to'))
            params: dict[str, object] = {}
            for executable, name, text in LAYOUTS[layout]:
                proc = NodeProcess(
                    NodeSpec('vd_observer_node', executable, name, dict(params)), logs, node_env
                )
                graph.nodes.append(proc)
                ready.append((proc, text))
            alive = [p.popen for p, _ in ready] + [probe.popen]
            checks = [(p.log_path, t) for p, t in ready] + [(probe.log_path, 'probe ready')]
            for log, text in checks:
                if not _wait_for(log, text, alive, 30.0):
                    result.error = (
                        f'{log.stem} not ready: {log.read_text(errors="replace")[-800:]}'
                    )
                    return result
            time.sleep(1.5)  # discovery between the waiting nodes
            sim = graph.start(
                NodeSpec(
                    'vd_sim_node',
                    'sim_node',
                    'sim',
                    {
                        'scenario_file': str(scenario),
                        'rate_hz': float(rate_hz),
                        'real_time_factor': 1.0,
                        'publish_truth': publish_truth,
                        'start_delay': 1.0,
                        # one progress line, at the first sample: the start of the window
                        'progress_period': 10.0 * duration_s,
                    },
                )
            )
            others = {n.spec.name: n.popen.pid for n in graph.nodes if n is not sim}
            others['probe'] = probe.popen.pid
            cpus = sorted(os.sched_getaffinity(0))
            if layout in PINNED:
                _pin(sim.popen.pid, set(cpus[:-1]))
            if not _wait_for(sim.log_path, 'progress t=0.0', [sim.popen], 60.0):
                result.error = f'sim did not start: {sim.log_tail(800)}'
                return result
            if layout in PINNED:  # before the first sample (the sim's start_delay)
                for name, pid in [*others.items(), ('sim', sim.popen.pid)]:
                    mine = name in {n for _, n, _ in LAYOUTS[layout]}
                    _pin(pid, {cpus[-1]} if mine else set(cpus[:-1]))
            t0 = time.monotonic()
            start = {name: proc_stats(pid) for name, pid in others.items()}
            sim_start = proc_stats(sim.popen.pid)
            sim_last = sim_start
            while sim.running and time.monotonic() - t0 < timeout:
                time.sleep(0.2)
                sample = proc_stats(sim.popen.pid)
                if sample is not None and sample.rss_mib == sample.rss_mib:  # not a zombie
                    sim_last = sample
            t1 = time.monotonic()
            end = {name: proc_stats(pid) for name, pid in others.items()}
            if sim.running:
                result.error = f'simulator still running after {timeout:g} s'
            window = t1 - t0
            for name in others:
                a, b = start[name], end[name]
                if a is not None and b is not None:
                    result.cpu_pct[name] = 100.0 * (b.cpu_s - a.cpu_s) / window
                    result.rss_mib[name] = b.rss_mib
                    result.hwm_mib[name] = b.hwm_mib
            if sim_start is not None and sim_last is not None:
                result.cpu_pct['sim'] = 100.0 * (sim_last.cpu_s - sim_start.cpu_s) / window
                result.rss_mib['sim'] = sim_last.rss_mib
                result.hwm_mib['sim'] = sim_last.hwm_mib
            found = _FINISHED.findall(sim.log_tail(4000))
            if found:
                n, simulated, wall = found[-1]
                result.published = int(n)
                result.achieved_rtf = float(simulated) / float(wall)
            elif not result.error:
                result.error = f'simulator did not finish: {sim.log_tail(800)}'
            time.sleep(2.0)  # the last samples through observer and estimator
        finally:
            probe.stop()
            result.exit_codes = graph.stop_all(timeout_s=10.0)
            result.exit_codes['probe'] = int(probe.popen.returncode)
    if npz.exists():
        _analyse_probe(result, npz)
    elif not result.error:
        result.error = f'probe wrote nothing: {probe.log_path.read_text(errors="replace")[-800:]}'
    if recorder and bag.exists():
        from vd_observer_node.bag import BagReader

        with contextlib.suppress(Exception):
            result.in_bag = {
                name: info.message_count for name, info in BagReader(bag).topics.items()
            }
    return result


def _median(values: Sequence[float]) -> float:
    clean = [v for v in values if v == v]
    return statistics.median(clean) if clean else float('nan')


def _print_runs(title: str, runs: Sequence[RunResult]) -> None:
    print(f'\n== {title}: {len(runs)} run(s); medians over runs (min..max)')
    for r in runs:
        if r.error:
            print(f'  run error: {r.error}')
    good = [r for r in runs if r.published > 0]
    if not good:
        return

    def spread(values: Sequence[float], fmt: str) -> str:
        return (
            f'{format(_median(values), fmt)} ({format(min(values), fmt)}..'
            f'{format(max(values), fmt)})'
        )

    print(f'  samples published     : {spread([r.published for r in good], ".0f")}')
    print(f'  achieved real-time    : {spread([r.achieved_rtf for r in good], ".3f")}')
    print(
        '  lost (published - received by the probe' + (', - in bag)' if good[0].recorder else ')')
    )
    for topic in WATCHED:
        lost = [r.lost().get(topic, r.published) for r in good]
        line = f'    {topic:28s} {spread(lost, ".0f")}'
        if good[0].recorder:
            bag_lost = [r.published - r.in_bag.get(topic, 0) for r in good]
            line += f'   bag: {spread(bag_lost, ".0f")}'
        print(line)
    shares = ', '.join(
        f'{100.0 * (1.0 - r.lost().get(ESTIMATES_SLOPE, r.published) / max(r.published, 1)):.1f}'
        for r in good
    )
    print(f'  slope estimates delivered per run: {shares} % (issue 39: >= 99 % in every run)')
    if good[0].recorder:
        others = sorted({t for r in good for t in r.in_bag} - set(WATCHED))
        for topic in others:
            counts = [r.in_bag.get(topic, 0) for r in good]
            print(f'    bag {topic:24s} {spread(counts, ".0f")} messages')
    lat = [r for r in good if r.latency_ms]
    if lat:
        for key in ('p50', 'p99', 'max'):
            print(
                f'  latency {key:3s} angles->slope: '
                f'{spread([r.latency_ms[key] for r in lat], ".2f")} ms'
            )
        negative = [100.0 * r.latency_ms.get('negative', float('nan')) for r in lat]
        print(f'  share of negative angles->slope (probe behind): {spread(negative, ".1f")} %')
        for key in ('p50', 'p99', 'max'):
            print(
                f'  slope lateness vs real-time schedule {key}: '
                f'{spread([r.latency_ms["sched_" + key] for r in lat], ".2f")} ms'
            )
    names = [
        n
        for n in ('sim', 'observer', 'estimator', 'alerts', 'pipeline', 'recorder', 'probe')
        if n in good[0].cpu_pct
    ]
    for name in names:
        cpu = [r.cpu_pct.get(name, float('nan')) for r in good]
        rss = [r.rss_mib.get(name, float('nan')) for r in good]
        hwm = [r.hwm_mib.get(name, float('nan')) for r in good]
        print(
            f'  {name:9s} CPU {spread(cpu, ".0f")} % of one core, RSS {_median(rss):.0f} MiB '
            f'(peak {_median(hwm):.0f})'
        )
    codes = {k: v for r in good for k, v in r.exit_codes.items() if v != 0}
    if codes:
        print(f'  non-zero exit codes: {codes}')


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark, print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--quick', action='store_true', help='smoke run: 5 s runs, short sweep')
    parser.add_argument('--repeat', type=int, default=1, help='runs per configuration')
    parser.add_argument('--duration', type=float, default=60.0, help='simulated s per main run')
    parser.add_argument('--rate', type=float, default=1000.0, help='sensor rate of main runs')
    parser.add_argument(
        '--sweep', type=float, nargs='*', default=[100.0, 200.0, 500.0, 1000.0], help='[Hz]'
    )
    parser.add_argument('--sweep-duration', type=float, default=5.0, help='[s] per sweep run')
    parser.add_argument('--no-truth', action='store_true', help=f'sim without {TRUTH_NAMESPACE}*')
    parser.add_argument(
        '--skip', nargs='*', default=[], choices=['main', 'rec', 'sweep', 'events']
    )
    parser.add_argument('--keep', type=Path, default=None, help='keep logs/bags in this folder')
    parser.add_argument(
        '--layouts',
        nargs='*',
        default=['nodes', 'pipeline', 'pipeline-pinned'],
        choices=sorted(LAYOUTS),
    )
    args = parser.parse_args(argv)
    if args.quick:
        args.duration, args.sweep_duration, args.sweep = 5.0, 3.0, [200.0, 1000.0]
    truth = not args.no_truth
    load = os.getloadavg()[0]
    print(
        f'live graph: {args.duration:g} s of paper_table1 at {args.rate:g} Hz, real-time '
        f'factor 1.0, truth {"on" if truth else "off"}; {os.cpu_count()} cores, load (1 min) '
        f'{load:.2f}',
        flush=True,
    )
    with tempfile.TemporaryDirectory(prefix='vd_bench_live_') as tmp:
        base = args.keep or Path(tmp)
        salt = 0

        def run(tag: str, rate: float, duration: float, **kw: object) -> RunResult:
            nonlocal salt
            salt += 1
            return run_graph(rate, duration, work=base / f'{tag}_{salt}', salt=salt, **kw)  # type: ignore[arg-type]

        for layout in args.layouts:
            label = layout
            if 'main' not in args.skip:
                runs = [
                    run(
                        f'main_{layout}',
                        args.rate,
                        args.duration,
                        recorder=False,
                        publish_truth=truth,
                        layout=layout,
                    )
                    for _ in range(args.repeat)
                ]
                _print_runs(f'sim + {label} at {args.rate:g} Hz', runs)
            if 'rec' not in args.skip:
                runs = [
                    run(
                        f'rec_{layout}',
                        args.rate,
                        args.duration,
                        recorder=True,
                        publish_truth=truth,
                        layout=layout,
                    )
                    for _ in range(args.repeat)
                ]
                _print_runs(f'sim + {label} + recorder at {args.rate:g} Hz', runs)
        if 'sweep' not in args.skip:
            print(
                f'\n== rate sweep, {args.sweep_duration:g} s runs, observer + estimator + alerts',
                flush=True,
            )
            best = 0.0
            for rate in args.sweep:
                r = run('sweep', rate, args.sweep_duration, recorder=False, publish_truth=truth)
                lost = max(r.lost().values(), default=-1)
                p99 = r.latency_ms.get('p99', float('nan'))
                p50 = r.latency_ms.get('p50', float('nan'))
                print(
                    f'  {rate:6g} Hz: published {r.published}, worst loss {lost}, achieved '
                    f'real time {r.achieved_rtf:.3f}, latency p50 {p50:.1f} p99 {p99:.1f} ms, '
                    f'CPU sim '
                    f'{r.cpu_pct.get("sim", float("nan")):.0f} % obs '
                    f'{r.cpu_pct.get("observer", float("nan")):.0f} % est '
                    f'{r.cpu_pct.get("estimator", float("nan")):.0f} %'
                    + (f'  ERROR {r.error}' if r.error else ''),
                    flush=True,
                )
                if r.lossless():
                    best = max(best, rate)
            print(f'  highest rate without loss at real time: {best:g} Hz')
        if 'events' not in args.skip:
            print(
                '\n== VD_ROS_EXECUTOR=single_threaded (the old executor) on the estimation nodes '
                f'({args.rate:g} Hz, 5 s)',
                flush=True,
            )
            r = run(
                'events',
                args.rate,
                5.0,
                recorder=False,
                publish_truth=truth,
                executor='single_threaded',
                timeout_s=40.0,
            )
            print(
                f'  published {r.published}, received by the probe: '
                f'{ {t.split("/")[-1]: n for t, n in r.received.items()} }'
            )
            print(f'  latency: { {k: round(v, 2) for k, v in r.latency_ms.items()} } ms')
            print(f'  exit codes after SIGINT (-9 = needed SIGKILL): {r.exit_codes}')
            if r.error:
                print(f'  error: {r.error}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
