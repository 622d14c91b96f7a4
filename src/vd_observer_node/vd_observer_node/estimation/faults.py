"""Fault kinds of the observers and the estimator, their severity and per-kind counters.

The core counts what went wrong with its inputs (and the rare internal overflow) in a
`FaultCounter`; the nodes turn `FaultCounter.report` into one ``/diagnostics`` status per
node, so the live graph and the offline cascade count the same faults on the same input.
See docs/faults.md for what each kind means and what the core does about it.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Final

from vd_observer_node.errors import ConfigurationError
from vd_observer_node.kernel._jit import jit

__all__ = [
    'ENGINE_FAULTS',
    'ERROR',
    'ESTIMATOR_FAULTS',
    'FAULT_LEVELS',
    'OBSERVER_FAULTS',
    'OK',
    'RESTART_FAULTS',
    'STAMP_FAULTS',
    'WARN',
    'FaultCounter',
    'FaultReport',
    'classify_stamp',
    'merge_reports',
    'stamp_dt',
    'stamp_step',
    'summarise',
]

#: Levels, numerically equal to diagnostic_msgs/DiagnosticStatus OK, WARN, ERROR.
OK: Final = 0
WARN: Final = 1
ERROR: Final = 2

#: Severity of every fault kind. Input faults are WARN: the core handles them (drops, holds,
#: resets) and the outputs stay finite; ERROR means the core had to throw its state away
#: because a computation overflowed.
FAULT_LEVELS: Final[Mapping[str, int]] = {
    'non_finite_stamp': WARN,
    'non_finite_value': WARN,
    'duplicate_stamp': WARN,
    'out_of_order': WARN,
    'gap': WARN,
    'time_jump_back': WARN,
    'wheel_lift': WARN,
    'mu_out_of_range': WARN,
    'slope_out_of_range': WARN,
    'arcsin_domain': WARN,
    'mass_clamped': WARN,
    'radius_clamped': WARN,
    'torque_offset_clamped': WARN,
    'non_finite_output': ERROR,
}

#: Input kinds every online estimator counts: the stamp rules of `classify_stamp` and a
#: non-finite value.
STAMP_FAULTS: Final = (
    'non_finite_stamp',
    'non_finite_value',
    'duplicate_stamp',
    'out_of_order',
    'gap',
    'time_jump_back',
)
#: The stamp faults after which an estimator starts again from the new sample.
RESTART_FAULTS: Final = frozenset({'gap', 'time_jump_back'})
#: Kinds an observer (differentiator) can count.
OBSERVER_FAULTS: Final = (*STAMP_FAULTS, 'non_finite_output')
#: Kinds the estimator can count ('mass_clamped', 'radius_clamped': its online mass or
#: rolling radius hit a bound).
ESTIMATOR_FAULTS: Final = (*OBSERVER_FAULTS, 'wheel_lift', 'mu_out_of_range',
                           'slope_out_of_range', 'arcsin_domain', 'mass_clamped',
                           'radius_clamped')  # fmt: skip
#: Kinds the engine path can count ('torque_offset_clamped': the engine-torque offset learnt
#: in neutral is beyond its bound, counted per stamp).
ENGINE_FAULTS: Final = ('torque_offset_clamped',)


@dataclass(frozen=True)
class FaultReport:
    """What happened since the previous report, and the totals.

    Attributes:
        level: OK, WARN or ERROR: the worst severity among `active`.
        active: kinds counted since the previous report, in `FAULT_LEVELS` order.
        counts: total count per kind since start (every kind, zeros included).
    """

    level: int
    active: tuple[str, ...]
    counts: dict[str, int]

    @property
    def message(self) -> str:
        """One line for DiagnosticStatus.message: 'ok' or the active kinds."""
        if not self.active:
            return 'ok'
        return 'faults since last report: ' + ', '.join(self.active)


class FaultCounter:
    """Counts faults per kind; `report` also says which kinds occurred since the last report."""

    def __init__(self, kinds: Iterable[str] = tuple(FAULT_LEVELS)) -> None:
        """Create zeroed counters.

        Args:
            kinds: fault kinds to count, each a key of `FAULT_LEVELS`.

        Raises:
            ConfigurationError: an unknown kind.
        """
        self._counts = {k: 0 for k in kinds}
        unknown = set(self._counts) - set(FAULT_LEVELS)
        if unknown:
            raise ConfigurationError(f'unknown fault kinds {sorted(unknown)}')
        self._reported = dict(self._counts)

    def count(self, kind: str, n: int = 1) -> None:
        """Add n occurrences of `kind` (a kind this counter was created with)."""
        self._counts[kind] += n

    @property
    def counts(self) -> dict[str, int]:
        """Total per kind since creation (a copy)."""
        return dict(self._counts)

    @property
    def total(self) -> int:
        """Sum over all kinds."""
        return sum(self._counts.values())

    def report(self) -> FaultReport:
        """Summarise and start a new reporting period."""
        report = summarise(self._counts, self._reported)
        self._reported = dict(self._counts)
        return report


def summarise(counts: Mapping[str, int], previous: Mapping[str, int]) -> FaultReport:
    """FaultReport of totals `counts` against the totals at the previous report."""
    active = tuple(k for k in FAULT_LEVELS if counts.get(k, 0) > previous.get(k, 0))
    level = max((FAULT_LEVELS[k] for k in active), default=OK)
    return FaultReport(level=level, active=active, counts=dict(counts))


def merge_reports(reports: Mapping[str, FaultReport]) -> FaultReport:
    """Combine the reports of several parts of one node (e.g. 'wheel', 'speed').

    Counters are prefixed by the part name ('wheel.gap'); level and active kinds combine
    (an active kind is named once, prefixed).
    """
    level = max((r.level for r in reports.values()), default=OK)
    active = tuple(f'{part}.{k}' for part, r in reports.items() for k in r.active)
    counts = {f'{part}.{k}': v for part, r in reports.items() for k, v in r.counts.items()}
    return FaultReport(level=level, active=active, counts=counts)


#: `stamp_step`'s codes: indices into `STAMP_FAULTS` (-1: no fault).
_NON_FINITE_STAMP, _DUPLICATE, _OUT_OF_ORDER, _GAP, _JUMP_BACK = 0, 2, 3, 4, 5


@jit
def stamp_step(last: float, t: float, max_gap: float) -> tuple[int, float]:
    """The stamp rules of the online estimators, as a compiled step.

    A non-finite stamp, a repeated one or one slightly older than the last (by at most
    ``max_gap``) is rejected; one older by more (a looped bag) or newer by more than
    ``max_gap`` restarts from this sample (`RESTART_FAULTS`).

    Args:
        last: stamp [s] of the last accepted sample, nan before the first.
        t: this sample's stamp [s].
        max_gap: [s] > 0.

    Returns:
        (index into `STAMP_FAULTS` of the fault to count, -1 for none; dt [s]): dt nan
        rejects the sample, 0.0 starts (again) at t, > 0 steps on.
    """
    if not math.isfinite(t):
        return _NON_FINITE_STAMP, math.nan
    if math.isnan(last):
        return -1, 0.0
    dt = t - last
    if dt == 0.0:
        return _DUPLICATE, math.nan
    if dt < 0.0:
        if -dt <= max_gap:
            return _OUT_OF_ORDER, math.nan
        return _JUMP_BACK, 0.0
    if dt > max_gap:
        return _GAP, 0.0
    return -1, dt


@jit
def stamp_dt(last: float, t: float, max_gap: float) -> float:
    """`stamp_step` without the fault kind: dt [s] (0.0 at the start), nan to hold (a
    rejected stamp), -1.0 to restart (a gap or a jump back)."""
    kind, dt = stamp_step(last, t, max_gap)
    return -1.0 if kind in (_GAP, _JUMP_BACK) else dt


def classify_stamp(
    last: float | None, t: float, max_gap: float
) -> tuple[str | None, float | None]:
    """`stamp_step` with the kind by name and None for the missing stamp and dt.

    Args:
        last: stamp [s] of the last accepted sample, None before the first.
        t: this sample's stamp [s].
        max_gap: [s] > 0.

    Returns:
        (the fault kind to count or None, dt [s]): dt None rejects the sample, 0.0 starts
        (again) at t, > 0 steps on.
    """
    kind, dt = stamp_step(math.nan if last is None else float(last), float(t), float(max_gap))
    return (None if kind < 0 else STAMP_FAULTS[kind]), (None if math.isnan(dt) else dt)
