"""What one message costs in rclpy, and what the raw path saves (issue 14, message path).

Prints, per message [us] (median of repeated runs, CPU of this one process):

1. decode: rclpy's deserialization to a Python message + numpy, against
   `bag.cdr_message.MessageCodec.decode` of the same CDR bytes;
2. encode: building a message from numpy arrays + rclpy's serialization, against
   `MessageCodec.encode`;
3. publish: `Publisher.publish(msg)` against `Publisher.publish(bytes)` (one subscriber);
4. mapped inputs: `inputs.decode.InputDecoder.decode` of one message of each input type the
   live nodes take through an input mapping (vd's WheelAngles through its struct codec,
   JointState, Odometry and Float64MultiArray through rosbags and the replay's extractors);
5. receive: the executor's cost per delivered message (wait set, take, callback), typed and
   raw subscriptions, SingleThreadedExecutor and the experimental EventsExecutor: K messages
   are published first, then the executor is timed until it has delivered all of them;
6. one stamp of pipeline_node's estimates published as its seven per-quantity messages
   against one vd_msgs/Estimates (``estimate_topics: combined``), raw, CPU per stamp.

Run inside ``. ./env.sh``; takes about 20 s.
"""

from __future__ import annotations

import os
import statistics
import time
from collections.abc import Callable

import numpy as np
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.experimental import EventsExecutor
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from vd_observer_node.bag.cdr_message import MessageCodec

from vd_msgs.msg import WheelAngles, WheelStates

QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST, depth=5000, reliability=ReliabilityPolicy.RELIABLE
)
REPEATS = 5


def per_call_us(fn: Callable[[], object], n: int = 20000) -> float:
    """Median over REPEATS of the mean cost of fn() [us]."""
    runs = []
    for _ in range(REPEATS):
        start = time.perf_counter()
        for _ in range(n):
            fn()
        runs.append((time.perf_counter() - start) / n * 1e6)
    return statistics.median(runs)


def codec_figures() -> None:
    angles = WheelAngles()
    angles.header.frame_id = 'base_link'
    angles.header.stamp.sec = 12
    angles.angle = [1.0, 2.0, 3.0, 4.0]
    raw = serialize_message(angles)
    codec = MessageCodec('vd_msgs/msg/WheelAngles')
    typed = per_call_us(lambda: np.asarray(deserialize_message(raw, WheelAngles).angle))
    lean = per_call_us(lambda: np.array(codec.decode(raw)[2][0]))
    print(f'decode WheelAngles      rclpy {typed:6.2f} us   raw codec {lean:6.2f} us')

    a, w, wd = np.ones(4), np.ones(4) * 2.0, np.ones(4) * 3.0
    states_codec = MessageCodec('vd_msgs/msg/WheelStates', 'base_link')

    def typed_encode() -> bytes:
        msg = WheelStates(header=angles.header)
        msg.angle = a.tolist()
        msg.omega = w.tolist()
        msg.omega_dot = wd.tolist()
        return serialize_message(msg)

    def raw_encode() -> bytes:
        return states_codec.encode(12_000_000_000, [*a.tolist(), *w.tolist(), *wd.tolist()])

    typed = per_call_us(typed_encode)
    lean = per_call_us(raw_encode)
    print(f'encode WheelStates      rclpy {typed:6.2f} us   raw codec {lean:6.2f} us')


def mapped_input_figures() -> None:
    from nav_msgs.msg import Odometry
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray
    from vd_observer_node.inputs.decode import InputDecoder
    from vd_observer_node.inputs.mapping import default_mapping, mapping_from_dict

    joints = ['wheel_fl', 'wheel_fr', 'wheel_rl', 'wheel_rr']
    user = mapping_from_dict(
        {
            'wheel_angles': {
                'topic': '/joint_states',
                'type': 'sensor_msgs/msg/JointState',
                'joints': joints,
                'sign': [1, -1, 1, -1],
            },
            'body_speed': {'topic': '/odom', 'type': 'nav_msgs/msg/Odometry'},
            'wheel_torques': {'topic': '/t', 'type': 'std_msgs/msg/Float64MultiArray'},
        }
    )
    angles = WheelAngles()
    angles.angle = [1.0, 2.0, 3.0, 4.0]
    states = JointState(name=['steering', *joints], position=[0.0, 1.0, 2.0, 3.0, 4.0])
    odom = Odometry()
    odom.twist.twist.linear.x = 10.0
    array = Float64MultiArray(data=[1.0, 2.0, 3.0, 4.0])
    for spec, msg in (
        (default_mapping().wheels, angles),
        (user.wheels, states),
        (user.body_speed, odom),
        (user.wheel_torques, array),
    ):
        decoder = InputDecoder(spec)
        data = serialize_message(msg)
        cost = per_call_us(lambda d=decoder, b=data: d.decode(b, 0), n=5000)
        print(f'mapped input {spec.msgtype:<32} {cost:6.2f} us')


def wait_for_one_subscriber(pub: object, count: int = 1, timeout: float = 10.0) -> None:
    """Wait until the publisher has matched exactly `count` subscriptions (discovery)."""
    deadline = time.monotonic() + timeout
    while pub.get_subscription_count() != count:  # type: ignore[attr-defined]
        if time.monotonic() > deadline:
            raise RuntimeError(f'discovery: {pub.get_subscription_count()} subscribers')  # type: ignore[attr-defined]
        time.sleep(0.01)


def publish_and_receive_figures() -> None:
    node = rclpy.create_node('bench_message_path')
    pub = node.create_publisher(WheelStates, '/bench/states', QOS)
    received = [0]

    def on_msg(_: object) -> None:
        received[0] += 1

    node.create_subscription(WheelStates, '/bench/states', on_msg, QOS)
    msg = WheelStates()
    msg.header.frame_id = 'base_link'
    msg.angle = [1.0, 2.0, 3.0, 4.0]
    data = serialize_message(msg)
    wait_for_one_subscriber(pub)
    n = 2000
    for label, payload in (('message', msg), ('bytes  ', data)):
        runs = []
        for _ in range(REPEATS):
            start = time.perf_counter()
            for _ in range(n):
                pub.publish(payload)
            runs.append((time.perf_counter() - start) / n * 1e6)
        print(f'publish WheelStates as {label}  {statistics.median(runs):6.2f} us')
    node.destroy_node()
    n = 2000
    for raw in (False, True):
        for kind, make in (
            ('single_threaded', SingleThreadedExecutor),
            ('events', EventsExecutor),
        ):
            costs = [receive_cost(raw, make, n, data) for _ in range(3)]
            label = 'raw  ' if raw else 'typed'
            print(f'receive {label} {kind:16s} {statistics.median(costs):6.2f} us CPU per message')


def stamp_layout_figures() -> None:
    """One stamp of pipeline_node's estimates: the seven per-quantity messages against the
    one vd_msgs/Estimates (``estimate_topics``), raw bytes, one subscriber per topic."""
    from geometry_msgs.msg import AccelStamped, TwistStamped
    from vd_observer_node.bag.cdr_message import MessageCodec

    from vd_msgs.msg import Estimates, Friction, Resistances, Slope, TireForces

    node = rclpy.create_node('bench_stamp_layout')
    four = [1.0, 2.0, 3.0, 4.0]
    separate = [
        (WheelStates, 'vd_msgs/msg/WheelStates', [*four, *four, *four]),
        (AccelStamped, 'geometry_msgs/msg/AccelStamped', [0.5, 0, 0, 0, 0, 0]),
        (TwistStamped, 'geometry_msgs/msg/TwistStamped', [10.0, 0, 0, 0, 0, 0]),
        (TireForces, 'vd_msgs/msg/TireForces', [*four, *four, 0]),
        (Friction, 'vd_msgs/msg/Friction', [*four, *four, True, True, True, True, 0]),
        (Resistances, 'vd_msgs/msg/Resistances', [*four, 1.0]),
        (Slope, 'vd_msgs/msg/Slope', [0.01, True, 0, 1]),
    ]
    combined = [*four, *four, *four, 10.0, 0.5, *four, *four, *four, *four]
    combined += [True] * 4 + [*four, 1.0, 0.01, True, 1, 0]
    layouts = {
        'separate (7 messages)': [
            (cls, MessageCodec(name, 'base_link').encode(1, values))
            for cls, name, values in separate
        ],
        'combined (1 message) ': [
            (Estimates, MessageCodec('vd_msgs/msg/Estimates', 'base_link').encode(1, combined))
        ],
    }
    n = 2000
    for label, messages in layouts.items():
        pubs = []
        for k, (cls, data) in enumerate(messages):
            topic = f'/bench/layout_{len(messages)}_{k}'
            pub = node.create_publisher(cls, topic, QOS)
            node.create_subscription(cls, topic, lambda _: None, QOS, raw=True)
            wait_for_one_subscriber(pub)
            pubs.append((pub, data))
        runs = []
        for _ in range(REPEATS):
            start = time.process_time()
            for _ in range(n):
                for pub, data in pubs:
                    pub.publish(data)
            runs.append((time.process_time() - start) / n * 1e6)
        size = sum(len(d) for _, d in messages)
        print(
            f'publish one stamp of estimates, {label}: {statistics.median(runs):6.1f} us CPU '
            f'({size} bytes)'
        )
    node.destroy_node()


def receive_cost(raw: bool, make: Callable[[], object], n: int, data: bytes) -> float:
    """CPU [us] per message the executor spends delivering n queued messages."""
    node = rclpy.create_node('bench_receive')
    received = [0]

    def on_msg(_: object) -> None:
        received[0] += 1

    pub = node.create_publisher(WheelStates, '/bench/receive', QOS)
    node.create_subscription(WheelStates, '/bench/receive', on_msg, QOS, raw=raw)
    wait_for_one_subscriber(pub)
    executor = make()
    executor.add_node(node)  # type: ignore[attr-defined]
    for _ in range(n):
        pub.publish(data)
    start = time.process_time()
    end = time.monotonic() + 10.0
    while received[0] < n and time.monotonic() < end:
        executor.spin_once(timeout_sec=0.1)  # type: ignore[attr-defined]
    cost = (time.process_time() - start) / n * 1e6
    executor.shutdown()  # type: ignore[attr-defined]
    node.destroy_node()
    if received[0] < n:
        raise RuntimeError(f'{make.__name__}: {received[0]} of {n} messages delivered')  # type: ignore[attr-defined]
    return cost


def main() -> None:
    print(f'load average {os.getloadavg()[0]:.2f} (figures taken above ~1.5 are not figures)')
    codec_figures()
    mapped_input_figures()
    rclpy.init()
    try:
        publish_and_receive_figures()
        stamp_layout_figures()
    finally:
        rclpy.try_shutdown()


if __name__ == '__main__':
    main()
