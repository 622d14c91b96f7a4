"""Errors of the input mapping: a refused mapping, or data that does not fit it."""

from __future__ import annotations

from vd_observer_node.errors import ConfigurationError

__all__ = ['MappingError']


class MappingError(ConfigurationError):
    """The input mapping is malformed, or a mapped topic's messages do not fit it (a joint
    name or array element absent). The message names the mapping key, on one line."""
