"""Aligners: exact stamps and latest samples, live and offline, and the two equal."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from vd_observer_node.errors import ConfigurationError
from vd_observer_node.estimation.alignment import (
    LatestAligner,
    StampAligner,
    align_latest,
    align_stamps,
)

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


# --- offline alignment ------------------------------------------------------------------


def test_exact_alignment_keeps_the_stamps_every_input_has() -> None:
    got = align_stamps(
        [np.array([1, 2, 3, 3, 5]), np.array([5, 3, 1]), np.array([1, 3, 4, 5])], 'exact', 1.0
    )
    assert got.stamp_ns.tolist() == [1, 3, 5]
    assert [i.tolist() for i in got.indexes] == [[0, 3, 4], [2, 1, 0], [0, 1, 3]]


def test_latest_alignment_holds_the_newest_sample_and_drops_stale_stamps() -> None:
    wheel = np.array([10, 20, 30, 40, 50, 60]) * 1_000_000  # [ns] every 10 ms
    speed = np.array([15, 35]) * 1_000_000  # 20 ms apart, then stops
    torque = np.array([5, 25, 45, 55]) * 1_000_000
    got = align_stamps([wheel, speed, torque], 'latest', 0.02)
    # 10 ms: no speed yet; 60 ms: the speed of 35 ms is 25 ms old > 20 ms
    assert (got.stamp_ns // 1_000_000).tolist() == [20, 30, 40, 50]
    assert [i.tolist() for i in got.indexes] == [[1, 2, 3, 4], [0, 0, 1, 1], [0, 1, 1, 2]]
    assert got.stale == 2


# --- live latest alignment --------------------------------------------------------------


def test_latest_aligner_waits_until_the_held_samples_are_final() -> None:
    aligner = LatestAligner(('wheel', 'speed', 'torque'), max_age_ns=20)
    assert aligner.push('wheel', 10, 'w10') == []  # no speed yet
    assert aligner.push('speed', 5, 's5') == []
    assert aligner.push('torque', 8, 'q8') == []  # a later torque may still come
    assert aligner.push('torque', 12, 'q12') == []  # speed not known past 10 yet
    assert aligner.push('speed', 15, 's15') == [
        (10, {'wheel': 'w10', 'speed': 's5', 'torque': 'q8'})
    ]
    assert aligner.push('wheel', 20, 'w20') == []
    assert aligner.push('torque', 30, 'q30') == []  # the speed is known only up to 15
    assert aligner.push('speed', 25, 's25') == [
        (20, {'wheel': 'w20', 'speed': 's15', 'torque': 'q12'})
    ]
    assert aligner.push('wheel', 60, 'w60') == []
    assert aligner.push('speed', 61, 's61') == []
    # both final now, but the torque of 30 is 30 > 20 old: dropped, counted
    assert aligner.push('torque', 70, 'q70') == []
    assert aligner.counts()['unmatched_dropped'] == 1
    assert aligner.push('speed', 14, 'late') == [] and aligner.stale_count == 1


@settings(max_examples=60)
@given(
    rates=st.lists(st.integers(3, 40), min_size=3, max_size=3),
    phases=st.lists(st.integers(0, 50), min_size=3, max_size=3),
    lags=st.lists(st.integers(0, 60), min_size=3, max_size=3),
    max_age=st.integers(5, 80),
)
def test_latest_aligner_gives_the_offline_sets(
    rates: list[int], phases: list[int], lags: list[int], max_age: int
) -> None:
    """Each topic in order but delivered with its own transport lag: the live sets are the
    offline ones (every driving stamp whose held samples are final by the end)."""
    topics = ('wheel', 'speed', 'torque')
    stamps = [np.arange(p, 600, r, dtype=np.int64) for r, p in zip(rates, phases, strict=True)]
    arrivals = sorted(
        (int(s) + lag, k, i)
        for k, (series, lag) in enumerate(zip(stamps, lags, strict=True))
        for i, s in enumerate(series.tolist())
    )
    aligner = LatestAligner(topics, max_age_ns=max_age)
    live: list[tuple[int, ...]] = []
    for _, k, i in arrivals:
        for stamp, matched in aligner.push(topics[k], int(stamps[k][i]), i):
            assert stamp == stamps[0][matched['wheel']]
            live.append(tuple(matched[t] for t in topics))
    offline = align_latest(stamps, max_age)
    expected = list(zip(*(i.tolist() for i in offline.indexes), strict=True))
    # the driving stamps after the last sample of a slower topic are still pending live
    assert live == expected[: len(live)]
    done = min(int(s[-1]) for s in stamps[1:])
    assert len(live) == sum(1 for t in offline.stamp_ns.tolist() if t <= done)


@pytest.mark.parametrize('first', ['wheel', 'speed'])
def test_latest_aligner_matches_a_looped_stream_from_its_first_stamp(first: str) -> None:
    # a bag played in a loop: every topic jumps back to the start, in either order. The
    # first stamps of each new loop are matched as on the first loop (a speed that jumped
    # first was dropped as stale, and the restart then lost the first stamp of the loop).
    aligner = LatestAligner(('wheel', 'speed'), max_age_ns=20, max_jump_back_ns=30)
    loop = [100, 110, 120, 130, 140, 150]
    matched: list[int] = []
    for _ in range(3):
        for t in loop:
            order = ['wheel', 'speed'] if first == 'wheel' else ['speed', 'wheel']
            for topic in order:
                matched += [stamp for stamp, _ in aligner.push(topic, t, f'{topic}{t}')]
    assert matched == loop * 3
    assert aligner.jump_back_count == 2
    assert aligner.stale_count == 0 and aligner.dropped_count == 0
