"""`ImuHold`: each stamp of the live chain takes the IMU sample the replay takes, whatever order
the subscriptions deliver in."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from vd_observer_node.inputs.imu_hold import ImuHold

MAX_AGE = 0.1
WHEELS = [k * 1_000_000 for k in range(1, 301)]  # 1 kHz wheel stamps [ns]
IMU = [(k * 1e-3, float(k), math.nan) for k in range(0, 301, 3)]  # a 333 Hz IMU


def _replay_rule(stamp_ns: int) -> tuple[float, float, float] | None:
    """The replay's: the newest sample not later than the stamp."""
    times = np.array([s[0] for s in IMU])
    k = int(np.searchsorted(times, stamp_ns * 1e-9, side='right')) - 1
    return IMU[k] if k >= 0 else None


@settings(max_examples=50, deadline=None)
@given(st.randoms(use_true_random=False))
def test_any_interleaving_gives_the_replay_s_samples(rng: object) -> None:
    # each stream in its order, each message delayed at random (the IMU by less than its
    # max_age: a later one is a dropout by design), delivered in the order they arrive
    uniform = rng.uniform  # type: ignore[attr-defined]
    arrivals: list[tuple[float, str, object]] = []
    last = {'w': 0.0, 'i': 0.0}
    for kind, stream, delay in (('w', WHEELS, 0.03), ('i', IMU, 0.095)):
        for value in stream:
            stamp = value * 1e-9 if kind == 'w' else value[0]  # type: ignore[index,operator]
            last[kind] = max(last[kind], stamp + uniform(0.0, delay))  # in order per stream
            arrivals.append((last[kind], kind, value))
    arrivals.sort(key=lambda a: a[0])
    hold: ImuHold[int] = ImuHold(MAX_AGE)
    released = []
    for _, kind, value in arrivals:
        if kind == 'w':
            released += hold.stamp(value, value)  # type: ignore[arg-type]
        else:
            released += hold.sample(value)  # type: ignore[arg-type]
    released += hold.flush()
    assert [r[0] for r in released] == WHEELS  # every stamp, once, in order
    assert all(r[2] == _replay_rule(r[0]) for r in released)


def test_an_imu_that_stops_holds_the_stamps_back_no_longer_than_its_age() -> None:
    hold: ImuHold[int] = ImuHold(MAX_AGE)
    assert hold.sample((0.010, 1.0, 0.0)) == []
    released = []
    for k in range(11, 200):
        released += hold.stamp(k * 1_000_000, k)
    # stamps up to 0.1 s after the IMU's last sample waited; from 0.111 s on the IMU is gone
    # and they all went, each with the last sample
    assert [r[1] for r in released] == list(range(11, 200))
    assert hold.waiting == 0
    assert {r[2] for r in released} == {(0.010, 1.0, 0.0)}
    # an IMU that never comes is awaited max_age from the first stamp, then no longer
    none: ImuHold[int] = ImuHold(MAX_AGE)
    out = [r for k in range(1, 300) for r in none.stamp(k * 1_000_000, k)]
    assert [r[1] for r in out] == list(range(1, 300)) and {r[2] for r in out} == {None}
    assert none.stamp(300_000_000, 300) == [(300_000_000, 300, None)]  # no waiting any more


def test_the_last_stamps_of_a_drive_go_when_flushed() -> None:
    hold: ImuHold[int] = ImuHold(MAX_AGE)
    hold.sample((0.001, 1.0, 0.0))
    assert hold.stamp(2_000_000, 2) == []  # the IMU of 2 ms may still come
    assert hold.waiting == 1
    assert hold.flush() == [(2_000_000, 2, (0.001, 1.0, 0.0))]


def test_a_sample_out_of_stamp_order_goes_where_the_replay_s_sort_puts_it() -> None:
    hold: ImuHold[int] = ImuHold(MAX_AGE)
    for sample in ((0.000, 0.0, 0.0), (0.003, 3.0, 0.0), (0.001, 1.0, 0.0)):
        assert hold.sample(sample) == []
    assert hold.late == 1
    # the stamp of 2 ms takes the sample of 1 ms that came late, as the sorted bag gives it
    assert hold.stamp(2_000_000, 2) == [(2_000_000, 2, (0.001, 1.0, 0.0))]
