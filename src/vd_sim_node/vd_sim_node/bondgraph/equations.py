"""Turn a causal bond graph into ordered assignment statements (the equation system).

Each statement assigns one or more symbols from an expression template whose ``{k}``
placeholders refer to other symbols; ordering the statements topologically gives explicit
equations, and a cycle is an algebraic loop. Symbols are Python identifiers of the generated
code: ``e3``/``f3`` effort/flow of bond 3, ``x2`` state 2, ``dx2`` its derivative, ``u1``
input 1, ``s4`` signal 4 (sensor or block), ``m5`` modulation value of element 5, ``t`` time.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from .causality import RESISTANCE, Causality, two_port_bonds
from .elements import Element, Kind
from .errors import AlgebraicLoopError, UnknownNameError
from .graph import BondGraph

__all__ = ['EquationSystem', 'Statement', 'build_equations']


@dataclass(frozen=True)
class Statement:
    """``targets = template.format(*args)``; ``origin`` names the element for messages."""

    targets: tuple[str, ...]
    template: str
    args: tuple[str, ...]
    origin: str
    bonds: tuple[str, ...] = ()

    @property
    def is_alias(self) -> bool:
        """A plain copy ``a = b`` (emitted as a substitution, not an assignment)."""
        return len(self.targets) == 1 and self.template == '{0}'


@dataclass
class EquationSystem:
    """Statements plus the symbol tables the code generator needs.

    Attributes:
        statements: unordered statements (every symbol assigned exactly once).
        constants: global name -> Python object bound into the generated code.
        state_symbols: ``x{k}`` in state order; derivative symbols are ``dx{k}``.
        state_names: e.g. ``'mass.p'``, ``'spring.q'``.
        state_elements: storage element name per state.
        input_symbols / signal_symbols: name -> symbol.
        bond_symbols: bond name -> (effort symbol, flow symbol).
        source_power, dissipated_power, storage_power: (sign, effort, flow) product terms [W].
        energy_terms: per state: template over ``{0}`` (the state) or None if unknown.
    """

    statements: list[Statement] = field(default_factory=list)
    constants: dict[str, object] = field(default_factory=dict)
    state_symbols: list[str] = field(default_factory=list)
    state_names: list[str] = field(default_factory=list)
    state_elements: list[str] = field(default_factory=list)
    input_symbols: dict[str, str] = field(default_factory=dict)
    signal_symbols: dict[str, str] = field(default_factory=dict)
    bond_symbols: dict[str, tuple[str, str]] = field(default_factory=dict)
    source_power: list[tuple[int, str, str]] = field(default_factory=list)
    dissipated_power: list[tuple[int, str, str]] = field(default_factory=list)
    storage_power: list[tuple[int, str, str]] = field(default_factory=list)
    energy_terms: list[str | None] = field(default_factory=list)

    def ordered(self, wanted: list[str], graph: BondGraph) -> list[Statement]:
        """Statements needed for ``wanted`` symbols, dependencies first.

        Raises:
            AlgebraicLoopError: the dependencies contain a cycle (names elements and bonds).
        """
        by_target: dict[str, Statement] = {}
        for statement in self.statements:
            for target in statement.targets:
                by_target[target] = statement
        done: set[int] = set()
        active: list[Statement] = []
        on_path: set[int] = set()
        order: list[Statement] = []
        for symbol in wanted:
            root = by_target.get(symbol)
            if root is None or id(root) in done:
                continue
            # Iterative DFS so deep junction chains cannot hit the recursion limit.
            stack: list[tuple[Statement, int]] = [(root, 0)]
            on_path.add(id(root))
            active.append(root)
            while stack:
                statement, position = stack[-1]
                if position < len(statement.args):
                    stack[-1] = (statement, position + 1)
                    child = by_target.get(statement.args[position])
                    if child is None or id(child) in done:
                        continue
                    if id(child) in on_path:
                        cycle = active[active.index(child) :]
                        raise _loop_error(cycle, self, graph)
                    on_path.add(id(child))
                    active.append(child)
                    stack.append((child, 0))
                    continue
                stack.pop()
                active.pop()
                on_path.discard(id(statement))
                done.add(id(statement))
                order.append(statement)
        return order


def _loop_error(cycle: list[Statement], system: EquationSystem, graph: BondGraph) -> Exception:
    names = {sym: f'effort of {bond!r}' for bond, (sym, _) in system.bond_symbols.items()}
    names.update({sym: f'flow of {bond!r}' for bond, (_, sym) in system.bond_symbols.items()})
    names.update({sym: f'signal {name!r}' for name, sym in system.signal_symbols.items()})
    elements: list[str] = []
    bonds: list[str] = []
    steps: list[str] = []
    for statement in cycle:
        if statement.origin not in elements:
            elements.append(statement.origin)
        for bond in statement.bonds:
            if bond not in bonds:
                bonds.append(bond)
        steps.append(
            f'{", ".join(names.get(t, t) for t in statement.targets)} (by {statement.origin!r})'
        )
    return AlgebraicLoopError(
        f'algebraic loop in bond graph {graph.name!r} through elements {elements} and bonds '
        f'{bonds}: ' + ' <- '.join(steps) + ' <- (back to the start)',
        elements=elements,
        bonds=bonds,
    )


def _signed_sum(terms: list[tuple[int, str]]) -> tuple[str, tuple[str, ...]]:
    """Template ``{0} - {1} + ...`` for sum(sign * symbol); '0.0' if empty."""
    if not terms:
        return '0.0', ()
    parts: list[str] = []
    for k, (sign, _) in enumerate(terms):
        if k == 0:
            parts.append(f'{{{k}}}' if sign > 0 else f'-{{{k}}}')
        else:
            parts.append(f' + {{{k}}}' if sign > 0 else f' - {{{k}}}')
    return ''.join(parts), tuple(symbol for _, symbol in terms)


class _Builder:
    def __init__(self, graph: BondGraph, causality: Causality) -> None:
        self.graph = graph
        self.causality = causality
        self.system = EquationSystem()
        self.callables: dict[int, str] = {}

    def bind(self, obj: Callable[..., object]) -> str:
        """Global name of a callable in the generated code (one per distinct object)."""
        key = id(obj)
        if key not in self.callables:
            name = f'c{len(self.callables)}'
            self.callables[key] = name
            self.system.constants[name] = obj
        return self.callables[key]

    def add(
        self,
        targets: str | tuple[str, ...],
        template: str,
        args: tuple[str, ...],
        origin: str,
        bonds: tuple[str, ...] = (),
    ) -> None:
        if isinstance(targets, str):
            targets = (targets,)
        self.system.statements.append(Statement(targets, template, args, origin, bonds))

    def signal_args(self, element_name: str, signals: tuple[str, ...]) -> tuple[str, ...]:
        symbols: list[str] = []
        for signal in signals:
            if signal in self.system.input_symbols:
                symbols.append(self.system.input_symbols[signal])
            elif signal in self.system.signal_symbols:
                symbols.append(self.system.signal_symbols[signal])
            else:
                raise UnknownNameError(
                    f'{element_name!r} reads signal {signal!r}, which is no input, sensor or block'
                )
        return tuple(symbols)

    def modulated(self, element: Element) -> tuple[str, tuple[str, ...]]:
        """(template, args) of a constant or fn(t, *signals) value."""
        if element.law is None:
            assert element.param is not None
            return repr(element.param), ()
        args = ('t', *self.signal_args(element.name, element.signals))
        fn = self.bind(element.law)
        return f'{fn}(' + ', '.join(f'{{{k}}}' for k in range(len(args))) + ')', args

    def build(self) -> EquationSystem:
        graph = self.graph
        system = self.system
        for k, bond in enumerate(graph.bonds):
            system.bond_symbols[bond] = (f'e{k}', f'f{k}')
        for k, name in enumerate(graph.inputs):
            system.input_symbols[name] = f'u{k}'
        for k, name in enumerate([*graph.sensors, *graph.blocks]):
            system.signal_symbols[name] = f's{k}'
        for sensor in graph.sensors.values():
            effort, flow = system.bond_symbols[sensor.bond]
            self.add(
                system.signal_symbols[sensor.name],
                '{0}',
                (effort if sensor.quantity == 'e' else flow,),
                sensor.name,
                (sensor.bond,),
            )
        for block in graph.blocks.values():
            args = ('t', *self.signal_args(block.name, block.signals))
            fn = self.bind(block.fn)
            template = f'{fn}(' + ', '.join(f'{{{k}}}' for k in range(len(args))) + ')'
            self.add(system.signal_symbols[block.name], template, args, block.name)
        for index, element in enumerate(graph.elements.values()):
            self.element(index, element)
        return system

    def element(self, index: int, element: Element) -> None:
        kind = element.kind
        graph = self.graph
        setter = self.causality.effort_setter
        name = element.name
        if kind.is_one_port:
            bond = element.bonds[0]
            e, f = self.system.bond_symbols[bond]
            into = graph.bonds[bond].into(name)
            neg = '' if into > 0 else '-'
            if kind is Kind.SE:
                template, args = self.modulated(element)
                self.add(e, template, args, name, (bond,))
                self.system.source_power.append((-into, e, f))
            elif kind is Kind.SF:
                template, args = self.modulated(element)
                template = template if into < 0 else f'-({template})'
                self.add(f, template, args, name, (bond,))
                self.system.source_power.append((-into, e, f))
            elif kind.is_storage:
                self.storage(element, bond, e, f, into)
            else:
                self.resistor(element, bond, e, f, into, neg)
            return
        if kind is Kind.RFIELD:
            efforts = tuple(self.system.bond_symbols[b][0] for b in element.bonds)
            flows = tuple(self.system.bond_symbols[b][1] for b in element.bonds)
            args = (*flows, *self.signal_args(name, element.signals))
            fn = self.bind(element.law)  # type: ignore[arg-type]
            template = f'{fn}(' + ', '.join(f'{{{k}}}' for k in range(len(args))) + ')'
            self.add(efforts, template, args, name, tuple(element.bonds))
            for e, f in zip(efforts, flows, strict=True):
                self.system.dissipated_power.append((1, e, f))
            return
        if kind in (Kind.TF, Kind.GY):
            self.two_port(index, element)
            return
        # Junctions.
        zero = kind is Kind.ZERO
        bonds = element.bonds
        special = [b for b in bonds if (setter[b] != name) == zero]
        assert len(special) == 1, (name, special)
        strong = special[0]
        position = 0 if zero else 1
        common = self.system.bond_symbols[strong][position]
        for bond in bonds:
            if bond != strong:
                self.add(self.system.bond_symbols[bond][position], '{0}', (common,), name, (bond,))
        s_strong = graph.bonds[strong].into(name)
        terms = [
            (-s_strong * graph.bonds[b].into(name), self.system.bond_symbols[b][1 - position])
            for b in bonds
            if b != strong
        ]
        template, args = _signed_sum(terms)
        self.add(
            self.system.bond_symbols[strong][1 - position], template, args, name, tuple(bonds)
        )

    def storage(self, element: Element, bond: str, e: str, f: str, into: int) -> None:
        system = self.system
        k = len(system.state_symbols)
        x = f'x{k}'
        system.state_symbols.append(x)
        system.state_elements.append(element.name)
        is_i = element.kind is Kind.I
        system.state_names.append(f'{element.name}.{"p" if is_i else "q"}')
        if element.param is not None:
            law = f'{{0}} * {1.0 / element.param!r}'
            system.energy_terms.append(f'{{0}} * {{0}} * {0.5 / element.param!r}')
        else:
            law = f'{self.bind(element.law)}({{0}})'  # type: ignore[arg-type]
            system.energy_terms.append(
                None if element.energy is None else f'{self.bind(element.energy)}({{0}})'
            )
        neg = '' if into > 0 else '-'
        if is_i:
            # The element sees flow into it (into * f) and the effort as carried.
            self.add(f, f'{neg}({law})' if neg else law, (x,), element.name, (bond,))
            self.add(f'd{x}', '{0}', (e,), element.name, (bond,))
        else:
            self.add(e, law, (x,), element.name, (bond,))
            self.add(f'd{x}', f'{neg}{{0}}', (f,), element.name, (bond,))
        system.storage_power.append((into, e, f))

    def resistor(self, element: Element, bond: str, e: str, f: str, into: int, neg: str) -> None:
        mode = self.causality.r_modes[element.name]
        signals = self.signal_args(element.name, element.signals)
        name = element.name
        if mode == RESISTANCE:
            if element.param is not None:
                self.add(e, f'{neg}{{0}} * {element.param!r}', (f,), name, (bond,))
            else:
                fn = self.bind(element.law)  # type: ignore[arg-type]
                inner = ', '.join(f'{{{k}}}' for k in range(1, 1 + len(signals)))
                first = '{0}' if into > 0 else '-{0}'
                call = f'{fn}({first}' + (f', {inner})' if inner else ')')
                self.add(e, call, (f, *signals), name, (bond,))
        elif element.param is not None:
            self.add(f, f'{neg}{{0}} * {1.0 / element.param!r}', (e,), name, (bond,))
        else:
            fn = self.bind(element.conductance_law)  # type: ignore[arg-type]
            inner = ', '.join(f'{{{k}}}' for k in range(1, 1 + len(signals)))
            call = f'{fn}({{0}}' + (f', {inner})' if inner else ')')
            self.add(f, f'-({call})' if into < 0 else call, (e, *signals), name, (bond,))
        self.system.dissipated_power.append((into, e, f))

    def two_port(self, index: int, element: Element) -> None:
        name = element.name
        port0, port1 = two_port_bonds(self.graph, element)
        e0, f0 = self.system.bond_symbols[port0]
        e1, f1 = self.system.bond_symbols[port1]
        bonds = (port0, port1)
        extra: tuple[str, ...]
        if element.law is None:
            assert element.param is not None
            ratio, inverse, extra = repr(element.param), repr(1.0 / element.param), ()
            times, divide = f' * {ratio}', f' * {inverse}'
        else:
            template, args = self.modulated(element)
            symbol = f'm{index}'
            self.add(symbol, template, args, name, bonds)
            times, divide, extra = ' * {1}', ' / {1}', (symbol,)
        sets_port0 = self.causality.effort_setter[port0] == name
        if element.kind is Kind.TF:
            if sets_port0:
                self.add(e0, '{0}' + times, (e1, *extra), name, bonds)
                self.add(f1, '{0}' + times, (f0, *extra), name, bonds)
            else:
                self.add(e1, '{0}' + divide, (e0, *extra), name, bonds)
                self.add(f0, '{0}' + divide, (f1, *extra), name, bonds)
        elif sets_port0:
            self.add(e1, '{0}' + times, (f0, *extra), name, bonds)
            self.add(e0, '{0}' + times, (f1, *extra), name, bonds)
        else:
            self.add(f0, '{0}' + divide, (e1, *extra), name, bonds)
            self.add(f1, '{0}' + divide, (e0, *extra), name, bonds)


def build_equations(graph: BondGraph, causality: Causality) -> EquationSystem:
    """Statements of every bond variable, signal, modulation and state derivative.

    Raises:
        UnknownNameError: an element or block reads an undefined signal.
    """
    return _Builder(graph, causality).build()
