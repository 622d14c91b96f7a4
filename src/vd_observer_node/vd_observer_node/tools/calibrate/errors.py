"""Errors of the calibration fits."""

from vd_observer_node.errors import ObserverError

__all__ = ['CalibrationError', 'NotDeterminedError']


class CalibrationError(ObserverError):
    """Bad calibration input (no speed reference, mismatched arrays)."""


class NotDeterminedError(CalibrationError):
    """The drive does not determine the value (too few usable samples); the reason is the text."""
