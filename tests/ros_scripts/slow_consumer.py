"""Test helper: a consumer slower than the simulator, which reports its progress.

    python slow_consumer.py IN_TOPIC=pkg.msg/Type OUT_TOPIC DELAY_S LAST_STAMP_NS TIMEOUT_S

Takes each message of IN_TOPIC (raw, reliable, depth 1000 like vd's nodes), spends DELAY_S
on it (a sleep: a node that cannot keep up), then publishes a std_msgs/Header with its stamp
on OUT_TOPIC, the progress a simulator in lockstep follows. Prints 'SUBSCRIBED' once
matched, and exits 0 after the message stamped LAST_STAMP_NS (or 1 after TIMEOUT_S) with
'GOT N FIRST_NS LAST_NS MAX_GAP_NS': how many distinct stamps it took and the largest step
between two consecutive ones (one sample period when nothing was lost).
"""

from __future__ import annotations

import importlib
import itertools
import struct
import sys
import time

import rclpy
from rclpy.experimental import EventsExecutor
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import Header


def main() -> int:
    in_topic, kind = sys.argv[1].split('=', 1)
    out_topic = sys.argv[2]
    delay = float(sys.argv[3])
    last = int(sys.argv[4])
    timeout = float(sys.argv[5])
    rclpy.init()
    node = rclpy.create_node('vd_test_slow_consumer')
    qos = QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE
    )
    module, name = kind.split('/')
    cls = getattr(importlib.import_module(module), name)
    pub = node.create_publisher(Header, out_topic, qos)
    stamps: list[int] = []

    def on_message(data: bytes) -> None:
        sec, nanosec = struct.unpack_from('<iI', data, 4)
        time.sleep(delay)
        stamps.append(sec * 1_000_000_000 + nanosec)
        msg = Header()
        msg.stamp.sec, msg.stamp.nanosec = sec, nanosec
        pub.publish(msg)

    sub = node.create_subscription(cls, in_topic, on_message, qos, raw=True)
    executor = EventsExecutor()
    executor.add_node(node)
    deadline = time.monotonic() + timeout
    announced = False
    code = 1
    while time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
        if not announced and sub.get_publisher_count() > 0:
            print('SUBSCRIBED', flush=True)
            announced = True
        if stamps and stamps[-1] >= last:
            code = 0
            break
    unique = sorted(set(stamps))
    gap = max((b - a for a, b in itertools.pairwise(unique)), default=0)
    print(f'GOT {len(unique)} {unique[0] if unique else -1} {unique[-1] if unique else -1} {gap}')
    executor.shutdown()
    node.destroy_node()
    rclpy.try_shutdown()
    return code


if __name__ == '__main__':
    sys.exit(main())
