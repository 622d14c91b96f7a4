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
    channel_episodes,
    data_conditions,
    false_alarms,
)
from vd_observer_node.tools.report.mu_max import (
    MuMaxAccumulator,
    axle_utilisation,
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
        self._axles = [MuMaxAccumulator(), MuMaxAccumulator()]
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
        self._axles = [MuMaxAccumulator(), MuMaxAccumulator()]
        self._segment = None

    def result(self, notes: tuple[str, ...]) -> AlertsSection:
        self._close()
        episodes = [e for kind in self.channels for ch in kind for e in ch.episodes]
        alarms = [a for kind in self.channels for ch in kind for a in ch.alarms]
        segments = [*self.segments[0], *self.segments[1]]
        return alerts_section(self.cfg, self.rows, self.judged, episodes, alarms, segments, notes)


# -- the evaluation ---------------------------------------------------------------------------
