"""Publishing that never ends a node, and the start and end of a source's stream.

A publish the middleware refuses (Fast DDS: ``RCLError: cannot publish data``, seen under
overload on a 2-core machine) never ends a node: every publisher is made through
`PublishRefusals`, which counts the refusal per topic, logs the first one of each topic and
puts a WARN on the node's ``/diagnostics`` (docs/faults.md). `SubscriberGate` holds a source
(simulator, player) until its subscribers are there; `deliver_pending` lets the last messages
arrive before a node exits; `ros_message_class` finds a message class by its type name.
"""

from __future__ import annotations

import importlib
from collections.abc import Sequence
from typing import Any

from rclpy._rclpy_pybind11 import RCLError
from rclpy.node import Node
from rclpy.qos import QoSProfile

__all__ = [
    'GuardedPublisher',
    'PublishRefusals',
    'SubscriberGate',
    'deliver_pending',
    'ros_message_class',
]


class GuardedPublisher:
    """A publisher whose refused publishes are counted by its `PublishRefusals`, not raised.

    Everything but `publish` is the wrapped rclpy publisher's (``topic_name``,
    ``get_subscription_count``, ``wait_for_all_acked`` ...).
    """

    __slots__ = ('_publisher', '_refusals', 'topic_name')

    def __init__(self, publisher: Any, refusals: PublishRefusals) -> None:
        self._publisher = publisher
        self._refusals = refusals
        self.topic_name: str = publisher.topic_name

    def publish(self, msg: Any) -> bool:
        """Publish `msg` (a message or its CDR bytes); False if the middleware refused it."""
        try:
            self._publisher.publish(msg)
        except RCLError as exc:
            self._refusals.note(self.topic_name, exc)
            return False
        return True

    def __getattr__(self, name: str) -> Any:
        return getattr(self._publisher, name)


class PublishRefusals:
    """Makes a node's publishers and counts the publishes the middleware refused, per topic.

    A refused publish is a lost message, not a reason to stop: the node goes on with the next
    sample. The first refusal of each topic is logged (WARN) with the middleware's words; the
    counts go to ``/diagnostics`` through `status`.
    """

    def __init__(self, node: Node) -> None:
        """Publishers made by `publisher` are `node`'s; refusals are logged by its logger."""
        self._node = node
        #: refused publishes per topic, since the node started
        self.counts: dict[str, int] = {}
        self._reported = 0

    @property
    def total(self) -> int:
        """Refused publishes on all topics since the node started."""
        return sum(self.counts.values())

    def publisher(self, msg_type: Any, topic: str, qos: QoSProfile) -> GuardedPublisher:
        """``node.create_publisher(msg_type, topic, qos)``, guarded."""
        return self.guard(self._node.create_publisher(msg_type, topic, qos))

    def guard(self, publisher: Any) -> GuardedPublisher:
        """Wrap an rclpy publisher of the node."""
        return GuardedPublisher(publisher, self)

    def note(self, topic: str, exc: BaseException) -> None:
        """Count one refused publish on `topic`; log the first of the topic."""
        n = self.counts.get(topic, 0) + 1
        self.counts[topic] = n
        if n == 1:
            first_line = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            self._node.get_logger().warning(
                f'publish refused on {topic} ({first_line}): counted on /diagnostics, going on'
            )

    def status(self, level: int, message: str) -> tuple[int, str, dict[str, object]]:
        """A node's diagnostic level and message with the refusals since the last call added.

        Args:
            level: the node's level so far, 0 (OK), 1 (WARN), 2 (ERROR).
            message: its message so far ('ok' when level is 0).

        Returns:
            (level, message, values): WARN at least when publishes were refused since the
            previous call, the message naming how many and where; values holds the total
            ``refused_publishes`` and the count per topic.
        """
        total = self.total
        values: dict[str, object] = {'refused_publishes': total}
        values.update({f'refused_publishes[{topic}]': n for topic, n in self.counts.items()})
        new = total - self._reported
        self._reported = total
        if new:
            topics = ', '.join(sorted(self.counts))
            note = f'{new} publishes refused by the middleware ({topics})'
            message = note if level == 0 else f'{message}; {note}'
            level = max(level, 1)
        return level, message, values


class SubscriberGate:
    """Decides when a source node (simulator, player) may send its first message.

    Open once every given publisher has `min_subscribers` subscribers (one number for all, or
    one per publisher) and the counts have not changed for `settle_s` (a topic whose first
    subscriber, say the recorder, matched may still be waiting for its second, the observer),
    or once `deadline` (monotonic [s]) has passed.
    """

    def __init__(
        self,
        publishers: Sequence[Any],
        deadline: float,
        settle_s: float = 1.0,
        min_subscribers: int | Sequence[int] = 1,
    ):
        self.publishers = list(publishers)
        self.min_subscribers = (
            [min_subscribers] * len(self.publishers)
            if isinstance(min_subscribers, int)
            else list(min_subscribers)
        )
        if len(self.min_subscribers) != len(self.publishers):
            raise ValueError('min_subscribers: one number, or one per publisher')
        self.deadline = deadline
        self.settle_s = settle_s
        self._counts: tuple[int, ...] = ()
        self._since = 0.0
        self.missing: list[str] = []

    def ready(self, now: float) -> bool:
        """True when the source may start; `missing` then names topics short of subscribers."""
        counts = tuple(p.get_subscription_count() for p in self.publishers)
        if counts != self._counts:
            self._counts, self._since = counts, now
        self.missing = [
            p.topic_name
            for p, n, least in zip(self.publishers, counts, self.min_subscribers, strict=True)
            if n < least
        ]
        settled = not self.missing and now - self._since >= self.settle_s
        return settled or now >= self.deadline


def deliver_pending(node: Node, timeout_s: float = 2.0) -> bool:
    """Wait until every reliable subscriber has acknowledged what `node` published.

    Call before a node exits on its own: a process that ends right after its last publish
    would otherwise take messages still in flight with it.
    Returns True if everything was acknowledged within `timeout_s` (per publisher).
    """
    from rclpy.duration import Duration

    acked = True
    for publisher in node.publishers:
        acked = publisher.wait_for_all_acked(Duration(seconds=timeout_s)) and acked
    return acked


def ros_message_class(type_name: str) -> Any:
    """The rclpy message class of ``'pkg/msg/Type'`` (what rosidl_runtime_py.get_message does).

    Raises:
        ImportError: the interface package is not installed.
        AttributeError: the package has no such message.
    """
    package, _, name = type_name.rpartition('/')
    module = importlib.import_module(package.replace('/', '.'))
    return getattr(module, name)
