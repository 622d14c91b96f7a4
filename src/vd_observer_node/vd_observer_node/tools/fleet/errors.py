"""Exception types of the fleet replay."""

from __future__ import annotations

from vd_observer_node.errors import ObserverError

__all__ = ['FleetEngineError', 'FleetError', 'FleetInputError']


class FleetError(ObserverError):
    """Base class of every error raised by :mod:`vd_observer_node.tools.fleet`."""


class FleetInputError(FleetError):
    """No bag to process, an unreadable list file or baseline, or a bad fleet setting."""


class FleetEngineError(FleetError):
    """The distributed engine is not installed, or its cluster cannot be reached."""
