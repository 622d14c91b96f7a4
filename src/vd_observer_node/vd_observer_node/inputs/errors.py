"""Errors of the input mapping: a refused mapping, or data that does not fit it."""

from __future__ import annotations

from vd_observer_node.errors import ConfigurationError, ObserverError

__all__ = ['MappingError', 'MountingNotDeterminedError']


class MappingError(ConfigurationError):
    """The input mapping is malformed, or a mapped topic's messages do not fit it (a joint
    name or array element absent). The message names the mapping key, on one line."""


class MountingNotDeterminedError(ObserverError):
    """The drive so far does not determine the IMU's mounting (too little acceleration on
    straight road, a sensor that does not follow the car, a roll or yaw too uncertain); the
    reason is the text, on one line."""
