"""The accuracy report's settings and records: what `evaluation` computes and the formats read.

:class:`EvaluationSettings` (what counts and how), :class:`Comparison` (one quantity's
estimate and truth on common stamps), :class:`QuantityMetrics`, :class:`SlopeConvergence`,
:class:`EstimateStats` and the whole :class:`AccuracyReport`, with the simulator's
:data:`TARGETS`. Split from `evaluation` so that each stays small enough to read (#40), and
so that the streamed evaluation, the formats and the figures read the records without the
computations.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from vd_common.topics import (
    TRUTH_NAMESPACE,
    TRUTH_SLOPE,
)

from vd_observer_node.tools.report.alerts import (
    AlertsSection,
)
from vd_observer_node.tools.report.metrics import (
    ErrorStats,
    ValueStats,
)

__all__ = [
    'NO_REFERENCE_HINT',
    'TARGETS',
    'TARGETS_TITLE',
    'AccuracyReport',
    'Comparison',
    'EstimateStats',
    'EvaluationSettings',
    'QuantityMetrics',
    'SlopeConvergence',
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: The issue's accuracy targets with ideal sensors: metric key -> (quantity key, limit).
TARGETS: dict[str, tuple[str, str, float]] = {
    'slope RMS [deg]': ('slope', 'rms', 0.2),
    'mu RMS [-]': ('mu', 'rms', 0.01),
    'Fx RMS [% of max |Fx|]': ('fx', 'rms_pct_of_max_truth', 2.0),
    'Fz RMS [% of static load]': ('fz', 'rms_pct_of_static', 1.0),
    'omega relative RMS [%]': ('omega', 'rel_rms_pct', 0.1),
}
#: What :data:`TARGETS` are: judged only on the simulator's bags, never on a real car's.
TARGETS_TITLE = "Targets for the simulator's ideal sensors"

#: How a bag without reference gets one (the report's note and the command's first line).
NO_REFERENCE_HINT = (
    f'to compare, record a reference on {TRUTH_NAMESPACE}* in the bag (e.g. a grade from '
    f'a GNSS/INS as {TRUTH_SLOPE}, vd_msgs/msg/Slope, on its own clock: it is interpolated '
    'onto the estimates; docs/report.md)'
)


@dataclass(frozen=True)
class EvaluationSettings:
    """How the metrics are taken.

    Attributes:
        settle_s: [s] after the first stamp not evaluated (start-up of the differentiators).
        exclusion_half_width_s: [s] excluded either side of slope steps and gear changes.
        slope_step_min_deg: [deg] smallest sample-to-sample change of the true slope that
            counts as a step.
        convergence_threshold_deg: [deg] |slope error| bound for convergence.
        convergence_hold_s: [s] the error must stay below the bound this long.
        mu_excitation: mu is evaluated only where |Fx_true| > mu_excitation * Fz_true.
        omega_min: [rad/s] omega relative error only where |omega_true| exceeds this.
        reference_max_gap_s: [s] a reference on its own clock (a real car's, not the
            simulator's: fewer than half of the estimates' stamps found in it) is
            interpolated linearly onto the estimates' stamps between two of its samples at
            most this far apart; elsewhere it is absent and the stamp is not evaluated.
    """

    settle_s: float = 1.0
    exclusion_half_width_s: float = 0.5
    slope_step_min_deg: float = 0.1
    convergence_threshold_deg: float = 0.5
    convergence_hold_s: float = 1.0
    mu_excitation: float = 0.05
    omega_min: float = 5.0
    reference_max_gap_s: float = 0.5


@dataclass(frozen=True)
class Comparison:
    """One quantity: estimate and truth on common stamps (either may be absent).

    Attributes:
        key: short name ('omega', 'fx', 'slope', ...).
        title: human name for tables and figures.
        unit: unit of ``estimate`` and ``truth`` (already converted, e.g. slope in deg).
        t: shape (M,), [s] since the bag's first stamp.
        estimate: shape (M,) or (M, 4) (wheel order FL, FR, RL, RR), or None.
        truth: same shape, or None.
        mask: shape (M,) or (M, 4), bool: samples that count in the metrics.
        estimate_label: legend text of the estimate.
        truth_label: legend text of the truth.
        symbol: axis label of the quantity without its unit (e.g. 'Fx').
        estimate_valid: same shape as ``estimate``: the estimator's own validity flags
            (mu, slope), or None for the other quantities.
    """

    key: str
    title: str
    unit: str
    t: FloatArray
    estimate: FloatArray | None
    truth: FloatArray | None
    mask: BoolArray
    estimate_label: str
    truth_label: str
    symbol: str = ''
    estimate_valid: BoolArray | None = None

    @property
    def per_wheel(self) -> bool:
        """True for 4-wheel quantities (arrays of shape (M, 4))."""
        data = self.estimate if self.estimate is not None else self.truth
        return data is not None and data.ndim == 2


@dataclass(frozen=True)
class QuantityMetrics:
    """Accuracy of one estimated quantity.

    Attributes:
        key: short name (see :class:`Comparison`).
        title: human name.
        unit: unit of the error statistics.
        overall: statistics over all wheels (or the scalar quantity).
        wheels: per wheel FL, FR, RL, RR; empty for scalar quantities.
        extras: further figures by name (e.g. 'rms_pct_of_max_truth' [%]).
        note: caveats (e.g. 'no truth').
    """

    key: str
    title: str
    unit: str
    overall: ErrorStats
    wheels: tuple[ErrorStats, ...]
    extras: dict[str, float]
    note: str = ''


@dataclass(frozen=True)
class SlopeConvergence:
    """Slope estimate convergence after one true slope step.

    Attributes:
        step_s: [s] since the first stamp.
        from_deg: true slope before the step [deg].
        to_deg: true slope after the step [deg].
        delay_s: [s] until |error| stays below the threshold for the hold time; None if it
            never did before the next step or the end.
    """

    step_s: float
    from_deg: float
    to_deg: float
    delay_s: float | None


@dataclass(frozen=True)
class AccuracyReport:
    """Everything the report prints and writes.

    Attributes:
        bag: path of the bag.
        first_stamp_s: [s] absolute header stamp taken as t = 0.
        duration_s: [s] covered by the stamps.
        settings: how the metrics were taken.
        slope_steps_s: [s] detected true slope steps.
        gear_changes_s: [s] detected gear changes.
        evaluated_fraction: share of the truth samples inside the evaluation window.
        quantities: metrics per estimated quantity with truth.
        convergence: slope convergence after each step.
        targets: target name -> (value, limit, met) for the issue's targets found.
        notes: what is missing from the bag and other caveats.
        alerts: the alerts and friction-potential section (None: skipped, see ``notes``).
        reference: what the estimates were compared with: 'simulator' (the simulator's
            truth, on the estimates' stamps), 'reference' (a real car's, e.g. on its own
            clock or in a mapped bag: no targets judged) or 'none' (an estimates-only
            report: ``quantities`` and ``targets`` are empty, ``estimates`` holds the
            statistics).
        estimates: statistics of every estimate's own values (estimates-only reports).
    """

    bag: str
    first_stamp_s: float
    duration_s: float
    settings: EvaluationSettings
    slope_steps_s: tuple[float, ...]
    gear_changes_s: tuple[float, ...]
    evaluated_fraction: float
    quantities: tuple[QuantityMetrics, ...]
    convergence: tuple[SlopeConvergence, ...]
    targets: dict[str, tuple[float, float, bool]]
    notes: tuple[str, ...]
    alerts: AlertsSection | None = None
    reference: str = 'simulator'
    estimates: tuple[EstimateStats, ...] = ()


@dataclass(frozen=True)
class EstimateStats:
    """One estimate's values over the drive (a report without reference).

    Attributes:
        key: short name (see :class:`Comparison`).
        title: human name.
        unit: unit of the statistics (e.g. deg for the slope).
        overall: over all wheels (or the scalar quantity), every sample of the bag.
        wheels: per wheel FL, FR, RL, RR; empty for scalar quantities.
        note: what counts as valid.
    """

    key: str
    title: str
    unit: str
    overall: ValueStats
    wheels: tuple[ValueStats, ...]
    note: str = ''
