"""Errors raised by the scenario loader and the simulator.

The bond-graph core has its own hierarchy in ``vd_sim_node.bondgraph.errors``; these are the
domain errors of the Clio model built on top of it. A bad vehicle file raises
``vd_common.errors.ParameterError`` (the parser is shared with the estimator).
"""

from __future__ import annotations

from vd_common.errors import VdError

__all__ = [
    'ScenarioError',
    'SimulationError',
    'VehicleSimError',
]


class VehicleSimError(VdError):
    """Base class of every error raised by the vehicle simulator package."""


class ScenarioError(VehicleSimError):
    """A scenario file is missing a key, has a malformed signal or an out-of-range value."""


class SimulationError(VehicleSimError):
    """The integration failed (solver error, non-finite state) or was misused."""
