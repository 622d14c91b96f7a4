"""The compiled model: generated RHS, outputs and power bookkeeping behind a small API."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .causality import Causality, assign_causality
from .codegen import GeneratedCode, generate_code
from .equations import build_equations
from .errors import MissingLawError, ShapeError, UnknownNameError
from .graph import BondGraph

__all__ = ['CompiledModel', 'compile_model']

FloatArray = NDArray[np.float64]
# A float for one state vector, an array of shape (N,) for a batch of N states.
ScalarOrSeries = float | FloatArray


class CompiledModel:
    """ẋ = f(t, x, u) and every output of one bond graph, generated and compiled once.

    Shapes: x (n_states,) or batch (n_states, N); u (n_inputs,) or batch (n_inputs, N) or
    empty (then the input defaults are used); t float or, for batch calls, shape (N,).

    Attributes:
        state_names: ``'<I name>.p'`` / ``'<C name>.q'`` in element order.
        input_names: declared inputs in order.
        output_names: sensors, blocks, ``'<bond>.e'``, ``'<bond>.f'`` per bond, then
            ``'P.sources'``, ``'P.dissipated'``, ``'P.stored'``.
        causality: the causal assignment used.
        source_code: the generated Python source.
    """

    def __init__(
        self,
        graph: BondGraph,
        causality: Causality,
        code: GeneratedCode,
        state_names: Sequence[str],
        state_elements: Sequence[str],
    ) -> None:
        self.name = graph.name
        self.causality = causality
        self.source_code = code.source
        self.state_names: tuple[str, ...] = tuple(state_names)
        self.state_elements: tuple[str, ...] = tuple(state_elements)
        self.input_names: tuple[str, ...] = tuple(graph.inputs)
        self.output_names: tuple[str, ...] = code.output_names
        self.state_index = {name: k for k, name in enumerate(self.state_names)}
        self.input_index = {name: k for k, name in enumerate(self.input_names)}
        self.output_index = {name: k for k, name in enumerate(self.output_names)}
        self.n_states = len(self.state_names)
        self.n_inputs = len(self.input_names)
        self.n_outputs = len(self.output_names)
        self._defaults = np.array([graph.inputs[n].default for n in self.input_names], float)
        self._code = code
        #: THE hot path: rhs(t, x, u=()) -> ndarray (n_states,). Bound directly, no wrapper.
        self.rhs: Callable[..., FloatArray] = code.rhs
        self._missing_energy = [
            e
            for e in state_elements
            if graph.elements[e].param is None and graph.elements[e].energy is None
        ]

    # -- vectors --------------------------------------------------------------------------

    def initial_state(self, values: Mapping[str, float] | None = None) -> FloatArray:
        """State vector from {state or storage element name: value}; missing -> 0.0.

        Values are energy variables: momentum p of an I (e.g. [kg m/s], [N m s]), displacement
        q of a C (e.g. [m], [rad]). Returns shape (n_states,).
        """
        x = np.zeros(self.n_states)
        for key, value in (values or {}).items():
            if key in self.state_index:
                x[self.state_index[key]] = value
            elif key in self.state_elements:
                x[self.state_elements.index(key)] = value
            else:
                raise UnknownNameError(f'{key!r} is no state of {self.name!r}: {self.state_names}')
        return x

    def input_vector(self, values: Mapping[str, float] | None = None) -> FloatArray:
        """Input vector from {input name: value}; missing inputs take their default."""
        u = self._defaults.copy()
        for key, value in (values or {}).items():
            if key not in self.input_index:
                raise UnknownNameError(f'{key!r} is no input of {self.name!r}: {self.input_names}')
            u[self.input_index[key]] = value
        return u

    def bind(self, u: ArrayLike = ()) -> Callable[[float, FloatArray], FloatArray]:
        """``f(t, x)`` with the inputs frozen (for ``scipy.integrate.solve_ivp``)."""
        rhs = self._code.rhs
        frozen = np.asarray(u, dtype=float) if np.size(u) else self._defaults.copy()
        if frozen.shape != (self.n_inputs,):
            raise ShapeError(
                f'{self.name!r} has {self.n_inputs} inputs {self.input_names}, got u of shape '
                f'{frozen.shape}'
            )

        def bound(t: float, x: FloatArray) -> FloatArray:
            return rhs(t, x, frozen)

        return bound

    # -- batch ----------------------------------------------------------------------------

    def _batch(
        self,
        fast: Callable[..., object],
        slow: Callable[..., object],
        rows: int,
        t: ArrayLike,
        x: FloatArray,
        u: ArrayLike,
    ) -> FloatArray:
        """Run the vectorised function; fall back to a column loop for scalar-only laws."""
        uu = np.asarray(u, dtype=float) if np.size(u) else self._defaults
        tt = np.asarray(t, dtype=float)
        try:
            with np.errstate(all='ignore'):
                result = np.asarray(fast(tt, x, uu), dtype=float)
            if result.shape == (rows, x.shape[1]):
                return result
        except (TypeError, ValueError):
            pass
        n = x.shape[1]
        out = np.empty((rows, n))
        times = np.broadcast_to(tt, (n,))
        inputs = np.broadcast_to(uu.reshape(len(uu), -1), (len(uu), n)) if len(uu) else None
        for k in range(n):
            column_u = inputs[:, k] if inputs is not None else ()
            out[:, k] = np.asarray(slow(float(times[k]), x[:, k], column_u), dtype=float)
        return out

    @staticmethod
    def _as_states(x: ArrayLike) -> FloatArray:
        return np.asarray(x, dtype=float)

    def rhs_batch(self, t: ArrayLike, x: ArrayLike, u: ArrayLike = ()) -> FloatArray:
        """ẋ for many states at once: x (n_states, N) -> (n_states, N)."""
        X = self._as_states(x)
        if X.ndim != 2:
            raise ShapeError(f'rhs_batch wants x of shape (n_states, N), got {X.shape}')
        return self._batch(self._code.rhs_batch, self._code.rhs, self.n_states, t, X, u)

    # -- outputs --------------------------------------------------------------------------

    def output_vector(self, t: ArrayLike, x: ArrayLike, u: ArrayLike = ()) -> FloatArray:
        """All outputs: shape (n_outputs,) for one state, (n_outputs, N) for x (n_states, N)."""
        X = self._as_states(x)
        if X.ndim == 2:
            return self._batch(
                self._code.outputs_batch, self._code.outputs, self.n_outputs, t, X, u
            )
        return self._code.outputs(float(np.asarray(t)), X, np.asarray(u, dtype=float))

    def outputs(self, t: ArrayLike, x: ArrayLike, u: ArrayLike = ()) -> dict[str, FloatArray]:
        """All outputs by name (sensors, blocks, '<bond>.e'/'.f', 'P.*')."""
        values = self.output_vector(t, x, u)
        return {name: values[k] for k, name in enumerate(self.output_names)}

    # -- power bookkeeping ----------------------------------------------------------------

    def _power(self, t: ArrayLike, x: ArrayLike, u: ArrayLike, which: int) -> ScalarOrSeries:
        X = self._as_states(x)
        if X.ndim == 2:
            series: FloatArray = self.output_vector(t, X, u)[self.n_outputs - 3 + which]
            return series
        values = self._code.power(float(np.asarray(t)), X, np.asarray(u, dtype=float))
        return float(values[which])

    def source_power(self, t: ArrayLike, x: ArrayLike, u: ArrayLike = ()) -> ScalarOrSeries:
        """Power delivered by all Se and Sf [W]; float or shape (N,)."""
        return self._power(t, x, u, 0)

    def dissipated_power(self, t: ArrayLike, x: ArrayLike, u: ArrayLike = ()) -> ScalarOrSeries:
        """Power into all R and R-fields [W]; float or shape (N,)."""
        return self._power(t, x, u, 1)

    def storage_power(self, t: ArrayLike, x: ArrayLike, u: ArrayLike = ()) -> ScalarOrSeries:
        """d(stored energy)/dt [W] = sum over storage of effort * flow in; float or (N,)."""
        return self._power(t, x, u, 2)

    def stored_energy(self, x: ArrayLike) -> ScalarOrSeries:
        """Energy in all I and C [J]; float for x (n_states,), shape (N,) for (n_states, N).

        Raises:
            MissingLawError: a nonlinear storage element was given no ``energy`` callable.
        """
        energy = self._code.energy
        if energy is None:
            raise MissingLawError(
                f'stored energy of {self.name!r} needs energy= for nonlinear storage '
                f'{self._missing_energy}'
            )
        X = self._as_states(x)
        if X.ndim == 2:
            try:
                result = np.asarray(energy(X), dtype=float)
                if result.shape == (X.shape[1],):
                    return result
            except (TypeError, ValueError):
                pass
            return np.array([float(energy(X[:, k])) for k in range(X.shape[1])])
        return float(energy(X))


def compile_model(graph: BondGraph, causality: Causality | None = None) -> CompiledModel:
    """Assign causality (unless given), build the equations, generate and compile the code.

    Raises:
        BondGraphError: any structural or causal problem (see ``errors``).
    """
    if causality is None:
        causality = assign_causality(graph)
    system = build_equations(graph, causality)
    code = generate_code(system, graph)
    return CompiledModel(graph, causality, code, system.state_names, system.state_elements)
