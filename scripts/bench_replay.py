#!/usr/bin/env python3
"""Benchmark of the bag core and offline replay; prints figures, asserts nothing.

    python scripts/bench_replay.py [--duration 20] [--rate 1000]

1. Writer at the demo data rate: 3 sensor + 2 truth + 6 estimate topics at ``--rate`` Hz.
   Prints write throughput, compression and the log-time span of the chunks: a SIGKILL loses
   at most the open chunk, i.e. at most the largest span (and never more than the writer's
   chunk_duration_s of wall time).
2. Reader: raw messages/s and batch decoding messages/s.
3. Offline replay of a synthetic drive: full (real cascade) and bag pipeline only (a null
   cascade), as real-time factor and sensor messages per second (goal: >= 100x, >= 100 k/s),
   from wall time and from process CPU time (meaningful on a loaded machine).
4. The ``vd replay`` command as a user runs it (issue 30's figure): wall clock from the
   process start to its end, Python start-up, imports and loading the cached kernels
   included, on a 1 s bag (the start-up alone) and on bags of ``--command-durations``
   seconds, ``--command-runs`` each, with the load average at the start (figures taken at a
   load above ~1.5 on 2 cores are not figures), beside rosbags' and mcap's raw read of the
   same bag run by run (issue 39's ratio).
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'src' / 'vd_observer_node'))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'src' / 'vd_common'))

from vd_common.topics import (
    SENSORS_BODY_VELOCITY,
    SENSORS_WHEEL_ANGLES,
    SENSORS_WHEEL_TORQUES,
    TRUTH_BODY_ACCEL,
    TRUTH_WHEEL_STATES,
)
from vd_observer_node.bag import BagReader, BagWriter
from vd_observer_node.bag.cdr_batch import decode_batch, encode_batch, flat_fields
from vd_observer_node.bag.writer import DEFAULT_CHUNK_DURATION_S, DEFAULT_CHUNK_SIZE
from vd_observer_node.estimation.cascade import CascadeResult, CascadeSeries
from vd_observer_node.testing.synthetic_bags import write_synthetic_drive_bag
from vd_observer_node.tools.replay import ESTIMATE_TOPICS, replay_bag


def _null_cascade(series: CascadeSeries, *_: object) -> CascadeResult:
    """Zero estimates of the right shapes: isolates the bag pipeline's own cost."""
    t = np.asarray(series.t)
    n = len(t)
    w = np.zeros((n, 4))
    s = np.zeros(n)
    b4 = np.zeros((n, 4), dtype=bool)
    return CascadeResult(t, w, w, s, s, w, w, w, b4, w, w, s, s, s.astype(bool), b4)


def _demo_stream(n: int) -> dict[str, tuple[str, list[bytes]]]:
    rng = np.random.default_rng(0)
    stamps = np.arange(n, dtype=np.int64) * 1_000_000
    topics = {
        SENSORS_WHEEL_ANGLES: 'vd_msgs/msg/WheelAngles',
        SENSORS_BODY_VELOCITY: 'geometry_msgs/msg/TwistStamped',
        SENSORS_WHEEL_TORQUES: 'vd_msgs/msg/WheelTorques',
        TRUTH_WHEEL_STATES: 'vd_msgs/msg/WheelStates',
        TRUTH_BODY_ACCEL: 'geometry_msgs/msg/AccelStamped',
        **ESTIMATE_TOPICS,
    }
    stream = {}
    for topic, msgtype in topics.items():
        values = {}
        for f in flat_fields(msgtype):
            shape = (n, f.count) if f.count > 1 else (n,)
            if np.dtype(f.dtype).kind == 'f':
                # Smooth signals with noise, like real data (compresses like real data).
                base = np.cumsum(rng.normal(0, 0.01, size=shape), axis=0)
                values[f.name] = base + rng.normal(0, 1e-3, size=shape)
            else:
                values[f.name] = np.ones(shape, dtype=f.dtype)
        stream[topic] = (msgtype, encode_batch(msgtype, stamps, 'base_link', values))
    return stream


def bench_writer(folder: Path, seconds: float, rate: float) -> Path:
    n = int(seconds * rate)
    stream = _demo_stream(n)
    period = int(1e9 / rate)
    path = folder / 'demo'
    started = time.perf_counter()
    with BagWriter(path) as writer:
        for topic, (msgtype, _) in stream.items():
            writer.add_topic(topic, msgtype)
        items = list(stream.items())
        for k in range(n):
            for topic, (_, datas) in items:
                writer.write(topic, datas[k], k * period)
    elapsed = time.perf_counter() - started
    count = n * len(stream)
    raw = sum(len(d) for _, datas in stream.values() for d in datas)
    size = (path / 'demo_0.mcap').stat().st_size
    from mcap.reader import make_reader

    with (path / 'demo_0.mcap').open('rb') as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    spans = [(c.message_end_time - c.message_start_time) * 1e-9 for c in summary.chunk_indexes]
    print('== writer (demo data rate)')
    print(
        f'  {len(stream)} topics at {rate:.0f} Hz = {len(stream) * rate:.0f} msg/s, '
        f'{raw / seconds / 1e6:.2f} MB/s of CDR'
    )
    print(
        f'  wrote {count} messages in {elapsed:.2f} s: {count / elapsed:,.0f} msg/s '
        f'({count / elapsed / (len(stream) * rate):.0f}x the demo rate)'
    )
    print(f'  file {size / 1e6:.2f} MB for {raw / 1e6:.2f} MB CDR: zstd ratio {raw / size:.1f}')
    print(
        f'  {len(spans)} chunks (chunk_size {DEFAULT_CHUNK_SIZE // 1024} KiB, '
        f'chunk_duration_s {DEFAULT_CHUNK_DURATION_S}); chunk log-time span '
        f'mean {np.mean(spans):.3f} s, max {np.max(spans):.3f} s'
    )
    print(
        f'  => SIGKILL loses at most {min(np.max(spans) + 1 / rate, DEFAULT_CHUNK_DURATION_S):.3f}'
        f' s of data at this rate (bound: chunk_duration_s = {DEFAULT_CHUNK_DURATION_S} s)'
    )
    return path


def bench_reader(path: Path) -> None:
    reader = BagReader(path)
    started = time.perf_counter()
    count = sum(1 for _ in reader.raw_messages())
    elapsed = time.perf_counter() - started
    arrays = reader.topic_arrays([SENSORS_WHEEL_TORQUES])[SENSORS_WHEEL_TORQUES]
    started = time.perf_counter()
    decode_batch(arrays.msgtype, arrays.datas)
    decode = time.perf_counter() - started
    print('== reader')
    print(f'  raw: {count} messages in {elapsed:.2f} s: {count / elapsed:,.0f} msg/s')
    print(f'  batch decode WheelTorques: {len(arrays.datas) / decode:,.0f} msg/s')


def bench_replay(folder: Path, seconds: float, rate: float) -> None:
    drive = folder / 'drive'
    write_synthetic_drive_bag(drive, seconds, rate)
    print(
        f'== offline replay of a {seconds:.0f} s drive at {rate:.0f} Hz '
        '(3 sensor + 2 truth topics)'
    )
    runs: tuple[tuple[str, dict[str, object]], ...] = (
        (
            'bag pipeline only (null cascade, no alerts)',
            {'cascade': _null_cascade, 'situation': False},
        ),
        ('cascade without alerts', {'situation': False}),
        ('full (cascade + alerts and friction potential)', {}),
    )
    for i, (label, kwargs) in enumerate(runs):
        out = folder / f'out_{i}'
        cpu_start = time.process_time()
        report = replay_bag(drive, out, progress=False, **kwargs)  # type: ignore[arg-type]
        cpu = time.process_time() - cpu_start
        other = report.wall_time_s - report.cascade_time_s - report.situation_time_s
        print(
            f'  {label}: {report.wall_time_s:.2f} s wall (cascade '
            f'{report.cascade_time_s:.2f} s, alerts {report.situation_time_s:.2f} s, rest '
            f'{other:.2f} s): {report.real_time_factor:.0f}x real time, '
            f'{report.samples_per_second:,.0f} sensor msg/s'
        )
        print(
            f'    CPU time {cpu:.2f} s (wall time suffers when the 2 cores are shared): '
            f'{seconds / cpu:.0f}x real time, {report.sensor_messages / cpu:,.0f} sensor msg/s'
        )
        if 'cascade' not in kwargs and kwargs.get('situation', True):
            per_sample = report.cascade_time_s / report.samples * 1e6
            print(
                f'  cascade cost: {per_sample:.0f} us per sample (3 sensor messages); alerts '
                f'and friction potential {report.situation_us_per_sample:.0f} us per sample'
            )


def _children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _peer_reads(bag: Path) -> tuple[float, float]:
    """Seconds rosbags' Reader and mcap's reader take to iterate the bag's raw messages (no
    decoding: the least any tool reading the bag does), in this process."""
    from mcap.reader import make_reader
    from rosbags.rosbag2 import Reader

    start = time.perf_counter()
    with Reader(bag) as reader:
        for _ in reader.messages():
            pass
    rosbags = time.perf_counter() - start
    start = time.perf_counter()
    for path in sorted(bag.glob('*.mcap')):
        with path.open('rb') as f:
            for _ in make_reader(f).iter_messages():
                pass
    return rosbags, time.perf_counter() - start


def bench_command(folder: Path, durations: list[float], rate: float, runs: int) -> None:
    """`vd replay` as a process, start to end, on bags of each duration [s], beside the peers'
    raw reads of the same bag (issue 39: vd replay's wall clock <= rosbags' raw read)."""
    print(f'== the vd replay command, wall clock start to end, {rate:.0f} Hz, {runs} runs each')
    command = [sys.executable, '-m', 'vd_observer_node.tools.cli', 'replay', '--no-progress']
    for seconds in [1.0, *durations]:
        bag = folder / f'command_{seconds:g}'
        write_synthetic_drive_bag(bag, seconds, rate)
        walls, cpus, peers = [], [], []
        load = os.getloadavg()[0]
        for k in range(runs):
            out = folder / f'command_out_{seconds:g}_{k}'
            cpu_start = _children_cpu()
            start = time.perf_counter()
            subprocess.run([*command, str(bag), str(out)], check=True, capture_output=True)
            walls.append(time.perf_counter() - start)
            cpus.append(_children_cpu() - cpu_start)
            peers.append(_peer_reads(bag))
        label = 'start-up (1 s bag)' if seconds == 1.0 else f'{seconds:.0f} s bag'
        print(
            f'  {label}: wall {min(walls):.2f}-{max(walls):.2f} s '
            f'({seconds / max(walls):.0f}-{seconds / min(walls):.0f}x real time), CPU '
            f'{min(cpus):.2f}-{max(cpus):.2f} s, load average {load:.2f} at the start'
        )
        ratios = [w / p[0] for w, p in zip(walls, peers, strict=True)]
        print(
            f'    raw read of the same bag: rosbags {min(p[0] for p in peers):.2f}-'
            f'{max(p[0] for p in peers):.2f} s, mcap {min(p[1] for p in peers):.2f}-'
            f'{max(p[1] for p in peers):.2f} s; vd replay / rosbags (run by run) '
            f'{min(ratios):.2f}-{max(ratios):.2f}x (goal <= 1.0x)'
        )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--duration', type=float, default=20.0, help='data seconds')
    parser.add_argument('--rate', type=float, default=1000.0, help='sensor rate [Hz]')
    parser.add_argument(
        '--command-durations',
        type=float,
        nargs='*',
        default=[120.0, 600.0],
        help='bag lengths [s] for the vd replay command (none: skip section 4)',
    )
    parser.add_argument('--command-runs', type=int, default=3, help='runs per bag')
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix='vd-bench-') as tmp:
        folder = Path(tmp)
        demo = bench_writer(folder, args.duration, args.rate)
        bench_reader(demo)
        bench_replay(folder, args.duration, args.rate)
        if args.command_durations:
            bench_command(folder, args.command_durations, args.rate, args.command_runs)
    return 0


if __name__ == '__main__':
    sys.exit(main())
