"""Test helper: print what a node publishes, for DURATION_S, one line per message.

    python collect_outputs.py DURATION_S TOPIC=pkg.msg/Type [...]

Each message of a TOPIC: 'MSG TOPIC STAMP_NS FINITE FIRST VALID SOURCE' (FINITE 1 when every
float field is finite; FIRST the repr of its first float field, e.g. a Slope's angle; VALID
its ``valid`` field where that is one bool (a Slope's), SOURCE its ``torque_source`` field,
'-' where the message has none); each /diagnostics
status: 'DIAG NAME LEVEL MESSAGE'. Prints 'SUBSCRIBED' once each TOPIC has a publisher and
exits 0 after DURATION_S.
"""

from __future__ import annotations

import importlib
import math
import sys
import time
from typing import Any

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.experimental import EventsExecutor
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy


def _floats(msg: Any) -> list[float]:
    out: list[float] = []
    for name in msg.get_fields_and_field_types():
        value = getattr(msg, name)
        if isinstance(value, float):
            out.append(value)
        elif hasattr(value, 'get_fields_and_field_types'):
            out += _floats(value)
        elif hasattr(value, '__len__') and not isinstance(value, str | bytes):
            out += [float(v) for v in value if isinstance(v, float)]
    return out


def main() -> int:
    duration = float(sys.argv[1])
    topics = dict(arg.split('=', 1) for arg in sys.argv[2:])
    rclpy.init()
    node = rclpy.create_node('vd_test_collect_outputs')
    qos = QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE
    )
    subs = []
    for topic, kind in topics.items():
        module, name = kind.split('/')
        cls = getattr(importlib.import_module(module), name)

        def on_message(msg: Any, topic: str = topic) -> None:
            stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
            floats = _floats(msg)
            finite = int(all(math.isfinite(v) for v in floats))
            first = repr(floats[0]) if floats else '-'
            valid = getattr(msg, 'valid', None)
            flag = int(valid) if isinstance(valid, bool) else '-'
            source = getattr(msg, 'torque_source', '-')
            print(f'MSG {topic} {stamp} {finite} {first} {flag} {source}', flush=True)

        subs.append(node.create_subscription(cls, topic, on_message, qos))

    def on_diagnostics(msg: DiagnosticArray) -> None:
        for status in msg.status:
            level = int.from_bytes(status.level, 'little')
            print(f'DIAG {status.name} {level} {status.message}', flush=True)

    node.create_subscription(DiagnosticArray, '/diagnostics', on_diagnostics, 10)
    executor = EventsExecutor()
    executor.add_node(node)
    deadline = time.monotonic() + duration
    announced = False
    while time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
        if not announced and all(s.get_publisher_count() > 0 for s in subs):
            print('SUBSCRIBED', flush=True)
            announced = True
    executor.shutdown()
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
