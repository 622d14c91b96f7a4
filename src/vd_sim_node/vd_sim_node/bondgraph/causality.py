"""Sequential causality assignment procedure (SCAP).

Causality is stored per bond as the *effort setter*: the end element that imposes the
effort (the other end imposes the flow; the causal stroke sits at the end that receives the
effort). The procedure: (1) sources, (2) storage in integral causality, (3) R elements
(resistance causality preferred), (4) any bond still free; each step is propagated through
junctions, TF and GY until nothing more is forced.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

from .elements import Element, Kind
from .errors import (
    CausalConflictError,
    DerivativeCausalityError,
    InvalidConnectionError,
    MissingLawError,
    UnconnectedPortError,
)
from .graph import BondGraph

__all__ = ['Causality', 'assign_causality', 'validate_structure']

RESISTANCE = 'resistance'
CONDUCTANCE = 'conductance'


@dataclass(frozen=True)
class Causality:
    """A complete causal assignment.

    Attributes:
        effort_setter: bond name -> name of the end element that imposes its effort.
        r_modes: R name -> 'resistance' (effort = law(flow)) or 'conductance'.
    """

    effort_setter: dict[str, str]
    r_modes: dict[str, str]

    def stroke_end(self, bond: str, graph: BondGraph) -> str:
        """The end receiving the effort, where the causal stroke is drawn."""
        return graph.bonds[bond].other(self.effort_setter[bond])

    def describe(self) -> str:
        """One line per bond: which end imposes the effort."""
        return '\n'.join(
            f'{bond}: effort imposed by {setter}' for bond, setter in self.effort_setter.items()
        )


def validate_structure(graph: BondGraph) -> None:
    """Check port counts and orientations before any causal reasoning.

    Raises:
        UnconnectedPortError: an element without bonds, a TF/GY with fewer than two bonds.
        InvalidConnectionError: wrong TF/GY orientation, R-field bond pointing out.
    """
    for element in graph.elements.values():
        kind = element.kind
        if not element.bonds:
            raise UnconnectedPortError(f'{kind.value} {element.name!r} has no bond')
        if kind in (Kind.TF, Kind.GY):
            if len(element.bonds) != 2:
                raise UnconnectedPortError(
                    f'{kind.value} {element.name!r} needs two bonds (port 0 in, port 1 out), '
                    f'has {element.bonds}'
                )
            into = [graph.bonds[b].into(element.name) for b in element.bonds]
            if sorted(into) != [-1, 1]:
                raise InvalidConnectionError(
                    f'{kind.value} {element.name!r}: one bond must point in (port 0) and one '
                    f'out (port 1); bonds {element.bonds} point '
                    f'{["in" if s > 0 else "out" for s in into]}'
                )
        if kind is Kind.RFIELD:
            for b in element.bonds:
                if graph.bonds[b].into(element.name) < 0:
                    raise InvalidConnectionError(
                        f'R-field {element.name!r}: bond {b!r} must point into the field'
                    )


def two_port_bonds(graph: BondGraph, element: Element) -> tuple[str, str]:
    """(port 0 bond pointing in, port 1 bond pointing out) of a TF or GY."""
    first, second = element.bonds
    if graph.bonds[first].into(element.name) > 0:
        return first, second
    return second, first


class _Assigner:
    """Holds the partial assignment and propagates constraints with a work list."""

    def __init__(self, graph: BondGraph) -> None:
        self.graph = graph
        self.setter: dict[str, str] = {}
        self.origin: dict[str, str] = {}
        # Why each bond got its causality: the rule that forced it and the bond that
        # triggered that rule, so errors can print the causal path back to its origin.
        self.why: dict[str, str] = {}
        self.trigger: dict[str, str | None] = {}
        self.via: dict[str, str] = {}
        self.r_modes: dict[str, str] = {}
        self.pending: deque[str] = deque()

    # -- core operations ------------------------------------------------------------------

    def path(self, bond: str) -> tuple[str, list[str], list[str]]:
        """(text, elements, bonds) of the causal path that fixed ``bond``, newest first."""
        steps: list[str] = []
        elements: list[str] = []
        bonds: list[str] = []
        current: str | None = bond
        while current is not None and current not in bonds:
            bonds.append(current)
            steps.append(f'bond {current!r} set by {self.why[current]}')
            elements.append(self.via[current])
            current = self.trigger.get(current)
        return ' <- '.join(steps), elements, bonds

    def force(
        self,
        bond: str,
        setter: str,
        origin: str,
        via: str,
        why: str,
        trigger: str | None = None,
    ) -> None:
        """Set the effort setter of ``bond``; a contradiction is a causal conflict."""
        current = self.setter.get(bond)
        if current == setter:
            return
        if current is not None:
            b = self.graph.bonds[bond]
            text, elements, bonds = self.path(bond)
            if trigger is not None:
                new_text, new_elements, new_bonds = self.path(trigger)
                text += f'; new demand via {new_text}'
                elements += new_elements
                bonds += new_bonds
            raise CausalConflictError(
                f'causal conflict on bond {bond!r} ({b.tail} -> {b.head}): {why} requires '
                f'{setter!r} to impose its effort, but {current!r} already does; causal '
                f'path: {text}',
                elements=(setter, current, origin, *elements),
                bonds=(bond, *bonds),
            )
        self.setter[bond] = setter
        self.origin[bond] = origin
        self.why[bond] = why
        self.via[bond] = via
        self.trigger[bond] = trigger
        b = self.graph.bonds[bond]
        self.pending.extend((b.tail, b.head))

    def propagate(self) -> None:
        while self.pending:
            self.check(self.graph.elements[self.pending.popleft()])

    def start(self, bond: str, setter: str, origin: str, why: str) -> None:
        self.force(bond, setter, origin, origin, why)
        self.propagate()

    # -- element rules --------------------------------------------------------------------

    def check(self, element: Element) -> None:
        name = element.name
        kind = element.kind
        graph = self.graph
        if kind.is_one_port:
            bond = element.bonds[0]
            setter = self.setter.get(bond)
            if setter is None:
                return
            origin = self.origin[bond]
            text, path_elements, path_bonds = self.path(bond)
            if kind is Kind.SE and setter != name:
                raise CausalConflictError(
                    f'Se {name!r} must impose the effort on bond {bond!r}, but '
                    f'{setter!r} does; causal path: {text}',
                    elements=(name, setter, *path_elements),
                    bonds=tuple(path_bonds),
                )
            if kind is Kind.SF and setter == name:
                raise CausalConflictError(
                    f'Sf {name!r} must impose the flow on bond {bond!r}, but the graph '
                    f'forces it to impose the effort; causal path: {text}',
                    elements=(name, *path_elements),
                    bonds=tuple(path_bonds),
                )
            if (kind is Kind.I and setter == name) or (kind is Kind.C and setter != name):
                raise DerivativeCausalityError(
                    f'{kind.value} {name!r} is forced into derivative causality on bond '
                    f'{bond!r} by the causality propagated from {origin!r} (causal path: '
                    f'{text}): the storage is dependent; merge it with the storage it '
                    f'depends on',
                    element=name,
                    bond=bond,
                    forced_by=origin,
                    path_elements=path_elements,
                    path_bonds=path_bonds,
                )
            if kind is Kind.R:
                self.set_r_mode(element, RESISTANCE if setter == name else CONDUCTANCE)
            return
        if kind is Kind.RFIELD:
            for bond in element.bonds:
                setter = self.setter.get(bond)
                if setter is not None and setter != name:
                    raise CausalConflictError(
                        f'R-field {name!r} supports resistance causality only, but bond '
                        f'{bond!r} is forced to bring it an effort (propagated from '
                        f'{self.origin[bond]!r})',
                        elements=(name, self.origin[bond]),
                        bonds=(bond,),
                    )
            return
        if kind in (Kind.TF, Kind.GY):
            port0, port1 = two_port_bonds(graph, element)
            for known, other in ((port0, port1), (port1, port0)):
                setter = self.setter.get(known)
                if setter is None:
                    continue
                element_sets_known = setter == name
                # TF passes effort through (exactly one side set by the TF); GY swaps (both
                # or neither).
                element_sets_other = (
                    not element_sets_known if kind is Kind.TF else element_sets_known
                )
                target = name if element_sets_other else graph.bonds[other].other(name)
                self.force(
                    other, target, self.origin[known], name, f'{kind.value} {name!r}', known
                )
            return
        self.check_junction(element)

    def check_junction(self, element: Element) -> None:
        """0: exactly one bond brings the effort in; 1: exactly one bond takes it out."""
        name = element.name
        graph = self.graph
        # A 'special' bond: at a 0-junction the one whose far end imposes the effort, at a
        # 1-junction the one on which the junction imposes the effort (it gets the flow).
        zero = element.kind is Kind.ZERO

        def is_special(bond: str) -> bool:
            return (self.setter[bond] != name) if zero else (self.setter[bond] == name)

        known = [b for b in element.bonds if b in self.setter]
        special = [b for b in known if is_special(b)]
        free = [b for b in element.bonds if b not in self.setter]
        label = f'{element.kind.value}-junction {name!r}'
        if len(special) > 1:
            what = 'effort' if zero else 'flow'
            raise CausalConflictError(
                f'causal conflict at {label}: bonds {special} all impose the junction '
                f'{what} (from {[self.origin[b] for b in special]})',
                elements=(name, *[self.origin[b] for b in special]),
                bonds=tuple(special),
            )
        if len(special) == 1:
            origin = self.origin[special[0]]
            for bond in free:
                # Non-special bonds: 0-junction imposes their effort, 1-junction gets it.
                setter = name if zero else graph.bonds[bond].other(name)
                self.force(bond, setter, origin, name, label, special[0])
            return
        if len(free) == 1:
            bond = free[0]
            setter = graph.bonds[bond].other(name) if zero else name
            origins = [self.origin[b] for b in known]
            trigger = known[-1] if known else None
            self.force(bond, setter, origins[-1] if origins else name, name, label, trigger)
            return
        if not free:
            what = 'effort' if zero else 'flow'
            raise CausalConflictError(
                f'causal conflict at {label}: no bond determines the junction {what} '
                f'(bonds {element.bonds})',
                elements=(name, *[self.origin[b] for b in known]),
                bonds=tuple(element.bonds),
            )

    def set_r_mode(self, element: Element, mode: str) -> None:
        name = element.name
        if element.param is None:
            law = element.law if mode == RESISTANCE else element.conductance_law
            if law is None:
                bond = element.bonds[0]
                raise MissingLawError(
                    f'R {name!r} is forced into {mode} causality on bond {bond!r} '
                    f'(propagated from {self.origin[bond]!r}) but has no '
                    f'{"law" if mode == RESISTANCE else "conductance_law"}'
                )
        self.r_modes[name] = mode


def assign_causality(graph: BondGraph) -> Causality:
    """Run SCAP on ``graph``.

    Returns:
        The complete causal assignment.

    Raises:
        UnconnectedPortError, InvalidConnectionError: structural problems.
        CausalConflictError: contradictory causal demands (names elements and bonds).
        DerivativeCausalityError: dependent storage (names the storage, bond and cause).
        MissingLawError: an R forced into a causality it has no law for.
    """
    validate_structure(graph)
    work = _Assigner(graph)
    elements = list(graph.elements.values())
    for element in elements:
        if element.kind.is_source:
            bond = element.bonds[0]
            setter = (
                element.name if element.kind is Kind.SE else graph.bonds[bond].other(element.name)
            )
            work.start(bond, setter, element.name, f'{element.kind.value} {element.name!r}')
    for element in elements:
        if element.kind.is_storage and element.bonds[0] not in work.setter:
            bond = element.bonds[0]
            setter = (
                element.name if element.kind is Kind.C else graph.bonds[bond].other(element.name)
            )
            work.start(bond, setter, element.name, f'integral causality of {element.name!r}')
    for element in elements:
        if element.kind is Kind.RFIELD:
            for bond in element.bonds:
                if bond not in work.setter:
                    work.start(bond, element.name, element.name, f'R-field {element.name!r}')
        if element.kind is Kind.R and element.bonds[0] not in work.setter:
            bond = element.bonds[0]
            prefer_resistance = element.param is not None or element.law is not None
            setter = element.name if prefer_resistance else graph.bonds[bond].other(element.name)
            work.start(bond, setter, element.name, f'R {element.name!r}')
    for record in graph.bonds.values():
        if record.name not in work.setter:
            # Only junction structure is left: any choice closes an algebraic loop (if one
            # exists), which equation ordering then reports with the bonds involved.
            work.start(record.name, record.tail, record.tail, f'free bond {record.name!r}')
    return Causality(
        effort_setter={b: work.setter[b] for b in graph.bonds}, r_modes=dict(work.r_modes)
    )
