"""ROS 2 node: plays topics of a bag with their original timing (live replay).

Publishes the selected topics of an MCAP bag as stored (serialized CDR, no decode), spaced
by their log times divided by ``rate``, and ``/clock`` with the bag's log time, like
``ros2 bag play --clock``. The nodes then recompute the estimates, and the recorder can record
them; the estimating nodes need no ``use_sim_time``, as they stamp their outputs with the
inputs' header stamps and put a headerless input's receipt on the same clock
(`raw_io.ReceiptStamps`); the recorder needs it to log on the bag's time line. With ``loop``
the bag starts over at its end (time jumps backwards; the observers re-initialise); otherwise
the node exits with code 0 when everything has been played.

With an input mapping (``input_mapping`` or ``inputs.*``, docs/input_mapping.md) and ``topics``
left at its default, it plays the mapped input topics of a user's bag as they are (their own
names and types), so that nodes given the same mapping consume them; a mapped topic absent
from the bag or of another type is refused at start, naming the mapping key.
"""

from __future__ import annotations

import time
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.node import Node
from rosgraph_msgs.msg import Clock as ClockMsg
from vd_common.ros.diagnostics import node_status
from vd_common.ros.lifecycle import finish, run_node
from vd_common.ros.parameters import ParamSpec, declare_parameters, log_settings
from vd_common.ros.publishing import (
    PublishRefusals,
    SubscriberGate,
    deliver_pending,
    ros_message_class,
)
from vd_common.ros.qos import CLOCK_QOS, DIAGNOSTICS_QOS, STREAM_QOS
from vd_common.ros.stamps import ns_to_time
from vd_common.topics import SENSORS_BODY_VELOCITY, SENSORS_WHEEL_ANGLES, SENSORS_WHEEL_TORQUES

from vd_observer_node.bag import BagReader
from vd_observer_node.bag.errors import ReplayInputError
from vd_observer_node.inputs.errors import MappingError
from vd_observer_node.inputs.mapping import InputMapping
from vd_observer_node.nodes.node_params import INPUT_PARAMS, take_input_mapping, undeclared_inputs

__all__ = ['SENSOR_TOPICS', 'PlayerNode', 'main']

SENSOR_TOPICS = [
    SENSORS_WHEEL_ANGLES,
    SENSORS_BODY_VELOCITY,
    SENSORS_WHEEL_TORQUES,
]

PARAMS = [
    ParamSpec('bag', '', 'bag folder or .mcap file to play (required)'),
    ParamSpec(
        'topics',
        SENSOR_TOPICS,
        "topics to play (['all'] = every topic of the bag; this default = the input "
        "mapping's topics, vd's own sensor topics without a mapping)",
    ),
    ParamSpec('rate', 1.0, 'playback speed factor (2.0 = twice as fast)', low=1e-3, high=1e4),
    ParamSpec('loop', False, 'start over at the end of the bag'),
    ParamSpec('clock', True, 'publish /clock with the bag log time'),
    ParamSpec('start_delay', 0.5, 'wall time to wait before playing [s]', low=0.0, high=60.0),
    ParamSpec(
        'wait_for_subscribers',
        10.0,
        'wait up to this long [s] until every played topic has a subscriber, so that '
        'nodes started together with the player miss nothing (0 = do not wait)',
        low=0.0,
        high=600.0,
    ),
    ParamSpec(
        'min_subscribers',
        1,
        'subscribers each played topic must have before playing starts (e.g. 2 when a '
        'recorder and an observer both listen)',
        low=1,
        high=1000,
    ),
    *INPUT_PARAMS,
]


def mapped_topics(mapping: InputMapping, available: dict[str, str]) -> list[str]:
    """The input topics the mapping's torque source reads (`InputMapping.used_specs`), and
    the IMU's where it is mapped and recorded (an optional input), checked against the bag's
    topics (name -> type).

    Raises:
        MappingError: a mapped topic is absent from the bag or has another type (one line
            naming the mapping key).
    """
    origin = f'{mapping.source}: ' if mapping.source else ''
    used = mapping.used_specs
    for spec in used:
        msgtype = available.get(spec.topic)
        if msgtype is None:
            raise MappingError(
                f'{origin}{spec.name}.topic: the bag has no topic {spec.topic} '
                f'(it has {", ".join(sorted(available))})'
            )
        if msgtype != spec.msgtype:
            raise MappingError(
                f'{origin}{spec.name}.type: {spec.topic} is {msgtype} in the bag, '
                f'not {spec.msgtype}'
            )
    topics = [spec.topic for spec in used]
    imu = mapping.imu
    if imu is not None and imu.topic in available:
        if available[imu.topic] != imu.msgtype:
            raise MappingError(
                f'{origin}{imu.name}.type: {imu.topic} is {available[imu.topic]} in the bag, '
                f'not {imu.msgtype}'
            )
        topics.append(imu.topic)
    return list(dict.fromkeys(topics))


_PERIOD = 0.002  # [s] publishing timer period


class PlayerNode(Node):
    """Holds the selected messages in memory and publishes each when its time has come."""

    def __init__(self) -> None:
        super().__init__('player_node')
        v = declare_parameters(self, PARAMS)
        log_settings(self, PARAMS, v)
        mapping = take_input_mapping(v, undeclared_inputs(self))
        if not v['bag']:
            raise ReplayInputError("parameter 'bag' is required: -p bag:=PATH")
        reader = BagReader(v['bag'])
        available = reader.topics
        if v['topics'] == SENSOR_TOPICS:  # the default: the mapped inputs, as recorded
            wanted = mapped_topics(mapping, {t: i.msgtype for t, i in available.items()})
        else:
            wanted = list(available) if v['topics'] == ['all'] else list(v['topics'])
        missing = [t for t in wanted if t not in available]
        if missing:
            raise ReplayInputError(
                f'{v["bag"]}: no topic {", ".join(missing)}; it has {", ".join(sorted(available))}'
            )
        self.messages = list(reader.raw_messages(wanted, ordered=True))
        if not self.messages:
            raise ReplayInputError(f'{v["bag"]}: the selected topics hold no message')
        self.refusals = PublishRefusals(self)
        self.publishers_by_topic = {
            t: self.refusals.publisher(ros_message_class(available[t].msgtype), t, STREAM_QOS)
            for t in wanted
        }
        self.p_clock = (
            self.refusals.publisher(ClockMsg, '/clock', CLOCK_QOS) if v['clock'] else None
        )
        self.p_diag = self.refusals.publisher(DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
        self.rate = v['rate']
        self.loop = v['loop']
        self.index = 0
        self.loops = 0
        self.played = 0
        self.t0_bag = self.messages[0].log_time_ns
        self.t0_wall: float | None = None
        self.start_at = time.monotonic() + v['start_delay']
        self.gate = SubscriberGate(
            list(self.publishers_by_topic.values()),
            self.start_at + v['wait_for_subscribers'],
            min_subscribers=v['min_subscribers'],
        )
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.play_timer = self.create_timer(_PERIOD, self.play, clock=steady)
        self.create_timer(1.0, self.publish_diagnostics, clock=steady)
        span = (self.messages[-1].log_time_ns - self.t0_bag) * 1e-9
        self.get_logger().info(
            f'playing {len(self.messages)} messages ({span:.1f} s) of {len(wanted)} topics '
            f'from {v["bag"]} at rate {self.rate:g}' + (' in a loop' if self.loop else '')
        )

    def play(self) -> None:
        now = time.monotonic()
        if now < self.start_at:
            return
        if self.t0_wall is None:
            if not self.gate.ready(now):
                return
            if self.gate.missing and self.loops == 0:
                self.get_logger().warning(f'no subscriber yet on {", ".join(self.gate.missing)}')
            self.t0_wall = now
        due_ns = self.t0_bag + int((now - self.t0_wall) * self.rate * 1e9)
        last: Any = None
        while self.index < len(self.messages) and self.messages[self.index].log_time_ns <= due_ns:
            last = self.messages[self.index]
            # a refused publish (overload) is counted by self.refusals: play on
            self.publishers_by_topic[last.topic].publish(last.data)
            self.index += 1
            self.played += 1
        if last is not None and self.p_clock is not None:
            self.p_clock.publish(ClockMsg(clock=ns_to_time(last.log_time_ns)))
        if self.index >= len(self.messages):
            if not self.loop:
                self.get_logger().info(f'played {len(self.messages)} messages')
                deliver_pending(self)
                self.play_timer.cancel()
                finish(self)
                return
            self.loops += 1
            self.index = 0
            self.t0_wall = None

    def publish_diagnostics(self) -> None:
        values = {'messages_played': self.played, 'loops': self.loops}
        self.p_diag.publish(
            node_status(self, 'vd: player', 'player_node', 0, 'ok', values, self.refusals)
        )


def main(args: list[str] | None = None) -> int:
    """Entry point of ``ros2 run vd_observer_node player_node``."""
    return run_node(PlayerNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
