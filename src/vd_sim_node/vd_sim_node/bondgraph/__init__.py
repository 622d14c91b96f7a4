"""ROS-free bond-graph core: build a graph, assign causality (SCAP), generate the equations.

See ``docs/bondgraph.md`` for a user guide.
"""

from .causality import Causality, assign_causality
from .elements import Kind
from .errors import (
    AlgebraicLoopError,
    BondGraphError,
    CausalConflictError,
    CausalityError,
    DerivativeCausalityError,
    DuplicateNameError,
    ElementDefinitionError,
    InvalidConnectionError,
    MissingLawError,
    ShapeError,
    UnconnectedPortError,
    UnknownNameError,
)
from .graph import BondGraph
from .model import CompiledModel, compile_model
from .simplify import MergeResult, merge_rigid_inertias
from .walker import GraphWalker

__all__ = [
    'AlgebraicLoopError',
    'BondGraph',
    'BondGraphError',
    'CausalConflictError',
    'Causality',
    'CausalityError',
    'CompiledModel',
    'DerivativeCausalityError',
    'DuplicateNameError',
    'ElementDefinitionError',
    'GraphWalker',
    'InvalidConnectionError',
    'Kind',
    'MergeResult',
    'MissingLawError',
    'ShapeError',
    'UnconnectedPortError',
    'UnknownNameError',
    'assign_causality',
    'compile_model',
    'merge_rigid_inertias',
]
