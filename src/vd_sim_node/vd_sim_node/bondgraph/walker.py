"""A reference evaluator that walks the causal graph on every call (no code generation).

It is a second, independent implementation of the element semantics: the tests compare it
with the generated code, and the benchmark measures how much code generation gains over it.
Each call resolves bond efforts and flows on demand by recursion through the elements,
memoised per call in dicts.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .causality import RESISTANCE, Causality, assign_causality, two_port_bonds
from .elements import Element, Kind
from .graph import BondGraph

__all__ = ['GraphWalker']


class GraphWalker:
    """ẋ = f(t, x, u) by walking ``graph`` per call; same state and input order as the
    compiled model.

    Args:
        graph: the bond graph.
        causality: a causal assignment (computed with SCAP if None).
    """

    def __init__(self, graph: BondGraph, causality: Causality | None = None) -> None:
        self.graph = graph
        self.causality = causality if causality is not None else assign_causality(graph)
        self.storage = [e for e in graph.elements.values() if e.kind.is_storage]
        self.state_index = {e.name: k for k, e in enumerate(self.storage)}
        self.input_index = {name: k for k, name in enumerate(graph.inputs)}
        self.defaults = [inp.default for inp in graph.inputs.values()]

    def rhs(self, t: float, x: ArrayLike, u: ArrayLike = ()) -> NDArray[np.float64]:
        """State derivative, shape (n_states,)."""
        walk = _Walk(self, t, np.asarray(x, dtype=float), u)
        return np.array([walk.derivative(e) for e in self.storage])

    def effort(self, bond: str, t: float, x: ArrayLike, u: ArrayLike = ()) -> float:
        """Effort of one bond."""
        return _Walk(self, t, np.asarray(x, dtype=float), u).effort(bond)

    def flow(self, bond: str, t: float, x: ArrayLike, u: ArrayLike = ()) -> float:
        """Flow of one bond."""
        return _Walk(self, t, np.asarray(x, dtype=float), u).flow(bond)


class _Walk:
    def __init__(self, walker: GraphWalker, t: float, x: NDArray[np.float64], u: ArrayLike):
        self.w = walker
        self.t = t
        self.x = x
        self.u = list(np.asarray(u, dtype=float)) if np.size(u) else walker.defaults
        self.efforts: dict[str, float] = {}
        self.flows: dict[str, float] = {}
        self.values: dict[str, float] = {}

    def signal(self, name: str) -> float:
        graph = self.w.graph
        if name in graph.inputs:
            return float(self.u[self.w.input_index[name]])
        if name in graph.sensors:
            sensor = graph.sensors[name]
            return self.effort(sensor.bond) if sensor.quantity == 'e' else self.flow(sensor.bond)
        block = graph.blocks[name]
        return float(block.fn(self.t, *[self.signal(s) for s in block.signals]))

    def value(self, element: Element) -> float:
        """Constant or modulated value of a source / TF / GY."""
        if element.name not in self.values:
            if element.law is None:
                assert element.param is not None
                result = element.param
            else:
                result = float(element.law(self.t, *[self.signal(s) for s in element.signals]))
            self.values[element.name] = result
        return self.values[element.name]

    def state(self, element: Element) -> float:
        return float(self.x[self.w.state_index[element.name]])

    def derivative(self, element: Element) -> float:
        bond = element.bonds[0]
        if element.kind is Kind.I:
            return self.effort(bond)
        return self.w.graph.bonds[bond].into(element.name) * self.flow(bond)

    def effort(self, bond: str) -> float:
        if bond not in self.efforts:
            owner = self.w.graph.elements[self.w.causality.effort_setter[bond]]
            self.efforts[bond] = self._effort_from(owner, bond)
        return self.efforts[bond]

    def flow(self, bond: str) -> float:
        if bond not in self.flows:
            record = self.w.graph.bonds[bond]
            owner = self.w.graph.elements[record.other(self.w.causality.effort_setter[bond])]
            self.flows[bond] = self._flow_from(owner, bond)
        return self.flows[bond]

    def _law(self, fn: Callable[..., Any] | None, *args: float) -> Any:
        assert fn is not None
        return fn(*args)

    def _effort_from(self, element: Element, bond: str) -> float:
        graph = self.w.graph
        kind = element.kind
        into = graph.bonds[bond].into(element.name)
        signals = [self.signal(s) for s in element.signals] if kind is Kind.R else []
        if kind is Kind.SE:
            return self.value(element)
        if kind is Kind.C:
            q = self.state(element)
            return q / element.param if element.param is not None else self._law(element.law, q)
        if kind is Kind.R:
            f_in = into * self.flow(bond)
            if element.param is not None:
                return element.param * f_in
            return float(self._law(element.law, f_in, *signals))
        if kind is Kind.RFIELD:
            flows = [self.flow(b) for b in element.bonds]
            field_signals = [self.signal(s) for s in element.signals]
            efforts = self._law(element.law, *flows, *field_signals)
            return float(efforts[element.bonds.index(bond)])
        if kind in (Kind.TF, Kind.GY):
            port0, port1 = two_port_bonds(graph, element)
            ratio = self.value(element)
            if kind is Kind.TF:
                return ratio * self.effort(port1) if bond == port0 else self.effort(port0) / ratio
            return ratio * self.flow(port1 if bond == port0 else port0)
        if kind is Kind.ZERO:
            strong = next(
                b for b in element.bonds if self.w.causality.effort_setter[b] != element.name
            )
            return self.effort(strong)
        assert kind is Kind.ONE
        total = 0.0
        for other in element.bonds:
            if other != bond:
                total += graph.bonds[other].into(element.name) * self.effort(other)
        return -into * total

    def _flow_from(self, element: Element, bond: str) -> float:
        graph = self.w.graph
        kind = element.kind
        into = graph.bonds[bond].into(element.name)
        if kind is Kind.SF:
            return -into * self.value(element)
        if kind is Kind.I:
            p = self.state(element)
            f_in = p / element.param if element.param is not None else self._law(element.law, p)
            return into * float(f_in)
        if kind is Kind.R:
            assert self.w.causality.r_modes[element.name] != RESISTANCE
            e = self.effort(bond)
            if element.param is not None:
                return into * e / element.param
            signals = [self.signal(s) for s in element.signals]
            return into * float(self._law(element.conductance_law, e, *signals))
        if kind in (Kind.TF, Kind.GY):
            port0, port1 = two_port_bonds(graph, element)
            ratio = self.value(element)
            if kind is Kind.TF:
                return ratio * self.flow(port0) if bond == port1 else self.flow(port1) / ratio
            return self.effort(port1 if bond == port0 else port0) / ratio
        if kind is Kind.ONE:
            strong = next(
                b for b in element.bonds if self.w.causality.effort_setter[b] == element.name
            )
            return self.flow(strong)
        assert kind is Kind.ZERO
        total = 0.0
        for other in element.bonds:
            if other != bond:
                total += graph.bonds[other].into(element.name) * self.flow(other)
        return -into * total
