"""PublishRefusals: a publish the middleware refuses is counted and reported, never raised."""

from __future__ import annotations

from typing import Any

import pytest
from rclpy._rclpy_pybind11 import RCLError
from vd_common.ros.publishing import GuardedPublisher, PublishRefusals


class _Logger:
    def __init__(self) -> None:
        self.warnings: list[str] = []

    def warning(self, text: str) -> None:
        self.warnings.append(text)


class _Publisher:
    """An rclpy publisher stand-in: refuses the publishes whose index is in `refuse`."""

    def __init__(self, topic: str, refuse: set[int]) -> None:
        self.topic_name = topic
        self.refuse = refuse
        self.sent: list[Any] = []
        self.calls = 0

    def publish(self, msg: Any) -> None:
        self.calls += 1
        if self.calls in self.refuse:
            raise RCLError('failed to publish message: cannot publish data')
        if not isinstance(msg, bytes):
            raise TypeError('expected bytes')
        self.sent.append(msg)

    def get_subscription_count(self) -> int:
        return 2


class _Node:
    def __init__(self, refuse: dict[str, set[int]]) -> None:
        self.logger = _Logger()
        self.refuse = refuse
        self.made: list[_Publisher] = []

    def get_logger(self) -> _Logger:
        return self.logger

    def create_publisher(self, _type: Any, topic: str, _qos: Any) -> _Publisher:
        self.made.append(_Publisher(topic, self.refuse.get(topic, set())))
        return self.made[-1]


def test_refusals_are_counted_logged_once_per_topic_and_reported_once_per_period() -> None:
    node = _Node({'/a': {2, 3, 5}, '/b': {1}})
    refusals = PublishRefusals(node)  # type: ignore[arg-type]
    a = refusals.publisher(object, '/a', None)  # type: ignore[arg-type]
    b = refusals.publisher(object, '/b', None)  # type: ignore[arg-type]
    assert isinstance(a, GuardedPublisher)
    sent = [a.publish(b'%d' % k) for k in range(1, 7)]
    assert sent == [True, False, False, True, False, True]
    assert node.made[0].sent == [b'1', b'4', b'6']  # the others are lost, not retried
    assert b.publish(b'x') is False and b.publish(b'y') is True
    assert refusals.counts == {'/a': 3, '/b': 1} and refusals.total == 4
    assert len(node.logger.warnings) == 2  # the first refusal of each topic
    assert (
        'publish refused on /a (failed to publish message: cannot publish data)'
        in (node.logger.warnings[0])
    )

    level, message, values = refusals.status(0, 'ok')
    assert level == 1
    assert message == '4 publishes refused by the middleware (/a, /b)'
    assert values == {
        'refused_publishes': 4,
        'refused_publishes[/a]': 3,
        'refused_publishes[/b]': 1,
    }
    # next period, nothing new: the node's own level and message, the totals still there
    assert refusals.status(0, 'ok') == (0, 'ok', values)
    # an ERROR of the node stays an ERROR; the note is appended
    a.publish(b'7')
    a.publish(b'8')
    node.made[0].refuse.add(9)
    a.publish(b'9')
    level, message, values = refusals.status(2, 'estimator: 3 non-finite')
    assert (level, message) == (
        2,
        'estimator: 3 non-finite; 1 publishes refused by the middleware (/a, /b)',
    )
    assert values['refused_publishes'] == 5


def test_only_refusals_are_swallowed_and_the_rest_is_the_publishers() -> None:
    node = _Node({})
    pub = PublishRefusals(node).publisher(object, '/c', None)  # type: ignore[arg-type]
    with pytest.raises(TypeError):  # a programming error is not a refusal
        pub.publish('not bytes')
    assert pub.topic_name == '/c'
    assert pub.get_subscription_count() == 2  # delegated to the rclpy publisher
