#!/usr/bin/env python3
"""ROS probe for bench_live_graph.py: wall-clock reception time of every stamped message.

Subscribes (reliable, KEEP_LAST 1000) to the given topics as RAW serialized messages, so a
message costs the probe no deserialization: every vd stream starts with a std_msgs/Header,
whose stamp sits right after the 4-byte CDR encapsulation header (int32 sec, uint32 nanosec,
little endian). For each message it keeps (topic index, stamp [ns], reception time
[ns, CLOCK_MONOTONIC]). On SIGINT it writes them to an .npz file and exits.

Usage (inside env.sh):
    python scripts/latency_probe.py --out probe.npz /vd/sensors/wheel_angles ...

It prints 'probe ready' once every subscription exists.
"""

from __future__ import annotations

import argparse
import struct
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from vd_common.topics import (
    ESTIMATES_ALERTS,
    ESTIMATES_FRICTION,
    ESTIMATES_FRICTION_POTENTIAL,
    ESTIMATES_RESISTANCES,
    ESTIMATES_SLOPE,
    ESTIMATES_TIRE_FORCES,
    OBSERVER_BODY_ACCEL,
    OBSERVER_BODY_VELOCITY,
    OBSERVER_WHEEL_STATES,
    SENSORS_BODY_VELOCITY,
    SENSORS_WHEEL_ANGLES,
    SENSORS_WHEEL_TORQUES,
)

__all__ = ['TOPIC_TYPES', 'main', 'stamp_from_cdr']

# topic -> (module, type) of every stream the benchmark may watch
TOPIC_TYPES: dict[str, tuple[str, str]] = {
    SENSORS_WHEEL_ANGLES: ('vd_msgs.msg', 'WheelAngles'),
    SENSORS_BODY_VELOCITY: ('geometry_msgs.msg', 'TwistStamped'),
    SENSORS_WHEEL_TORQUES: ('vd_msgs.msg', 'WheelTorques'),
    OBSERVER_WHEEL_STATES: ('vd_msgs.msg', 'WheelStates'),
    OBSERVER_BODY_ACCEL: ('geometry_msgs.msg', 'AccelStamped'),
    OBSERVER_BODY_VELOCITY: ('geometry_msgs.msg', 'TwistStamped'),
    ESTIMATES_TIRE_FORCES: ('vd_msgs.msg', 'TireForces'),
    ESTIMATES_FRICTION: ('vd_msgs.msg', 'Friction'),
    ESTIMATES_RESISTANCES: ('vd_msgs.msg', 'Resistances'),
    ESTIMATES_SLOPE: ('vd_msgs.msg', 'Slope'),
    ESTIMATES_ALERTS: ('vd_msgs.msg', 'Alerts'),
    ESTIMATES_FRICTION_POTENTIAL: ('vd_msgs.msg', 'FrictionPotential'),
}

_STAMP = struct.Struct('<iI')


def stamp_from_cdr(data: bytes) -> int:
    """Header stamp [ns] of a serialized (little-endian CDR) message that starts with a Header."""
    sec, nanosec = _STAMP.unpack_from(data, 4)
    return int(sec) * 1_000_000_000 + int(nanosec)


def main(argv: list[str] | None = None) -> int:
    """Run the probe until SIGINT; write the records; return the exit code."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--out', type=Path, required=True, help='.npz output file')
    parser.add_argument('topics', nargs='+', help='topics to watch')
    args = parser.parse_args(argv)
    unknown = [t for t in args.topics if t not in TOPIC_TYPES]
    if unknown:
        print(f'error: unknown topics {unknown}', file=sys.stderr)
        return 2

    import importlib
    import signal

    import rclpy
    from rclpy.experimental import EventsExecutor
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from rclpy.signals import SignalHandlerOptions

    qos = QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE
    )
    records: list[tuple[int, int, int]] = []
    append = records.append
    clock = time.monotonic_ns

    # Our own SIGINT/SIGTERM handlers: a flag the spin loop checks, no shutdown race. The
    # EventsExecutor costs ~2 us per raw message against ~50 us for the SingleThreadedExecutor
    # (bench_message_path.py): the probe must not load the machine it measures.
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    stop = [False]

    def on_signal(*_: object) -> None:
        stop[0] = True

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    node = rclpy.create_node('vd_latency_probe')

    def callback(index: int) -> Any:
        def on_message(data: bytes) -> None:
            append((index, stamp_from_cdr(data), clock()))

        return on_message

    for i, topic in enumerate(args.topics):
        module, name = TOPIC_TYPES[topic]
        kind = getattr(importlib.import_module(module), name)
        node.create_subscription(kind, topic, callback(i), qos, raw=True)
    print('probe ready', flush=True)
    executor = EventsExecutor()
    executor.add_node(node)
    try:
        while not stop[0]:
            executor.spin_once(timeout_sec=0.1)
    finally:
        arr = np.array(records, dtype=np.int64).reshape(-1, 3)
        np.savez(args.out, topics=np.array(args.topics), records=arr)
        print(f'probe wrote {len(arr)} records to {args.out}', flush=True)
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
