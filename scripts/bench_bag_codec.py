#!/usr/bin/env python3
"""vd's bag codec against the libraries, side by side in one run; prints, asserts nothing.

    python scripts/bench_bag_codec.py [--messages 20000] [--duration 10] [--repeat 3]

1. CDR: `cdr_batch.decode_batch` / `encode_batch` (one numpy pass per batch) against rosbags'
   per-message `Typestore.deserialize_cdr` / `serialize_cdr`, per sensor and estimate type.
2. Reading a bag written by vd (11 topics at 1 kHz, zstd chunks), all messages as raw bytes:
   vd `BagReader.raw_messages` and `topic_arrays` against `mcap`'s indexed reader and
   `rosbags.rosbag2.Reader` (both as the tests use them, without decoding).
3. Writing the same messages to a zstd-chunked MCAP: vd `BagWriter.write` (per message) and
   `write_interleaved` (batch) against `mcap.writer.Writer` and `rosbags.rosbag2.Writer`.

Every figure is the best of ``--repeat`` runs (wall and this process's CPU time); the load
average is printed before and after, since the 2 cores may be shared.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'src' / 'vd_observer_node'))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'src' / 'vd_sim_node'))

from bench_replay import _demo_stream
from vd_observer_node.bag import BagReader, BagWriter
from vd_observer_node.bag.cdr_batch import decode_batch, encode_batch, flat_fields
from vd_observer_node.bag.typestore import message_definition, vd_typestore

CODEC_TYPES = (
    'vd_msgs/msg/WheelAngles',
    'geometry_msgs/msg/TwistStamped',
    'vd_msgs/msg/WheelTorques',
    'vd_msgs/msg/WheelStates',
    'vd_msgs/msg/TireForces',
    'vd_msgs/msg/Slope',
)


def loadavg() -> str:
    return Path('/proc/loadavg').read_text().split(' ')[0]


def best(fn: Callable[[], object], repeat: int) -> tuple[float, float]:
    """(wall, CPU) seconds of the fastest of ``repeat`` calls."""
    walls, cpus = [], []
    for _ in range(repeat):
        wall, cpu = time.perf_counter(), time.process_time()
        fn()
        walls.append(time.perf_counter() - wall)
        cpus.append(time.process_time() - cpu)
    return min(walls), min(cpus)


def _batch(msgtype: str, n: int) -> list[bytes]:
    rng = np.random.default_rng(1)
    stamps = np.arange(n, dtype=np.int64) * 1_000_000
    values = {}
    for f in flat_fields(msgtype):
        shape = (n, f.count) if f.count > 1 else (n,)
        if np.dtype(f.dtype).kind == 'f':
            values[f.name] = rng.normal(size=shape)
        else:
            values[f.name] = np.ones(shape, dtype=f.dtype)
    return encode_batch(msgtype, stamps, 'base_link', values)


def _each(fn: Callable[[Any, str], Any], items: list[Any], msgtype: str) -> list[Any]:
    """rosbags' way: one call per message."""
    return [fn(item, msgtype) for item in items]


def bench_codec(n: int, repeat: int) -> None:
    store = vd_typestore()
    print(f'== CDR, {n} messages per type: us per message (CPU), best of {repeat}')
    print(
        f'  {"type":34} {"decode vd":>10} {"rosbags":>9} {"ratio":>6}'
        f'   {"encode vd":>10} {"rosbags":>9} {"ratio":>6}'
    )
    for msgtype in CODEC_TYPES:
        datas = _batch(msgtype, n)
        msgs = [store.deserialize_cdr(d, msgtype) for d in datas]
        fields = decode_batch(msgtype, datas)
        stamps = np.asarray(fields.stamp_ns, dtype=np.int64)
        values = dict(fields.values)
        _, dec_vd = best(partial(decode_batch, msgtype, datas), repeat)
        _, dec_rb = best(partial(_each, store.deserialize_cdr, datas, msgtype), repeat)
        _, enc_vd = best(partial(encode_batch, msgtype, stamps, 'base_link', values), repeat)
        _, enc_rb = best(partial(_each, store.serialize_cdr, msgs, msgtype), repeat)
        print(
            f'  {msgtype:34} {dec_vd / n * 1e6:10.3f} {dec_rb / n * 1e6:9.2f} '
            f'{dec_rb / dec_vd:5.0f}x   {enc_vd / n * 1e6:10.3f} {enc_rb / n * 1e6:9.2f} '
            f'{enc_rb / enc_vd:5.0f}x'
        )


def bench_read(path: Path, repeat: int) -> None:
    from mcap.reader import make_reader
    from rosbags.rosbag2 import Reader as RosbagsReader

    mcap_file = next(path.glob('*.mcap'))

    def vd_raw() -> int:
        return sum(1 for _ in BagReader(path).raw_messages())

    def vd_arrays() -> int:
        return sum(len(a.datas) for a in BagReader(path).topic_arrays().values())

    def mcap_lib() -> int:
        with mcap_file.open('rb') as f:
            return sum(1 for _ in make_reader(f).iter_messages())

    def rosbags_lib() -> int:
        with RosbagsReader(path) as reader:
            return sum(1 for _ in reader.messages())

    count = vd_raw()
    assert count == vd_arrays() == mcap_lib() == rosbags_lib()
    print(f'== reading {count} messages (raw bytes), best of {repeat}')
    base = None
    for name, fn in (
        ('vd BagReader.topic_arrays', vd_arrays),
        ('vd BagReader.raw_messages', vd_raw),
        ('mcap make_reader.iter_messages', mcap_lib),
        ('rosbags rosbag2.Reader.messages', rosbags_lib),
    ):
        wall, cpu = best(fn, repeat)
        base = base or cpu
        print(
            f'  {name:34} {wall:6.3f} s wall {cpu:6.3f} s CPU  {count / cpu / 1e3:7.0f} k msg/s '
            f'({cpu / base:4.1f}x the CPU of topic_arrays)'
        )


def bench_write(folder: Path, stream: dict[str, tuple[str, list[bytes]]], repeat: int) -> None:
    from mcap.writer import CompressionType
    from mcap.writer import Writer as McapWriter
    from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin
    from rosbags.rosbag2 import Writer as RosbagsWriter

    n = len(next(iter(stream.values()))[1])
    topics = list(stream)
    period = 1_000_000
    order = [(t, k) for k in range(n) for t in topics]  # interleaved, as recorded
    count = len(order)
    runs = iter(range(10**6))

    def vd_write() -> None:
        with BagWriter(folder / f'vd_{next(runs)}') as writer:
            for topic, (msgtype, _) in stream.items():
                writer.add_topic(topic, msgtype)
            for topic, k in order:
                writer.write(topic, stream[topic][1][k], k * period)

    which = np.tile(np.arange(len(topics)), n)
    datas = [stream[t][1][k] for t, k in order]
    times = np.repeat(np.arange(n, dtype=np.int64) * period, len(topics))

    def vd_interleaved() -> None:
        with BagWriter(folder / f'vdi_{next(runs)}') as writer:
            for topic, (msgtype, _) in stream.items():
                writer.add_topic(topic, msgtype)
            writer.write_interleaved(topics, which, datas, times)

    def mcap_write() -> None:
        with (folder / f'mcap_{next(runs)}.mcap').open('wb') as f:
            writer = McapWriter(f, compression=CompressionType.ZSTD)
            writer.start(profile='ros2', library='bench')
            ids = {}
            for topic, (msgtype, _) in stream.items():
                schema = writer.register_schema(
                    msgtype, 'ros2msg', message_definition(msgtype).encode()
                )
                ids[topic] = writer.register_channel(topic, 'cdr', schema)
            for topic, k in order:
                writer.add_message(ids[topic], k * period, stream[topic][1][k], k * period)
            writer.finish()

    def rosbags_write() -> None:
        writer = RosbagsWriter(
            folder / f'rb_{next(runs)}', version=9, storage_plugin=StoragePlugin.MCAP
        )
        writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        with writer:
            conns = {
                topic: writer.add_connection(topic, msgtype, typestore=vd_typestore())
                for topic, (msgtype, _) in stream.items()
            }
            for topic, k in order:
                writer.write(conns[topic], k * period, stream[topic][1][k])

    print(f'== writing {count} messages (zstd chunks), best of {repeat}')
    base = None
    for name, fn in (
        ('vd BagWriter.write_interleaved', vd_interleaved),
        ('vd BagWriter.write', vd_write),
        ('mcap Writer.add_message', mcap_write),
        ('rosbags rosbag2.Writer.write', rosbags_write),
    ):
        wall, cpu = best(fn, repeat)
        base = base or cpu
        print(
            f'  {name:34} {wall:6.3f} s wall {cpu:6.3f} s CPU  {count / cpu / 1e3:7.0f} k msg/s '
            f'({cpu / base:4.1f}x the CPU of write_interleaved)'
        )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--messages', type=int, default=20000, help='per type, CDR part')
    parser.add_argument('--duration', type=float, default=10.0, help='bag seconds at 1 kHz')
    parser.add_argument('--repeat', type=int, default=3)
    args = parser.parse_args()
    print(f'load average (1 min) at start: {loadavg()}')
    bench_codec(args.messages, args.repeat)
    stream = _demo_stream(int(args.duration * 1000))
    with tempfile.TemporaryDirectory(prefix='vd-codec-') as tmp:
        folder = Path(tmp)
        with BagWriter(folder / 'bag') as writer:
            for topic, (msgtype, _) in stream.items():
                writer.add_topic(topic, msgtype)
            for k in range(len(next(iter(stream.values()))[1])):
                for topic, (_, datas) in stream.items():
                    writer.write(topic, datas[k], k * 1_000_000)
        bench_read(folder / 'bag', args.repeat)
        bench_write(folder, stream, args.repeat)
    print(f'load average (1 min) at end: {loadavg()}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
