"""Exception types of the accuracy report."""

from __future__ import annotations

from vd_observer_node.errors import ObserverError

__all__ = [
    'ReferenceClockError',
    'ReportError',
    'ReportInputError',
    'ReportOutputError',
    'StampOrderError',
]


class ReportError(ObserverError):
    """Base class of every error raised by :mod:`vd_observer_node.tools.report`."""


class ReportInputError(ReportError):
    """The bag lacks what a report needs (no truth topics, or no estimate to compare)."""


class ReportOutputError(ReportError):
    """The output folder cannot take the report: a file, or a non-empty folder that holds
    no previous report (vd report removes only the files it wrote itself)."""


class StampOrderError(ReportError):
    """A topic's header stamps go backwards in file order: the streamed evaluation, which
    pairs topics as it reads, cannot take the bag (the whole-bag path sorts it first)."""


class ReferenceClockError(ReportError):
    """A reference runs on its own clock (fewer than half of an estimate topic's stamps are
    in it): the streamed evaluation pairs by stamp only; the whole-bag path
    (:func:`~vd_observer_node.tools.report.evaluation.evaluate`) interpolates it."""
