"""How well one input stream arrives: the share of its expected stamps, its lag, its losses.

A live node cannot know which messages the middleware dropped, but it knows the stamps it
got: a stream at a steady rate shows each lost message as a gap of two (or more) periods.
`StreamHealth` estimates the nominal period from the shortest intervals between consecutive
stamps seen so far (their 10th percentile per window, the smallest over the windows: losses
only lengthen intervals; a stream that has lost every second message from its very start
looks like one at half the rate) and counts, per window (one diagnostics period) and in
total, the stamps that arrived against those expected between them. Only header stamps
qualify: an input stamped on receipt arrives in bursts and its losses cannot be told. The
lag is the node clock at arrival minus the stamp. ROS-free: the nodes feed it and publish
`WindowHealth` on ``/diagnostics``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ['HealthLimits', 'StreamHealth', 'WindowHealth', 'health_notes']


@dataclass(frozen=True)
class HealthLimits:
    """When an input is reported (WARN).

    Attributes:
        min_share: below this share of expected stamps in a window, [0, 1] (issue 28: a
            WARN whenever less than 99 % of a 1 kHz stream arrives).
        max_lag: [s] above this mean lag in a window; none by default: the lag is the node
            clock minus the stamp, meaningful only where both run on one time base at one
            rate (not a simulator in lockstep or faster than real time, not a bag played at
            another rate), so the default only reports it.
        max_queue_share: above this share of the matcher's capacity waiting for one input.
    """

    min_share: float = 0.99
    max_lag: float = math.inf
    max_queue_share: float = 0.8


@dataclass(frozen=True)
class WindowHealth:
    """One input over one window.

    Attributes:
        received: distinct new stamps that arrived.
        expected: stamps expected between the window's first and last ones (at the estimated
            period), counting from the last stamp of the previous window.
        share: received / expected (1.0 when nothing was expected).
        lost_total: expected minus received, since the start.
        period: [s] the estimated nominal period (nan before two stamps).
        lag_mean: [s] mean lag of the window's messages (nan without any).
        lag_max: [s] largest lag of the window's messages (nan without any).
    """

    received: int
    expected: int
    share: float
    lost_total: int
    period: float
    lag_mean: float
    lag_max: float


class StreamHealth:
    """Arrivals of one input, window by window (see the module docstring)."""

    def __init__(self) -> None:
        """Nothing seen yet."""
        self._stamps: list[int] = []
        self._lags: list[int] = []
        self._previous: int | None = None
        self._period_ns: float = math.nan
        self.received_total = 0
        self.expected_total = 0

    def add(self, stamp_ns: int, lag_ns: int | None = None) -> None:
        """Note one message stamped `stamp_ns` [ns], `lag_ns` [ns] after its stamp."""
        self._stamps.append(stamp_ns)
        if lag_ns is not None:
            self._lags.append(lag_ns)

    def add_many(self, stamps_ns: NDArray[np.int64]) -> None:
        """Note the messages of a block of a recording (stamps [ns], in arrival order; no lag)."""
        self._stamps.extend(np.asarray(stamps_ns, dtype=np.int64).tolist())

    def window(self) -> WindowHealth:
        """Close the window: its figures; the next window starts empty."""
        stamps = np.asarray(self._stamps, dtype=np.int64)
        lags = np.asarray(self._lags, dtype=np.float64) * 1e-9
        self._stamps.clear()
        self._lags.clear()
        if self._previous is not None:
            stamps = np.concatenate(([self._previous], stamps))
        gaps = np.diff(stamps)
        # a jump back (a looped bag, a restart) starts the count afresh; a repeat is no news
        forward = gaps[gaps > 0]
        if forward.size >= 1:
            # losses only lengthen intervals: the short ones tell the nominal period
            short = float(np.percentile(forward, 10))
            self._period_ns = short if math.isnan(self._period_ns) else min(short, self._period_ns)
        received = int(forward.size)
        expected = int(np.maximum(np.rint(forward / self._period_ns), 1).sum()) if received else 0
        if stamps.size:
            self._previous = int(stamps[-1])
        self.received_total += received
        self.expected_total += expected
        return WindowHealth(
            received=received,
            expected=expected,
            share=received / expected if expected else 1.0,
            lost_total=self.expected_total - self.received_total,
            period=self._period_ns * 1e-9,
            lag_mean=float(lags.mean()) if lags.size else math.nan,
            lag_max=float(lags.max()) if lags.size else math.nan,
        )


def health_notes(
    topic: str,
    health: WindowHealth,
    limits: HealthLimits,
    queue: int | None = None,
    capacity: int | None = None,
) -> tuple[list[str], dict[str, object]]:
    """What to say of one input on ``/diagnostics``: the WARN notes (empty: healthy) and the
    key values, each key starting with `topic`.

    Args:
        topic: the input's topic.
        health: its last window.
        limits: the thresholds.
        queue: messages of this input waiting in the node's matcher (None: not matched).
        capacity: the matcher's capacity per input.
    """
    values: dict[str, object] = {
        f'{topic} share_of_expected': round(health.share, 4),
        f'{topic} lost_total': health.lost_total,
    }
    notes: list[str] = []
    if health.expected and health.share < limits.min_share:
        notes.append(
            f'{topic}: {100.0 * health.share:.0f} % of the expected stamps arrived '
            f'({health.expected - health.received} of {health.expected} lost)'
        )
    if not math.isnan(health.lag_mean):
        values[f'{topic} lag_s'] = round(health.lag_mean, 4)
        values[f'{topic} lag_max_s'] = round(health.lag_max, 4)
        if health.lag_mean > limits.max_lag:
            notes.append(f'{topic} lags {health.lag_mean:.2f} s behind its stamps')
    if queue is not None:
        values[f'{topic} queue'] = queue
        if capacity and queue > limits.max_queue_share * capacity:
            notes.append(f'{topic}: {queue} of {capacity} messages queued')
    return notes, values
