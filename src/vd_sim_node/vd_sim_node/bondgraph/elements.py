"""Element, bond and signal records of a bond graph (plain data, no behaviour).

The builder :class:`~vd_sim_node.bondgraph.graph.BondGraph` creates these; causality
assignment, code generation and the graph walker read them.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from enum import Enum
from typing import Any

__all__ = [
    'Block',
    'Bond',
    'Element',
    'Input',
    'Kind',
    'Sensor',
    'Value',
]

# A constant, or a modulating callable fn(t, *signals) -> float.
Value = float | Callable[..., float]


class Kind(Enum):
    """Kinds of bond-graph elements."""

    SE = 'Se'
    SF = 'Sf'
    I = 'I'  # noqa: E741 - the standard bond-graph name of the inertia element
    C = 'C'
    R = 'R'
    RFIELD = 'R-field'
    TF = 'TF'
    GY = 'GY'
    ZERO = '0'
    ONE = '1'

    @property
    def is_source(self) -> bool:
        """True for Se and Sf."""
        return self in (Kind.SE, Kind.SF)

    @property
    def is_storage(self) -> bool:
        """True for I and C."""
        return self in (Kind.I, Kind.C)

    @property
    def is_junction(self) -> bool:
        """True for 0- and 1-junctions."""
        return self in (Kind.ZERO, Kind.ONE)

    @property
    def is_one_port(self) -> bool:
        """True for Se, Sf, I, C and R (exactly one bond)."""
        return self in (Kind.SE, Kind.SF, Kind.I, Kind.C, Kind.R)


@dataclass
class Element:
    """One bond-graph element.

    Attributes:
        name: unique name.
        kind: element kind.
        param: linear parameter (inertia, compliance, resistance) or constant source value /
            TF-GY ratio; None when a law or a callable is used instead.
        law: constitutive law (I: flow(p), C: effort(q), R: effort(flow, *signals),
            R-field: efforts(*flows, *signals)) or the modulating callable of a source or
            TF/GY (fn(t, *signals)).
        conductance_law: R only: flow(effort, *signals).
        energy: storage only: energy(state) [J] for a nonlinear law.
        signals: names of the signals passed to ``law`` after its own arguments.
        bonds: names of the attached bonds in connection order.
    """

    name: str
    kind: Kind
    param: float | None = None
    law: Callable[..., Any] | None = None
    conductance_law: Callable[..., float] | None = None
    energy: Callable[[float], float] | None = None
    signals: tuple[str, ...] = ()
    bonds: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class Bond:
    """A power bond; positive power e*f flows from ``tail`` to ``head``."""

    name: str
    tail: str
    head: str

    def other(self, element: str) -> str:
        """Name of the element at the other end of the bond from ``element``."""
        return self.head if element == self.tail else self.tail

    def into(self, element: str) -> int:
        """+1 if the bond points into ``element`` (it is the head), -1 otherwise."""
        return 1 if element == self.head else -1


@dataclass(frozen=True)
class Input:
    """An external input u[name] supplied by the caller."""

    name: str
    default: float = 0.0


@dataclass(frozen=True)
class Sensor:
    """Reads the effort (``quantity == 'e'``) or flow (``'f'``) of a bond."""

    name: str
    bond: str
    quantity: str


@dataclass(frozen=True)
class Block:
    """A signal block: value = fn(t, *signals)."""

    name: str
    fn: Callable[..., float]
    signals: tuple[str, ...] = ()
