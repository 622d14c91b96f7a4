"""Generate and compile the straight-line Python functions of a causal bond graph.

Generated functions (n = states, m = inputs, k = outputs):

* ``rhs(t, x, u)``: scalar, ``x.tolist()`` unpacked into float locals, returns shape (n,).
* ``rhs_batch(t, X, U)``: the same statements on numpy rows, X shape (n, N) -> (n, N).
* ``outputs(t, x, u)`` / ``outputs_batch(t, X, U)``: every output, shape (k,) / (k, N).
* ``power(t, x, u)``: (source, dissipated, storage) power [W], scalar or batch rows.
* ``energy(x)``: stored energy [J], scalar or batch rows.

Parameters are inlined as float literals, callables bound as module globals ``c0, c1 ...``,
so nothing is looked up in a dict per call.
"""

from __future__ import annotations

import ast
import itertools
import linecache
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from .equations import EquationSystem, Statement
from .graph import BondGraph

__all__ = ['GeneratedCode', 'generate_code']

_INDENT = '    '
_COMPILED = itertools.count(1)


@dataclass(frozen=True)
class GeneratedCode:
    """The compiled functions, the source text and the output names in order."""

    source: str
    rhs: Callable[..., np.ndarray]
    rhs_batch: Callable[..., np.ndarray]
    outputs: Callable[..., np.ndarray]
    outputs_batch: Callable[..., np.ndarray]
    power: Callable[..., tuple[float, float, float]]
    energy: Callable[..., Any] | None
    output_names: tuple[str, ...]


class _Emitter:
    def __init__(self, system: EquationSystem, graph: BondGraph) -> None:
        self.system = system
        self.graph = graph
        self.aliases: dict[str, str] = {}
        # Constants (constant sources, empty junction sums) are substituted as literals so
        # the hot path does not spend a statement on them.
        self.literals: set[int] = set()
        for statement in system.statements:
            if statement.is_alias:
                self.aliases[statement.targets[0]] = statement.args[0]
            elif not statement.args and len(statement.targets) == 1:
                # The template is a float literal or its negation, e.g. '-(9.81)'.
                value = float(ast.literal_eval(statement.template))
                self.aliases[statement.targets[0]] = f'({value!r})' if value < 0 else repr(value)
                self.literals.add(id(statement))

    def resolve(self, symbol: str) -> str:
        seen = 0
        while symbol in self.aliases:
            symbol = self.aliases[symbol]
            seen += 1
            if seen > len(self.aliases):
                break  # a pure alias cycle; ordering has already reported it
        return symbol

    def body(self, ordered: list[Statement]) -> list[str]:
        lines: list[str] = []
        for statement in ordered:
            if statement.is_alias or id(statement) in self.literals:
                continue
            expr = statement.template.format(*[self.resolve(a) for a in statement.args])
            targets = ', '.join(statement.targets)
            if len(statement.targets) > 1:
                targets += ','
            lines.append(f'{_INDENT}{targets} = {expr}  # {statement.origin}')
        return lines

    def power_exprs(self) -> tuple[str, str, str]:
        def product_sum(terms: list[tuple[int, str, str]]) -> str:
            if not terms:
                return '0.0'
            parts = []
            for k, (sign, e, f) in enumerate(terms):
                op = ('' if sign > 0 else '-') if k == 0 else (' + ' if sign > 0 else ' - ')
                parts.append(f'{op}{self.resolve(e)} * {self.resolve(f)}')
            return ''.join(parts)

        return (
            product_sum(self.system.source_power),
            product_sum(self.system.dissipated_power),
            product_sum(self.system.storage_power),
        )

    def power_symbols(self) -> list[str]:
        system = self.system
        symbols: list[str] = []
        for terms in (system.source_power, system.dissipated_power, system.storage_power):
            for _, e, f in terms:
                symbols.extend((e, f))
        return symbols

    def unpack(self, batch: bool) -> list[str]:
        lines: list[str] = []
        n = len(self.system.state_symbols)
        m = len(self.system.input_symbols)
        if n:
            xs = ', '.join(self.system.state_symbols) + (',' if n == 1 else '')
            source = 'x' if batch else 'x.tolist() if x.__class__ is _ndarray else x'
            lines.append(f'{_INDENT}{xs} = {source}')
        if m:
            lines.append(f'{_INDENT}if not len(u):')
            lines.append(f'{_INDENT * 2}u = _U0')
            us = ', '.join(self.system.input_symbols.values()) + (',' if m == 1 else '')
            source = 'u' if batch else 'u.tolist() if u.__class__ is _ndarray else u'
            lines.append(f'{_INDENT}{us} = {source}')
        return lines


def _output_symbols(system: EquationSystem, graph: BondGraph) -> tuple[list[str], list[str]]:
    names: list[str] = []
    symbols: list[str] = []
    for name in [*graph.sensors, *graph.blocks]:
        names.append(name)
        symbols.append(system.signal_symbols[name])
    for bond, (e, f) in system.bond_symbols.items():
        names.extend((f'{bond}.e', f'{bond}.f'))
        symbols.extend((e, f))
    return names, symbols


def generate_code(system: EquationSystem, graph: BondGraph) -> GeneratedCode:
    """Emit, compile and return the model functions.

    Raises:
        AlgebraicLoopError: the equations cannot be ordered explicitly.
    """
    emitter = _Emitter(system, graph)
    derivatives = [f'd{x}' for x in system.state_symbols]
    out_names, out_symbols = _output_symbols(system, graph)
    power_symbols = emitter.power_symbols()
    everything = [*derivatives, *out_symbols, *power_symbols]
    # Ordering everything first reports any algebraic loop, even one outside the RHS.
    all_ordered = system.ordered(everything, graph)
    rhs_ordered = system.ordered(derivatives, graph)
    power_ordered = system.ordered(power_symbols, graph)
    p_source, p_diss, p_store = emitter.power_exprs()
    n = len(system.state_symbols)
    resolved_derivatives = [emitter.resolve(d) for d in derivatives]
    resolved_outputs = [emitter.resolve(s) for s in out_symbols]
    all_outputs = [*resolved_outputs, p_source, p_diss, p_store]
    out_names = [*out_names, 'P.sources', 'P.dissipated', 'P.stored']

    lines = [f'# Generated from bond graph {graph.name!r}; do not edit.']
    names_comment = ', '.join(
        f'{s}={name}' for s, name in zip(system.state_symbols, system.state_names, strict=True)
    )
    lines.append(f'# states: {names_comment}')

    def tuple_expr(items: list[str]) -> str:
        if not items:
            return '()'
        return '(' + ', '.join(items) + (',)' if len(items) == 1 else ')')

    lines.append('def rhs(t, x, u=()):')
    lines += emitter.unpack(batch=False)
    lines += emitter.body(rhs_ordered)
    lines.append(f'{_INDENT}return _array({tuple_expr(resolved_derivatives)})')
    lines.append('')

    def batch_result(items: list[str], rows: int) -> list[str]:
        result = [f'{_INDENT}_out = _empty(({rows}, _columns(x, u, t)))']
        result += [f'{_INDENT}_out[{k}] = {item}' for k, item in enumerate(items)]
        result.append(f'{_INDENT}return _out')
        return result

    lines.append('def rhs_batch(t, x, u=()):')
    lines += emitter.unpack(batch=True)
    lines += emitter.body(rhs_ordered)
    lines += batch_result(resolved_derivatives, n)
    lines.append('')

    lines.append('def outputs(t, x, u=()):')
    lines += emitter.unpack(batch=False)
    lines += emitter.body(all_ordered)
    lines.append(f'{_INDENT}return _array({tuple_expr(all_outputs)})')
    lines.append('')

    lines.append('def outputs_batch(t, x, u=()):')
    lines += emitter.unpack(batch=True)
    lines += emitter.body(all_ordered)
    lines += batch_result(all_outputs, len(all_outputs))
    lines.append('')

    lines.append('def power(t, x, u=()):')
    lines += emitter.unpack(batch=False)
    lines += emitter.body(power_ordered)
    lines.append(f'{_INDENT}return ({p_source}, {p_diss}, {p_store})')
    lines.append('')

    energy_known = all(term is not None for term in system.energy_terms)
    if energy_known:
        lines.append('def energy(x):')
        if n:
            xs = ', '.join(system.state_symbols) + (',' if n == 1 else '')
            lines.append(f'{_INDENT}{xs} = x')
        terms = [
            term.format(x)  # type: ignore[union-attr]
            for term, x in zip(system.energy_terms, system.state_symbols, strict=True)
        ]
        lines.append(f'{_INDENT}return 0.0 + ' + (' + '.join(terms) if terms else '0.0'))
        lines.append('')

    source = '\n'.join(lines)
    namespace: dict[str, object] = dict(system.constants)
    namespace.update(
        _array=np.array,
        _empty=np.empty,
        _ndarray=np.ndarray,
        _columns=_columns,
        _U0=tuple(inp.default for inp in graph.inputs.values()),
    )
    filename = f'<bondgraph {graph.name} #{next(_COMPILED)}>'
    # Registering the source lets tracebacks through a failing user law show the generated
    # line that called it.
    linecache.cache[filename] = (len(source), None, source.splitlines(True), filename)
    code = compile(source, filename, 'exec')
    exec(code, namespace)  # the source is generated above from our own templates
    return GeneratedCode(
        source=source,
        rhs=namespace['rhs'],  # type: ignore[arg-type]
        rhs_batch=namespace['rhs_batch'],  # type: ignore[arg-type]
        outputs=namespace['outputs'],  # type: ignore[arg-type]
        outputs_batch=namespace['outputs_batch'],  # type: ignore[arg-type]
        power=namespace['power'],  # type: ignore[arg-type]
        energy=namespace['energy'] if energy_known else None,  # type: ignore[arg-type]
        output_names=tuple(out_names),
    )


def _columns(x: Any, u: Any, t: Any) -> int:
    """Number of samples N of a batch call (from x, else u, else t)."""
    for candidate in (x, u, t):
        shape = np.shape(candidate)
        if len(shape) >= 2:
            return int(shape[-1])
    shape = np.shape(t)
    return int(shape[0]) if shape else 1
