"""The alerts section's input: the alert, friction-potential and truth rows of a bag, paired.

:class:`AlertData` holds the section's arrays on common stamps; :func:`alert_data` builds it
from a whole bag's series, :func:`paired_alert_data` from rows the streamed evaluation has
paired; :func:`alert_section_skip`, :func:`alert_section_topics` and :func:`alert_data_notes`
say which topics the section needs and what it left out. `alerts` scores the episodes and
mu_max on it. Split from `alerts` so that each stays small enough to read (#40).
"""

from __future__ import annotations

from collections.abc import Collection, Mapping
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray
from vd_common.topics import TRUTH_FRICTION

from vd_observer_node.tools.report.load import BagSeries
from vd_observer_node.tools.report.topics import (
    ALERT_TOPIC,
    ESTIMATED_POTENTIAL_TOPIC,
    TRUE_POTENTIAL_TOPIC,
)

__all__ = [
    'NO_COMMON_STAMP',
    'AlertData',
    'alert_data',
    'alert_data_notes',
    'alert_section_skip',
    'alert_section_topics',
    'paired_alert_data',
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
IntArray = NDArray[np.int64]


@dataclass(frozen=True)
class AlertData:
    """The arrays of the section on common stamps (t from the bag's first stamp).

    Attributes:
        t: shape (N,), [s].
        slip: shape (N, 4), [-] true slip.
        mu: shape (N, 4), [-] true μ.
        peak_slip: shape (N, 4), [-] true peak slip (the axle's value on both its wheels).
        peak_mu: shape (N, 4), [-] true peak μ (the axle's value on both its wheels).
        true_mu_max: shape (N, 2), [-].
        true_road_class: shape (N, 2), codes.
        level: shape (N, 3, 4), alert levels, or None (no alerts topic).
        onset: shape (N, 3, 4), [s] the alerts' onset stamps (nan while inactive), or None.
        mu_max: shape (N, 2), [-] estimated μ_max, or None (no friction-potential estimate).
        confidence: shape (N, 2), or None.
        road_class: shape (N, 2), estimated codes, or None.
    """

    t: FloatArray
    slip: FloatArray
    mu: FloatArray
    peak_slip: FloatArray
    peak_mu: FloatArray
    true_mu_max: FloatArray
    true_road_class: IntArray
    level: IntArray | None = None
    onset: FloatArray | None = None
    mu_max: FloatArray | None = None
    confidence: FloatArray | None = None
    road_class: IntArray | None = None


def _rows(stamps: np.ndarray, wanted: np.ndarray) -> np.ndarray:
    """Row of each wanted stamp in a sorted stamp array (all present)."""
    return np.searchsorted(stamps, wanted)


def alert_data(series: BagSeries) -> tuple[AlertData | None, list[str]]:
    """Pair the alerts, the friction-potential estimate and their truth by header stamp.

    Returns:
        (data, notes); data is None with a note saying why when the bag cannot be judged
        (no true friction potential, or neither alerts nor a friction-potential estimate).
    """
    topics = series.topics
    skip = alert_section_skip(set(topics))
    if skip:
        return None, [skip]
    present = alert_section_topics(set(topics))
    stamps = topics[present[0]].stamp_ns
    for name in present[1:]:
        stamps = np.intersect1d(stamps, topics[name].stamp_ns)
    if stamps.size == 0:
        return None, [NO_COMMON_STAMP]
    t0 = min(int(s.stamp_ns[0]) for s in topics.values())
    rows = {
        name: {k: v[_rows(topics[name].stamp_ns, stamps)] for k, v in topics[name].values.items()}
        for name in present
    }
    dropped = topics[TRUE_POTENTIAL_TOPIC].stamp_ns.size - stamps.size
    return paired_alert_data(stamps, rows, t0), alert_data_notes(set(present), dropped)


def alert_section_skip(present: Collection[str]) -> str:
    """Why the section cannot be judged from a bag with these topics ('' if it can)."""
    missing = [name for name in (TRUE_POTENTIAL_TOPIC, TRUTH_FRICTION) if name not in present]
    if missing:
        return (
            'alerts section skipped: no '
            + ' or '.join(missing)
            + ' in the bag (recorded before the simulator published the true friction '
            'potential, or without truth)'
        )
    if ALERT_TOPIC not in present and ESTIMATED_POTENTIAL_TOPIC not in present:
        return (
            f'alerts section skipped: neither {ALERT_TOPIC} nor {ESTIMATED_POTENTIAL_TOPIC} '
            'in the bag (run the alerts node, or `vd replay` the bag)'
        )
    return ''


def alert_section_topics(present: Collection[str]) -> list[str]:
    """The section's topics found among ``present``, paired on their common stamps."""
    wanted = (TRUE_POTENTIAL_TOPIC, TRUTH_FRICTION, ALERT_TOPIC, ESTIMATED_POTENTIAL_TOPIC)
    return [name for name in wanted if name in present]


#: Why the section is skipped when its topics share no stamp.
NO_COMMON_STAMP = 'alerts section skipped: no stamp common to the alerts and the truth'


def alert_data_notes(present: Collection[str], dropped: int) -> list[str]:
    """What the section lacks: the estimate topics absent, true stamps left unmatched.

    Args:
        present: the section's topics found in the bag.
        dropped: true friction-potential messages without a stamp common to all of them.
    """
    notes: list[str] = []
    if ALERT_TOPIC not in present:
        notes.append(f'{ALERT_TOPIC} missing: no alert delays or false alarms')
    if ESTIMATED_POTENTIAL_TOPIC not in present:
        notes.append(f'{ESTIMATED_POTENTIAL_TOPIC} missing: no μ_max error')
    if dropped > 0:
        notes.append(f'alerts section: {dropped} truth stamps without a matching estimate')
    return notes


def paired_alert_data(
    stamps: np.ndarray, rows: Mapping[str, Mapping[str, np.ndarray]], t0: int
) -> AlertData:
    """The section's arrays from rows already paired on common stamps.

    Args:
        stamps: shape (N,), [ns] the common header stamps, increasing.
        rows: topic -> field -> values on those stamps (first axis N), for the true friction
            and friction potential and, when in the bag, the alerts and the estimated
            friction potential.
        t0: [ns] the bag's first stamp (t = 0).
    """
    t = (stamps - t0) * 1e-9
    fric = rows[TRUTH_FRICTION]
    pot = rows[TRUE_POTENTIAL_TOPIC]
    true_mu_max = pot['mu_max'].astype(np.float64)
    true_slip_peak = pot['slip_peak'].astype(np.float64)
    wheel = np.array([0, 0, 1, 1])
    data = AlertData(
        t=t,
        slip=fric['slip'].astype(np.float64),
        mu=fric['mu'].astype(np.float64),
        peak_slip=true_slip_peak[:, wheel],
        peak_mu=true_mu_max[:, wheel],
        true_mu_max=true_mu_max,
        true_road_class=pot['road_class'].astype(np.int64),
    )
    kw: dict[str, np.ndarray] = {}
    alerts = rows.get(ALERT_TOPIC)
    if alerts is not None:
        kw['level'] = alerts['level'].astype(np.int64)
        onset_ns = alerts['onset_ns']
        kw['onset'] = np.where(onset_ns > 0, (onset_ns - t0) * 1e-9, np.nan)
    est = rows.get(ESTIMATED_POTENTIAL_TOPIC)
    if est is not None:
        kw['mu_max'] = est['mu_max'].astype(np.float64)
        kw['confidence'] = est['confidence'].astype(np.float64)
        kw['road_class'] = est['road_class'].astype(np.int64)
    return replace(data, **kw)
