"""Estimate-vs-truth comparisons and accuracy metrics of a decoded bag.

Estimates and truth are paired by identical ``header.stamp`` (both derive from the same
measurement), never by log time. Evaluation window (the project's accuracy targets): from
1 s after the first stamp, excluding +-0.5 s around slope steps (found in the true slope)
and gear changes (found in ``/vd/sensors/wheel_torques.gear``).
"""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from vd_common.topics import (
    ESTIMATES_FRICTION,
    ESTIMATES_NAMESPACE,
    ESTIMATES_RESISTANCES,
    ESTIMATES_SLOPE,
    ESTIMATES_TIRE_FORCES,
    OBSERVER_BODY_ACCEL,
    OBSERVER_BODY_VELOCITY,
    OBSERVER_NAMESPACE,
    OBSERVER_WHEEL_STATES,
    TRUTH_BODY_ACCEL,
    TRUTH_BODY_VELOCITY,
    TRUTH_FRICTION,
    TRUTH_NAMESPACE,
    TRUTH_RESISTANCES,
    TRUTH_SLOPE,
    TRUTH_TIRE_FORCES,
    TRUTH_WHEEL_STATES,
)

from vd_observer_node.inputs.decode import InputStats
from vd_observer_node.tools.report.accumulate import ConvergenceAccumulator, QuantityAccumulator
from vd_observer_node.tools.report.alert_data import AlertData, alert_data
from vd_observer_node.tools.report.alerts import (
    AlertEpisode,
    AlertSettings,
    AlertsSection,
    FalseAlarm,
    MuMaxSegment,
    alerts_section,
    data_conditions,
    evaluate_alerts,
)
from vd_observer_node.tools.report.errors import ReportInputError
from vd_observer_node.tools.report.load import BagSeries, TopicSeries
from vd_observer_node.tools.report.metrics import (
    ValueStats,
    change_times,
    evaluation_mask,
    step_times,
    value_stats,
)
from vd_observer_node.tools.report.mu_max import (
    axle_utilisation,
    mu_max_errors,
    segments_from_peaks,
)
from vd_observer_node.tools.report.results import (
    NO_REFERENCE_HINT,
    TARGETS,
    AccuracyReport,
    Comparison,
    EstimateStats,
    EvaluationSettings,
    QuantityMetrics,
    SlopeConvergence,
)
from vd_observer_node.tools.report.topics import ESTIMATE_TOPICS, GEAR_TOPIC, TRUTH_TOPICS

__all__ = [
    'build_comparisons',
    'closing_notes',
    'evaluate',
    'evaluate_alerts_section',
    'evaluate_estimates',
    'has_reference',
    'reference_kind',
    'target_values',
    'torque_path',
    'torque_path_note',
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class _Spec:
    key: str
    title: str
    unit: str
    est_topic: str
    truth_topic: str
    field: str
    factor: float
    estimate_label: str
    truth_label: str
    symbol: str


# fmt: off
_SPECS = tuple(_Spec(*row) for row in (
    # key, title, unit, estimate topic, truth topic, field, factor, legends, axis symbol
    ('omega', 'Wheel speed ω', 'rad/s', OBSERVER_WHEEL_STATES, TRUTH_WHEEL_STATES,
     'omega', 1.0, 'estimated (differentiator)', 'true (simulator)', 'ω'),
    ('omega_dot', 'Wheel acceleration ω̇', 'rad/s²', OBSERVER_WHEEL_STATES,
     TRUTH_WHEEL_STATES, 'omega_dot', 1.0, 'estimated (differentiator)',
     'true (simulator)', 'dω/dt'),
    ('accel', 'Body acceleration', 'm/s²', OBSERVER_BODY_ACCEL, TRUTH_BODY_ACCEL,
     'accel.linear.x', 1.0, 'estimated', 'true (simulator)', 'acceleration'),
    ('speed', 'Body speed', 'm/s', OBSERVER_BODY_VELOCITY, TRUTH_BODY_VELOCITY,
     'twist.linear.x', 1.0, 'estimated', 'true (simulator)', 'speed'),
    ('fx', 'Longitudinal tyre force Fx', 'N', ESTIMATES_TIRE_FORCES, TRUTH_TIRE_FORCES,
     'fx', 1.0, 'estimated', 'simulated', 'Fx'),
    ('fz', 'Normal tyre load Fz', 'N', ESTIMATES_TIRE_FORCES, TRUTH_TIRE_FORCES,
     'fz', 1.0, 'estimated', 'simulated', 'Fz'),
    ('mu', 'Utilised friction μ', '-', ESTIMATES_FRICTION, TRUTH_FRICTION,
     'mu', 1.0, 'estimated (where valid)', 'Pacejka (simulator)', 'μ = Fx/Fz'),
    ('slip', 'Longitudinal slip', '-', ESTIMATES_FRICTION, TRUTH_FRICTION,
     'slip', 1.0, 'estimated', 'simulated', 'slip'),
    ('rolling', 'Rolling resistance', 'N', ESTIMATES_RESISTANCES, TRUTH_RESISTANCES,
     'rolling', 1.0, 'estimated', 'simulated', 'rolling resistance'),
    ('aero', 'Aerodynamic drag', 'N', ESTIMATES_RESISTANCES, TRUTH_RESISTANCES,
     'aero', 1.0, 'estimated', 'simulated', 'drag force'),
    ('slope', 'Road slope', 'deg', ESTIMATES_SLOPE, TRUTH_SLOPE,
     'angle', float(np.degrees(1.0)), 'estimated', 'true (scenario, Table 1)', 'slope'),
))
# fmt: on


def _common(a: TopicSeries, b: TopicSeries) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stamps present in both topics and their indices (first occurrence of duplicates)."""
    common, ia, ib = np.intersect1d(
        a.stamp_ns, b.stamp_ns, assume_unique=False, return_indices=True
    )
    return common, ia, ib


def _on_own_clock(est: TopicSeries, truth: TopicSeries) -> bool:
    """The reference does not share the estimates' stamps: fewer than half are found in it
    (the simulator's truth carries every one of them)."""
    found = np.isin(est.stamp_ns, truth.stamp_ns)
    return 2 * int(np.count_nonzero(found)) < est.stamp_ns.size


def _interpolated(
    truth: TopicSeries, field: str, stamps_ns: np.ndarray, max_gap_s: float
) -> FloatArray:
    """The reference's `field` linearly interpolated at `stamps_ns`.

    Args:
        truth: the reference topic (sorted by stamp).
        field: its field, shape (N,) or (N, K).
        stamps_ns: shape (M,), [ns], where it is wanted.
        max_gap_s: [s] interpolate only between samples at most this far apart (an exact
            stamp always counts).

    Returns:
        shape (M,) or (M, K), nan where the reference is absent (before its first sample,
        after its last one, across a longer gap or at a non-finite sample).
    """
    t_ref = truth.stamp_ns
    values = truth.values[field].astype(np.float64)
    if values.ndim == 1:
        return _interp_column(t_ref, values, stamps_ns, max_gap_s)
    columns = [_interp_column(t_ref, column, stamps_ns, max_gap_s) for column in values.T]
    return np.stack(columns, axis=1)


def _interp_column(
    t_ref: np.ndarray, values: FloatArray, stamps_ns: np.ndarray, max_gap_s: float
) -> FloatArray:
    keep = np.isfinite(values)
    t_ref, values = t_ref[keep], values[keep]
    out = np.full(stamps_ns.shape, np.nan)
    if t_ref.size == 0:
        return out
    right = np.searchsorted(t_ref, stamps_ns, side='left')
    exact = (right < t_ref.size) & (t_ref[np.minimum(right, t_ref.size - 1)] == stamps_ns)
    inside = (right > 0) & (right < t_ref.size)
    lo = np.maximum(right - 1, 0)
    hi = np.minimum(right, t_ref.size - 1)
    close = inside & ((t_ref[hi] - t_ref[lo]) * 1e-9 <= max_gap_s)
    # float64 seconds from the first reference stamp: ns since the epoch lose precision
    base = t_ref[0]
    out[close] = np.interp((stamps_ns[close] - base) * 1e-9, (t_ref - base) * 1e-9, values)
    out[exact] = values[hi[exact]]
    return out


def _first_stamp(series: BagSeries) -> int:
    return min(int(s.stamp_ns[0]) for s in series.topics.values())


def _events(
    series: BagSeries, settings: EvaluationSettings, t0: int
) -> tuple[FloatArray, FloatArray, FloatArray | None, FloatArray | None]:
    """Slope steps [s], gear changes [s], and the true slope (t [s], deg) if present."""
    steps = np.zeros(0)
    slope_t: FloatArray | None = None
    slope_deg: FloatArray | None = None
    truth_slope = series.topics.get(TRUTH_SLOPE)
    if truth_slope is not None:
        slope_t = (truth_slope.stamp_ns - t0) * 1e-9
        slope_deg = np.degrees(truth_slope.values['angle'].astype(np.float64))
        steps = step_times(slope_t, slope_deg, settings.slope_step_min_deg)
    gears = np.zeros(0)
    torques = series.topics.get(GEAR_TOPIC)
    if torques is not None:
        gears = change_times((torques.stamp_ns - t0) * 1e-9, torques.values['gear'])
    return steps, gears, slope_t, slope_deg


def has_reference(topics: Collection[str]) -> bool:
    """True when a bag's topics hold a reference to compare the estimates with (any
    ``/vd/truth/*`` topic)."""
    return any(t in topics for t in TRUTH_TOPICS)


def reference_kind(series: BagSeries) -> str:
    """'simulator', 'reference' or 'none': what the bag's ``/vd/truth/*`` topics are.

    The simulator's truth carries the estimates' own stamps and comes without an input
    mapping; a reference on its own clock (interpolated) or in a mapped bag (a car's own
    topics) is a real car's reference, which the simulator's targets do not judge.
    """
    if not has_reference(series.topics):
        return 'none'
    if series.inputs:
        return 'reference'
    for spec in _SPECS:
        est = series.topics.get(spec.est_topic)
        truth = series.topics.get(spec.truth_topic)
        if est is not None and truth is not None and _on_own_clock(est, truth):
            return 'reference'
    return 'simulator'


def build_comparisons(
    series: BagSeries, settings: EvaluationSettings | None = None
) -> tuple[list[Comparison], FloatArray, FloatArray, list[str]]:
    """Pair every estimated quantity with its truth on common stamps.

    Args:
        series: the decoded bag.
        settings: evaluation settings; default :class:`EvaluationSettings`.

    Returns:
        (comparisons, slope steps [s], gear changes [s], notes on what is missing).
    """
    cfg = settings or EvaluationSettings()
    t0 = _first_stamp(series)
    steps, gears, _, _ = _events(series, cfg, t0)
    events = np.concatenate([steps, gears])
    notes: list[str] = []
    out: list[Comparison] = []
    simulator = reference_kind(series) == 'simulator'
    for spec in _SPECS:
        est = series.topics.get(spec.est_topic)
        truth = series.topics.get(spec.truth_topic)
        if est is None and truth is None:
            continue
        ie: np.ndarray | None = None
        truth_label = spec.truth_label if simulator else f'reference ({spec.truth_topic})'
        if est is not None and truth is not None and _on_own_clock(est, truth):
            # a real car's reference: its own clock, interpolated onto the estimates
            stamps, ie = est.stamp_ns, np.arange(est.stamp_ns.size)
            estimate = est.values[spec.field].astype(np.float64) * spec.factor
            true = _interpolated(truth, spec.field, stamps, cfg.reference_max_gap_s) * spec.factor
            truth_label = f'reference ({spec.truth_topic}, interpolated)'
            covered = np.isfinite(true) if true.ndim == 1 else np.isfinite(true).all(axis=1)
            notes.append(
                f'{spec.title}: the reference {spec.truth_topic} runs on its own clock: '
                f"interpolated onto the estimates' stamps (gaps up to "
                f'{cfg.reference_max_gap_s:g} s), {100 * covered.mean():.0f} % of them covered'
            )
        elif est is not None and truth is not None:
            stamps, ie, it = _common(est, truth)
            estimate = est.values[spec.field][ie].astype(np.float64) * spec.factor
            true = truth.values[spec.field][it].astype(np.float64) * spec.factor
        elif est is not None:
            notes.append(f'{spec.title}: no reference ({spec.truth_topic} missing), plotted only')
            stamps = est.stamp_ns
            estimate, true = est.values[spec.field].astype(np.float64) * spec.factor, None
        else:
            assert truth is not None
            notes.append(f'{spec.title}: no estimate ({spec.est_topic} missing)')
            stamps = truth.stamp_ns
            estimate, true = None, truth.values[spec.field].astype(np.float64) * spec.factor
        t = (stamps - t0) * 1e-9
        mask = evaluation_mask(
            t, start=cfg.settle_s, events=events, half_width=cfg.exclusion_half_width_s
        )
        if true is not None:  # a reference absent there (own clock, beyond its gaps)
            finite = np.isfinite(true)
            mask = mask & (finite if mask.ndim == finite.ndim else finite.all(axis=1))
        if spec.key == 'mu' and estimate is not None and true is not None:
            mask = _mu_mask(series, stamps, mask, cfg, notes)
        elif spec.key == 'slope' and est is not None and true is not None:
            mask = mask & est.values['valid'][ie].astype(bool)
        out.append(
            Comparison(
                spec.key,
                spec.title,
                spec.unit,
                t,
                estimate,
                true,
                mask,
                spec.estimate_label,
                truth_label,
                spec.symbol,
                _validity(est, ie) if spec.key in _FLAGGED else None,
            )
        )
    return out, steps, gears, notes


#: The quantities whose message's ``valid`` flags are theirs (the friction message's flags
#: are mu's, not the slip's).
_FLAGGED = frozenset({'mu', 'slope'})


def _validity(est: TopicSeries | None, rows: np.ndarray | None) -> BoolArray | None:
    """The estimate's own ``valid`` flags on the compared rows (None: no such field)."""
    if est is None or 'valid' not in est.values:
        return None
    flags = est.values['valid'].astype(bool)
    return flags if rows is None else flags[rows]


def _mu_mask(
    series: BagSeries,
    stamps: np.ndarray,
    mask: BoolArray,
    cfg: EvaluationSettings,
    notes: list[str],
) -> BoolArray:
    """mu counts where the wheel is excited (|Fx| > k Fz, true forces) and the estimate valid."""
    est = series.topics[ESTIMATES_FRICTION]
    valid = est.values['valid'][np.searchsorted(est.stamp_ns, stamps)].astype(bool)
    forces = series.topics.get(TRUTH_TIRE_FORCES)
    excited = np.zeros(valid.shape, dtype=bool)
    if forces is None:
        notes.append(f'μ: {TRUTH_TIRE_FORCES} missing, cannot select excited samples')
    else:
        _, ia, ib = np.intersect1d(stamps, forces.stamp_ns, return_indices=True)
        fx, fz = forces.values['fx'][ib], forces.values['fz'][ib]
        excited[ia] = np.abs(fx) > cfg.mu_excitation * fz
    selected: BoolArray = mask[:, None] & excited & valid
    return selected


def _static_loads(series: BagSeries, settle_s: float) -> FloatArray | None:
    """Median true Fz over the first ``settle_s`` seconds, per wheel [N]."""
    forces = series.topics.get(TRUTH_TIRE_FORCES)
    if forces is None:
        return None
    first = forces.stamp_ns <= forces.stamp_ns[0] + round(settle_s * 1e9)
    loads: FloatArray = np.median(forces.values['fz'][first].astype(np.float64), axis=0)
    return loads


def evaluate(
    series: BagSeries,
    *,
    settings: EvaluationSettings | None = None,
    static_loads: FloatArray | None = None,
    alert_settings: AlertSettings | None = None,
) -> tuple[AccuracyReport, list[Comparison]]:
    """Metrics of every estimated quantity against the truth in the bag.

    Args:
        series: the decoded bag.
        settings: evaluation settings; default :class:`EvaluationSettings`.
        static_loads: shape (4,), [N], static wheel loads for the Fz percentage; default the
            median true Fz over the first ``settle_s`` seconds.
        alert_settings: definitions of the alerts section; default :class:`AlertSettings`.

    Returns:
        (report, comparisons for the figures).

    Raises:
        ReportInputError: the bag holds no truth topic (:func:`evaluate_estimates` reports
            such a bag), or no topic at all.
    """
    cfg = settings or EvaluationSettings()
    if not series.topics:
        raise ReportInputError(f'{series.path}: none of the vd topics found in the bag')
    present_truth = [t for t in TRUTH_TOPICS if t in series.topics]
    if not present_truth:
        raise ReportInputError(
            f'{series.path}: no truth topics (need at least one of {TRUTH_NAMESPACE}*: '
            + ', '.join(name.rsplit('/', 1)[1] for name in TRUTH_TOPICS)
            + ')'
        )
    comparisons, steps, gears, notes = build_comparisons(series, cfg)
    loads = static_loads if static_loads is not None else _static_loads(series, cfg.settle_s)
    t0 = _first_stamp(series)
    last = max(int(s.stamp_ns[-1]) for s in series.topics.values())
    quantities: list[QuantityMetrics] = []
    for c in comparisons:
        if c.estimate is None or c.truth is None:
            continue
        window = None
        if c.key == 'slope':
            window = evaluation_mask(
                c.t,
                start=cfg.settle_s,
                events=np.concatenate([steps, gears]),
                half_width=cfg.exclusion_half_width_s,
            )
        metrics = QuantityAccumulator(c.key, c.title, c.unit, cfg)
        metrics.add(c.estimate, c.truth, c.mask, window=window, static_loads=loads)
        quantities.append(metrics.result())
    convergence = _convergence(comparisons, steps, cfg, notes)
    truth_t = (series.topics[present_truth[0]].stamp_ns - t0) * 1e-9
    window = evaluation_mask(
        truth_t,
        start=cfg.settle_s,
        events=np.concatenate([steps, gears]),
        half_width=cfg.exclusion_half_width_s,
    )
    notes.extend(
        closing_notes(set(series.topics), torque_path(series), series.skipped, series.inputs)
    )
    data, alert_notes = alert_data(series)
    section = (
        None
        if data is None
        else evaluate_alerts_section(data, alert_settings or AlertSettings(), tuple(alert_notes))
    )
    if section is None:
        notes.extend(alert_notes)
    kind = reference_kind(series)
    if kind != 'simulator':
        notes.append(
            "the reference is a car's (on its own clock or in a mapped bag), not the "
            "simulator's truth: the simulator's ideal-sensor targets are not judged"
        )
    report = AccuracyReport(
        bag=str(series.path),
        first_stamp_s=t0 * 1e-9,
        duration_s=(last - t0) * 1e-9,
        settings=cfg,
        slope_steps_s=tuple(steps.tolist()),
        gear_changes_s=tuple(gears.tolist()),
        evaluated_fraction=float(window.mean()) if window.size else 0.0,
        quantities=tuple(quantities),
        convergence=tuple(convergence),
        targets=_targets(quantities) if kind == 'simulator' else {},
        notes=tuple(notes),
        alerts=section,
        reference=kind,
    )
    return report, comparisons


def evaluate_estimates(
    series: BagSeries,
    *,
    settings: EvaluationSettings | None = None,
) -> tuple[AccuracyReport, list[Comparison]]:
    """The report of a bag without reference: every estimate's own values, no accuracy.

    Per estimate (and wheel): samples, the share valid (finite, and the estimator's ``valid``
    flag where its message has one: mu, slope), min / mean / max of the valid values over the
    whole bag (no evaluation window: there are no steps to exclude).

    Args:
        series: the decoded bag (its ``/vd/truth/*`` topics, if any, are not used).
        settings: evaluation settings (the figures' grey start-up band); default
            :class:`EvaluationSettings`.

    Returns:
        (report with ``reference`` 'none', ``estimates`` filled, ``quantities`` and
        ``targets`` empty; comparisons without truth, for the figures).

    Raises:
        ReportInputError: the bag holds none of the vd topics, or no estimate.
    """
    cfg = settings or EvaluationSettings()
    if not series.topics:
        raise ReportInputError(f'{series.path}: none of the vd topics found in the bag')
    if not any(t in series.topics for t in ESTIMATE_TOPICS):
        raise ReportInputError(
            f'{series.path}: no {OBSERVER_NAMESPACE}* or {ESTIMATES_NAMESPACE}* topic and no '
            'reference: nothing to report (compute the estimates with `vd replay IN OUT`, or '
            'give --mapping)'
        )
    without = BagSeries(
        series.path,
        {k: v for k, v in series.topics.items() if k not in TRUTH_TOPICS},
        series.skipped,
        series.read_time_s,
        series.message_count,
        series.inputs,
    )
    comparisons, steps, gears, _ = build_comparisons(without, cfg)
    comparisons = [c for c in comparisons if c.estimate is not None]
    stats: list[EstimateStats] = []
    for c in comparisons:
        assert c.estimate is not None
        valid = c.estimate_valid
        overall = value_stats(c.estimate, valid)
        wheels: tuple[ValueStats, ...] = ()
        if c.per_wheel:
            wheels = tuple(
                value_stats(c.estimate[:, k], None if valid is None else valid[:, k])
                for k in range(c.estimate.shape[1])
            )
        note = 'finite and flagged valid' if valid is not None else 'finite'
        stats.append(EstimateStats(c.key, c.title, c.unit, overall, wheels, note))
    t0 = _first_stamp(without)
    last = max(int(s.stamp_ns[-1]) for s in without.topics.values())
    notes = [f'no reference in the bag: no accuracy computed; {NO_REFERENCE_HINT}']
    notes.extend(
        n
        for n in closing_notes(
            set(without.topics), torque_path(without), series.skipped, series.inputs
        )
        # what excludes samples from an accuracy window says nothing without one
        if not n.startswith(('reference topics missing', f'{TRUTH_SLOPE} missing', GEAR_TOPIC))
    )
    report = AccuracyReport(
        bag=str(series.path),
        first_stamp_s=t0 * 1e-9,
        duration_s=(last - t0) * 1e-9,
        settings=cfg,
        slope_steps_s=tuple(steps.tolist()),
        gear_changes_s=tuple(gears.tolist()),
        evaluated_fraction=0.0,
        quantities=(),
        convergence=(),
        targets={},
        notes=tuple(notes),
        alerts=None,
        reference='none',
        estimates=tuple(stats),
    )
    return report, comparisons


def evaluate_alerts_section(
    data: AlertData, settings: AlertSettings | None = None, notes: tuple[str, ...] = ()
) -> AlertsSection:
    """All metrics of the section from the paired arrays."""
    cfg = settings or AlertSettings()
    episodes: list[AlertEpisode] = []
    alarms: list[FalseAlarm] = []
    if data.level is not None:
        truth, relaxed = data_conditions(data, cfg)
        episodes, alarms = evaluate_alerts(data.t, truth, relaxed, data.level, data.onset, cfg)
    segments: list[MuMaxSegment] = []
    if data.mu_max is not None:
        segments = mu_max_errors(
            data.t,
            axle_utilisation(data.mu, data.peak_mu),
            data.true_mu_max,
            data.mu_max,
            segments_from_peaks(data.true_mu_max, cfg.road_jump),
            confidence=data.confidence,
            road_classes=(data.road_class, data.true_road_class),
            settings=cfg,
        )
    return alerts_section(
        cfg, int(data.t.size), data.level is not None, episodes, alarms, segments, notes
    )


def closing_notes(
    present: Collection[str],
    torque: str,
    skipped: Mapping[str, str],
    inputs: Sequence[InputStats],
) -> list[str]:
    """The report's notes on what the bag lacks, after the comparisons' own notes.

    Args:
        present: the topics decoded from the bag.
        torque: the torque-path note (:func:`torque_path`), '' for none.
        skipped: topic -> why it was not used.
        inputs: the mapped inputs' arrival summaries.
    """
    notes: list[str] = []
    if GEAR_TOPIC not in present:
        notes.append(f'{GEAR_TOPIC} missing: gear shifts not excluded')
    if TRUTH_SLOPE not in present:
        notes.append(f'{TRUTH_SLOPE} missing: slope steps not excluded, no convergence times')
    if not any(t in present for t in ESTIMATE_TOPICS):
        notes.append(
            f'no {OBSERVER_NAMESPACE}* or {ESTIMATES_NAMESPACE}* topic: nothing to compare '
            '(compute them offline with `vd replay IN OUT`)'
        )
    if torque:
        notes.append(torque)
    missing_truth = [t for t in TRUTH_TOPICS if t not in present]
    if missing_truth:
        notes.append('reference topics missing: ' + ', '.join(missing_truth))
    notes.extend(f'{name} skipped: {why}' for name, why in skipped.items())
    notes.extend(f'input {stats.text()}' for stats in inputs)
    return notes


#: Names of vd_msgs' TORQUE_* codes (estimation.drivetrain.TORQUE_SOURCES).
_TORQUE_PATHS = {
    0: 'measured wheel torques',
    1: 'engine torque and gear (drivetrain of the vehicle file)',
    2: 'none (Fx is 0, mu and slope invalid)',
}


def torque_path(series: BagSeries) -> str:
    """Which torque path the estimates came from, from their torque_source field ('' without
    tyre-force estimates)."""
    forces = series.topics.get(ESTIMATES_TIRE_FORCES)
    if forces is None:
        return ''
    codes = forces.values.get('torque_source')
    return torque_path_note(None if codes is None else np.unique(codes))


def torque_path_note(codes: np.ndarray | None) -> str:
    """The torque-path note from the distinct torque_source codes of the tyre-force estimates
    (shape (K,), sorted; None: the field is not in the bag's messages)."""
    if codes is None:
        return (
            'torque path: not recorded (estimates from before the torque_source field: measured)'
        )
    names = [_TORQUE_PATHS.get(int(c), f'unknown code {int(c)}') for c in codes]
    return 'torque path: ' + '; '.join(names)


def _convergence(
    comparisons: list[Comparison], steps: FloatArray, cfg: EvaluationSettings, notes: list[str]
) -> list[SlopeConvergence]:
    slope = next((c for c in comparisons if c.key == 'slope'), None)
    if slope is None or slope.estimate is None or slope.truth is None or steps.size == 0:
        return []
    if slope.t.size == 0:
        # no common stamps (said in the notes already): a reference on its own clock, which
        # is not interpolated onto the estimates yet
        notes.append('slope convergence skipped: no stamp shared by the estimate and the truth')
        return []
    convergence = ConvergenceAccumulator(cfg)
    convergence.feed(slope.t, slope.estimate, slope.truth, steps)
    return convergence.result()


def target_values(quantities: Sequence[QuantityMetrics]) -> dict[str, float]:
    """The figures :data:`TARGETS` name, where finite (target name -> value), whether or
    not the bag is one the targets judge."""
    by_key = {q.key: q for q in quantities}
    out: dict[str, float] = {}
    for name, (key, metric, _) in TARGETS.items():
        q = by_key.get(key)
        if q is None:
            continue
        value = q.overall.rms if metric == 'rms' else q.extras.get(metric, float('nan'))
        if np.isfinite(value):
            out[name] = float(value)
    return out


def _targets(quantities: Sequence[QuantityMetrics]) -> dict[str, tuple[float, float, bool]]:
    return {
        name: (value, TARGETS[name][2], bool(value <= TARGETS[name][2]))
        for name, value in target_values(quantities).items()
    }
