"""μ_max against the truth per axle and road segment: the running figures the whole-record
report and the streamed evaluation share (definitions: `report.alerts`, docs/alerts.md 4.1).

`MuMaxAccumulator` takes one axle's rows of one road segment in stamp order, all at once
(`mu_max_errors`, the whole record) or block by block (`stream_alerts.AlertStream`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray
from vd_common.vehicle.friction import ROAD_UNKNOWN

from vd_observer_node.tools.report.alerts import AlertSettings, MuMaxSegment

__all__ = [
    'MuMaxAccumulator',
    'axle_utilisation',
    'mu_max_errors',
    'segments_from_peaks',
    'segments_from_road',
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


def axle_utilisation(mu: ArrayLike, peak_mu: ArrayLike) -> FloatArray:
    """True utilisation of each axle: the larger |μ| / peak μ of its two wheels.

    Args:
        mu: shape (N, 4), [-] true μ.
        peak_mu: shape (N, 4), [-] true peak μ (floored at 1e-6: no division by zero).

    Returns:
        Shape (N, 2) (front, rear).
    """
    util = np.abs(np.asarray(mu, dtype=np.float64)) / np.maximum(
        np.asarray(peak_mu, dtype=np.float64), 1e-6
    )
    out: FloatArray = np.maximum(util[:, 0::2], util[:, 1::2])
    return out


def segments_from_road(road_mu: ArrayLike) -> IntArray:
    """Start indices of the constant-road segments from the true road_mu (in memory)."""
    r = np.asarray(road_mu, dtype=np.float64)
    out: IntArray = np.concatenate([[0], np.flatnonzero(np.diff(r) != 0.0) + 1]).astype(np.int64)
    return out


def segments_from_peaks(axle_mu_max: ArrayLike, road_jump: float = 0.05) -> IntArray:
    """Start indices of constant-road segments from the true μ_max of both axles (bags).

    A road step scales both axles' peak by the same factor within one sample; a load step
    moves them by a few per cent and in opposite directions. A new segment starts where both
    axles jump by more than ``road_jump`` (relative) the same way.

    Args:
        axle_mu_max: shape (N, 2), [-] true μ_max (front, rear).
        road_jump: relative jump threshold.
    """
    m = np.maximum(np.asarray(axle_mu_max, dtype=np.float64), 1e-9)
    ratio = np.log(m[1:] / m[:-1])
    step = math.log1p(road_jump)
    jump = ((ratio > step).all(axis=1)) | ((ratio < -step).all(axis=1))
    out: IntArray = np.concatenate([[0], np.flatnonzero(jump) + 1]).astype(np.int64)
    return out


@dataclass
class MuMaxAccumulator:
    """Running μ_max figures of one axle over one road segment, fed in stamp order: what
    :func:`mu_max_errors` gives for the whole record and the streamed evaluation
    (`stream_alerts.AlertStream`) block by block.

    The fields are the running sums; :meth:`feed` adds rows, :meth:`result` reads them.
    """

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
    classes: IntArray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    true_classes: IntArray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    recent_n: int = 0
    recent_squares: float = 0.0
    recent_within: int = 0
    recent_unknown: int = 0
    recent_known_wrong: int = 0
    classified: bool = True

    def feed(
        self,
        t: FloatArray,
        util: FloatArray,
        truth: FloatArray,
        est: FloatArray,
        conf: FloatArray | None,
        klass: IntArray | None,
        tclass: IntArray | None,
        cfg: AlertSettings,
    ) -> None:
        """Add rows of the segment.

        Args:
            t: shape (K,), [s].
            util: shape (K,), the axle's true utilisation |μ| / peak μ.
            truth: shape (K,), the true μ_max.
            est: shape (K,), the estimated μ_max.
            conf: shape (K,), its confidence, or None (the confidence mean is then nan).
            klass: shape (K,), the estimated road class codes, or None (class -1).
            tclass: shape (K,), the true road class codes, or None (class -1).
            cfg: the definitions.
        """
        excited_mask = util >= cfg.excitation_ratio
        last = np.maximum.accumulate(np.where(excited_mask, t, -np.inf))
        last = np.maximum(last, self.last_excited)
        if last.size:
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
        if klass is None:
            self.classified = False
        else:
            unknown = klass[recent] == ROAD_UNKNOWN
            self.recent_unknown += int(unknown.sum())
            wrong = np.abs(err_recent) > cfg.mu_max_goal
            self.recent_known_wrong += int(np.sum(wrong & ~unknown))
        err = est[begin:] - truth[begin:]
        if err.size == 0:
            return
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
        self.confidence_sum += math.nan if conf is None else float(np.sum(conf[begin:]))
        if klass is not None:
            self.classes = _add_counts(self.classes, klass[begin:])
        if tclass is not None:
            self.true_classes = _add_counts(self.true_classes, tclass[begin:])

    def result(self, axle: int, start_index: int, start_s: float, end_s: float) -> MuMaxSegment:
        """The segment's figures (call once it was excited: `excited_s` set)."""
        assert self.excited_s is not None
        has_recent = self.recent_n > 0
        return MuMaxSegment(
            axle=axle,
            start_index=start_index,
            start_s=start_s,
            end_s=end_s,
            excited_s=self.excited_s,
            true_mu_max=self.truth_sum / self.n,
            true_road_class=int(self.true_classes.argmax()) if self.true_classes.size else -1,
            recent_samples=self.recent_n,
            recent_rms=math.sqrt(self.recent_squares / self.recent_n) if has_recent else math.nan,
            recent_within_pct=self._recent_pct(self.recent_within, True),
            recent_unknown_pct=self._recent_pct(self.recent_unknown, self.classified),
            recent_known_wrong_pct=self._recent_pct(self.recent_known_wrong, self.classified),
            estimate_mean=self.estimate_sum / self.n,
            max_abs=self.max_abs,
            rms=math.sqrt(self.squares / self.n),
            within_pct=100.0 * self.within / self.n,
            last_miss_s=self.last_miss - self.excited_s if self.last_miss is not None else 0.0,
            confidence_mean=self.confidence_sum / self.n,
            road_class=int(self.classes.argmax()) if self.classes.size else -1,
        )

    def _recent_pct(self, count: int, available: bool) -> float:
        """[%] `count` of the recent samples (nan without any, or without `available`)."""
        return 100.0 * count / self.recent_n if self.recent_n and available else math.nan


def _add_counts(counts: IntArray, codes: IntArray) -> IntArray:
    """`counts` (per code) plus the counts of `codes` (non-negative ints)."""
    more = np.bincount(codes)
    size = max(counts.size, more.size)
    out: IntArray = np.pad(counts, (0, size - counts.size)) + np.pad(more, (0, size - more.size))
    return out


def mu_max_errors(
    t: ArrayLike,
    utilisation: ArrayLike,
    true_mu_max: ArrayLike,
    estimate: ArrayLike,
    segment_starts: ArrayLike,
    *,
    confidence: ArrayLike | None = None,
    road_classes: tuple[ArrayLike | None, ArrayLike | None] = (None, None),
    settings: AlertSettings | None = None,
) -> list[MuMaxSegment]:
    """μ_max error per axle and constant-road segment after the axle's first excitation.

    Args:
        t: shape (N,), [s].
        utilisation: shape (N, 2), true |μ| / peak μ per axle (:func:`axle_utilisation`).
        true_mu_max: shape (N, 2), [-].
        estimate: shape (N, 2), [-] estimated μ_max.
        segment_starts: start indices of the segments (first 0), increasing.
        confidence: shape (N, 2), estimated confidence, or None.
        road_classes: the estimated and the true road class codes, each shape (N, 2) or
            None.
        settings: definitions.

    Returns:
        One :class:`MuMaxSegment` per axle (front first) and segment with an excitation.
    """
    cfg = settings or AlertSettings()
    tt = np.asarray(t, dtype=np.float64)
    util = np.asarray(utilisation, dtype=np.float64)
    truth = np.asarray(true_mu_max, dtype=np.float64)
    est = np.asarray(estimate, dtype=np.float64)
    starts = np.asarray(segment_starts, dtype=np.int64)
    conf = None if confidence is None else np.asarray(confidence, dtype=np.float64)
    klass, tclass = (None if c is None else np.asarray(c, dtype=np.int64) for c in road_classes)
    out: list[MuMaxSegment] = []
    for axle in range(2):
        for seg in np.split(np.arange(tt.size), starts[1:]):
            if seg.size == 0:
                continue
            rows = slice(int(seg[0]), int(seg[-1]) + 1)
            acc = MuMaxAccumulator()
            acc.feed(
                tt[rows],
                util[rows, axle],
                truth[rows, axle],
                est[rows, axle],
                None if conf is None else conf[rows, axle],
                None if klass is None else klass[rows, axle],
                None if tclass is None else tclass[rows, axle],
                cfg,
            )
            if acc.excited_s is not None:
                out.append(acc.result(axle, int(seg[0]), float(tt[seg[0]]), float(tt[seg[-1]])))
    return out
