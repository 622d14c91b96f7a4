"""Streamed evaluation of one bag: the report's figures in memory bounded by a block.

:func:`evaluate_bag` gives the same :class:`~.evaluation.AccuracyReport` as
``evaluate(load_bag_series(bag))`` (the reference, kept for ``vd report`` and its figures)
without holding the bag's series: it reads the bag in file order, in blocks of
``block_messages`` messages decoded per topic (:func:`~.stream_join.iter_topic_blocks`).

* A first look reads each topic's first message only (t = 0 is the earliest stamp).
* One pass then reads every topic: it checks the stamps' order and counts them (the last
  stamp, the torque path, and for ``vd fleet`` the distance and the alert activations),
  finds the true slope steps, gear changes and static loads as they come
  (:class:`~.stream_join.Scout`), pairs estimate and truth by header stamp
  (:class:`~.stream_join.StampJoin`: rows wait only until every topic of the pair has passed
  their stamp), holds the paired rows until the events that could exclude them are known (a
  sample within +-0.5 s of a step or shift is excluded, also one *before* it: rows wait
  until the slope truth and the gear are 0.5 s past them, and for the first second's true
  forces), then adds them into running sums (`accumulate.QuantityAccumulator`, which
  `evaluate` uses too: sums of squares, sums, maxima, counts) and the slope convergence
  trackers; the alert-episode state machines
  (:class:`~.stream_alerts.AlertStream`: ~2 s of rows either side of the rows being scored,
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

import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from vd_common.topics import (
    ESTIMATES_FRICTION,
    TRUTH_NAMESPACE,
    TRUTH_SLOPE,
    TRUTH_TIRE_FORCES,
)

from vd_observer_node.bag.reader import BagReader
from vd_observer_node.tools.report.accumulate import ConvergenceAccumulator, QuantityAccumulator
from vd_observer_node.tools.report.alert_data import (
    NO_COMMON_STAMP,
    alert_data_notes,
    alert_section_skip,
    alert_section_topics,
    paired_alert_data,
)
from vd_observer_node.tools.report.alerts import ALERT_KINDS, AlertSettings, AlertsSection
from vd_observer_node.tools.report.errors import (
    ReferenceClockError,
    ReportInputError,
)
from vd_observer_node.tools.report.evaluation import (
    _SPECS,
    _Spec,
    _targets,
    closing_notes,
)
from vd_observer_node.tools.report.load import decode_topic, select_report_topics
from vd_observer_node.tools.report.metrics import evaluation_mask, merge_times
from vd_observer_node.tools.report.results import (
    AccuracyReport,
    EvaluationSettings,
    QuantityMetrics,
)
from vd_observer_node.tools.report.stream_alerts import AlertStream
from vd_observer_node.tools.report.stream_join import (
    DEFAULT_BLOCK_MESSAGES,
    NEVER,
    Paired,
    Scout,
    StampJoin,
    iter_topic_blocks,
)
from vd_observer_node.tools.report.topics import (
    ALERT_TOPIC,
    ESTIMATED_POTENTIAL_TOPIC,
    GEAR_TOPIC,
    TRUE_POTENTIAL_TOPIC,
    TRUTH_TOPICS,
)

__all__ = ['StreamedEvaluation', 'evaluate_bag']

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

_STEP_MERGE_S = 0.5  # [s] metrics.step_times' default merge window (the reference's)


@dataclass
class _Events:
    """What the verdict of a sample depends on, as far as the bag has been read: the true
    slope steps and gear changes [s] (``events`` = both) and the static loads [N]."""

    steps: FloatArray = field(default_factory=lambda: np.zeros(0))
    gears: FloatArray = field(default_factory=lambda: np.zeros(0))
    events: FloatArray = field(default_factory=lambda: np.zeros(0))
    loads: FloatArray | None = None


class _Quantity:
    """One estimated quantity against its truth: the joined rows made into compared samples
    for its `QuantityAccumulator` (the metrics `evaluate` computes too), and the slope's
    convergence."""

    def __init__(self, spec: _Spec, cfg: EvaluationSettings, t0: int, known: _Events) -> None:
        self.spec, self.cfg, self.t0, self.known = spec, cfg, t0, known
        self.rows = 0
        self.metrics = QuantityAccumulator(spec.key, spec.title, spec.unit, cfg)
        self.convergence = ConvergenceAccumulator(cfg) if spec.key == 'slope' else None

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
        t = (stamps - self.t0) * 1e-9
        window = evaluation_mask(
            t, start=cfg.settle_s, events=self.known.events, half_width=cfg.exclusion_half_width_s
        )
        mask = window
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
        self.metrics.add(
            estimate,
            true,
            mask,
            window=window if spec.key == 'slope' else None,
            static_loads=self.known.loads,
        )
        if self.convergence is not None:
            self.convergence.feed(t, estimate, true, self.known.steps)

    def result(self) -> QuantityMetrics:
        return self.metrics.result()


# -- alerts and μ_max -----------------------------------------------------------------------------


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
    tally = Scout(cfg)
    report: AccuracyReport | None = None
    no_report = ''
    try:
        report = _the_pass(
            reader,
            tally,
            present,
            skipped,
            t0,
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


def _delayed_rows(queue: list[Paired], horizon: int) -> list[Paired]:
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
    tally: Scout,
    present: list[str],
    skipped: dict[str, str],
    t0: int,
    static_loads: FloatArray | None,
    alert_settings: AlertSettings | None,
    block_messages: int,
) -> AccuracyReport:
    """The pass over every topic: the tally (``tally``, which holds the settings) and, with
    truth, the report.

    Paired rows wait (:func:`_delayed_rows`) until the events that may exclude them are known:
    the slope truth and the gear have passed their stamp + ``exclusion_half_width_s`` (+1 ms
    against rounding), and the first ``settle_s`` of true forces (the static loads) are read.

    Raises:
        ReportInputError: no truth topic (after the pass: the tally is complete).
        StampOrderError: a topic's stamps go backwards.
    """
    cfg = tally.cfg
    have = set(present)
    if not any(t in have for t in TRUTH_TOPICS):
        for block in iter_topic_blocks(reader, present, block_messages):
            tally.feed(block)
        raise ReportInputError(
            f'{reader.path}: no truth topics (need at least one of {TRUTH_NAMESPACE}*: '
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
            return NEVER
        if loads_pending and TRUTH_TIRE_FORCES in have and not tally.loads_known():
            return -1
        seen = [tally.last.get(t) for t in event_topics]
        if any(s is None for s in seen):
            return -1
        return min([NEVER, *[int(s) - margin_ns for s in seen if s is not None]])

    # one join per (estimate, truth) pair; μ also needs the true forces where they exist
    joins: dict[tuple[str, str], tuple[StampJoin, list[_Quantity]]] = {}
    waiting: dict[tuple[str, str], list[Paired]] = {}
    notes: list[str] = []
    for spec in _SPECS:
        has_est, has_truth = spec.est_topic in have, spec.truth_topic in have
        if has_est and has_truth:
            key = (spec.est_topic, spec.truth_topic)
            if key not in joins:
                forces = spec.est_topic == ESTIMATES_FRICTION and TRUTH_TIRE_FORCES in have
                optional: tuple[str, ...] = (TRUTH_TIRE_FORCES,) if forces else ()
                joins[key] = (StampJoin(key, optional), [])
                waiting[key] = []
            joins[key][1].append(_Quantity(spec, cfg, t0, known))
    truth_topic = next(t for t in TRUTH_TOPICS if t in have)
    window = [0, 0]  # evaluated, all samples of the first truth topic
    truth_waiting: list[np.ndarray] = []
    section_skip = alert_section_skip(have)
    alerts: AlertStream | None = None
    alert_join: StampJoin | None = None
    acfg = alert_settings or AlertSettings()
    if not section_skip:
        section_topics = tuple(alert_section_topics(have))
        alert_join = StampJoin(section_topics)
        alerts = AlertStream(acfg, ALERT_TOPIC in have, ESTIMATED_POTENTIAL_TOPIC in have)

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
        bag=str(reader.path),
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
