"""ROS 2 node: records every ``/vd/**`` topic, as raw CDR, to a rosbag2 MCAP bag.

Topics are discovered as they appear (checked every ``discovery_period`` seconds); messages
are taken serialized (``raw=True``: no decode/encode) and written by
:class:`vd_observer_node.bag.BagWriter` (zstd chunks, embedded ``ros2msg`` definitions,
``metadata.yaml``). Log time = the recorder clock at reception (the system clock, or
``/clock`` with ``use_sim_time``), as ``ros2 bag record`` does.

It also publishes its progress on ``/vd/status/recorder_progress`` (std_msgs/Header, up to
50 Hz, where it changed): the newest stamp up to which every per-sample vd topic that has a
publisher has been written (the minimum over those topics of the newest header stamp
received; the on-change topics and ``/vd/status/*`` do not count). A simulator in lockstep
waits on it, so that the bag misses nothing however slow the machine.

What it missed: the stamps of each per-sample topic (those of the progress) are counted
against the stamps expected between them (`inputs.health.StreamHealth`: a lost message is a
gap of two periods). A topic that lost more than 5 % of its stamps in a second turns the
status WARN, naming it; the values hold each topic's stamps lost since the start, and the
closing line says which topics lost how many. (The publishers' sequence numbers would count
exactly, but rclpy's EventsExecutor does not pass the message info that holds them.)

SIGINT/SIGTERM close the bag completely. After SIGKILL or power loss, ``vd bag repair BAG``
recovers every chunk already written: at most ``chunk_duration`` seconds are lost (the writer
writes a chunk when it is that old, and this node checks every 0.1 s).
"""

from __future__ import annotations

import re
import sys
import time
from pathlib import Path
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from std_msgs.msg import Header
from vd_common.ros.diagnostics import node_status
from vd_common.ros.lifecycle import run_node
from vd_common.ros.parameters import ParamSpec, declare_parameters, log_settings
from vd_common.ros.publishing import PublishRefusals, ros_message_class
from vd_common.ros.qos import CLOCK_QOS, DIAGNOSTICS_QOS, STREAM_QOS
from vd_common.ros.stamps import header_stamp_ns, ns_to_time
from vd_common.topics import CONTRACT, NAMESPACE, ON_CHANGE, STATUS, STATUS_RECORDER_PROGRESS

from vd_observer_node.bag import BagWriter
from vd_observer_node.bag.errors import BagError, UnknownMessageTypeError
from vd_observer_node.bag.metadata import format_qos_profiles
from vd_observer_node.estimation.faults import ERROR, OK, WARN
from vd_observer_node.inputs.health import HealthLimits, StreamHealth, health_notes

__all__ = ['RecorderNode', 'main']

PARAMS = [
    ParamSpec('output', '', "bag folder to create ('' = vd_<date>_<time> in the working dir)"),
    ParamSpec(
        'topic_regex', '^' + re.escape(NAMESPACE), 'record topics whose name matches this regex'
    ),
    ParamSpec(
        'contract_topics',
        True,
        'subscribe to every topic of the vd contract at start, before it is published, '
        'so the first messages are not lost to discovery',
    ),
    ParamSpec('include_clock', False, 'also record /clock'),
    ParamSpec('include_diagnostics', False, 'also record /diagnostics'),
    ParamSpec(
        'discovery_period', 0.5, 'how often to look for new topics [s]', low=0.01, high=60.0
    ),
    ParamSpec(
        'chunk_duration',
        0.5,
        'max age of buffered data before it is written [s]: the most a SIGKILL can lose',
        low=0.01,
        high=60.0,
    ),
    ParamSpec(
        'chunk_size', 262144, 'chunk size before compression [bytes]', low=1024, high=1 << 30
    ),
]

# rosbag2 stores the offered QoS per topic; all vd streams are offered like this.
_STREAM_QOS_YAML = format_qos_profiles(
    [{'history': 'keep_last', 'depth': 1000, 'reliability': 'reliable', 'durability': 'volatile'}]
)


class RecorderNode(Node):
    """Discovers topics, subscribes with raw=True, hands the bytes to the bag writer."""

    def __init__(self) -> None:
        super().__init__('recorder_node')
        self.refusals = PublishRefusals(self)  # a refused publish is counted, not fatal
        #: [s] run_node spins this long after a stop signal, so what was delivered is written
        self.drain_on_stop_s = 0.3
        v = declare_parameters(self, PARAMS)
        log_settings(self, PARAMS, v)
        output = v['output'] or time.strftime('vd_%Y%m%d_%H%M%S')
        self.pattern = re.compile(v['topic_regex'])
        self.extra = {
            '/clock': v['include_clock'],
            '/diagnostics': v['include_diagnostics'],
        }
        self.writer = BagWriter(
            Path(output), chunk_size=v['chunk_size'], chunk_duration_s=v['chunk_duration']
        )
        self.subscriptions_by_topic: dict[str, Any] = {}
        self.skipped: set[str] = set()
        self.write_errors = 0
        self.closed = False
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.create_timer(v['discovery_period'], self.discover, clock=steady)
        self.create_timer(0.1, self.flush, clock=steady)
        self.create_timer(1.0, self.publish_diagnostics, clock=steady)
        self.pub_diag = self.refusals.publisher(DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
        # progress: newest header stamp per per-sample contract topic, over those with a
        # publisher; published where the minimum moved
        self.pub_progress = self.refusals.publisher(Header, STATUS_RECORDER_PROGRESS, STREAM_QOS)
        self.latest_stamp: dict[str, int | None] = {}
        #: stamps received per per-sample topic, to tell the stamps it missed
        self.health: dict[str, StreamHealth] = {}
        self.limits = HealthLimits()
        self.publishers_seen: dict[str, int] = {}
        self._progress_sent: int | None = None
        self.create_timer(0.02, self.publish_progress, clock=steady)
        self.get_logger().info(f'recording to {self.writer.path}')
        if v['contract_topics']:
            for topic, type_name in CONTRACT.items():
                if self.wanted(topic):
                    self.subscribe(topic, type_name)
        self.discover()

    def wanted(self, topic: str) -> bool:
        if topic in STATUS:  # the nodes' own progress, not data
            return False
        if topic in self.extra:
            return bool(self.extra[topic])
        return bool(self.pattern.search(topic))

    def discover(self) -> None:
        for topic, types in self.get_topic_names_and_types():
            if topic in self.subscriptions_by_topic or topic in self.skipped:
                continue
            if self.wanted(topic):
                self.subscribe(topic, types[0])

    def subscribe(self, topic: str, type_name: str) -> None:
        """Declare `topic` in the bag and subscribe to it, serialized."""
        try:
            self.writer.add_topic(topic, type_name, _STREAM_QOS_YAML)
            kind = ros_message_class(type_name)
        except (UnknownMessageTypeError, ImportError, AttributeError) as exc:
            self.skipped.add(topic)
            self.get_logger().warning(f'not recording {topic} ({type_name}): {exc}')
            return
        qos = (
            CLOCK_QOS
            if topic == '/clock'
            else (DIAGNOSTICS_QOS if topic == '/diagnostics' else STREAM_QOS)
        )
        self.subscriptions_by_topic[topic] = self.create_subscription(
            kind,
            topic,
            self._make_callback(topic),
            qos,
            raw=True,
            event_callbacks=SubscriptionEventCallbacks(matched=self._on_matched(topic, type_name)),
        )

    def _on_matched(self, topic: str, type_name: str) -> Any:
        """Log 'recording TOPIC (TYPE)' once, when the first publisher is connected: from then
        on what it publishes reaches the bag (a topic without a publisher logs nothing)."""
        announced = False

        def on_matched(info: Any) -> None:
            nonlocal announced
            self.publishers_seen[topic] = info.current_count
            if not announced and info.current_count > 0:
                announced = True
                self.get_logger().info(f'recording {topic} ({type_name})')

        return on_matched

    def _make_callback(self, topic: str) -> Any:
        clock = self.get_clock()
        progress = topic in CONTRACT and topic not in ON_CHANGE
        if progress:
            self.latest_stamp[topic] = None
            self.health[topic] = StreamHealth()
        latest = self.latest_stamp
        health = self.health.get(topic)

        def callback(data: bytes) -> None:
            if self.closed:
                return
            try:
                self.writer.write(topic, data, clock.now().nanoseconds)
            except BagError as exc:
                self.write_errors += 1
                if self.write_errors == 1:
                    self.get_logger().error(f'cannot write {topic}: {exc}')
                return
            if progress:
                stamp = latest[topic] = header_stamp_ns(data)
                if health is not None and stamp is not None:
                    health.add(stamp)

        return callback

    def flush(self) -> None:
        if self.closed:
            return
        try:
            self.writer.flush_if_due()
        except BagError as exc:
            self.write_errors += 1
            self.get_logger().error(f'cannot flush the bag: {exc}')

    def progress_ns(self) -> int | None:
        """Newest stamp [ns] up to which every per-sample topic with a publisher was written.

        None while one of them has brought nothing yet, or no such topic has a publisher.
        """
        stamps = [
            stamp
            for topic, stamp in self.latest_stamp.items()
            if self.publishers_seen.get(topic, 0) > 0
        ]
        if not stamps or any(stamp is None for stamp in stamps):
            return None
        return min(stamp for stamp in stamps if stamp is not None)

    def progress_held_by(self) -> str:
        """The per-sample topic with a publisher that is furthest behind ('' if none)."""
        behind = [
            (-1 if stamp is None else stamp, topic)
            for topic, stamp in self.latest_stamp.items()
            if self.publishers_seen.get(topic, 0) > 0
        ]
        return min(behind)[1] if behind else ''

    def publish_progress(self) -> None:
        progress = self.progress_ns()
        if progress is None or progress == self._progress_sent:
            return
        self._progress_sent = progress
        self.pub_progress.publish(Header(stamp=ns_to_time(progress)))

    def missed(self) -> dict[str, int]:
        """Stamps missed so far per per-sample topic (only those that missed any)."""
        return {
            topic: health.expected_total - health.received_total
            for topic, health in self.health.items()
            if health.expected_total > health.received_total
        }

    def publish_diagnostics(self) -> None:
        level = OK if self.write_errors == 0 else ERROR
        notes = [] if self.write_errors == 0 else [f'{self.write_errors} write errors']
        lost: dict[str, object] = {}
        for topic, health in self.health.items():
            warned, numbers = health_notes(topic, health.window(), self.limits)
            lost[f'{topic} lost_total'] = numbers[f'{topic} lost_total']
            if warned:
                notes.extend(warned)
                level = max(level, WARN)
        message = '; '.join(notes) or 'ok'
        values = {
            'bag': str(self.writer.path),
            'topics': len(self.subscriptions_by_topic),
            'messages': self.writer.message_count,
            'write_errors': self.write_errors,
            'progress_s': '-'
            if self._progress_sent is None
            else f'{self._progress_sent * 1e-9:.3f}',
            'progress_held_by': self.progress_held_by(),
            **lost,
        }
        self.pub_diag.publish(
            node_status(
                self, 'vd: recorder', 'recorder_node', level, message, values, self.refusals
            )
        )

    def close(self) -> None:
        """Write the last chunk, the summary and metadata.yaml (called on shutdown)."""
        if self.closed:
            return
        self.closed = True
        # stderr, not the ROS logger: on SIGINT the rclpy context is already shut down here
        try:
            self.writer.close()
            missed = self.missed()
            said = (
                '; missed stamps: ' + ', '.join(f'{t} {n}' for t, n in missed.items())
                if missed
                else ''
            )
            print(
                f'bag closed: {self.writer.path} ({self.writer.message_count} messages{said})',
                file=sys.stderr,
                flush=True,
            )
        except BagError as exc:
            print(f'error: could not close the bag cleanly: {exc}', file=sys.stderr, flush=True)


def main(args: list[str] | None = None) -> int:
    """Entry point of ``ros2 run vd_observer_node recorder_node``."""
    return run_node(RecorderNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
