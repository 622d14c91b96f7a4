"""Test helper: exit 0 once every given topic has delivered a message stamped >= a stamp.

    python wait_for_stamp.py STAMP_NS TIMEOUT_S TOPIC=pkg.msg/Type [TOPIC=pkg.msg/Type ...]

Subscribes raw (reliable, depth 1000) and reads header.stamp at byte 4 of the CDR, so it
never decodes a message. Prints 'SUBSCRIBED' once each subscription has matched a publisher,
'REACHED' and exits 0 when every topic got there, exits 1 after TIMEOUT_S. The graph tests
wait on it instead of sleeping until the last sample has gone through the nodes.
"""

from __future__ import annotations

import importlib
import struct
import sys
import time

import rclpy
from rclpy.experimental import EventsExecutor
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy


def main() -> int:
    target = int(sys.argv[1])
    timeout = float(sys.argv[2])
    topics = dict(arg.split('=', 1) for arg in sys.argv[3:])
    rclpy.init()
    node = rclpy.create_node('vd_test_wait_for_stamp')
    qos = QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE
    )
    reached: set[str] = set()
    subs = []
    for topic, kind in topics.items():
        module, name = kind.split('/')
        cls = getattr(importlib.import_module(module), name)

        def on_message(data: bytes, topic: str = topic) -> None:
            sec, nanosec = struct.unpack_from('<iI', data, 4)
            if sec * 1_000_000_000 + nanosec >= target:
                reached.add(topic)

        subs.append(node.create_subscription(cls, topic, on_message, qos, raw=True))
    executor = EventsExecutor()
    executor.add_node(node)
    deadline = time.monotonic() + timeout
    announced = False
    code = 1
    while time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
        if not announced and all(s.get_publisher_count() > 0 for s in subs):
            print('SUBSCRIBED', flush=True)
            announced = True
        if len(reached) == len(topics):
            print('REACHED', flush=True)
            code = 0
            break
    executor.shutdown()
    node.destroy_node()
    rclpy.try_shutdown()
    return code


if __name__ == '__main__':
    sys.exit(main())
