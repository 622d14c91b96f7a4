"""Errors raised by the vehicle model, the scenario loader and the simulator.

The bond-graph core has its own hierarchy in ``vd_sim_node.bondgraph.errors``; these are the
domain errors of the Clio model built on top of it.
"""

from __future__ import annotations

__all__ = [
    'ParameterError',
    'ScenarioError',
    'SimulationError',
    'VdError',
    'VehicleSimError',
]


class VdError(Exception):
    """Base class of every error a vd package raises for bad input, files or settings.

    vd_observer_node's errors derive from it too, so the node plumbing
    (`vd_sim_node.ros_common.run_node`) reports any of them as one line without importing
    the packages built on top of this one.
    """


class VehicleSimError(VdError):
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
