"""Exception types of the accuracy report."""

from __future__ import annotations

from vd_observer_node.errors import ObserverError

__all__ = ['ReportError', 'ReportInputError', 'StampOrderError']


class ReportError(ObserverError):
    """Base class of every error raised by :mod:`vd_observer_node.tools.report`."""


class ReportInputError(ReportError):
    """The bag lacks what a report needs (no truth topics, or no estimate to compare)."""


class StampOrderError(ReportError):
    """A topic's header stamps go backwards in file order: the streamed evaluation, which
    pairs topics as it reads, cannot take the bag (the whole-bag path sorts it first)."""
