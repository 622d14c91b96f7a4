"""Property tests on random nonlinear networks: power balance, generated code vs graph walk.

The random networks are trees of junctions built so that causality is always integral and
free of algebraic loops: every 1-junction carries exactly one I (which fixes its flow), every
0-junction exactly one C (which fixes its effort); junctions joined by a bond or a TF
alternate 0/1, junctions joined by a GY have the same type. Each junction may also carry an
R (nonlinear, modulated by a sensor signal) and a source (modulated by time and an input).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from vd_sim_node.bondgraph import BondGraph, DerivativeCausalityError, GraphWalker, compile_model

POWER_RTOL = 1e-9

finite = st.floats(0.2, 5.0)


@dataclass(frozen=True)
class JunctionSpec:
    """One junction of the random tree and what hangs on it."""

    parent: int  # -1 for the root
    link: str  # 'bond', 'tf' or 'gy' to the parent
    link_outward: bool  # power flows parent -> child
    ratio: float
    modulated_link: bool
    storage_linear: bool
    storage_param: float
    storage_cubic: float
    storage_into: bool
    resistor: bool
    r_linear: float
    r_cubic: float
    r_into: bool
    source: bool
    source_amplitude: float
    source_out: bool


@st.composite
def junction_specs(draw: st.DrawFn) -> list[JunctionSpec]:
    count = draw(st.integers(1, 7))
    specs = []
    for k in range(count):
        specs.append(
            JunctionSpec(
                parent=draw(st.integers(0, k - 1)) if k else -1,
                link=draw(st.sampled_from(['bond', 'tf', 'gy'])),
                link_outward=draw(st.booleans()),
                ratio=draw(finite) * draw(st.sampled_from([1.0, -1.0])),
                modulated_link=draw(st.booleans()),
                storage_linear=draw(st.booleans()),
                storage_param=draw(finite),
                storage_cubic=draw(st.floats(0.0, 2.0)),
                storage_into=draw(st.booleans()),
                resistor=draw(st.booleans()),
                r_linear=draw(finite),
                r_cubic=draw(st.floats(0.0, 2.0)),
                r_into=draw(st.booleans()),
                source=draw(st.booleans()),
                source_amplitude=draw(st.floats(-3.0, 3.0)),
                source_out=draw(st.booleans()),
            )
        )
    return specs


@dataclass
class Network:
    graph: BondGraph
    coenergy: dict[str, object]  # state name -> law giving dE/dx


def _build(specs: list[JunctionSpec], root_is_one: bool) -> Network:
    bg = BondGraph('random')
    bg.add_input('drive')
    coenergy: dict[str, object] = {}
    types: list[bool] = []  # True for a 1-junction
    for k, spec in enumerate(specs):
        if spec.parent < 0:
            is_one = root_is_one
        else:
            same = spec.link == 'gy'
            is_one = types[spec.parent] if same else not types[spec.parent]
        types.append(is_one)
        j = f'J{k}'
        (bg.add_one if is_one else bg.add_zero)(j)
        # Storage: I on 1-junctions, C on 0-junctions, linear or hardening cubic.
        s = f'{"I" if is_one else "C"}{k}'
        a, b = 1.0 / spec.storage_param, spec.storage_cubic
        if spec.storage_linear:
            (bg.add_i if is_one else bg.add_c)(s, spec.storage_param)
            law = lambda x, a=a: a * x  # noqa: E731
        else:
            law = lambda x, a=a, b=b: a * x + b * x**3  # noqa: E731
            energy = lambda x, a=a, b=b: 0.5 * a * x**2 + 0.25 * b * x**4  # noqa: E731
            (bg.add_i if is_one else bg.add_c)(s, law=law, energy=energy)
        coenergy[f'{s}.{"p" if is_one else "q"}'] = law
        store_bond = bg.connect(j, s) if spec.storage_into else bg.connect(s, j)
        sensor = f'sig{k}'
        if is_one:
            bg.add_flow_sensor(sensor, store_bond)
        else:
            bg.add_effort_sensor(sensor, store_bond)
        if spec.resistor:
            r = f'R{k}'
            r1, r3 = spec.r_linear, spec.r_cubic
            # Dissipative for any signal value: the modulation factor stays in [0.5, 1.5].
            if is_one:
                bg.add_r(
                    r,
                    law=lambda f, z, r1=r1, r3=r3: r1 * (1 + 0.5 * np.tanh(z)) * f + r3 * f**3,
                    signals=(sensor,),
                )
            else:
                bg.add_r(
                    r,
                    conductance_law=lambda e, z, r1=r1, r3=r3: (
                        (1 + 0.5 * np.tanh(z)) * e / r1 + r3 * e**3
                    ),
                    signals=(sensor,),
                )
            bg.connect(j, r) if spec.r_into else bg.connect(r, j)
        if spec.source:
            src = f'S{k}'
            amp = spec.source_amplitude
            value = lambda t, u, amp=amp, k=k: amp * np.sin(1.3 * t + k) + u  # noqa: E731
            (bg.add_se if is_one else bg.add_sf)(src, value, signals=('drive',))
            bg.connect(src, j) if spec.source_out else bg.connect(j, src)
        if spec.parent >= 0:
            parent = f'J{spec.parent}'
            tail, head = (parent, j) if spec.link_outward else (j, parent)
            if spec.link == 'bond':
                bg.connect(tail, head)
                continue
            two_port = f'{spec.link.upper()}{k}'
            ratio: object = spec.ratio
            signals: tuple[str, ...] = ()
            if spec.modulated_link:
                base = spec.ratio
                ratio = lambda t, z, base=base: base * (1.0 + 0.5 * np.tanh(z))  # noqa: E731
                signals = (f'sig{spec.parent}',)
            add = bg.add_tf if spec.link == 'tf' else bg.add_gy
            add(two_port, ratio, signals=signals)  # type: ignore[arg-type]
            bg.connect(tail, two_port)
            bg.connect(two_port, head)
    return Network(bg, coenergy)


@settings(max_examples=60, deadline=None, derandomize=True)
@given(
    specs=junction_specs(),
    root_is_one=st.booleans(),
    seed=st.integers(0, 2**31 - 1),
)
def test_power_balance_and_codegen_match_the_graph_walk(
    specs: list[JunctionSpec], root_is_one: bool, seed: int
) -> None:
    network = _build(specs, root_is_one)
    model = compile_model(network.graph)
    walker = GraphWalker(network.graph, model.causality)
    rng = np.random.default_rng(seed)
    n_samples = 4
    X = rng.normal(scale=1.5, size=(model.n_states, n_samples))
    times = rng.uniform(0.0, 10.0, n_samples)
    U = rng.normal(size=(1, n_samples))
    for k in range(n_samples):
        t, x, u = float(times[k]), X[:, k], U[:, k]
        dx = model.rhs(t, x, u)
        # d(stored energy)/dt via the chain rule, from the generated state derivative.
        terms = [
            network.coenergy[name](x[i]) * dx[i]  # type: ignore[operator]
            for i, name in enumerate(model.state_names)
        ]
        p_source = model.source_power(t, x, u)
        p_diss = model.dissipated_power(t, x, u)
        p_store = model.storage_power(t, x, u)
        scale = abs(p_source) + abs(p_diss) + sum(abs(v) for v in terms) + 1e-300
        assert abs(sum(terms) - (p_source - p_diss)) <= POWER_RTOL * scale
        assert abs(p_store - (p_source - p_diss)) <= POWER_RTOL * scale
        assert p_diss >= -POWER_RTOL * scale  # the R laws are passive
        np.testing.assert_allclose(walker.rhs(t, x, u), dx, rtol=1e-11, atol=1e-11 * scale)
        out = model.outputs(t, x, u)
        for bond in network.graph.bonds:
            walked = (walker.effort(bond, t, x, u), walker.flow(bond, t, x, u))
            generated = (out[f'{bond}.e'], out[f'{bond}.f'])
            np.testing.assert_allclose(generated, walked, rtol=1e-11, atol=1e-11 * scale)
    # Batch evaluation (vectorised numpy path) agrees with column-by-column scalar calls.
    batch = model.rhs_batch(times, X, U)
    outputs = model.output_vector(times, X, U)
    for k in range(n_samples):
        scalar_dx = model.rhs(float(times[k]), X[:, k], U[:, k])
        np.testing.assert_allclose(batch[:, k], scalar_dx, rtol=1e-12, atol=1e-12)
        scalar_out = model.output_vector(float(times[k]), X[:, k], U[:, k])
        np.testing.assert_allclose(outputs[:, k], scalar_out, rtol=1e-12, atol=1e-12)
    energies = model.stored_energy(X)
    for k in range(n_samples):
        # A few ulps, not equality: on AVX-512 numpy's vectorised power/exp (SVML) and the
        # scalar ones differ in the last bit.
        scalar = float(model.stored_energy(X[:, k]))
        assert abs(energies[k] - scalar) <= 8 * np.finfo(float).eps * max(abs(scalar), 1e-300)


@settings(max_examples=40, deadline=None, derandomize=True)
@given(specs=junction_specs(), root_is_one=st.booleans(), data=st.data())
def test_extra_storage_on_a_junction_is_reported_as_derivative_causality(
    specs: list[JunctionSpec], root_is_one: bool, data: st.DataObject
) -> None:
    """A second I on a 1-junction (or C on a 0-junction) is always dependent storage."""
    network = _build(specs, root_is_one)
    bg = network.graph
    k = data.draw(st.integers(0, len(specs) - 1))
    junction = bg.elements[f'J{k}']
    is_one = junction.kind.value == '1'
    existing = f'{"I" if is_one else "C"}{k}'
    (bg.add_i if is_one else bg.add_c)('extra', 1.0)
    if data.draw(st.booleans()):
        bg.connect(junction.name, 'extra')
    else:
        bg.connect('extra', junction.name)
    with pytest.raises(DerivativeCausalityError) as info:
        compile_model(bg)
    assert info.value.element == 'extra'
    assert info.value.forced_by == existing
    assert junction.name in info.value.elements
