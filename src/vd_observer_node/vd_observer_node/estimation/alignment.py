"""Match messages of several topics by header stamp (for the estimator node)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from vd_observer_node.errors import ConfigurationError

__all__ = ['StampAligner']


class StampAligner:
    """Emit one set of messages per stamp once every topic has delivered that stamp.

    Stamps are compared as integer nanoseconds (header stamps are exact copies upstream).
    Each topic buffer is bounded: when full, its oldest message is dropped and counted.
    A message whose stamp is not newer than the last emitted stamp is stale: dropped and
    counted. When a set completes, older incomplete stamps can never complete in order and
    are discarded too (counted as dropped). A stamp older than the last emitted one by more
    than `max_jump_back_ns` (a looped bag, a restarted source) is not stale but a new time
    line: the buffers are cleared (their messages counted as dropped) and matching starts
    again (counted in `jump_back_count`).
    """

    def __init__(
        self, topics: Sequence[str], capacity: int = 200, max_jump_back_ns: int | None = None
    ) -> None:
        """Create the aligner.

        Args:
            topics: names of the topics to match (at least one, unique).
            capacity: maximum buffered messages per topic, >= 1.
            max_jump_back_ns: [ns] > 0, see the class docstring; None = never restart (every
                older stamp is stale).

        Raises:
            ConfigurationError: empty or duplicate topics, capacity < 1, max_jump_back_ns
                <= 0.
        """
        if not topics or len(set(topics)) != len(topics):
            raise ConfigurationError(f'topics must be non-empty and unique: {list(topics)}')
        if capacity < 1:
            raise ConfigurationError(f'capacity must be >= 1, got {capacity}')
        self._topics = tuple(topics)
        self._capacity = capacity
        if max_jump_back_ns is not None and max_jump_back_ns <= 0:
            raise ConfigurationError(f'max_jump_back_ns must be > 0, got {max_jump_back_ns}')
        self._max_jump_back_ns = max_jump_back_ns
        self.jump_back_count = 0
        self._buffers: dict[str, dict[int, Any]] = {name: {} for name in self._topics}
        self._last_emitted: int | None = None
        self.stale_count = 0
        self.dropped_count = 0

    def counts(self) -> dict[str, int]:
        """The totals a node reports on /diagnostics: messages dropped unmatched, stale
        (older than the last match) and restarts after a time jump back."""
        return {
            'unmatched_dropped': self.dropped_count,
            'stale': self.stale_count,
            'time_jump_back': self.jump_back_count,
        }

    def push(self, topic: str, stamp_ns: int, message: Any) -> dict[str, Any] | None:
        """Add one message; return {topic: message} for its stamp if now complete, else None.

        Args:
            topic: one of the configured topics.
            stamp_ns: header stamp [ns].
            message: any payload.

        Raises:
            ConfigurationError: unknown topic.
        """
        if topic not in self._buffers:
            raise ConfigurationError(f'unknown topic {topic!r}; expected one of {self._topics}')
        if self._last_emitted is not None and stamp_ns <= self._last_emitted:
            jump = self._last_emitted - stamp_ns
            if self._max_jump_back_ns is None or jump <= self._max_jump_back_ns:
                self.stale_count += 1
                return None
            self._restart()
        buffer = self._buffers[topic]
        buffer[stamp_ns] = message
        if len(buffer) > self._capacity:
            del buffer[min(buffer)]
            self.dropped_count += 1
        if not all(stamp_ns in b for b in self._buffers.values()):
            return None
        matched = {name: self._buffers[name].pop(stamp_ns) for name in self._topics}
        self._last_emitted = stamp_ns
        for b in self._buffers.values():
            for old in [s for s in b if s < stamp_ns]:
                del b[old]
                self.dropped_count += 1
        return matched

    def _restart(self) -> None:
        self.jump_back_count += 1
        for b in self._buffers.values():
            self.dropped_count += len(b)
            b.clear()
        self._last_emitted = None
