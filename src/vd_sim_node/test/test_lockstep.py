"""Lockstep pacing (pure): how far the simulator may run ahead of its consumers."""

from __future__ import annotations

import struct

import pytest
from vd_common.ros.stamps import header_stamp_ns
from vd_sim_node.lockstep import Lockstep, LockstepError

MS = 1_000_000


def test_the_first_window_needs_nothing_then_the_slowest_consumer_paces() -> None:
    pacing = Lockstep(['/a', '/b'], window_ns=100 * MS, timeout_s=5.0)
    assert all(pacing.allows(k * MS, now=0.0) for k in range(100))
    assert not pacing.allows(100 * MS, now=0.0)  # needs stamp 0 from both
    pacing.seen('/a', 0, now=0.1)
    assert not pacing.allows(100 * MS, now=0.1)
    assert pacing.waiting_for(100 * MS) == ['/b']
    pacing.seen('/b', 0, now=0.1)
    assert pacing.allows(100 * MS, now=0.1)
    pacing.seen('/a', 50 * MS, now=0.2)
    pacing.seen('/b', 20 * MS, now=0.2)
    assert pacing.allows(120 * MS, now=0.2) and not pacing.allows(121 * MS, now=0.2)
    assert pacing.lag_ns(121 * MS) == {'/a': 71 * MS, '/b': 101 * MS}
    pacing.seen('/b', 10 * MS, now=0.3)  # an older stamp is no progress
    assert not pacing.allows(121 * MS, now=0.3)
    pacing.seen('/other', 10**12, now=0.3)  # a topic nobody waits for changes nothing
    assert not pacing.allows(121 * MS, now=0.3)


def test_a_consumer_holding_the_simulator_without_progress_is_given_up() -> None:
    pacing = Lockstep(['/a', '/dead'], window_ns=10 * MS, timeout_s=2.0)
    pacing.allows(0, now=0.0)
    pacing.seen('/a', 0, now=0.0)
    assert not pacing.allows(10 * MS, now=1.0)  # '/dead' never published: its wait starts
    assert not pacing.allows(10 * MS, now=2.9)
    assert pacing.allows(10 * MS, now=3.1)  # > 2 s after its wait started
    assert pacing.given_up == ['/dead']
    # '/a' had nothing to take meanwhile: it is not blamed for those 3 s, it still paces
    assert not pacing.allows(11 * MS, now=3.1)
    pacing.seen('/a', 1 * MS, now=3.2)
    assert pacing.allows(11 * MS, now=3.2)
    assert not pacing.allows(20 * MS, now=4.0)  # '/a' holds from 4.0 s
    pacing.seen('/a', 5 * MS, now=5.5)  # progress, not enough: its wait starts again
    assert not pacing.allows(20 * MS, now=5.6)
    assert not pacing.allows(20 * MS, now=7.5)
    assert pacing.allows(20 * MS, now=7.7)
    assert pacing.given_up == ['/a', '/dead']


def test_caught_up_once_every_consumer_took_the_last_sample() -> None:
    pacing = Lockstep(['/a'], window_ns=100 * MS, timeout_s=5.0)
    pacing.allows(0, now=0.0)
    pacing.seen('/a', 3990 * MS, now=1.0)
    assert not pacing.caught_up(4000 * MS, now=1.0)
    pacing.seen('/a', 4000 * MS, now=1.1)
    assert pacing.caught_up(4000 * MS, now=1.1)


@pytest.mark.parametrize(
    ('topics', 'window', 'timeout'), [([], 1, 1.0), (['/a'], 0, 1.0), (['/a'], 1, 0.0)]
)
def test_settings_that_cannot_work_are_refused(
    topics: list[str], window: int, timeout: float
) -> None:
    with pytest.raises(LockstepError):
        Lockstep(topics, window, timeout)


def test_header_stamp_read_from_cdr_bytes_of_either_endianness() -> None:
    little = b'\x00\x01\x00\x00' + struct.pack('<iI', 12, 345) + b'\x00' * 8
    big = b'\x00\x00\x00\x00' + struct.pack('>iI', -2, 7)
    assert header_stamp_ns(little) == 12_000_000_345
    assert header_stamp_ns(big) == -2_000_000_000 + 7
    assert header_stamp_ns(little[:11]) is None
    assert header_stamp_ns(b'\x00\x07' + little[2:]) is None  # not plain CDR
