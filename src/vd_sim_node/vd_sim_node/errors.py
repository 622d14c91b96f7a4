"""Errors raised by the vehicle model, the scenario loader and the simulator.

The bond-graph core has its own hierarchy in ``vd_sim_node.bondgraph.errors``; these are the
domain errors of the Clio model built on top of it.
"""

from __future__ import annotations

__all__ = [
    'ParameterError',
    'ScenarioError',
    'SimulationError',
    'VehicleSimError',
]


class VehicleSimError(Exception):
    """Base class of every error raised by the vehicle simulator package."""


class ParameterError(VehicleSimError):
    """A vehicle parameter is missing, of the wrong type or outside its physical range.

    The message always names the parameter by its dotted YAML path, e.g.
    ``chassis.mass must be > 0 kg, got -3``.
    """


class ScenarioError(VehicleSimError):
    """A scenario file is missing a key, has a malformed signal or an out-of-range value."""


class SimulationError(VehicleSimError):
    """The integration failed (solver error, non-finite state) or was misused."""
