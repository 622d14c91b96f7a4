"""Put samples of several inputs together on the stamps the cascade runs on.

Two policies, each live (message by message, in the nodes) and offline (whole arrays, in
the replay), and the two give the same sets on the same data:

* ``'exact'`` (`StampAligner`, `align_exact`): the stamps every input has; vd's own sensors
  are stamped together.
* ``'latest'`` (`LatestAligner`, `align_latest`): the first (driving) input's stamps, each
  with the newest sample of every other input whose stamp is not later (sample and hold: a
  car's topics run on their own clocks). A driving stamp is dropped while another input has
  no sample yet or only one older than ``max_age``.

Whatever the policy, an input that a part takes at its own stamps (the body speed, for the
speed observer) also gives each cascade stamp every sample stamped since the previous one
(`samples_between`, `SampleQueue`): a sample whose driving stamp was lost is not lost with it.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping, Sequence
from typing import Any, Final, NamedTuple

import numpy as np
from numpy.typing import NDArray

from vd_observer_node.errors import ConfigurationError

__all__ = [
    'ALIGNMENTS',
    'Alignment',
    'BlockAligner',
    'LatestAligner',
    'SampleQueue',
    'StampAligner',
    'align_exact',
    'align_latest',
    'align_stamps',
    'samples_between',
]

IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]
FloatArray = NDArray[np.float64]
#: Alignment policies (module docstring).
ALIGNMENTS: Final = ('exact', 'latest')


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

    def queued(self) -> dict[str, int]:
        """Messages waiting for their stamp to complete, per topic."""
        return {name: len(buffer) for name, buffer in self._buffers.items()}

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


class LatestAligner:
    """Live 'latest' alignment: each driving message with the newest not-later other samples.

    A driving message waits until every other topic has delivered a message stamped at or
    after it, so the held samples are final and the sets are those of `align_latest` on the
    same data (each topic's stamps arriving in order). The wait is at most one period of the
    slowest other topic. A message not newer than its topic's last one is stale (dropped and
    counted); pending driving messages beyond ``capacity`` are dropped oldest first.

    A stamp older than its topic's last one by more than ``max_jump_back_ns`` (a looped bag,
    a restarted source) starts a new time line for that topic: for the driving topic a
    restart, for another topic its history afresh. The topics jump in any order: one that
    jumped before the driving topic keeps what it brought on the new line, one that has not
    jumped yet is emptied at the restart and waited for, so the first driving stamps of the
    new line are matched as on the first.
    """

    def __init__(
        self,
        topics: Sequence[str],
        max_age_ns: int,
        capacity: int = 1000,
        max_jump_back_ns: int | None = None,
    ) -> None:
        """Create the aligner.

        Args:
            topics: the topics, the driving one first (at least two, unique).
            max_age_ns: [ns] > 0, the oldest a held sample may be.
            capacity: maximum pending driving messages, >= 1.
            max_jump_back_ns: [ns] > 0, see the class docstring; None = never restart.

        Raises:
            ConfigurationError: bad topics or limits.
        """
        if len(topics) < 2 or len(set(topics)) != len(topics):
            raise ConfigurationError(f'topics must be >= 2 and unique: {list(topics)}')
        if max_age_ns <= 0 or capacity < 1:
            raise ConfigurationError(
                f'max_age_ns must be > 0 and capacity >= 1, got {max_age_ns}, {capacity}'
            )
        if max_jump_back_ns is not None and max_jump_back_ns <= 0:
            raise ConfigurationError(f'max_jump_back_ns must be > 0, got {max_jump_back_ns}')
        self._topics = tuple(topics)
        self._max_age = max_age_ns
        self._capacity = capacity
        self._max_jump_back_ns = max_jump_back_ns
        self.stale_count = 0
        self.dropped_count = 0
        self.jump_back_count = 0
        self._restart(count=False)

    def counts(self) -> dict[str, int]:
        """Totals for /diagnostics: driving messages dropped (no fresh sample of another
        input, or beyond capacity), stale messages, restarts after a time jump back."""
        return {
            'unmatched_dropped': self.dropped_count,
            'stale': self.stale_count,
            'time_jump_back': self.jump_back_count,
        }

    def _restart(self, count: bool = True) -> None:
        if count:
            self.jump_back_count += 1
            self.dropped_count += len(self._pending)
            self._line[self._topics[0]] += 1
            line = self._line[self._topics[0]]
            for topic in self._topics[1:]:
                if self._line[topic] < line:  # not on the new line yet: wait for it afresh
                    self._history[topic].clear()
                    self._last[topic] = None
                    self._line[topic] = line
            self._last[self._topics[0]] = None
            self._pending.clear()
            return
        self._pending: deque[tuple[int, Any]] = deque()
        self._history: dict[str, deque[tuple[int, Any]]] = {t: deque() for t in self._topics[1:]}
        self._last: dict[str, int | None] = dict.fromkeys(self._topics)
        #: per topic, how many time lines it has started (see the class docstring)
        self._line: dict[str, int] = dict.fromkeys(self._topics, 0)

    def queued(self) -> dict[str, int]:
        """Driving messages waiting for the other inputs, and each other input's kept samples
        (the newest not-later one for each waiting driving message), per topic."""
        return {
            self._topics[0]: len(self._pending),
            **{topic: len(history) for topic, history in self._history.items()},
        }

    def push(self, topic: str, stamp_ns: int, message: Any) -> list[tuple[int, dict[str, Any]]]:
        """Add one message; return the sets it completes, oldest first: (driving stamp [ns],
        {topic: message}).

        Raises:
            ConfigurationError: unknown topic.
        """
        if topic not in self._last:
            raise ConfigurationError(f'unknown topic {topic!r}; expected one of {self._topics}')
        last = self._last[topic]
        if last is not None and stamp_ns <= last:
            if self._max_jump_back_ns is None or last - stamp_ns <= self._max_jump_back_ns:
                self.stale_count += 1
                return []
            if topic == self._topics[0]:
                self._restart()
            else:  # this input's new time line; the driving topic restarts when it jumps
                self._line[topic] += 1
                self._history[topic].clear()
        self._last[topic] = stamp_ns
        if topic == self._topics[0]:
            self._pending.append((stamp_ns, message))
            if len(self._pending) > self._capacity:
                self._pending.popleft()
                self.dropped_count += 1
        else:
            self._history[topic].append((stamp_ns, message))
        return self._release()

    def _release(self) -> list[tuple[int, dict[str, Any]]]:
        out: list[tuple[int, dict[str, Any]]] = []
        while self._pending:
            t, message = self._pending[0]
            if not all((s := self._last[k]) is not None and s >= t for k in self._history):
                break
            self._pending.popleft()
            matched = {self._topics[0]: message}
            for k, history in self._history.items():
                # keep the newest sample <= t at the front: later driving stamps need it
                while len(history) > 1 and history[1][0] <= t:
                    history.popleft()
                held = history[0] if history and history[0][0] <= t else None
                if held is None or t - held[0] > self._max_age:
                    break
                matched[k] = held[1]
            if len(matched) == len(self._topics):
                out.append((t, matched))
            else:
                self.dropped_count += 1
        return out


class Alignment(NamedTuple):
    """Where each input's sample of each cascade stamp is (offline alignment).

    Attributes:
        stamp_ns: shape (M,), int64 [ns], the cascade's stamps (sorted, unique).
        indexes: per input, shape (M,), the index of its sample in its series.
        stale: driving stamps dropped because another input was missing or too old.
    """

    stamp_ns: IntArray
    indexes: list[IntArray]
    stale: int


def _last_of_each(stamps: IntArray, wanted: IntArray) -> IntArray:
    """Index in ``stamps`` of the last sample with each stamp of ``wanted`` (all present)."""
    order = np.argsort(stamps, kind='stable')
    found: IntArray = order[np.searchsorted(stamps[order], wanted, side='right') - 1]
    return found


def align_exact(stamps: list[IntArray]) -> Alignment:
    """Stamps common to every input (sorted, unique) and each input's index of them.

    The last message of a repeated stamp wins, as a re-sent stamp replaces the buffered one
    live.
    """
    common = stamps[0]
    for s in stamps[1:]:
        common = np.intersect1d(common, s)
    return Alignment(common, [_last_of_each(s, common) for s in stamps], 0)


def align_latest(stamps: list[IntArray], max_age_ns: int) -> Alignment:
    """The first input's stamps, each with the newest not-later sample of every other input.

    Args:
        stamps: per input, shape (N_i,), int64 [ns]; the first input drives.
        max_age_ns: a held sample older than this [ns] does not count.
    """
    drive = np.unique(stamps[0])
    keep = np.ones(drive.shape[0], dtype=bool)
    held: list[IntArray] = []
    for s in stamps[1:]:
        order = np.argsort(s, kind='stable')
        sorted_s = s[order]
        # position of the newest sample with stamp <= each drive stamp (-1: none yet)
        pos = np.searchsorted(sorted_s, drive, side='right') - 1
        ok = pos >= 0
        age = np.where(ok, drive - sorted_s[np.maximum(pos, 0)], 0)
        keep &= ok & (age <= max_age_ns)
        held.append(order[np.maximum(pos, 0)])
    first = _last_of_each(stamps[0], drive)
    stale = int(np.count_nonzero(~keep))
    return Alignment(drive[keep], [first[keep], *(h[keep] for h in held)], stale)


def align_stamps(stamps: list[IntArray], alignment: str, max_age: float) -> Alignment:
    """Dispatch by policy name (one of `ALIGNMENTS`); ``max_age`` in [s].

    Raises:
        ConfigurationError: unknown policy.
    """
    if alignment == 'exact':
        return align_exact(stamps)
    if alignment == 'latest':
        return align_latest(stamps, round(max_age * 1e9))
    raise ConfigurationError(f'alignment {alignment!r} is unknown (use one of {ALIGNMENTS})')


class BlockAligner:
    """`align_stamps` over inputs given in blocks (the streamed replay), with bounded carry.

    Each :meth:`push` adds a block of samples per input and returns the sets that can no
    longer change; the other samples are carried to the next block, never dropped. A stamp is
    final once every input has delivered a later one (the horizon: the smallest of the
    inputs' newest stamps), as `LatestAligner` waits live. With each input's stamps
    non-decreasing in arrival order, the sets of all blocks together are those of
    `align_stamps` on the whole record, in the same order (tested); a sample arriving after
    the horizon passed its stamp is not matched any more (it stays unused, as live).

    Samples carry payload columns (any arrays whose first axis is the sample), returned at the
    matched samples, so the caller needs no indexes into its own blocks.

    With ``max_wait``, an input that has fallen more than that behind the most advanced one
    (stopped, or not started yet) holds nobody: stamps older than the newest stamp of any
    input minus ``max_wait`` are final too, so the carry stays bounded by ``max_wait`` of
    samples. The sets are still those of `align_stamps` unless an input delivers a sample
    more than ``max_wait`` after another input delivered a later stamp (a late sample: not
    matched any more, as above).

    Attributes:
        stale: 'latest': driving stamps dropped so far (`Alignment.stale`).
        used: per input, samples that went into a set so far (each counted once, also a held
            sample that serves several driving stamps).
    """

    def __init__(
        self, inputs: int, alignment: str, max_age: float, max_wait: float | None = None
    ) -> None:
        """Create the aligner.

        Args:
            inputs: number of inputs (>= 1; the first drives with 'latest').
            alignment: one of `ALIGNMENTS`.
            max_age: [s] the oldest a held sample may be ('latest').
            max_wait: [s] > 0, the longest an input is waited for (class docstring); None:
                without limit.

        Raises:
            ConfigurationError: unknown policy, no input, or max_wait <= 0.
        """
        if alignment not in ALIGNMENTS:
            raise ConfigurationError(
                f'alignment {alignment!r} is unknown (use one of {ALIGNMENTS})'
            )
        if inputs < 1:
            raise ConfigurationError(f'inputs must be >= 1, got {inputs}')
        if max_wait is not None and not max_wait > 0:
            raise ConfigurationError(f'max_wait must be > 0, got {max_wait}')
        self._latest = alignment == 'latest'
        self._max_age_ns = round(max_age * 1e9)
        self._max_wait_ns = None if max_wait is None else round(max_wait * 1e9)
        self._stamps: list[IntArray] = [np.zeros(0, dtype=np.int64) for _ in range(inputs)]
        self._columns: list[dict[str, np.ndarray]] = [{} for _ in range(inputs)]
        self._used: list[BoolArray] = [np.zeros(0, dtype=bool) for _ in range(inputs)]
        self._newest: list[int | None] = [None] * inputs
        self.stale = 0
        self.used = [0] * inputs

    def held(self, k: int) -> dict[str, np.ndarray]:
        """The payload columns of input `k`'s samples carried to the next block."""
        return self._columns[k]

    @property
    def carried(self) -> int:
        """Samples held for the next block (all inputs)."""
        return sum(len(s) for s in self._stamps)

    def push(
        self,
        stamps: Sequence[IntArray],
        columns: Sequence[Mapping[str, np.ndarray]],
        final: bool = False,
    ) -> tuple[IntArray, list[dict[str, np.ndarray]]]:
        """Add one block per input; return the sets now final.

        Args:
            stamps: per input, shape (N_i,), int64 [ns], in arrival order (N_i may be 0).
            columns: per input, payload arrays of first dimension N_i (the same names in
                every block of an input).
            final: the last block: everything carried is aligned now.

        Returns:
            The sets' stamps (shape (M,), int64 [ns], sorted, as `Alignment.stamp_ns`) and,
            per input, its payload columns at each set's sample (first dimension M).
        """
        n = len(self._stamps)
        for k in range(n):
            block = np.asarray(stamps[k], dtype=np.int64)
            if block.size:
                top = int(block.max())
                old = self._newest[k]
                self._newest[k] = top if old is None else max(old, top)
            self._stamps[k] = np.concatenate([self._stamps[k], block])
            self._used[k] = np.concatenate([self._used[k], np.zeros(block.size, dtype=bool)])
            for name, value in columns[k].items():
                held = self._columns[k].get(name)
                self._columns[k][name] = value if held is None else np.concatenate([held, value])
        known = [v for v in self._newest if v is not None]
        if final:
            ready = [np.ones(len(s), dtype=bool) for s in self._stamps]
        elif not known:
            ready = [np.zeros(len(s), dtype=bool) for s in self._stamps]
        else:
            # final: what every input has passed (an input with nothing yet holds all) ...
            lowest = min(known) if len(known) == len(self._newest) else np.iinfo(np.int64).min
            if self._max_wait_ns is not None:  # ... or what one input passed long ago
                lowest = max(lowest, max(known) - self._max_wait_ns)
            ready = [s < lowest for s in self._stamps]
        if self._latest and n > 1:
            # the driving stamps that are final, with every sample of the others: the newest
            # not-later one of each is among them
            drive = np.flatnonzero(ready[0])
            found = align_latest([self._stamps[0][drive], *self._stamps[1:]], self._max_age_ns)
            indexes = [drive[found.indexes[0]], *found.indexes[1:]]
            keep = [~ready[0], *(self._held_after(k, ready[k], final) for k in range(1, n))]
        else:
            picked = [np.flatnonzero(r) for r in ready]
            found = align_exact([s[p] for s, p in zip(self._stamps, picked, strict=True)])
            indexes = [p[i] for p, i in zip(picked, found.indexes, strict=True)]
            keep = [~r for r in ready]
        self.stale += found.stale
        out = []
        for k in range(n):
            self._used[k][indexes[k]] = True
            out.append({name: v[indexes[k]] for name, v in self._columns[k].items()})
            drop = ~keep[k]
            self.used[k] += int(np.count_nonzero(self._used[k][drop]))
            self._stamps[k] = self._stamps[k][keep[k]]
            self._used[k] = self._used[k][keep[k]]
            self._columns[k] = {name: v[keep[k]] for name, v in self._columns[k].items()}
        return found.stamp_ns, out

    def _held_after(self, k: int, ready: BoolArray, final: bool) -> BoolArray:
        """The samples of a held ('latest') input still needed: those not final and the
        newest final one (what `align_latest` holds for the next driving stamps)."""
        keep = ~ready
        if final or not ready.any():
            return keep
        stamps = self._stamps[k]
        below = np.flatnonzero(ready)
        order = np.argsort(stamps[below], kind='stable')
        keep[below[order[-1]]] = True
        return keep


def samples_between(
    stamps_ns: IntArray, values: FloatArray, rows_ns: IntArray, after_ns: int | None, most: int
) -> tuple[FloatArray, FloatArray]:
    """Each row's samples of one input: stamped after the previous row, not after the row.

    Args:
        stamps_ns: shape (M,), int64 [ns], the samples' stamps, sorted.
        values: shape (M,), the samples.
        rows_ns: shape (N,), int64 [ns], the rows' stamps, increasing.
        after_ns: [ns] the stamp of the row before the first (None: the first row takes what
            came before it).
        most: the most samples a row takes (the newest of its own).

    Returns:
        Shape (N, most) each, oldest first: the samples' stamps [s] (nan after the last) and
        the samples (nan there).
    """
    n = rows_ns.shape[0]
    stamp = np.full((n, most), np.nan)
    sample = np.full((n, most), np.nan)
    if n == 0 or stamps_ns.shape[0] == 0:
        return stamp, sample
    high = np.searchsorted(stamps_ns, rows_ns, side='right')
    low = np.empty_like(high)
    low[0] = 0 if after_ns is None else np.searchsorted(stamps_ns, after_ns, side='right')
    low[1:] = high[:-1]
    index = np.maximum(low, high - most)[:, None] + np.arange(most)
    have = index < high[:, None]
    picked = index[have]
    stamp[have] = stamps_ns[picked] * 1e-9
    sample[have] = values[picked]
    return stamp, sample


class SampleQueue:
    """`samples_between` over samples that arrive in any chunks: one message (the live node)
    or one block (the replay), so both give each stamp the same samples.

    Samples stamped not after the last row taken come too late and are dropped; the carried
    ones (stamped after it) are bounded by ``capacity``, the oldest dropped first. A row stamped
    before the last one starts a new time line (a looped bag): the samples carried from the
    old line are dropped.

    Attributes:
        taken: samples given to a row so far.
    """

    def __init__(self, most: int, capacity: int = 4096) -> None:
        """Args:
        most: the most samples a row takes (`samples_between`), >= 1.
        capacity: the most samples carried between rows, >= most.

        Raises:
            ConfigurationError: most < 1 or capacity < most.
        """
        if most < 1 or capacity < most:
            raise ConfigurationError(f'need 1 <= most <= capacity, got {most}, {capacity}')
        self._most = most
        self._capacity = capacity
        self._stamps = np.zeros(0, dtype=np.int64)
        self._values = np.zeros(0)
        self._new_stamps: list[int] = []
        self._new_values: list[float] = []
        self._after: int | None = None
        self.taken = 0

    def __len__(self) -> int:
        return self._stamps.shape[0] + len(self._new_stamps)

    def add(self, stamp_ns: int, value: float) -> None:
        """One sample (a message)."""
        self._new_stamps.append(stamp_ns)
        self._new_values.append(value)
        if len(self._new_stamps) > 2 * self._capacity:  # no row for long: keep the newest
            self._gather(trim=True)

    def add_many(self, stamps_ns: IntArray, values: FloatArray) -> None:
        """A block of samples, shape (M,) each."""
        self._gather()
        self._stamps = np.concatenate([self._stamps, np.asarray(stamps_ns, dtype=np.int64)])
        self._values = np.concatenate([self._values, np.asarray(values, dtype=np.float64)])

    def _gather(self, trim: bool = False) -> None:
        if self._new_stamps:
            stamps = np.concatenate([self._stamps, np.array(self._new_stamps, dtype=np.int64)])
            values = np.concatenate([self._values, np.array(self._new_values)])
            self._new_stamps, self._new_values = [], []
        else:
            stamps, values = self._stamps, self._values
        order = np.argsort(stamps, kind='stable')
        stamps, values = stamps[order], values[order]
        if self._after is not None:
            late = np.searchsorted(stamps, self._after, side='right')
            stamps, values = stamps[late:], values[late:]
        if trim:
            stamps, values = stamps[-self._capacity :], values[-self._capacity :]
        self._stamps, self._values = stamps, values

    def take(self, rows_ns: IntArray) -> tuple[FloatArray, FloatArray]:
        """The rows' samples (`samples_between`), and the rows are done.

        Args:
            rows_ns: shape (N,), int64 [ns], increasing.
        """
        rows = np.asarray(rows_ns, dtype=np.int64)
        if rows.shape[0] == 0:
            return np.zeros((0, self._most)), np.zeros((0, self._most))
        if rows.shape[0] == 1:
            return self.take_one(int(rows[0]))
        return self._take_rows(rows)

    def _take_rows(self, rows: IntArray) -> tuple[FloatArray, FloatArray]:
        """`take` on arrays (a block, or a row after a block or a jump back)."""
        if self._after is not None and rows[0] <= self._after:  # a new time line
            after, self._after = self._after, None
            self._gather()
            keep = np.searchsorted(self._stamps, after, side='right')  # the old line's: after
            self._stamps, self._values = self._stamps[:keep], self._values[:keep]
        self._gather()
        out = samples_between(self._stamps, self._values, rows, self._after, self._most)
        self.taken += int(np.count_nonzero(~np.isnan(out[0])))
        self._after = int(rows[-1])
        self._gather(trim=True)  # what the rows took is now too late
        return out

    def take_one(self, row_ns: int) -> tuple[FloatArray, FloatArray]:
        """`take` of one row stamped ``row_ns`` [ns]: shape (1, most) each.

        With the samples given one at a time (`add`: the live node, a few a stamp) in plain
        Python, without array work but the two rows returned.
        """
        if self._stamps.shape[0] or (self._after is not None and row_ns <= self._after):
            return self._take_rows(np.array([row_ns], dtype=np.int64))
        stamps, values, after = self._new_stamps, self._new_values, self._after
        # stable, as argsort (one sample: nothing to sort)
        order = [0] if len(stamps) == 1 else sorted(range(len(stamps)), key=stamps.__getitem__)
        due = [i for i in order if stamps[i] <= row_ns and (after is None or stamps[i] > after)]
        use = due[-self._most :]
        stamp = np.full((1, self._most), np.nan)
        sample = np.full((1, self._most), np.nan)
        for j, i in enumerate(use):
            stamp[0, j] = stamps[i] * 1e-9
            sample[0, j] = values[i]
        later = [i for i in order if stamps[i] > row_ns][-self._capacity :]
        self._new_stamps = [stamps[i] for i in later]
        self._new_values = [values[i] for i in later]
        self.taken += len(use)
        self._after = row_ns
        return stamp, sample
