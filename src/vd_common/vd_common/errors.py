"""The error base of every vd package, and the vehicle file's parameter error.

The simulator's own errors are in ``vd_sim_node.errors``, the estimator's in
``vd_observer_node.errors``; the bond-graph core has its own hierarchy. All derive from
:class:`VdError`.
"""

from __future__ import annotations

__all__ = [
    'ParameterError',
    'VdError',
]


class VdError(Exception):
    """Base class of every error a vd package raises for bad input, files or settings.

    The errors of the packages built on this one derive from it, so the node plumbing
    (`vd_common.ros.lifecycle.run_node`) reports any of them as one line without importing
    those packages.
    """


class ParameterError(VdError):
    """A vehicle parameter is missing, of the wrong type or outside its physical range.

    The message always names the parameter by its dotted YAML path, e.g.
    ``chassis.mass must be > 0 kg, got -3``.
    """
