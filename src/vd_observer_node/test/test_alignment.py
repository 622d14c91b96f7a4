"""StampAligner: matching three topics by stamp, stale and overflow handling."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st
from vd_observer_node.errors import ConfigurationError
from vd_observer_node.estimation.alignment import StampAligner

TOPICS = ('wheel_states', 'body_accel', 'wheel_torques')


def test_emits_when_all_topics_have_the_stamp() -> None:
    aligner = StampAligner(TOPICS)
    assert aligner.push('wheel_states', 10, 'w10') is None
    assert aligner.push('wheel_torques', 10, 't10') is None
    matched = aligner.push('body_accel', 10, 'a10')
    assert matched == {'wheel_states': 'w10', 'body_accel': 'a10', 'wheel_torques': 't10'}


def test_stale_messages_are_dropped_and_counted() -> None:
    aligner = StampAligner(TOPICS)
    for topic in TOPICS:
        aligner.push(topic, 20, topic)
    assert aligner.push('body_accel', 20, 'again') is None
    assert aligner.push('body_accel', 5, 'old') is None
    assert aligner.stale_count == 2


def test_incomplete_older_stamps_are_discarded_when_newer_completes() -> None:
    aligner = StampAligner(TOPICS)
    aligner.push('wheel_states', 1, 'w1')  # its partners never arrive
    for topic in TOPICS:
        result = aligner.push(topic, 2, topic)
    assert result is not None
    assert aligner.dropped_count == 1


def test_buffer_is_bounded() -> None:
    aligner = StampAligner(TOPICS, capacity=3)
    for stamp in range(10):
        aligner.push('wheel_states', stamp, stamp)
    assert aligner.dropped_count == 7
    for topic in ('body_accel', 'wheel_torques'):
        result = aligner.push(topic, 9, topic)
    assert result is not None and result['wheel_states'] == 9


def test_configuration_errors() -> None:
    with pytest.raises(ConfigurationError):
        StampAligner([])
    with pytest.raises(ConfigurationError):
        StampAligner(['a', 'a'])
    with pytest.raises(ConfigurationError):
        StampAligner(['a'], capacity=0)
    with pytest.raises(ConfigurationError):
        StampAligner(['a']).push('b', 0, None)


@given(st.lists(st.integers(0, 2), min_size=0, max_size=60))
def test_interleaved_in_order_streams_match_every_stamp(order: list[int]) -> None:
    # Each topic delivers stamps 0..K-1 in order; whatever the interleaving, every stamp is
    # matched exactly once, in increasing order, with nothing dropped.
    n_stamps = 8
    aligner = StampAligner(TOPICS, capacity=n_stamps)
    next_stamp = [0, 0, 0]
    emitted: list[int] = []
    schedule = order + [i for i in range(3) for _ in range(n_stamps)]
    for index in schedule:
        if next_stamp[index] >= n_stamps:
            continue
        stamp = next_stamp[index]
        next_stamp[index] += 1
        result = aligner.push(TOPICS[index], stamp, (TOPICS[index], stamp))
        if result is not None:
            assert all(value == (topic, stamp) for topic, value in result.items())
            emitted.append(stamp)
    assert emitted == list(range(n_stamps))
    assert aligner.dropped_count == 0 and aligner.stale_count == 0
