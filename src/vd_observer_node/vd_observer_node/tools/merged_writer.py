"""The replay's output, written in log-time order as its blocks come (`MergedWriter`)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from vd_observer_node.bag.packed import PackedMessages, PackedParts
from vd_observer_node.bag.writer import BagWriter

__all__ = ['MergedWriter', 'OutOfOrderError']

_WRITE_BLOCK = 65536  # messages per vectorized write (and progress-bar update)


class OutOfOrderError(Exception):
    """A message logged before what the streamed replay already wrote (internal signal)."""


class MergedWriter:
    """Writes the replay's messages in log-time order as the blocks come.

    Messages are held until :meth:`flush` is told that nothing earlier can come any more;
    the order is that of one stable sort of everything by log time with ties in topic order
    (inputs, truth, estimates, alerts) and then in arrival order, which is how the whole
    replay wrote them.
    """

    def __init__(self, writer: BagWriter, infos: Mapping[str, Any], raw: int, bar: Any) -> None:
        self._writer = writer
        self._infos = infos
        self._raw = raw  # the first `raw` topics are the copied inputs and truth
        self._bar = bar
        self._names: list[str] = []
        self._index: dict[str, int] = {}
        self._counts: list[int] = []
        # the held messages, one entry per topic and `add` (each in its order): topic index,
        # log times [ns], sequence numbers within the topic, the messages
        self._held: list[tuple[int, np.ndarray, np.ndarray, PackedMessages]] = []
        self.newest_ns = -1  # [ns] newest log time of an input or truth message added
        self._flushed = -1  # [ns] everything logged before this was written
        self.written = 0

    def declare(self, topic: str, msgtype: str) -> int:
        """The topic's index (in first-declared order), declared to the writer once."""
        k = self._index.get(topic)
        if k is None:
            info = self._infos.get(topic)
            self._writer.add_topic(topic, msgtype, info.qos_profiles_yaml if info else '')
            k = self._index[topic] = len(self._names)
            self._names.append(topic)
            self._counts.append(0)
        return k

    def add(self, topic: str, msgtype: str, log_ns: np.ndarray, datas: Sequence[bytes]) -> None:
        """Hold messages of one topic (in their order) until they can be written.

        Raises:
            OutOfOrderError: an input or truth message logged before what was written.
        """
        k = self.declare(topic, msgtype)
        n = len(datas)
        log = np.asarray(log_ns, dtype=np.int64)
        if k < self._raw and n and int(log.min()) < self._flushed:
            raise OutOfOrderError(topic)
        seq = np.arange(self._counts[k], self._counts[k] + n, dtype=np.int64)
        self._held.append((k, log, seq, PackedMessages.from_list(datas)))
        self._counts[k] += n
        if k < self._raw and n:
            self.newest_ns = max(self.newest_ns, int(log.max()))

    def flush(self, before_ns: int | None) -> None:
        """Write the held messages logged before `before_ns` [ns] (None: all), in order."""
        if not self._held:
            return
        # In topic order, each topic's messages in their order: a stable sort by log time
        # then orders by (log time, topic, sequence), and finds the held runs already sorted.
        held = sorted(self._held, key=lambda entry: (entry[0], entry[2][:1].tolist()))
        log = np.concatenate([entry[1] for entry in held])
        which = np.concatenate([np.full(entry[1].size, entry[0], np.int64) for entry in held])
        seq = np.concatenate([entry[2] for entry in held])
        ready = np.ones(len(log), dtype=bool) if before_ns is None else log < before_ns
        if before_ns is not None:
            self._flushed = max(self._flushed, before_ns)
        order = np.flatnonzero(ready)
        order = order[np.argsort(log[order], kind='stable')]
        # everything held, as it is (one buffer per topic and block); the writer copies the
        # selected messages from there into its chunks
        datas = PackedParts.join([entry[3] for entry in held])
        for start in range(0, len(order), _WRITE_BLOCK):
            sel = order[start : start + _WRITE_BLOCK]
            self._writer.write_interleaved(self._names, which[sel], datas.take(sel), log[sel])
            self._bar.update(int(np.count_nonzero(which[sel] < self._raw)))
        self.written += len(order)
        rest = np.flatnonzero(~ready)  # in topic order, each topic's in its order
        self._held = []
        for k in np.unique(which[rest]).tolist():
            mine = rest[which[rest] == k]
            self._held.append((k, log[mine], seq[mine], datas.take(mine).compact()))
