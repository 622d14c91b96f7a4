"""Test helper: make rclpy refuse publishes, as Fast DDS does under overload.

Put this folder first on PYTHONPATH of a node's process and set
``VD_TEST_REFUSE_TOPICS=/topic,/other`` (and ``VD_TEST_REFUSE_EVERY=N``, default 3): every
N-th publish on those topics raises the ``RCLError`` that ``Publisher.publish`` raises when the
middleware refuses a write ("failed to publish message: cannot publish data"). A real
overload cannot be produced on demand (a stalled reliable subscriber does not make Fast DDS
refuse a KEEP_LAST writer), so the refusal is made at the boundary the nodes see.
"""

from __future__ import annotations

import os

_TOPICS = {t for t in os.environ.get('VD_TEST_REFUSE_TOPICS', '').split(',') if t}

if _TOPICS:
    from typing import Any

    import rclpy.publisher
    from rclpy._rclpy_pybind11 import RCLError

    _EVERY = int(os.environ.get('VD_TEST_REFUSE_EVERY', '3'))
    _publish = rclpy.publisher.Publisher.publish
    _counts: dict[str, int] = {}

    def _refusing_publish(self: Any, msg: Any) -> None:
        topic = self.topic_name
        if topic in _TOPICS:
            n = _counts[topic] = _counts.get(topic, 0) + 1
            if n % _EVERY == 0:
                raise RCLError('failed to publish message: cannot publish data (test)')
        _publish(self, msg)

    rclpy.publisher.Publisher.publish = _refusing_publish  # type: ignore[method-assign]
