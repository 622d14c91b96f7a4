"""Exception types of the observer / estimator core."""

from vd_common.errors import VdError

__all__ = [
    'ConfigurationError',
    'InputShapeError',
    'ObserverError',
    'VehicleParameterError',
]


class ObserverError(VdError):
    """Base class of every error raised by vd_observer_node."""


class ConfigurationError(ObserverError):
    """A differentiator, observer or estimator setting is invalid (unknown name, bad gain)."""


class VehicleParameterError(ObserverError):
    """The vehicle parameter file is missing a key or holds a non-physical value."""


class InputShapeError(ObserverError):
    """An input array does not have the documented shape."""
