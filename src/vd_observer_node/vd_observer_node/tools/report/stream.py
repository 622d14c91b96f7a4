"""Streamed evaluation of one bag: the report's figures in memory bounded by a block.

:func:`evaluate_bag` gives the same :class:`~.evaluation.AccuracyReport` as
``evaluate(load_bag_series(bag))`` (the reference, kept for ``vd report`` and its figures)
without holding the bag's series: it reads the bag in file order, in blocks of
``block_messages`` messages decoded per topic (:func:`iter_topic_blocks`).

* A first look reads each topic's first message only (t = 0 is the earliest stamp).
* One pass then reads every topic: it checks the stamps' order and counts them (the last
  stamp, the torque path, and for ``vd fleet`` the distance and the alert activations), finds
  the true slope steps, gear changes and static loads as they come (:class:`_Scout`), pairs
  estimate and truth by header stamp (:class:`_StampJoin`: rows wait only until every topic
  of the pair has passed their stamp), holds the paired rows until the events that could
  exclude them are known (a sample within +-0.5 s of a step or shift is excluded, also one
  *before* it: rows wait until the slope truth and the gear are 0.5 s past them, and for the
  first second's true forces), then adds them into running sums (:class:`_StatsSum`: sums
  of squares, sums, maxima, counts) and the slope convergence trackers; the alert-episode
  state machines (:class:`_AlertStream`: ~2 s of rows either side of the rows being scored,
  since a false alarm and a detection look up to 1 s back and ahead) and the μ_max
  accumulators per axle and road segment take the paired alert rows.

Memory: one block of raw and decoded messages, the rows of the pairs still waiting for their
partner (none in a replayed bag: the topics of one stamp are written together) or for the
events (~0.5 s), ~4 s of alert rows, and the results (episodes, segments, events) - not the
bag's length.

Figures equal the reference's exactly where they are counts, times, maxima or per-sample
decisions; means and RMS values add the samples in another order (blocks, not numpy's pairwise
summation of the whole record) and agree to ~1e-12 relative. Not produced: the comparisons
(whole time series) for the figures, the mapped inputs' summary (``vd report --mapping``), and
a reference on its own clock interpolated onto the estimates (a real car's; ``vd report``
does it, ``EvaluationSettings.reference_max_gap_s``): here estimate and truth pair by stamp
only, as a simulator's recordings do.
Header stamps must not go backwards within a topic (:class:`StampOrderError` otherwise: the
caller falls back to the whole-bag path, which sorts).
"""

from __future__ import annotations

import itertools
import math
import os
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field, fields, replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from vd_common.topics import (
    ESTIMATES_FRICTION,
    ESTIMATES_TIRE_FORCES,
    OBSERVER_BODY_VELOCITY,
    SENSORS_BODY_VELOCITY,
    TRUTH_NAMESPACE,
    TRUTH_SLOPE,
    TRUTH_TIRE_FORCES,
)

from vd_observer_node.bag.reader import BagReader, TopicArrays
from vd_observer_node.tools.report.alerts import (
    ALERT_KINDS,
    NO_COMMON_STAMP,
    AlertData,
    AlertEpisode,
    AlertSettings,
    AlertsSection,
    FalseAlarm,
    MuMaxSegment,
    activation_indices,
    alert_data_notes,
    alert_section_skip,
    alert_section_topics,
    alerts_section,
    axle_utilisation,
    channel_episodes,
    data_conditions,
    false_alarms,
    paired_alert_data,
    segments_from_peaks,
)
from vd_observer_node.tools.report.errors import (
    ReferenceClockError,
    ReportInputError,
    StampOrderError,
)
from vd_observer_node.tools.report.evaluation import (
    _SPECS,
    AccuracyReport,
    EvaluationSettings,
    QuantityMetrics,
    SlopeConvergence,
    _Spec,
    _targets,
    closing_notes,
    quantity_note,
    torque_path_note,
)
from vd_observer_node.tools.report.load import TopicSeries, decode_topic, select_report_topics
from vd_observer_node.tools.report.metrics import (
    ErrorStats,
    evaluation_mask,
    merge_times,
    selected_errors,
)
from vd_observer_node.tools.report.topics import (
    ALERT_TOPIC,
    ESTIMATED_POTENTIAL_TOPIC,
    GEAR_TOPIC,
    TRUE_POTENTIAL_TOPIC,
    TRUTH_TOPICS,
)

__all__ = ['DEFAULT_BLOCK_MESSAGES', 'StreamedEvaluation', 'evaluate_bag', 'iter_topic_blocks']

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
#: Rows paired on common stamps: (stamps (M,), topic -> field -> rows, optional topic -> (M,)
#: bool where it has the stamp).
_Paired = tuple[np.ndarray, dict[str, dict[str, np.ndarray]], dict[str, BoolArray]]

#: Messages per block: ~20 topics x 10 k stamps; a few tens of MiB decoded.
DEFAULT_BLOCK_MESSAGES = 200_000
_NEVER = np.iinfo(np.int64).max  # [ns] a join horizon past every stamp (end of the bag)
_STEP_MERGE_S = 0.5  # [s] metrics.step_times' default merge window (the reference's)


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


def _with_previous(previous: np.ndarray | None, values: np.ndarray) -> tuple[np.ndarray, int]:
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


class _Scout:
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
            ext, k = _with_previous(self._slope, deg)
            jumps = np.flatnonzero(np.abs(np.diff(ext)) > self.cfg.slope_step_min_deg) + 1 - k
            self.slope_jumps_ns.extend(stamps[jumps].tolist())
            self._slope = deg[-1]
        elif topic == GEAR_TOPIC:
            gear = values['gear']
            ext, k = _with_previous(self._gear, gear)
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
            ext, k = _with_previous(self._level, active)
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


class _StampJoin:
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

    def pop(self, final: bool) -> _Paired | None:
        """Resolved rows: (common stamps (M,), topic -> field -> rows (M, ...), optional topic
        -> (M,) bool where it has the stamp (its rows are meaningless elsewhere)); None while
        a topic has not been seen (and not ``final``)."""
        if final:
            horizon = _NEVER
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


class _StatsSum:
    """Running :class:`ErrorStats` of the selected finite elements (``metrics.error_stats``)."""

    def __init__(self) -> None:
        self.squares = 0.0
        self.total = 0.0
        self.max_abs = -math.inf
        self.samples = 0

    def add(self, error: FloatArray, mask: BoolArray | None) -> None:
        values = selected_errors(error, mask)
        if values.size:
            self.squares += float(np.sum(np.square(values)))
            self.total += float(np.sum(values))
            self.max_abs = max(self.max_abs, float(np.max(np.abs(values))))
            self.samples += int(values.size)

    def result(self) -> ErrorStats:
        if self.samples == 0:
            return ErrorStats(math.nan, math.nan, math.nan, 0)
        n = self.samples
        return ErrorStats(math.sqrt(self.squares / n), self.max_abs, self.total / n, n)


@dataclass
class _Events:
    """What the verdict of a sample depends on, as far as the bag has been read: the true
    slope steps and gear changes [s] (``events`` = both) and the static loads [N]."""

    steps: FloatArray = field(default_factory=lambda: np.zeros(0))
    gears: FloatArray = field(default_factory=lambda: np.zeros(0))
    events: FloatArray = field(default_factory=lambda: np.zeros(0))
    loads: FloatArray | None = None


class _Convergence:
    """Slope convergence after each true step, as ``metrics.convergence_times`` and
    ``evaluation._convergence`` take it, from the compared slope samples in stamp order.

    Steps are added as they are found; samples come only once every step up to them is known
    (so a new step lies after every sample seen: the one before it is the last seen)."""

    def __init__(self, known: _Events, cfg: EvaluationSettings) -> None:
        self.known = known
        self.cfg = cfg
        self.steps: list[float] = []
        self.delays: list[float | None] = []
        self._open: list[float | None] = []  # start of a good stretch
        self._before: list[float | None] = []
        self._after: list[float | None] = []
        self._first: float | None = None
        self._last: float | None = None

    def feed(self, t: FloatArray, estimate: FloatArray, truth: FloatArray) -> None:
        for step in self.known.steps.tolist()[len(self.steps) :]:
            self.steps.append(step)
            self.delays.append(None)
            self._open.append(None)
            self._before.append(self._last)
            self._after.append(None)
        if t.size == 0 or not self.steps:
            if t.size:
                self._first = float(truth[0]) if self._first is None else self._first
                self._last = float(truth[-1])
            return
        if self._first is None:
            self._first = float(truth[0])
        ok = np.abs(estimate - truth) < self.cfg.convergence_threshold_deg
        stops = [*self.steps[1:], math.inf]
        for i, (start, stop) in enumerate(zip(self.steps, stops, strict=True)):
            k = int(np.searchsorted(t, start))  # first sample at or after the step
            if k > 0:
                self._before[i] = float(truth[k - 1])
            if k < t.size and self._after[i] is None:
                self._after[i] = float(truth[k])
            if self.delays[i] is not None:
                continue
            window = (t >= start) & (t < stop)
            if window.any():
                self._stretches(i, start, t[window], ok[window])
        self._last = float(truth[-1])

    def _stretches(self, i: int, start: float, tw: FloatArray, ok: BoolArray) -> None:
        edges = np.diff(np.concatenate(([0], ok.astype(np.int8), [0])))
        firsts = np.flatnonzero(edges == 1)
        lasts = np.flatnonzero(edges == -1) - 1
        begin = tw[firsts]
        if firsts.size and firsts[0] == 0 and self._open[i] is not None:
            begin[0] = self._open[i]  # the stretch goes on from the previous block
        long_enough = tw[lasts] - begin >= self.cfg.convergence_hold_s - 1e-9
        if long_enough.any():
            self.delays[i] = float(begin[np.argmax(long_enough)] - start)
        open_at_end = lasts.size > 0 and lasts[-1] == tw.size - 1
        self._open[i] = float(begin[-1]) if open_at_end else None

    def result(self) -> list[SlopeConvergence]:
        out = []
        for i, step in enumerate(self.steps):
            before = self._before[i] if self._before[i] is not None else self._first
            after = self._after[i] if self._after[i] is not None else self._last
            assert before is not None and after is not None
            out.append(SlopeConvergence(step, before, after, self.delays[i]))
        return out


class _Quantity:
    """One estimated quantity against its truth: ``evaluate``'s metrics, streamed."""

    def __init__(self, spec: _Spec, cfg: EvaluationSettings, t0: int, known: _Events) -> None:
        self.spec, self.cfg, self.t0, self.known = spec, cfg, t0, known
        self.rows = 0
        self.overall = _StatsSum()
        self.wheels = [_StatsSum() for _ in range(4)]
        self.per_wheel = False
        self.relative = _StatsSum()  # omega: |error| / |truth|; fz: error / static load
        self.spinning_error = _StatsSum()  # omega: the error where the wheel spins
        self.spinning_truth = _StatsSum()  # omega: the truth on the same samples
        self.peak = -math.inf  # fx: max |true Fx| in the window
        self.peak_seen = False
        self.base = _StatsSum()  # slope: every sample of the window, valid or not
        self.base_count = 0
        self.mask_count = 0
        self.convergence = _Convergence(known, cfg) if spec.key == 'slope' else None

    def feed(
        self,
        stamps: np.ndarray,
        rows: Mapping[str, Mapping[str, np.ndarray]],
        present: Mapping[str, BoolArray],
    ) -> None:
        spec, cfg = self.spec, self.cfg
        est, truth = rows[spec.est_topic], rows[spec.truth_topic]
        estimate = est[spec.field].astype(np.float64) * spec.factor
        true = truth[spec.field].astype(np.float64) * spec.factor
        self.rows += stamps.size
        self.per_wheel = estimate.ndim == 2
        t = (stamps - self.t0) * 1e-9
        mask = evaluation_mask(
            t, start=cfg.settle_s, events=self.known.events, half_width=cfg.exclusion_half_width_s
        )
        base = mask
        loads = self.known.loads
        if spec.key == 'mu':
            valid = est['valid'].astype(bool)
            excited = np.zeros(valid.shape, dtype=bool)
            if TRUTH_TIRE_FORCES in present:
                has = present[TRUTH_TIRE_FORCES]
                forces = rows[TRUTH_TIRE_FORCES]
                fx, fz = forces['fx'][has], forces['fz'][has]
                excited[has] = np.abs(fx) > cfg.mu_excitation * fz
            mask = mask[:, None] & excited & valid
        elif spec.key == 'slope':
            mask = mask & est['valid'].astype(bool)
        error = estimate - true
        self.overall.add(error, mask)
        if self.per_wheel:
            for k in range(4):
                self.wheels[k].add(error[:, k], mask if mask.ndim == 1 else mask[:, k])
        row_mask = np.broadcast_to(mask if mask.ndim == true.ndim else mask[:, None], true.shape)
        if spec.key == 'omega':
            # the RMS of the error over the RMS of the truth, as `evaluation._extras`
            spinning = row_mask & (np.abs(true) > cfg.omega_min) & np.isfinite(error)
            with np.errstate(divide='ignore', invalid='ignore'):
                ratio = np.abs(error) / np.abs(true)
            self.relative.add(ratio, spinning)
            self.spinning_error.add(error, spinning)
            self.spinning_truth.add(true, spinning)
        elif spec.key == 'fx' and row_mask.any():
            self.peak = float(np.maximum(self.peak, np.abs(true[row_mask]).max()))
            self.peak_seen = True
        elif spec.key == 'fz' and loads is not None:
            with np.errstate(divide='ignore', invalid='ignore'):
                ratio = error / loads[None, :]
            self.relative.add(ratio, row_mask)
        elif spec.key == 'slope':
            self.base.add(error, base)
            self.base_count += int(base.sum())
            self.mask_count += int(mask.sum())
            assert self.convergence is not None
            self.convergence.feed(t, estimate, true)

    def result(self) -> QuantityMetrics:
        spec, cfg = self.spec, self.cfg
        overall = self.overall.result()
        wheels = tuple(w.result() for w in self.wheels) if self.per_wheel else ()
        extras: dict[str, float] = {}
        if spec.key == 'omega':
            rel = self.relative.result()
            extras['rel_rms_pct'] = (
                100.0 * self.spinning_error.result().rms / self.spinning_truth.result().rms
            )
            extras['rel_max_pct'] = 100.0 * rel.max_abs
        elif spec.key == 'fx':
            peak = self.peak if self.peak_seen else math.nan
            extras['max_abs_truth'] = peak
            rms = overall.rms
            extras['rms_pct_of_max_truth'] = 100.0 * rms / peak if peak > 0 else math.nan
        elif spec.key == 'fz' and self.known.loads is not None:
            rel = self.relative.result()
            extras['rms_pct_of_static'] = 100.0 * rel.rms
            extras['max_pct_of_static'] = 100.0 * rel.max_abs
            loads = self.known.loads.tolist()
            for name, load in zip(('FL', 'FR', 'RL', 'RR'), loads, strict=True):
                extras[f'static_load_{name}'] = load
        elif spec.key == 'slope':
            extras['valid_pct'] = 100.0 * float(self.mask_count) / max(self.base_count, 1)
            extras['rms_incl_invalid'] = self.base.result().rms
        note = quantity_note(spec.key, cfg, overall.samples)
        return QuantityMetrics(spec.key, spec.title, spec.unit, overall, wheels, extras, note)


# -- alerts and μ_max -----------------------------------------------------------------------------


def _concat_data(a: AlertData | None, b: AlertData) -> AlertData:
    if a is None:
        return b
    return replace(
        a,
        **{
            f.name: np.concatenate([getattr(a, f.name), getattr(b, f.name)])
            for f in fields(a)
            if getattr(a, f.name) is not None
        },
    )


def _tail(a: AlertData, start: int) -> AlertData:
    return replace(
        a,
        **{
            f.name: getattr(a, f.name)[start:] for f in fields(a) if getattr(a, f.name) is not None
        },
    )


@dataclass
class _AxleSegment:
    """Running μ_max figures of one axle over one road segment (``alerts.mu_max_errors``)."""

    excited_s: float | None = None
    last_excited: float = -math.inf
    n: int = 0
    truth_sum: float = 0.0
    estimate_sum: float = 0.0
    squares: float = 0.0
    max_abs: float = -math.inf
    within: int = 0
    last_miss: float | None = None
    confidence_sum: float = 0.0
    classes: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    true_classes: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    recent_n: int = 0
    recent_squares: float = 0.0
    recent_within: int = 0

    def feed(
        self,
        t: FloatArray,
        util: FloatArray,
        truth: FloatArray,
        est: FloatArray,
        conf: FloatArray,
        klass: np.ndarray,
        tclass: np.ndarray,
        cfg: AlertSettings,
    ) -> None:
        excited_mask = util >= cfg.excitation_ratio
        last = np.maximum.accumulate(np.where(excited_mask, t, -np.inf))
        last = np.maximum(last, self.last_excited)
        self.last_excited = float(last[-1])
        if self.excited_s is None:
            excited = np.flatnonzero(excited_mask)
            if excited.size == 0:
                return
            self.excited_s = float(t[excited[0]])
            begin = int(excited[0])
        else:
            begin = 0
        recent = (t - last <= cfg.excitation_window_s) & (
            t >= self.excited_s + cfg.excitation_start_s
        )
        err_recent = est[recent] - truth[recent]
        self.recent_n += int(err_recent.size)
        self.recent_squares += float(np.sum(err_recent**2))
        self.recent_within += int(np.sum(np.abs(err_recent) <= cfg.mu_max_goal))
        err = est[begin:] - truth[begin:]
        within = np.abs(err) <= cfg.mu_max_goal
        bad = np.flatnonzero(~within)
        self.n += int(err.size)
        self.truth_sum += float(np.sum(truth[begin:]))
        self.estimate_sum += float(np.sum(est[begin:]))
        self.squares += float(np.sum(err**2))
        self.max_abs = float(np.maximum(self.max_abs, np.abs(err).max()))
        self.within += int(within.sum())
        if bad.size:
            self.last_miss = float(t[begin:][bad[-1]])
        self.confidence_sum += float(np.sum(conf[begin:]))
        self.classes = _add_counts(self.classes, klass[begin:])
        self.true_classes = _add_counts(self.true_classes, tclass[begin:])

    def result(self, axle: int, start_index: int, start_s: float, end_s: float) -> MuMaxSegment:
        assert self.excited_s is not None
        has_recent = self.recent_n > 0
        return MuMaxSegment(
            axle=axle,
            start_index=start_index,
            start_s=start_s,
            end_s=end_s,
            excited_s=self.excited_s,
            true_mu_max=self.truth_sum / self.n,
            true_road_class=int(self.true_classes.argmax()),
            recent_samples=self.recent_n,
            recent_rms=math.sqrt(self.recent_squares / self.recent_n) if has_recent else math.nan,
            recent_within_pct=(
                100.0 * self.recent_within / self.recent_n if has_recent else math.nan
            ),
            estimate_mean=self.estimate_sum / self.n,
            max_abs=self.max_abs,
            rms=math.sqrt(self.squares / self.n),
            within_pct=100.0 * self.within / self.n,
            last_miss_s=self.last_miss - self.excited_s if self.last_miss is not None else 0.0,
            confidence_mean=self.confidence_sum / self.n,
            road_class=int(self.classes.argmax()),
        )


def _add_counts(counts: np.ndarray, codes: np.ndarray) -> np.ndarray:
    more = np.bincount(codes)
    size = max(counts.size, more.size)
    return np.pad(counts, (0, size - counts.size)) + np.pad(more, (0, size - more.size))


@dataclass
class _Channel:
    last_start: float | None = None  # [s] the last raw onset (episodes merge against it)
    episodes: list[AlertEpisode] = field(default_factory=list)
    alarms: list[FalseAlarm] = field(default_factory=list)


class _AlertStream:
    """The alerts section from the paired rows in stamp order.

    Rows are scored once the stream is ``lookahead`` past them (an activation is excused by
    relaxed truth up to 0.1 s after it, an onset is detected up to 1 s after it), with
    ``lookback`` of earlier rows kept as context (activations 1 s before an onset, relaxed
    truth 0.5 s before an activation) plus the row before those (edges need it).
    """

    def __init__(self, cfg: AlertSettings, judged: bool, mu_max: bool) -> None:
        self.cfg = cfg
        self.judged = judged
        self.mu_max = mu_max
        self.lookback = max(cfg.early_s, cfg.false_before_s) + 1.0
        self.lookahead = max(cfg.false_after_s, cfg.max_delay_s) + 1.0
        self.buffer: AlertData | None = None
        self.todo = 0  # first row of the buffer not yet scored
        self.first_row_is_first = True  # the buffer starts at the stream's first row
        self.rows = 0  # rows scored
        self.channels = [[_Channel() for _ in range(4)] for _ in ALERT_KINDS]
        self.segments: list[list[MuMaxSegment]] = [[], []]
        self._segment: tuple[int, float, float] | None = None  # (start index, start_s, end_s)
        self._axles = [_AxleSegment(), _AxleSegment()]
        self._previous_peak: np.ndarray | None = None

    def feed(self, data: AlertData) -> None:
        """Add paired rows (after the earlier ones) and score those far enough behind."""
        self.buffer = _concat_data(self.buffer, data)
        self._score(final=False)

    def finish(self) -> None:
        """Score the rows left at the end of the bag."""
        self._score(final=True)

    def _score(self, final: bool) -> None:
        buf = self.buffer
        if buf is None or buf.t.size == 0:
            return
        tt = buf.t
        limit = math.inf if final else float(tt[-1]) - self.lookahead
        stop = int(np.searchsorted(tt, limit, side='right'))
        if stop <= self.todo:
            return
        if self.mu_max:
            self._mu_max(buf, self.todo, stop)
        if self.judged:
            self._episodes(buf, self.todo, stop)
        self.rows += stop - self.todo
        keep = max(0, int(np.searchsorted(tt, tt[stop - 1] - self.lookback, side='left')) - 1)
        self.buffer = _tail(buf, keep)
        self.todo = stop - keep
        self.first_row_is_first = self.first_row_is_first and keep == 0

    def _episodes(self, d: AlertData, lo: int, hi: int) -> None:
        cfg, tt = self.cfg, d.t
        assert d.level is not None
        truth, relaxed = data_conditions(d, cfg)
        floor = 0 if self.first_row_is_first else 1  # row 0 of a trimmed buffer has no edge
        for kind, name in enumerate(ALERT_KINDS):
            for wheel in range(4):
                ch = self.channels[kind][wheel]
                idx = activation_indices(d.level[:, kind, wheel])
                idx = idx[idx >= floor]
                acts = tt[idx]
                scored = acts[(idx >= lo) & (idx < hi)]
                for stamp in false_alarms(tt, scored, relaxed[:, kind, wheel], cfg).tolist():
                    ch.alarms.append(FalseAlarm(name, wheel, stamp))
                rising = activation_indices(truth[:, kind, wheel] & (tt >= cfg.settle_s))
                starts = tt[rising[(rising >= max(lo, floor)) & (rising < hi)]]
                if starts.size == 0:
                    continue
                previous = [] if ch.last_start is None else [ch.last_start]
                chain = np.concatenate([previous, starts])
                keep = np.diff(chain) > cfg.merge_s
                if ch.last_start is None:
                    keep = np.concatenate([[True], keep])
                ch.last_start = float(starts[-1])
                onsets = starts[keep]
                ons = None if d.onset is None else d.onset[:, kind, wheel]
                level = d.level[:, kind, wheel]
                ch.episodes.extend(
                    channel_episodes(name, wheel, tt, onsets, acts, level, ons, cfg)
                )

    def _mu_max(self, d: AlertData, lo: int, hi: int) -> None:
        assert d.mu_max is not None and d.confidence is not None and d.road_class is not None
        peaks = d.true_mu_max[lo:hi]
        ext, k = _with_previous(self._previous_peak, peaks)
        jumps = (segments_from_peaks(ext, self.cfg.road_jump)[1:] - k).tolist()
        cuts = jumps if self._segment is not None else [0, *jumps]
        self._previous_peak = peaks[-1]
        util = axle_utilisation(d.mu[lo:hi], d.peak_mu[lo:hi])
        t = d.t[lo:hi]
        edges = sorted({0, *cuts, hi - lo})
        for a, b in itertools.pairwise(edges):
            if a in cuts:  # a new road segment starts at row a
                self._close()
                self._segment = (self.rows + a, float(t[a]), float(t[b - 1]))
            else:
                assert self._segment is not None
                self._segment = (self._segment[0], self._segment[1], float(t[b - 1]))
            for axle in range(2):
                self._axles[axle].feed(
                    t[a:b],
                    util[a:b, axle],
                    d.true_mu_max[lo + a : lo + b, axle],
                    d.mu_max[lo + a : lo + b, axle],
                    d.confidence[lo + a : lo + b, axle],
                    d.road_class[lo + a : lo + b, axle],
                    d.true_road_class[lo + a : lo + b, axle],
                    self.cfg,
                )

    def _close(self) -> None:
        if self._segment is not None:
            for axle in range(2):
                if self._axles[axle].excited_s is not None:
                    self.segments[axle].append(self._axles[axle].result(axle, *self._segment))
        self._axles = [_AxleSegment(), _AxleSegment()]
        self._segment = None

    def result(self, notes: tuple[str, ...]) -> AlertsSection:
        self._close()
        episodes = [e for kind in self.channels for ch in kind for e in ch.episodes]
        alarms = [a for kind in self.channels for ch in kind for a in ch.alarms]
        segments = [*self.segments[0], *self.segments[1]]
        return alerts_section(self.cfg, self.rows, self.judged, episodes, alarms, segments, notes)


# -- the evaluation ---------------------------------------------------------------------------


@dataclass(frozen=True)
class StreamedEvaluation:
    """What one streamed evaluation found.

    Attributes:
        report: the accuracy report (as :func:`~.evaluation.evaluate`'s), or None when the bag
            has no truth (``no_report`` says why).
        no_report: the :class:`ReportInputError` message when ``report`` is None, else ''.
        topics: the report topics with messages, in the vd contract's order.
        first_stamp_ns: [ns] earliest header stamp of those topics.
        last_stamp_ns: [ns] latest one.
        distance_m: [m] integral of |body speed| (observer's, else the sensor's), None
            without one (as ``vd fleet`` reports it).
        activations: per alert kind, OK -> active transitions summed over the wheels; None
            without an alerts topic.
    """

    report: AccuracyReport | None
    no_report: str
    topics: tuple[str, ...]
    first_stamp_ns: int
    last_stamp_ns: int
    distance_m: float | None
    activations: dict[str, int] | None


def evaluate_bag(
    path: str | os.PathLike[str],
    *,
    settings: EvaluationSettings | None = None,
    static_loads: FloatArray | None = None,
    alert_settings: AlertSettings | None = None,
    block_messages: int = DEFAULT_BLOCK_MESSAGES,
) -> StreamedEvaluation:
    """The report's figures of a bag, streamed (see the module docstring).

    Args:
        path: bag folder or .mcap file.
        settings: evaluation settings; default :class:`EvaluationSettings`.
        static_loads: shape (4,), [N]; default the median true Fz of the first ``settle_s``.
        alert_settings: definitions of the alerts section; default :class:`AlertSettings`.
        block_messages: messages decoded at a time (memory vs. Python overhead), >= 1.

    Raises:
        BagError: the bag cannot be read.
        ReportInputError: none of the vd topics is in the bag.
        StampOrderError: a topic's header stamps go backwards (use the whole-bag path).
        ReferenceClockError: a reference runs on its own clock (use the whole-bag path, which
            interpolates it as ``vd report`` does).
        ValueError: ``block_messages`` < 1.
    """
    if block_messages < 1:
        raise ValueError(f'block_messages must be >= 1, got {block_messages}')
    cfg = settings or EvaluationSettings()
    reader = BagReader(path)
    skipped: dict[str, str] = {}
    selected = select_report_topics(reader, skipped)
    first = _first_stamps(reader, selected)
    present = [name for name in selected if name in first]
    skipped.update({name: 'no messages' for name in selected if name not in first})
    if not present:
        raise ReportInputError(f'{Path(path)}: none of the vd topics found in the bag')
    t0 = min(first.values())
    tally = _Scout(cfg)
    report: AccuracyReport | None = None
    no_report = ''
    try:
        report = _the_pass(
            reader,
            path,
            tally,
            present,
            skipped,
            t0,
            cfg,
            static_loads,
            alert_settings,
            block_messages,
        )
    except ReportInputError as exc:
        no_report = str(exc)
    last = max(tally.last.values())
    speed = next((d for d in tally.distance.values() if d.first is not None), None)
    activations = None
    if ALERT_TOPIC in tally.first:
        activations = {kind: int(tally.activations[k].sum()) for k, kind in enumerate(ALERT_KINDS)}
    return StreamedEvaluation(
        report,
        no_report,
        tuple(present),
        t0,
        last,
        None if speed is None else speed.result(),
        activations,
    )


def _first_stamps(reader: BagReader, topics: list[str]) -> dict[str, int]:
    """[ns] header stamp of each topic's first message in file order (topics without a
    message left out); reads only as far as every topic has been seen."""
    first: dict[str, int] = {}
    for topic, msgtype, _, data, _ in reader.raw_messages(topics):
        if topic not in first:
            fields_ = decode_topic(msgtype, reader.decoding_type(topic), [data])
            first[topic] = int(fields_.stamp_ns[0])
            if len(first) == len(topics):
                break
    return first


def _delayed_rows(queue: list[_Paired], horizon: int) -> list[_Paired]:
    """Take the paired rows with stamps up to ``horizon`` [ns] out of ``queue`` (in order)."""
    out = []
    while queue:
        stamps, rows, present = queue[0]
        cut = int(np.searchsorted(stamps, horizon, side='right'))
        if cut == stamps.size:
            out.append(queue.pop(0))
            continue
        take = slice(0, cut)
        keep = slice(cut, None)
        out.append(
            (
                stamps[take],
                {n: {k: v[take] for k, v in r.items()} for n, r in rows.items()},
                {n: v[take] for n, v in present.items()},
            )
        )
        queue[0] = (
            stamps[keep],
            {n: {k: v[keep] for k, v in r.items()} for n, r in rows.items()},
            {n: v[keep] for n, v in present.items()},
        )
        break
    return out


def _the_pass(
    reader: BagReader,
    path: str | os.PathLike[str],
    tally: _Scout,
    present: list[str],
    skipped: dict[str, str],
    t0: int,
    cfg: EvaluationSettings,
    static_loads: FloatArray | None,
    alert_settings: AlertSettings | None,
    block_messages: int,
) -> AccuracyReport:
    """The pass over every topic: the tally (``tally``) and, with truth, the report.

    Paired rows wait (:func:`_delayed_rows`) until the events that may exclude them are known:
    the slope truth and the gear have passed their stamp + ``exclusion_half_width_s`` (+1 ms
    against rounding), and the first ``settle_s`` of true forces (the static loads) are read.

    Raises:
        ReportInputError: no truth topic (after the pass: the tally is complete).
        StampOrderError: a topic's stamps go backwards.
    """
    have = set(present)
    if not any(t in have for t in TRUTH_TOPICS):
        for block in iter_topic_blocks(reader, present, block_messages):
            tally.feed(block)
        raise ReportInputError(
            f'{Path(path)}: no truth topics (need at least one of {TRUTH_NAMESPACE}*: '
            + ', '.join(name.rsplit('/', 1)[1] for name in TRUTH_TOPICS)
            + ')'
        )
    known = _Events(loads=static_loads)
    margin_ns = round(cfg.exclusion_half_width_s * 1e9) + 1_000_000
    event_topics = [t for t in (TRUTH_SLOPE, GEAR_TOPIC) if t in have]

    def horizon(final: bool) -> int:
        """[ns] stamps up to this are judged for good; refreshes ``known``."""
        jumps = (np.array(tally.slope_jumps_ns, dtype=np.int64) - t0) * 1e-9
        known.steps = merge_times(jumps.astype(np.float64), _STEP_MERGE_S)
        known.gears = ((np.array(tally.gear_changes_ns, dtype=np.int64) - t0) * 1e-9).astype(
            np.float64
        )
        known.events = np.concatenate([known.steps, known.gears])
        loads_pending = static_loads is None and known.loads is None
        if loads_pending and (final or tally.loads_known()):
            known.loads = tally.static_loads()
        if final:
            return _NEVER
        if loads_pending and TRUTH_TIRE_FORCES in have and not tally.loads_known():
            return -1
        seen = [tally.last.get(t) for t in event_topics]
        if any(s is None for s in seen):
            return -1
        return min([_NEVER, *[int(s) - margin_ns for s in seen if s is not None]])

    # one join per (estimate, truth) pair; μ also needs the true forces where they exist
    joins: dict[tuple[str, str], tuple[_StampJoin, list[_Quantity]]] = {}
    waiting: dict[tuple[str, str], list[_Paired]] = {}
    notes: list[str] = []
    for spec in _SPECS:
        has_est, has_truth = spec.est_topic in have, spec.truth_topic in have
        if has_est and has_truth:
            key = (spec.est_topic, spec.truth_topic)
            if key not in joins:
                forces = spec.est_topic == ESTIMATES_FRICTION and TRUTH_TIRE_FORCES in have
                optional: tuple[str, ...] = (TRUTH_TIRE_FORCES,) if forces else ()
                joins[key] = (_StampJoin(key, optional), [])
                waiting[key] = []
            joins[key][1].append(_Quantity(spec, cfg, t0, known))
    truth_topic = next(t for t in TRUTH_TOPICS if t in have)
    window = [0, 0]  # evaluated, all samples of the first truth topic
    truth_waiting: list[np.ndarray] = []
    section_skip = alert_section_skip(have)
    alerts: _AlertStream | None = None
    alert_join: _StampJoin | None = None
    acfg = alert_settings or AlertSettings()
    if not section_skip:
        section_topics = tuple(alert_section_topics(have))
        alert_join = _StampJoin(section_topics)
        alerts = _AlertStream(acfg, ALERT_TOPIC in have, ESTIMATED_POTENTIAL_TOPIC in have)

    def drain(final: bool) -> None:
        until = horizon(final)
        for key, (join, quantities) in joins.items():
            got = join.pop(final)
            if got is not None:
                waiting[key].append(got)
            for ready in _delayed_rows(waiting[key], until):
                for q in quantities:  # zero rows too: a quantity learns its shape
                    q.feed(*ready)
        stamps = np.concatenate(truth_waiting) if truth_waiting else np.zeros(0, np.int64)
        cut = int(np.searchsorted(stamps, until, side='right'))
        truth_waiting[:] = [stamps[cut:]] if cut < stamps.size else []
        mask = evaluation_mask(
            (stamps[:cut] - t0) * 1e-9,
            start=cfg.settle_s,
            events=known.events,
            half_width=cfg.exclusion_half_width_s,
        )
        window[0] += int(mask.sum())
        window[1] += int(mask.size)
        if alert_join is not None and alerts is not None:
            got = alert_join.pop(final)
            if got is not None and got[0].size:
                alerts.feed(paired_alert_data(got[0], got[1], t0))
            if final:
                alerts.finish()

    for block in iter_topic_blocks(reader, present, block_messages):
        tally.feed(block)  # first: it refuses stamps going backwards
        part = block.get(truth_topic)
        if part is not None and part.stamp_ns.size:
            truth_waiting.append(part.stamp_ns)
        for join, _ in joins.values():
            join.push(block)
        if alert_join is not None:
            alert_join.push(block)
        drain(False)
    drain(True)
    for (est_topic, truth_topic), (_, qs) in joins.items():
        # the whole-bag path's test (evaluation._on_own_clock) on the stamps paired here
        if 2 * qs[0].rows < tally.counts.get(est_topic, 0):
            raise ReferenceClockError(
                f'{truth_topic} runs on its own clock ({qs[0].rows} of '
                f'{tally.counts[est_topic]} stamps of {est_topic} found in it): it is '
                'interpolated by the whole-bag evaluation'
            )
    quantities: list[QuantityMetrics] = []
    for spec in _SPECS:
        has_est, has_truth = spec.est_topic in have, spec.truth_topic in have
        if has_est and has_truth:
            q = next(q for q in joins[(spec.est_topic, spec.truth_topic)][1] if q.spec is spec)
            if q.rows == 0:
                notes.append(
                    f'{spec.title}: no common stamps between {spec.est_topic} and '
                    f'{spec.truth_topic} (estimates must carry the measurement stamp)'
                )
            if spec.key == 'mu' and TRUTH_TIRE_FORCES not in have:
                notes.append(f'μ: {TRUTH_TIRE_FORCES} missing, cannot select excited samples')
            quantities.append(q.result())
        elif has_est:
            notes.append(f'{spec.title}: no reference ({spec.truth_topic} missing), plotted only')
        elif has_truth:
            notes.append(f'{spec.title}: no estimate ({spec.est_topic} missing)')
    slope = next((q for _, qs in joins.values() for q in qs if q.spec.key == 'slope'), None)
    convergence = (
        slope.convergence.result()
        if slope is not None and slope.convergence is not None and slope.rows and known.steps.size
        else []
    )
    notes.extend(closing_notes(have, tally.torque_note(), skipped, []))
    section: AlertsSection | None = None
    if section_skip:
        notes.append(section_skip)
    elif alerts is not None and alerts.rows == 0:
        notes.append(NO_COMMON_STAMP)
    elif alerts is not None:
        dropped = tally.counts[TRUE_POTENTIAL_TOPIC] - alerts.rows
        section = alerts.result(tuple(alert_data_notes(have, dropped)))
    return AccuracyReport(
        bag=str(Path(path)),
        first_stamp_s=t0 * 1e-9,
        duration_s=(max(tally.last.values()) - t0) * 1e-9,
        settings=cfg,
        slope_steps_s=tuple(known.steps.tolist()),
        gear_changes_s=tuple(known.gears.tolist()),
        evaluated_fraction=window[0] / window[1] if window[1] else 0.0,
        quantities=tuple(quantities),
        convergence=tuple(convergence),
        targets=_targets(quantities),
        notes=tuple(notes),
        alerts=section,
    )
