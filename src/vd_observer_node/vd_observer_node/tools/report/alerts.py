"""Alerts and friction-potential section of the report: detection delay, false alarms, μ_max error.

The metric functions are pure array functions, shared by ``vd report`` (arrays from a bag) and
``scripts/eval_alerts.py`` (arrays from an in-memory ``simulate()`` run). Definitions
(docs/alerts.md section 4.1), all against the simulator's truth of the friction potential
(``/vd/truth/friction_potential``: the tyre's Magic-Formula peak at the true load and road μ):

* truth condition per (kind, wheel): ``traction`` true slip >= peak slip; ``lock`` true slip
  <= -peak slip; ``low_friction`` |true μ| >= 0.8 x peak μ, or the wheel past its peak slip
  (traction or lock condition: past the peak the tyre uses all the friction there is, though
  its μ fell below 0.8 x the peak, e.g. 0.65 x at slip 0.95). Scaled by 0.8 ("relaxed": the
  tyre near, not past, its limit) to judge false alarms.
* Episodes: runs of the truth condition from ``settle_s`` (0.5 s) on, a run starting within
  1 s of the previous run's start merged into it. Delay = first activation (OK -> active) at
  or after onset - 1 s, minus the onset (negative = earlier than the truth); none, or more
  than 1 s late: missed. An episode beginning while the channel is already active from an
  activation more than 1 s before counts as detected with delay 0 ("already active"): the
  driver is being warned. Goal <= 100 ms.
* False alarm: an activation with no relaxed truth condition within [-0.5 s, +0.1 s] of it.
* μ_max error = estimate - true μ_max per axle and constant-road segment, (a) at samples where
  the axle's true utilisation |μ| / peak μ reached 0.5 within the last 0.5 s (from 0.1 s after
  the first such sample), (b) every sample after the first excitation. Goal |err| <= 0.1.
  Computed in `report.mu_max`.

Kinds in the order of ``vd_msgs/Alert`` (KIND_TRACTION=0, KIND_LOCK=1, KIND_LOW_FRICTION=2);
wheels FL=0, FR=1, RL=2, RR=3; axles 0 front, 1 rear. Time in seconds.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vd_observer_node.tools.report.alert_data import AlertData

__all__ = [
    'ALERT_KINDS',
    'AXLE_NAMES',
    'ROAD_NAMES',
    'AlertEpisode',
    'AlertSettings',
    'AlertsSection',
    'FalseAlarm',
    'MuMaxSegment',
    'activation_indices',
    'alerts_section',
    'already_active',
    'channel_episodes',
    'data_conditions',
    'evaluate_alerts',
    'false_alarms',
    'road_name',
    'score_episodes',
    'truth_conditions',
    'truth_episodes',
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
IntArray = NDArray[np.int64]

#: Alert kinds, index = vd_msgs/Alert KIND_* code.
ALERT_KINDS: Final = ('traction', 'lock', 'low_friction')
#: Road class names, index = vd_msgs/FrictionPotential ROAD_* code.
ROAD_NAMES: Final = ('unknown', 'ice', 'snow', 'wet', 'dry')
AXLE_NAMES: Final = ('front', 'rear')


@dataclass(frozen=True)
class AlertSettings:
    """Definitions of the alert and μ_max metrics (docs/alerts.md section 4.1).

    Attributes:
        low_friction_ratio: low_friction truth: |μ| >= this x peak μ.
        relaxed_scale: thresholds scale of the relaxed truth that excuses an activation.
        settle_s: [s] true onsets before this (from the first stamp) are not scored.
        merge_s: [s] an episode starting within this of the previous start is merged into it.
        early_s: [s] an activation up to this long before the true onset counts.
        max_delay_s: [s] later than this after the onset: missed.
        false_before_s: [s] relaxed truth looked for this long before an activation...
        false_after_s: [s] ...and this long after it.
        delay_goal_s: [s] detection delay goal.
        excitation_ratio: the axle counts as excited when a wheel's |μ| / peak μ reaches this.
        excitation_window_s: [s] (a) counts samples excited within this window before them...
        excitation_start_s: [s] ...from this long after the segment's first excitation.
        mu_max_goal: [-] |μ_max error| goal.
        road_jump: relative jump of the true μ_max of both axles, the same way within one
            sample, that starts a new constant-road segment (bags carry no road_mu; a load
            step moves the peak by a few per cent at most, and the axles oppositely).
    """

    low_friction_ratio: float = 0.8
    relaxed_scale: float = 0.8
    settle_s: float = 0.5
    merge_s: float = 1.0
    early_s: float = 1.0
    max_delay_s: float = 1.0
    false_before_s: float = 0.5
    false_after_s: float = 0.1
    delay_goal_s: float = 0.1
    excitation_ratio: float = 0.5
    excitation_window_s: float = 0.5
    excitation_start_s: float = 0.1
    mu_max_goal: float = 0.1
    road_jump: float = 0.05


@dataclass(frozen=True)
class AlertEpisode:
    """One truth episode of one (kind, wheel) channel and its detection.

    Attributes:
        kind: 'traction', 'lock' or 'low_friction'.
        wheel: 0..3 (FL, FR, RL, RR).
        true_onset_s: [s] first stamp of the truth condition.
        detected_s: [s] stamp of the activation that detects it (None: missed).
        delay_s: [s] detected - true onset (None: missed; negative: earlier than the truth).
        reported_onset_s: [s] the alert's own onset stamp at the detection (None if unknown).
        status: 'met' (delay <= goal), 'late' (detected within max_delay_s, after the goal),
            'missed' (no activation, or more than max_delay_s late).
        already_active: the channel was active at the true onset from an activation more
            than ``early_s`` before it: detected_s = true onset, delay 0, status 'met'.
    """

    kind: str
    wheel: int
    true_onset_s: float
    detected_s: float | None
    delay_s: float | None
    reported_onset_s: float | None
    status: str
    already_active: bool = False


@dataclass(frozen=True)
class FalseAlarm:
    """An activation with no relaxed truth condition near it.

    Attributes:
        kind: alert kind.
        wheel: 0..3.
        t_s: [s] stamp of the activation.
    """

    kind: str
    wheel: int
    t_s: float


@dataclass(frozen=True)
class MuMaxSegment:
    """μ_max error of one axle over one constant-road segment, after the first excitation.

    Attributes:
        axle: 0 front, 1 rear.
        start_index: first sample of the segment (index into the evaluated arrays).
        start_s: [s] segment start.
        end_s: [s] last stamp of the segment.
        excited_s: [s] first stamp with the axle excited (utilisation >= excitation_ratio).
        true_mu_max: [-] mean true μ_max from the first excitation on.
        true_road_class: most frequent true road class code from the first excitation on.
        recent_samples: samples of metric (a) (excited within the window).
        recent_rms: [-] RMS error of (a) (nan if no sample).
        recent_within_pct: [%] share of (a) within the goal (nan if no sample).
        recent_unknown_pct: [%] share of (a) with the estimated road class unknown: the
            estimator said the excitation does not determine μ_max (nan if no sample or no
            class).
        recent_known_wrong_pct: [%] share of (a) with a known class and the error beyond the
            goal: a confident wrong μ_max (nan if no sample or no class).
        estimate_mean: [-] mean estimate from the first excitation on (b).
        max_abs: [-] largest |error| of (b).
        rms: [-] RMS error of (b).
        within_pct: [%] share of (b) within the goal.
        last_miss_s: [s] after the first excitation of the last sample outside the goal (0:
            none).
        confidence_mean: mean estimated confidence of (b) (nan if not available).
        road_class: most frequent estimated road class code of (b) (-1 if not available).
    """

    axle: int
    start_index: int
    start_s: float
    end_s: float
    excited_s: float
    true_mu_max: float
    true_road_class: int
    recent_samples: int
    recent_rms: float
    recent_within_pct: float
    recent_unknown_pct: float
    recent_known_wrong_pct: float
    estimate_mean: float
    max_abs: float
    rms: float
    within_pct: float
    last_miss_s: float
    confidence_mean: float
    road_class: int


@dataclass(frozen=True)
class AlertsSection:
    """The report section (metrics only; no arrays, so it serialises to JSON).

    Attributes:
        settings: the definitions used.
        samples: evaluated stamps (common to alerts and truth).
        episodes: every truth episode, kind-major then wheel then time.
        false_alarms: every false alarm.
        mu_max: μ_max error per axle and segment (empty without a friction-potential estimate).
        counts: 'episodes', 'met', 'late', 'missed', 'false_alarms'.
        targets: goal name -> (value, limit, met), as the accuracy targets.
        notes: what was left out and why.
    """

    settings: AlertSettings
    samples: int
    episodes: tuple[AlertEpisode, ...]
    false_alarms: tuple[FalseAlarm, ...]
    mu_max: tuple[MuMaxSegment, ...]
    counts: dict[str, int]
    targets: dict[str, tuple[float, float, bool]]
    notes: tuple[str, ...] = ()


# -- truth ------------------------------------------------------------------------------------


def truth_conditions(
    slip: ArrayLike,
    mu: ArrayLike,
    peak_slip: ArrayLike,
    peak_mu: ArrayLike,
    *,
    scale: float = 1.0,
    low_friction_ratio: float = 0.8,
) -> BoolArray:
    """Truth condition of each alert kind per wheel.

    Args:
        slip: shape (N, 4), [-] true slip.
        mu: shape (N, 4), [-] true utilised μ = Fx / Fz.
        peak_slip: shape (N, 4), [-] true slip magnitude at the MF peak (side of the force).
        peak_mu: shape (N, 4), [-] true MF peak μ.
        scale: 1 for the truth, < 1 (0.8) for the relaxed condition of the false alarms.
        low_friction_ratio: low_friction holds at |μ| >= scale x this x peak μ, and wherever
            the traction or lock condition (at the same scale) holds.

    Returns:
        Shape (N, 3, 4), bool, kinds in :data:`ALERT_KINDS` order.
    """
    s = np.asarray(slip, dtype=np.float64)
    ps = np.asarray(peak_slip, dtype=np.float64)
    pm = np.asarray(peak_mu, dtype=np.float64)
    traction = s >= scale * ps
    lock = s <= -scale * ps
    # Past the peak μ falls again (0.65 x the peak at slip 0.95 on a spinning wheel): the
    # ratio alone would call the friction no longer scarce just when all of it is used.
    near_peak = np.abs(np.asarray(mu, dtype=np.float64)) >= scale * low_friction_ratio * pm
    out: BoolArray = np.stack([traction, lock, near_peak | traction | lock], axis=1)
    return out


def _rising(mask: BoolArray) -> IntArray:
    """Indices where a 1-D bool series becomes true (including index 0 if true there)."""
    prev = np.concatenate([[False], mask[:-1]])
    out: IntArray = np.flatnonzero(mask & ~prev).astype(np.int64)
    return out


def activation_indices(level: ArrayLike) -> IntArray:
    """Indices of the OK -> active transitions of one channel (level (N,), 0 = OK)."""
    return _rising(np.asarray(level) > 0)


def truth_episodes(
    t: ArrayLike, condition: ArrayLike, settings: AlertSettings | None = None
) -> FloatArray:
    """True onsets [s] of one channel: runs of the condition from ``settle_s`` on, merged.

    Args:
        t: shape (N,), [s] from the first stamp.
        condition: shape (N,), bool truth condition of the channel.
        settings: definitions (default :class:`AlertSettings`).
    """
    cfg = settings or AlertSettings()
    tt = np.asarray(t, dtype=np.float64)
    cond = np.asarray(condition, dtype=bool) & (tt >= cfg.settle_s)
    starts = tt[_rising(cond)]
    # a run within merge_s of the previous run's start is the same event with a short dip
    keep = np.concatenate([[True], np.diff(starts) > cfg.merge_s]) if starts.size else starts
    out: FloatArray = starts[keep.astype(bool)] if starts.size else starts
    return out


def already_active(
    onsets: ArrayLike,
    activations: ArrayLike,
    active_at_onset: ArrayLike,
    settings: AlertSettings | None = None,
) -> BoolArray:
    """Which true onsets find the channel already active from an activation > early_s before.

    Such an episode has no activation of its own to time (the alert never went back to OK),
    yet the driver is being warned: it counts as detected at the onset, delay 0.

    Args:
        onsets: shape (E,), [s] true onsets of one channel.
        activations: shape (A,), [s] activation stamps of that channel, increasing.
        active_at_onset: shape (E,), bool, the channel's level > 0 at each onset's stamp.
        settings: definitions.

    Returns:
        shape (E,), bool.
    """
    cfg = settings or AlertSettings()
    ons = np.asarray(onsets, dtype=np.float64)
    acts = np.asarray(activations, dtype=np.float64)
    # no activation in [onset - early_s, onset]: the one that made it active is older
    first_in_window = np.searchsorted(acts, ons - cfg.early_s, side='left')
    after_onset = np.searchsorted(acts, ons, side='right')
    out: BoolArray = np.asarray(active_at_onset, dtype=bool) & (first_in_window == after_onset)
    return out


def score_episodes(
    onsets: ArrayLike,
    activations: ArrayLike,
    settings: AlertSettings | None = None,
    *,
    active_at_onset: ArrayLike | None = None,
) -> list[tuple[float, float | None, float | None, str]]:
    """Detection of each true onset by the first activation at or after onset - early_s.

    Args:
        onsets: shape (E,), [s] true onsets of one channel.
        activations: shape (A,), [s] activation stamps of that channel, increasing.
        settings: definitions.
        active_at_onset: shape (E,), bool, the channel active at each onset's stamp, or None
            (unknown: never "already active"). See :func:`already_active`.

    Returns:
        Per onset: (onset, detection stamp or None, delay or None, status); an already
        active episode gives (onset, onset, 0.0, 'met').
    """
    cfg = settings or AlertSettings()
    acts = np.asarray(activations, dtype=np.float64)
    ons = np.asarray(onsets, dtype=np.float64)
    active = (
        np.zeros(ons.shape, dtype=bool)
        if active_at_onset is None
        else already_active(ons, acts, active_at_onset, cfg)
    )
    out: list[tuple[float, float | None, float | None, str]] = []
    for onset, was_active in zip(ons.tolist(), active.tolist(), strict=True):
        if was_active:
            out.append((onset, onset, 0.0, 'met'))
            continue
        k = int(np.searchsorted(acts, onset - cfg.early_s, side='left'))
        if k >= acts.size:
            out.append((onset, None, None, 'missed'))
            continue
        first = float(acts[k])
        delay = first - onset
        if delay > cfg.max_delay_s:
            out.append((onset, None, None, 'missed'))
            continue
        out.append((onset, first, delay, 'met' if delay <= cfg.delay_goal_s else 'late'))
    return out


def false_alarms(
    t: ArrayLike, activations: ArrayLike, relaxed: ArrayLike, settings: AlertSettings | None = None
) -> FloatArray:
    """Activations [s] of one channel with no relaxed truth within [-0.5 s, +0.1 s] of them.

    Args:
        t: shape (N,), [s].
        activations: shape (A,), [s] activation stamps.
        relaxed: shape (N,), bool relaxed truth condition of the channel.
        settings: definitions.
    """
    cfg = settings or AlertSettings()
    tt = np.asarray(t, dtype=np.float64)
    rel = np.asarray(relaxed, dtype=bool)
    # relaxed samples up to each stamp: a window holds one iff the count increases across it
    cum = np.concatenate([[0], np.cumsum(rel)])
    acts = np.asarray(activations, dtype=np.float64)
    lo = np.searchsorted(tt, acts - cfg.false_before_s, side='left')
    hi = np.searchsorted(tt, acts + cfg.false_after_s, side='right')
    out: FloatArray = acts[cum[hi] == cum[lo]]
    return out


def evaluate_alerts(
    t: ArrayLike,
    truth: ArrayLike,
    relaxed: ArrayLike,
    level: ArrayLike,
    onset: ArrayLike | None = None,
    settings: AlertSettings | None = None,
) -> tuple[list[AlertEpisode], list[FalseAlarm]]:
    """Episodes with their detection, and false alarms, of all 12 channels.

    Args:
        t: shape (N,), [s] increasing.
        truth: shape (N, 3, 4), bool, from :func:`truth_conditions`.
        relaxed: shape (N, 3, 4), bool, the relaxed truth (scale 0.8).
        level: shape (N, 3, 4), int alert level (0 OK).
        onset: shape (N, 3, 4), [s] the alerts' own onset stamps (nan while inactive), or None.
        settings: definitions.

    Returns:
        (episodes kind-major, wheel, time; false alarms in the same order).
    """
    cfg = settings or AlertSettings()
    tt = np.asarray(t, dtype=np.float64)
    tru = np.asarray(truth, dtype=bool)
    rel = np.asarray(relaxed, dtype=bool)
    lev = np.asarray(level)
    ons = None if onset is None else np.asarray(onset, dtype=np.float64)
    episodes: list[AlertEpisode] = []
    alarms: list[FalseAlarm] = []
    for kind, name in enumerate(ALERT_KINDS):
        for wheel in range(4):
            idx = activation_indices(lev[:, kind, wheel])
            acts = tt[idx]
            for stamp in false_alarms(tt, acts, rel[:, kind, wheel], cfg).tolist():
                alarms.append(FalseAlarm(name, wheel, stamp))
            onsets = truth_episodes(tt, tru[:, kind, wheel], cfg)
            episodes.extend(
                channel_episodes(
                    name,
                    wheel,
                    tt,
                    onsets,
                    acts,
                    lev[:, kind, wheel],
                    None if ons is None else ons[:, kind, wheel],
                    cfg,
                )
            )
    return episodes, alarms


def channel_episodes(
    kind: str,
    wheel: int,
    t: FloatArray,
    onsets: FloatArray,
    activations: FloatArray,
    level: np.ndarray,
    onset: FloatArray | None,
    settings: AlertSettings,
) -> list[AlertEpisode]:
    """The episodes of one (kind, wheel) channel with their detection.

    Args:
        kind: alert kind name.
        wheel: 0..3.
        t: shape (N,), [s] increasing; must cover every onset's stamp and the activations
            from ``early_s`` before the first onset to ``max_delay_s`` after the last.
        onsets: shape (E,), [s] true onsets (stamps among ``t``).
        activations: shape (A,), [s] the channel's activation stamps, increasing.
        level: shape (N,), the channel's alert level on ``t``.
        onset: shape (N,), [s] the alert's own onset stamp on ``t`` (nan while inactive), or
            None.
        settings: definitions.
    """
    active_at = level[np.searchsorted(t, onsets)] > 0
    was_active = already_active(onsets, activations, active_at, settings)
    scored = score_episodes(onsets, activations, settings, active_at_onset=active_at)
    out: list[AlertEpisode] = []
    for (true_onset, det, delay, status), prior in zip(scored, was_active.tolist(), strict=True):
        reported = None
        if det is not None and onset is not None:
            value = float(onset[int(np.searchsorted(t, det))])
            reported = value if math.isfinite(value) else None
        out.append(AlertEpisode(kind, wheel, true_onset, det, delay, reported, status, prior))
    return out


# -- the section ------------------------------------------------------------------------------


def data_conditions(data: AlertData, settings: AlertSettings) -> tuple[BoolArray, BoolArray]:
    """The truth and the relaxed truth conditions of paired rows, each shape (N, 3, 4)."""
    cfg = settings
    truth = truth_conditions(
        data.slip, data.mu, data.peak_slip, data.peak_mu, low_friction_ratio=cfg.low_friction_ratio
    )
    relaxed = truth_conditions(
        data.slip,
        data.mu,
        data.peak_slip,
        data.peak_mu,
        scale=cfg.relaxed_scale,
        low_friction_ratio=cfg.low_friction_ratio,
    )
    return truth, relaxed


def alerts_section(
    settings: AlertSettings,
    samples: int,
    judged: bool,
    episodes: Sequence[AlertEpisode],
    alarms: Sequence[FalseAlarm],
    segments: Sequence[MuMaxSegment],
    notes: tuple[str, ...] = (),
) -> AlertsSection:
    """The section from its scored episodes, false alarms and μ_max segments: counts, goals.

    Args:
        settings: the definitions used.
        samples: evaluated stamps.
        judged: the bag has alerts (False: no delay or false-alarm goal).
        episodes: kind-major, then wheel, then time.
        alarms: in the same order.
        segments: axle-major, then time.
        notes: what was left out and why.
    """
    cfg = settings
    counts = {
        'episodes': len(episodes),
        'met': sum(e.status == 'met' for e in episodes),
        'late': sum(e.status == 'late' for e in episodes),
        'missed': sum(e.status == 'missed' for e in episodes),
        'false_alarms': len(alarms),
    }
    targets: dict[str, tuple[float, float, bool]] = {}
    if judged:
        delays = [e.delay_s for e in episodes if e.delay_s is not None]
        if episodes:
            worst = max(delays) if len(delays) == len(episodes) else math.inf
            targets['alert delay, worst episode [s]'] = (
                worst,
                cfg.delay_goal_s,
                bool(worst <= cfg.delay_goal_s),
            )
        targets['false alarms [-]'] = (float(len(alarms)), 0.0, not alarms)
    recent = [s for s in segments if s.recent_samples]
    if recent:
        n = sum(s.recent_samples for s in recent)
        share = sum(s.recent_within_pct * s.recent_samples for s in recent) / n
        targets['mu_max within 0.1 while excited [%]'] = (share, 100.0, bool(share >= 100.0))
    return AlertsSection(
        settings=cfg,
        samples=samples,
        episodes=tuple(episodes),
        false_alarms=tuple(alarms),
        mu_max=tuple(segments),
        counts=counts,
        targets=targets,
        notes=notes,
    )


def road_name(code: int) -> str:
    """Name of a road class code ('n/a' for -1 or an unknown code)."""
    return ROAD_NAMES[code] if 0 <= code < len(ROAD_NAMES) else 'n/a'
