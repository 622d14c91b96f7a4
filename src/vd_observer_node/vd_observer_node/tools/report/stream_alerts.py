"""The streamed evaluation's alerts: episode state machines and mu_max per axle and segment.

:class:`AlertStream` takes the paired alert rows block by block, keeps ~2 s of them either
side of the rows being scored (a false alarm and a detection look up to 1 s back and ahead)
and accumulates what `report.alerts` computes on the whole record: episodes, detections,
false alarms and the friction potential's errors per axle and road segment.
Split from `stream` so that each stays small enough to read (#40).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field, fields, replace

import numpy as np
from numpy.typing import NDArray

from vd_observer_node.tools.report.alert_data import AlertData
from vd_observer_node.tools.report.alerts import (
    ALERT_KINDS,
    AlertEpisode,
    AlertSettings,
    AlertsSection,
    FalseAlarm,
    MuMaxSegment,
    activation_indices,
    alerts_section,
    axle_utilisation,
    channel_episodes,
    data_conditions,
    false_alarms,
    segments_from_peaks,
)
from vd_observer_node.tools.report.stream_join import with_previous

__all__ = ['AlertStream']

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


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


class AlertStream:
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
        ext, k = with_previous(self._previous_peak, peaks)
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
