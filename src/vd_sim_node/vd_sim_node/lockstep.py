"""Lockstep pacing: the simulator runs at most a bounded window ahead of its slowest consumer.

In real-time mode the simulator publishes at the wall clock's pace whether or not the nodes
keep up; on a busy machine their queues overflow and what is lost depends on the machine
(`make demo` at 1 kHz on two cores kept 89-95 k of 150 k truth messages). In lockstep, as in
CARLA's synchronous mode or Gazebo's lockstep with ros2_control, it advances only when every
named consumer has taken its samples up to ``window`` before the next one: each consumer's
progress is the newest header stamp it published on a topic (the estimator's slope, the
recorder's progress). With a window smaller than every reader's queue nothing is lost, and
the figures are the same on any machine; only the wall time differs.

A consumer that holds the simulator back and makes no progress for ``timeout_s`` of wall time
(it died, or never started) is given up: the simulator stops waiting for it and says so,
rather than hang. The time counts from when it began to hold the simulator back, so a
consumer that had nothing to take while another one held everything up is not blamed.
ROS-free: the node feeds it stamps and asks it before each step.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

__all__ = ['Lockstep', 'LockstepError']


class LockstepError(ValueError):
    """Lockstep settings that cannot work (no topic, a window that is not positive)."""


@dataclass
class _Consumer:
    latest_ns: int | None = None  # newest stamp seen on its topic
    # wall time [s] since which it holds the simulator back without progress (nan: it does not)
    waiting_since: float = math.nan
    given_up: bool = False


@dataclass
class Lockstep:
    """Which samples the simulator may publish, from its consumers' progress.

    Attributes:
        topics: one topic per consumer, whose header stamps are the consumer's progress.
        window_ns: how far [ns] of sample time the simulator may run ahead of the slowest
            consumer; keep it below every reader's queue (depth / rate).
        timeout_s: wall time [s] without progress after which a consumer is given up.
    """

    topics: Sequence[str]
    window_ns: int
    timeout_s: float
    _consumers: dict[str, _Consumer] = field(init=False, repr=False)
    _start_ns: int | None = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        if not self.topics:
            raise LockstepError('lockstep needs at least one topic to follow')
        if self.window_ns <= 0:
            raise LockstepError(f'lockstep window must be positive, got {self.window_ns} ns')
        if not self.timeout_s > 0.0:
            raise LockstepError(f'lockstep timeout must be positive, got {self.timeout_s} s')
        self._consumers = {topic: _Consumer() for topic in self.topics}

    def seen(self, topic: str, stamp_ns: int, now: float) -> None:
        """A consumer published `stamp_ns` on `topic` at wall time `now` [s]."""
        consumer = self._consumers.get(topic)
        if consumer is None:
            return
        if consumer.latest_ns is None or stamp_ns > consumer.latest_ns:
            consumer.latest_ns = stamp_ns
            consumer.waiting_since = math.nan

    def allows(self, stamp_ns: int, now: float) -> bool:
        """True if the sample stamped `stamp_ns` may be published at wall time `now` [s].

        It may when every consumer not given up has taken the samples up to
        ``stamp_ns - window_ns`` (the first window's samples need nothing). A consumer that
        has held the simulator back for `timeout_s` without progress is given up here.
        """
        if self._start_ns is None:
            self._start_ns = stamp_ns
        needed = stamp_ns - self.window_ns
        if needed < self._start_ns:
            return True
        allowed = True
        for consumer in self._consumers.values():
            if consumer.given_up:
                continue
            if consumer.latest_ns is not None and consumer.latest_ns >= needed:
                consumer.waiting_since = math.nan
                continue
            if math.isnan(consumer.waiting_since):
                consumer.waiting_since = now
            elif now - consumer.waiting_since > self.timeout_s:
                consumer.given_up = True
                continue
            allowed = False
        return allowed

    def caught_up(self, stamp_ns: int, now: float) -> bool:
        """True once every consumer not given up has taken `stamp_ns` (the last sample)."""
        return self.allows(stamp_ns + self.window_ns, now)

    @property
    def given_up(self) -> list[str]:
        """The topics whose consumers were given up."""
        return [topic for topic, c in self._consumers.items() if c.given_up]

    def waiting_for(self, stamp_ns: int) -> list[str]:
        """The topics whose consumers hold back the sample stamped `stamp_ns`."""
        needed = stamp_ns - self.window_ns
        return [
            topic
            for topic, c in self._consumers.items()
            if not c.given_up and (c.latest_ns is None or c.latest_ns < needed)
        ]

    def lag_ns(self, stamp_ns: int) -> dict[str, int | None]:
        """Per topic, how far [ns] its consumer is behind `stamp_ns` (None: nothing yet)."""
        return {
            topic: None if c.latest_ns is None else stamp_ns - c.latest_ns
            for topic, c in self._consumers.items()
        }
