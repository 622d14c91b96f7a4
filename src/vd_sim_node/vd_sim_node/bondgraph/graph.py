"""The bond-graph builder: add elements, junctions, bonds, inputs, sensors and blocks."""

from __future__ import annotations

from collections.abc import Callable, Sequence

from .elements import Block, Bond, Element, Input, Kind, Sensor, Value
from .errors import (
    DuplicateNameError,
    ElementDefinitionError,
    InvalidConnectionError,
    UnknownNameError,
)

__all__ = ['BondGraph']


def _check_linear_or_law(name: str, what: str, param: float | None, law: object) -> None:
    """Exactly one of a linear parameter or a law must describe a storage/R element."""
    if (param is None) == (law is None):
        raise ElementDefinitionError(
            f'element {name!r}: give exactly one of the linear {what} or law='
        )
    if param is not None and float(param) == 0.0:
        raise ElementDefinitionError(f'element {name!r}: {what} must be non-zero, got {param}')


class BondGraph:
    """A bond graph under construction.

    Elements, bonds, inputs, sensors and blocks share one namespace. Every ``add_*`` method
    returns the registered name. See ``docs/bondgraph.md`` for the conventions.

    Args:
        name: a label used in generated code comments and error messages.
    """

    def __init__(self, name: str = 'bondgraph') -> None:
        self.name = name
        self.elements: dict[str, Element] = {}
        self.bonds: dict[str, Bond] = {}
        self.inputs: dict[str, Input] = {}
        self.sensors: dict[str, Sensor] = {}
        self.blocks: dict[str, Block] = {}

    # -- namespace ------------------------------------------------------------------------

    def _claim(self, name: str) -> str:
        if not isinstance(name, str) or not name or not name.isprintable():
            raise ElementDefinitionError(
                f'names must be non-empty printable strings, got {name!r}'
            )
        if name in self.elements or name in self.bonds or self.is_signal(name):
            raise DuplicateNameError(f'name {name!r} is already used in bond graph {self.name!r}')
        return name

    def is_signal(self, name: str) -> bool:
        """True if ``name`` is an input, a sensor or a block."""
        return name in self.inputs or name in self.sensors or name in self.blocks

    def _add(self, element: Element) -> str:
        self._claim(element.name)
        self.elements[element.name] = element
        return element.name

    @staticmethod
    def _value(name: str, value: Value, signals: Sequence[str]) -> tuple[float | None, object]:
        """Split a source/ratio value into (constant, callable)."""
        if callable(value):
            return None, value
        if signals:
            raise ElementDefinitionError(
                f'element {name!r}: signals= needs a callable value fn(t, *signals)'
            )
        return float(value), None

    # -- inputs and signals ---------------------------------------------------------------

    def add_input(self, name: str, default: float = 0.0) -> str:
        """Declare an external input; its position in u follows declaration order."""
        self._claim(name)
        self.inputs[name] = Input(name, float(default))
        return name

    def add_effort_sensor(self, name: str, bond: str) -> str:
        """A signal equal to the effort of ``bond`` (as the bond carries it)."""
        return self._add_sensor(name, bond, 'e')

    def add_flow_sensor(self, name: str, bond: str) -> str:
        """A signal equal to the flow of ``bond`` (as the bond carries it)."""
        return self._add_sensor(name, bond, 'f')

    def _add_sensor(self, name: str, bond: str, quantity: str) -> str:
        self._claim(name)
        if bond not in self.bonds:
            raise UnknownNameError(f'sensor {name!r}: no bond named {bond!r}')
        self.sensors[name] = Sensor(name, bond, quantity)
        return name

    def add_block(
        self, name: str, fn: Callable[..., float], *, signals: Sequence[str] = ()
    ) -> str:
        """A signal block: value = fn(t, *signals)."""
        self._claim(name)
        if not callable(fn):
            raise ElementDefinitionError(f'block {name!r}: fn must be callable')
        self.blocks[name] = Block(name, fn, tuple(signals))
        return name

    # -- elements -------------------------------------------------------------------------

    def add_se(self, name: str, effort: Value, *, signals: Sequence[str] = ()) -> str:
        """Effort source: constant, fn(t) or fn(t, *signals)."""
        param, law = self._value(name, effort, signals)
        return self._add(Element(name, Kind.SE, param, law, signals=tuple(signals)))  # type: ignore[arg-type]

    def add_sf(self, name: str, flow: Value, *, signals: Sequence[str] = ()) -> str:
        """Flow source (flow out of the source): constant, fn(t) or fn(t, *signals)."""
        param, law = self._value(name, flow, signals)
        return self._add(Element(name, Kind.SF, param, law, signals=tuple(signals)))  # type: ignore[arg-type]

    def add_i(
        self,
        name: str,
        inertia: float | None = None,
        *,
        law: Callable[[float], float] | None = None,
        energy: Callable[[float], float] | None = None,
    ) -> str:
        """Inertia with state p: linear flow = p / inertia, or flow = law(p)."""
        _check_linear_or_law(name, 'inertia', inertia, law)
        param = None if inertia is None else float(inertia)
        return self._add(Element(name, Kind.I, param, law, energy=energy))

    def add_c(
        self,
        name: str,
        compliance: float | None = None,
        *,
        law: Callable[[float], float] | None = None,
        energy: Callable[[float], float] | None = None,
    ) -> str:
        """Capacitance with state q: linear effort = q / compliance, or effort = law(q)."""
        _check_linear_or_law(name, 'compliance', compliance, law)
        param = None if compliance is None else float(compliance)
        return self._add(Element(name, Kind.C, param, law, energy=energy))

    def add_r(
        self,
        name: str,
        resistance: float | None = None,
        *,
        law: Callable[..., float] | None = None,
        conductance_law: Callable[..., float] | None = None,
        signals: Sequence[str] = (),
    ) -> str:
        """Resistor: e = R*f, or e = law(f, *signals) / f = conductance_law(e, *signals)."""
        _check_linear_or_law(name, 'resistance', resistance, law or conductance_law)
        if resistance is not None and signals:
            raise ElementDefinitionError(f'element {name!r}: a linear R takes no signals')
        param = None if resistance is None else float(resistance)
        element = Element(
            name, Kind.R, param, law, conductance_law=conductance_law, signals=tuple(signals)
        )
        return self._add(element)

    def add_r_field(
        self, name: str, law: Callable[..., Sequence[float]], *, signals: Sequence[str] = ()
    ) -> str:
        """Multi-port R: efforts = law(f_0, ..., f_{n-1}, *signals), all bonds pointing in."""
        if not callable(law):
            raise ElementDefinitionError(f'R-field {name!r}: law must be callable')
        return self._add(Element(name, Kind.RFIELD, None, law, signals=tuple(signals)))

    def add_tf(self, name: str, ratio: Value, *, signals: Sequence[str] = ()) -> str:
        """Transformer: e0 = n*e1, f1 = n*f0; callable ratio fn(t, *signals) makes an MTF."""
        param, law = self._value(name, ratio, signals)
        return self._add(Element(name, Kind.TF, param, law, signals=tuple(signals)))  # type: ignore[arg-type]

    def add_gy(self, name: str, ratio: Value, *, signals: Sequence[str] = ()) -> str:
        """Gyrator: e1 = r*f0, e0 = r*f1; callable ratio fn(t, *signals) makes an MGY."""
        param, law = self._value(name, ratio, signals)
        return self._add(Element(name, Kind.GY, param, law, signals=tuple(signals)))  # type: ignore[arg-type]

    def add_zero(self, name: str) -> str:
        """0-junction: common effort, signed flows sum to zero."""
        return self._add(Element(name, Kind.ZERO))

    def add_one(self, name: str) -> str:
        """1-junction: common flow, signed efforts sum to zero."""
        return self._add(Element(name, Kind.ONE))

    # -- bonds ----------------------------------------------------------------------------

    def connect(self, tail: str, head: str, name: str | None = None) -> str:
        """Add a bond; positive power flows from ``tail`` to ``head``.

        Raises:
            UnknownNameError: an end is not an element.
            InvalidConnectionError: a 1-port already has its bond, or a self-loop.
        """
        for end in (tail, head):
            if end not in self.elements:
                raise UnknownNameError(f'connect({tail!r}, {head!r}): no element named {end!r}')
        if tail == head:
            raise InvalidConnectionError(f'connect({tail!r}, {head!r}): a bond needs two ends')
        if name is None:
            name = f'{tail}->{head}'
            suffix = 2
            while name in self.bonds or name in self.elements or self.is_signal(name):
                name = f'{tail}->{head}#{suffix}'
                suffix += 1
        self._claim(name)
        for end in (tail, head):
            element = self.elements[end]
            if element.kind.is_one_port and element.bonds:
                raise InvalidConnectionError(
                    f'{element.kind.value} {end!r} is a 1-port and already has bond '
                    f'{element.bonds[0]!r}; cannot also attach {name!r}'
                )
            if element.kind in (Kind.TF, Kind.GY) and len(element.bonds) >= 2:
                raise InvalidConnectionError(
                    f'{element.kind.value} {end!r} already has two bonds {element.bonds}; '
                    f'cannot also attach {name!r}'
                )
        self.bonds[name] = Bond(name, tail, head)
        self.elements[tail].bonds.append(name)
        self.elements[head].bonds.append(name)
        return name
