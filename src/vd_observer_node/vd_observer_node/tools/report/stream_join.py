"""The streamed evaluation's reading and pairing: topic blocks, the scout, the stamp join.

:func:`iter_topic_blocks` reads a bag's topics in file order a block at a time;
:class:`Scout` counts what one pass sees (stamps, torque path, distance, the true slope steps,
gear changes and static loads) as it goes; :class:`StampJoin` pairs estimate and truth rows
by header stamp, holding a row only until every topic of the pair has passed its stamp.
Split from `stream` so that each stays small enough to read (#40).
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence

import numpy as np
from numpy.typing import NDArray
from vd_common.topics import (
    ESTIMATES_TIRE_FORCES,
    OBSERVER_BODY_VELOCITY,
    SENSORS_BODY_VELOCITY,
    TRUTH_SLOPE,
    TRUTH_TIRE_FORCES,
)

from vd_observer_node.bag.reader import BagReader, TopicArrays
from vd_observer_node.tools.report.alerts import (
    ALERT_KINDS,
)
from vd_observer_node.tools.report.errors import (
    StampOrderError,
)
from vd_observer_node.tools.report.evaluation import torque_path_note
from vd_observer_node.tools.report.load import TopicSeries, decode_topic
from vd_observer_node.tools.report.results import EvaluationSettings
from vd_observer_node.tools.report.topics import (
    ALERT_TOPIC,
    GEAR_TOPIC,
)

__all__ = [
    'DEFAULT_BLOCK_MESSAGES',
    'NEVER',
    'Paired',
    'Scout',
    'StampJoin',
    'iter_topic_blocks',
    'with_previous',
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
#: Rows paired on common stamps: (stamps (M,), topic -> field -> rows, optional topic -> (M,)
#: bool where it has the stamp).
Paired = tuple[np.ndarray, dict[str, dict[str, np.ndarray]], dict[str, BoolArray]]

#: Messages per block: ~20 topics x 10 k stamps; a few tens of MiB decoded.
DEFAULT_BLOCK_MESSAGES = 200_000
NEVER = np.iinfo(np.int64).max  # [ns] a join horizon past every stamp (end of the bag)


def iter_topic_blocks(
    reader: BagReader, topics: list[str], block_messages: int = DEFAULT_BLOCK_MESSAGES
) -> Iterator[dict[str, TopicSeries]]:
    """The bag's messages of ``topics`` in file order, at most ``block_messages`` at a time,
    decoded per topic (stamps in file order, not sorted).

    Reads with :meth:`BagReader.topic_array_blocks` (per-topic batches of whole chunks, so no
    per-message Python) and cuts each of its blocks into pieces of ``block_messages``,
    merged across topics by log time (each topic's running maximum, so a topic's own order is
    kept even where its log times go back).

    Args:
        reader: the bag.
        topics: topic names (report topics with their expected types).
        block_messages: messages per block (all topics together), >= 1.

    Raises:
        BagError: the bag cannot be read.
    """
    infos = reader.topics
    kinds = {t: (infos[t].msgtype, reader.decoding_type(t)) for t in topics}
    for arrays in reader.topic_array_blocks(topics, block_messages=block_messages):
        for piece in _pieces(arrays, block_messages):
            yield _decode(piece, kinds)


def _pieces(
    arrays: Mapping[str, TopicArrays], block_messages: int
) -> Iterator[dict[str, Sequence[bytes]]]:
    """One block of the reader cut into pieces of at most ``block_messages`` messages."""
    names = [t for t in arrays if arrays[t].datas]
    total = sum(len(arrays[t].datas) for t in names)
    if total <= block_messages:
        yield {t: arrays[t].datas for t in names}
        return
    keys = np.concatenate([np.maximum.accumulate(arrays[t].log_time_ns) for t in names])
    which = np.concatenate([np.full(len(arrays[t].datas), k) for k, t in enumerate(names)])
    order = np.argsort(keys, kind='stable')  # stable: a topic's rows stay in its order
    taken = [0] * len(names)
    for start in range(0, total, block_messages):
        counts = np.bincount(which[order[start : start + block_messages]], minlength=len(names))
        piece = {}
        for k, name in enumerate(names):
            if counts[k]:
                piece[name] = arrays[name].datas[taken[k] : taken[k] + int(counts[k])]
                taken[k] += int(counts[k])
        yield piece


def _decode(
    pending: dict[str, Sequence[bytes]], kinds: Mapping[str, tuple[str, str]]
) -> dict[str, TopicSeries]:
    out = {}
    for topic, datas in pending.items():
        fields_ = decode_topic(*kinds[topic], datas)
        out[topic] = TopicSeries(fields_.stamp_ns.astype(np.int64), dict(fields_.values))
    return out


def with_previous(previous: np.ndarray | None, values: np.ndarray) -> tuple[np.ndarray, int]:
    """``values`` behind the previous block's last row (if any), and that row count (0/1)."""
    if previous is None:
        return values, 0
    return np.concatenate([previous[None], values]), 1


# -- tallies and events ---------------------------------------------------------------------------


class _Distance:
    """[m] trapezoid integral of |speed| over the finite samples, as ``fleet.process`` does."""

    def __init__(self) -> None:
        self.first: int | None = None
        self.stamps = 0
        self.finite = 0
        self.total = 0.0
        self._last: tuple[float, float] | None = None  # (t [s], |v|) of the last finite sample

    def feed(self, stamps: np.ndarray, speed: np.ndarray) -> None:
        if self.first is None:
            self.first = int(stamps[0])
        self.stamps += stamps.size
        t = (stamps - self.first) * 1e-9
        v = speed.astype(np.float64)
        ok = np.isfinite(v)
        t, y = t[ok], np.abs(v[ok])
        self.finite += int(t.size)
        if self._last is not None:
            t = np.concatenate([[self._last[0]], t])
            y = np.concatenate([[self._last[1]], y])
        if t.size > 1:
            self.total += float(np.trapezoid(y, t))
        if t.size:
            self._last = (float(t[-1]), float(y[-1]))

    def result(self) -> float | None:
        return self.total if self.stamps >= 2 and self.finite > 1 else None


class Scout:
    """Per topic: stamps in order, first and last stamps, counts; the slope steps, gear
    changes and static loads found so far; the torque path, the distance and the alert
    activations."""

    def __init__(self, cfg: EvaluationSettings) -> None:
        self.cfg = cfg
        self.first: dict[str, int] = {}
        self.last: dict[str, int] = {}
        self.counts: dict[str, int] = {}
        self.slope_jumps_ns: list[int] = []
        self.gear_changes_ns: list[int] = []
        self.torque_codes: set[int] = set()
        self.torque_recorded = True
        self.distance = {OBSERVER_BODY_VELOCITY: _Distance(), SENSORS_BODY_VELOCITY: _Distance()}
        self.activations = np.zeros((len(ALERT_KINDS), 4), dtype=np.int64)
        self._slope: np.ndarray | None = None
        self._gear: np.ndarray | None = None
        self._level: np.ndarray | None = None
        self._loads: list[np.ndarray] = []
        self._loads_until: int | None = None

    def feed(self, block: Mapping[str, TopicSeries]) -> None:
        for topic, part in block.items():
            stamps = part.stamp_ns
            if stamps.size == 0:
                continue
            back = topic in self.last and int(stamps[0]) < self.last[topic]
            if back or bool(np.any(np.diff(stamps) < 0)):
                raise StampOrderError(f'{topic}: header stamps go backwards in file order')
            self.first.setdefault(topic, int(stamps[0]))
            self.last[topic] = int(stamps[-1])
            self.counts[topic] = self.counts.get(topic, 0) + int(stamps.size)
            self._take(topic, part)

    def _take(self, topic: str, part: TopicSeries) -> None:
        stamps, values = part.stamp_ns, part.values
        if topic == TRUTH_SLOPE:
            deg = np.degrees(values['angle'].astype(np.float64))
            ext, k = with_previous(self._slope, deg)
            jumps = np.flatnonzero(np.abs(np.diff(ext)) > self.cfg.slope_step_min_deg) + 1 - k
            self.slope_jumps_ns.extend(stamps[jumps].tolist())
            self._slope = deg[-1]
        elif topic == GEAR_TOPIC:
            gear = values['gear']
            ext, k = with_previous(self._gear, gear)
            changes = np.flatnonzero(ext[1:] != ext[:-1]) + 1 - k
            self.gear_changes_ns.extend(stamps[changes].tolist())
            self._gear = gear[-1]
        elif topic == TRUTH_TIRE_FORCES:
            if self._loads_until is None:
                self._loads_until = int(stamps[0]) + round(self.cfg.settle_s * 1e9)
            first = stamps <= self._loads_until
            if first.any():
                self._loads.append(values['fz'][first])
        elif topic == ESTIMATES_TIRE_FORCES:
            codes = values.get('torque_source')
            if codes is None:
                self.torque_recorded = False
            else:
                self.torque_codes.update(np.unique(codes).tolist())
        elif topic in self.distance:
            self.distance[topic].feed(stamps, values['twist.linear.x'])
        elif topic == ALERT_TOPIC:
            active = values['level'] > 0
            ext, k = with_previous(self._level, active)
            rising = ext[1:] & ~ext[:-1] if k else np.concatenate([ext[:1], ext[1:] & ~ext[:-1]])
            self.activations += rising.sum(axis=0)
            self._level = active[-1]

    def loads_known(self) -> bool:
        """The true forces of the first ``settle_s`` (the static loads) have all been read."""
        until = self._loads_until
        return until is not None and self.last.get(TRUTH_TIRE_FORCES, until) > until

    def static_loads(self) -> FloatArray | None:
        if not self._loads:
            return None
        loads: FloatArray = np.median(np.concatenate(self._loads).astype(np.float64), axis=0)
        return loads

    def torque_note(self) -> str:
        if ESTIMATES_TIRE_FORCES not in self.first:
            return ''
        if not self.torque_recorded:
            return torque_path_note(None)
        return torque_path_note(np.array(sorted(self.torque_codes)))


# -- pairing by stamp -----------------------------------------------------------------------------


class StampJoin:
    """Rows of several topics paired on equal header stamps while the blocks stream in.

    ``required`` topics are intersected (as ``np.intersect1d`` on the whole record: the first
    row of a repeated stamp); ``optional`` ones are attached where they have the stamp (a
    left join). A stamp is resolved once every topic has passed it, so rows wait only for
    the slowest topic of the join.
    """

    def __init__(self, required: tuple[str, ...], optional: tuple[str, ...] = ()) -> None:
        self.required = required
        self.optional = optional
        self.names = required + optional
        self._chunks: dict[str, list[TopicSeries]] = {n: [] for n in self.names}
        self._seen: dict[str, int] = {}
        self._done: int | None = None  # [ns] every stamp up to this one is resolved
        self._empty: dict[str, TopicSeries] = {}  # zero rows of each topic, with its fields

    def push(self, block: Mapping[str, TopicSeries]) -> None:
        for name in self.names:
            part = block.get(name)
            if part is None or part.stamp_ns.size == 0:
                continue
            self._seen[name] = int(part.stamp_ns[-1])
            self._empty.setdefault(name, _rows_of(part, slice(0, 0)))
            if self._done is not None:  # a repeat of a resolved stamp: the first one counted
                part = _rows_of(part, part.stamp_ns > self._done)
            self._chunks[name].append(part)

    def pop(self, final: bool) -> Paired | None:
        """Resolved rows: (common stamps (M,), topic -> field -> rows (M, ...), optional topic
        -> (M,) bool where it has the stamp (its rows are meaningless elsewhere)); None while
        a topic has not been seen (and not ``final``)."""
        if final:
            horizon = NEVER
        elif len(self._seen) < len(self.names):
            return None
        else:
            horizon = min(self._seen.values())
        parts: dict[str, TopicSeries] = {}
        for name in self.names:
            chunks = self._chunks[name]
            if not chunks:
                parts[name] = self._empty.get(name, TopicSeries(np.zeros(0, np.int64), {}))
                continue
            whole = _concat_series(chunks)
            cut = int(np.searchsorted(whole.stamp_ns, horizon, side='right'))
            rest = _rows_of(whole, slice(cut, None))
            self._chunks[name] = [rest] if rest.stamp_ns.size else []
            stamps = whole.stamp_ns[:cut]
            first = np.ones(stamps.size, dtype=bool)  # the first row of a repeated stamp
            first[1:] = stamps[1:] != stamps[:-1]
            parts[name] = _rows_of(_rows_of(whole, slice(0, cut)), first)
        self._done = horizon
        common = parts[self.required[0]].stamp_ns
        for name in self.required[1:]:
            common = np.intersect1d(common, parts[name].stamp_ns, assume_unique=True)
        rows: dict[str, dict[str, np.ndarray]] = {}
        for name in self.required:
            at = np.searchsorted(parts[name].stamp_ns, common)
            rows[name] = {k: v[at] for k, v in parts[name].values.items()}
        present: dict[str, BoolArray] = {}
        for name in self.optional:
            stamps = parts[name].stamp_ns
            if stamps.size == 0:
                present[name] = np.zeros(common.size, dtype=bool)
                rows[name] = {
                    k: np.zeros((common.size, *v.shape[1:]), v.dtype)
                    for k, v in parts[name].values.items()
                }
                continue
            at = np.minimum(np.searchsorted(stamps, common), stamps.size - 1)
            present[name] = stamps[at] == common
            rows[name] = {k: v[at] for k, v in parts[name].values.items()}
        return common, rows, present


def _concat_series(chunks: list[TopicSeries]) -> TopicSeries:
    if len(chunks) == 1:
        return chunks[0]
    return TopicSeries(
        np.concatenate([c.stamp_ns for c in chunks]),
        {k: np.concatenate([c.values[k] for c in chunks]) for k in chunks[0].values},
    )


def _rows_of(series: TopicSeries, rows: slice | np.ndarray) -> TopicSeries:
    return TopicSeries(series.stamp_ns[rows], {k: v[rows] for k, v in series.values.items()})


# -- accuracy of the estimated quantities ---------------------------------------------------------
