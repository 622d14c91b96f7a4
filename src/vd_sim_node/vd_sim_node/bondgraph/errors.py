"""Errors of the bond-graph core.

Every error derives from :class:`BondGraphError`; the causality errors carry the names of the
elements and bonds involved as attributes as well as in their message.
"""

from __future__ import annotations

from collections.abc import Sequence

__all__ = [
    'AlgebraicLoopError',
    'BondGraphError',
    'CausalConflictError',
    'CausalityError',
    'DerivativeCausalityError',
    'DuplicateNameError',
    'ElementDefinitionError',
    'InvalidConnectionError',
    'MissingLawError',
    'ShapeError',
    'UnconnectedPortError',
    'UnknownNameError',
]


class BondGraphError(Exception):
    """Base class of every error raised by the bond-graph core."""


class DuplicateNameError(BondGraphError):
    """A name is already used by an element, bond, input, sensor or block."""


class UnknownNameError(BondGraphError):
    """A name refers to no element, bond or signal of the graph."""


class ElementDefinitionError(BondGraphError):
    """An element was given contradictory or missing parameters (e.g. both a law and a value)."""


class InvalidConnectionError(BondGraphError):
    """A bond is attached in a way the element does not accept (orientation, port count)."""


class UnconnectedPortError(BondGraphError):
    """An element or junction has no bond, or a two-port is missing one of its ports."""


class MissingLawError(BondGraphError):
    """A law needed by the assigned causality (or by the energy bookkeeping) was not given."""


class ShapeError(BondGraphError):
    """An array passed to a compiled model has the wrong shape."""


class CausalityError(BondGraphError):
    """Base of the errors found while assigning causality or ordering the equations.

    Attributes:
        elements: names of the elements involved.
        bonds: names of the bonds involved.
    """

    def __init__(self, message: str, elements: Sequence[str] = (), bonds: Sequence[str] = ()):
        super().__init__(message)
        self.elements: tuple[str, ...] = tuple(elements)
        self.bonds: tuple[str, ...] = tuple(bonds)


class CausalConflictError(CausalityError):
    """Two causal constraints contradict each other (e.g. two Se on one 0-junction)."""


class DerivativeCausalityError(CausalityError):
    """A storage element would need derivative causality (dependent storage).

    Attributes:
        element: the storage element forced into derivative causality.
        bond: its bond.
        forced_by: the element whose causal assignment propagated to it.
        elements / bonds: every element and bond on the causal path between them.
    """

    def __init__(
        self,
        message: str,
        element: str,
        bond: str,
        forced_by: str,
        path_elements: Sequence[str] = (),
        path_bonds: Sequence[str] = (),
    ):
        elements = dict.fromkeys((element, *path_elements, forced_by))
        bonds = dict.fromkeys((bond, *path_bonds))
        super().__init__(message, elements=tuple(elements), bonds=tuple(bonds))
        self.element = element
        self.bond = bond
        self.forced_by = forced_by


class AlgebraicLoopError(CausalityError):
    """The causal graph contains a zero-order (algebraic) loop: no explicit ordering exists."""
