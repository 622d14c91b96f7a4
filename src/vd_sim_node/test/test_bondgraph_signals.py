"""Modulated elements, signal blocks, R-fields and the compiled-model helpers."""

from __future__ import annotations

import math

import numpy as np
import pytest
from vd_sim_node.bondgraph import (
    BondGraph,
    DerivativeCausalityError,
    GraphWalker,
    ShapeError,
    UnknownNameError,
    compile_model,
)

GRAVITY = 9.81


def _tyre_force(v_slip: float, v_x: float, fz: float, mu: float) -> float:
    """Magic-formula-like longitudinal force [N] from the slip velocity [m/s]."""
    kappa = v_slip / max(abs(v_x), 0.5)
    return mu * fz * math.sin(1.6 * math.atan(10.0 * kappa))


def _wheel_on_chassis(mass: float, inertia: float, radius: float) -> BondGraph:
    """One driven wheel pushing a chassis on a slope, with a modulated tyre R."""
    bg = BondGraph('wheel_on_chassis')
    bg.add_input('torque')
    bg.add_input('slope')
    bg.add_input('mu', default=1.0)
    bg.add_se('drive', lambda t, tq: tq, signals=('torque',))
    bg.add_se('grade', lambda t, a: -mass * GRAVITY * math.sin(a), signals=('slope',))
    bg.add_one('spin')
    bg.add_i('wheel', inertia)
    bg.add_tf('radius', radius)
    bg.add_zero('contact')
    bg.add_one('chassis')
    bg.add_i('body', mass)
    bg.add_block('fz', lambda t, a: mass * GRAVITY * math.cos(a), signals=('slope',))
    bg.connect('drive', 'spin')
    bg.connect('spin', 'wheel')
    bg.connect('spin', 'radius')
    bg.connect('radius', 'contact', name='contact_in')
    bg.connect('contact', 'chassis', name='chassis_bond')
    bg.connect('grade', 'chassis')
    bg.connect('chassis', 'body')
    bg.add_flow_sensor('v_x', 'chassis_bond')
    bg.add_r('tyre', law=_tyre_force, signals=('v_x', 'fz', 'mu'))
    bg.connect('contact', 'tyre', name='slip_bond')
    bg.add_flow_sensor('slip_velocity', 'slip_bond')
    bg.add_effort_sensor('tyre_force', 'slip_bond')
    return bg


def test_modulated_tyre_resistor_matches_hand_equations() -> None:
    mass, inertia, radius = 900.0, 0.8, 0.26
    bg = _wheel_on_chassis(mass, inertia, radius)
    model = compile_model(bg)
    assert model.input_names == ('torque', 'slope', 'mu')
    assert model.causality.r_modes['tyre'] == 'resistance'
    rng = np.random.default_rng(3)
    for _ in range(25):
        p_w, p_b = rng.normal(size=2) * [20.0, 9000.0]
        torque, slope, mu = rng.normal() * 300.0, rng.normal() * 0.1, rng.uniform(0.2, 1.1)
        x = model.initial_state({'wheel.p': p_w, 'body': p_b})
        u = model.input_vector({'torque': torque, 'slope': slope, 'mu': mu})
        omega, v = p_w / inertia, p_b / mass
        force = _tyre_force(radius * omega - v, v, mass * GRAVITY * math.cos(slope), mu)
        dx = model.rhs(0.0, x, u)
        idx = model.state_index
        assert dx[idx['wheel.p']] == pytest.approx(torque - radius * force, rel=1e-12, abs=1e-9)
        assert dx[idx['body.p']] == pytest.approx(
            force - mass * GRAVITY * math.sin(slope), rel=1e-12, abs=1e-9
        )
        out = model.outputs(0.0, x, u)
        assert out['slip_velocity'] == pytest.approx(radius * omega - v, rel=1e-12, abs=1e-12)
        assert out['tyre_force'] == pytest.approx(force, rel=1e-12, abs=1e-9)
        assert out['fz'] == pytest.approx(mass * GRAVITY * math.cos(slope), rel=1e-12)
        assert out['P.dissipated'] == pytest.approx(force * (radius * omega - v), rel=1e-12)
        np.testing.assert_allclose(GraphWalker(bg).rhs(0.0, x, u), dx, rtol=1e-13)


def test_scalar_only_laws_fall_back_to_a_column_loop_in_batch_calls() -> None:
    """_tyre_force uses math and max(): the numpy path fails and must fall back silently."""
    bg = _wheel_on_chassis(900.0, 0.8, 0.26)
    model = compile_model(bg)
    rng = np.random.default_rng(11)
    X = rng.normal(size=(2, 6)) * [[20.0], [9000.0]]
    times = np.linspace(0.0, 1.0, 6)
    U = np.vstack([rng.normal(size=6) * 100.0, np.zeros(6), np.ones(6)])
    batch = model.output_vector(times, X, U)
    dx_batch = model.rhs_batch(times, X, U)
    for k in range(6):
        np.testing.assert_array_equal(batch[:, k], model.output_vector(times[k], X[:, k], U[:, k]))
        np.testing.assert_array_equal(dx_batch[:, k], model.rhs(times[k], X[:, k], U[:, k]))


def test_modulated_transformer_as_gear_ratio_from_an_input() -> None:
    bg = BondGraph('gearbox')
    bg.add_input('ratio', default=3.5)
    bg.add_se('engine_torque', 100.0)
    bg.add_one('engine')
    bg.add_i('crank', 0.15)
    bg.add_tf('gear', lambda t, n: 1.0 / n, signals=('ratio',))  # wheel speed = engine / n
    bg.add_one('wheel')
    bg.add_i('wheel_inertia', 1.2)
    bg.add_r('losses', 0.3)
    bg.connect('engine_torque', 'engine')
    bg.connect('engine', 'crank')
    bg.connect('engine', 'gear', name='shaft_in')
    bg.connect('gear', 'wheel', name='shaft_out')
    bg.connect('wheel', 'wheel_inertia')
    bg.connect('wheel', 'losses')
    bg.add_flow_sensor('engine_speed', 'shaft_in')
    bg.add_flow_sensor('wheel_speed', 'shaft_out')
    with pytest.raises(DerivativeCausalityError) as info:  # rigidly geared inertias
        compile_model(bg)
    assert info.value.element == 'wheel_inertia'
    assert info.value.forced_by == 'crank'
    assert 'gear' in info.value.elements
    # With a flexible shaft (C) between the gear and the wheel the model is well posed.
    bg2 = BondGraph('gearbox_flexible')
    bg2.add_input('ratio', default=3.5)
    bg2.add_se('engine_torque', 100.0)
    bg2.add_one('engine')
    bg2.add_i('crank', 0.15)
    bg2.add_tf('gear', lambda t, n: 1.0 / n, signals=('ratio',))
    bg2.add_zero('shaft')
    bg2.add_c('shaft_compliance', 1e-4)
    bg2.add_one('wheel')
    bg2.add_i('wheel_inertia', 1.2)
    bg2.connect('engine_torque', 'engine')
    bg2.connect('engine', 'crank')
    bg2.connect('engine', 'gear', name='shaft_in')
    bg2.connect('gear', 'shaft', name='shaft_out')
    bg2.connect('shaft', 'shaft_compliance')
    bg2.connect('shaft', 'wheel')
    bg2.connect('wheel', 'wheel_inertia')
    bg2.add_flow_sensor('engine_speed', 'shaft_in')
    bg2.add_flow_sensor('gear_out_speed', 'shaft_out')
    model = compile_model(bg2)
    x = model.initial_state(
        {'crank': 0.15 * 300.0, 'wheel_inertia': 1.2 * 40.0, 'shaft_compliance': 2e-3}
    )
    for ratio in (3.5, 1.9, 0.9):
        out = model.outputs(0.0, x, model.input_vector({'ratio': ratio}))
        assert out['gear_out_speed'] == pytest.approx(out['engine_speed'] / ratio, rel=1e-14)
        # Torque is multiplied by the ratio: shaft torque 20 N m -> crank reaction 20 / ratio.
        dx = model.rhs(0.0, x, [ratio])
        assert dx[model.state_index['crank.p']] == pytest.approx(100.0 - 20.0 / ratio, rel=1e-12)


def test_two_port_r_field_couples_two_velocities() -> None:
    R = np.array([[3.0, 1.0], [1.0, 2.0]])  # symmetric positive definite: passive
    bg = BondGraph('r_field')
    bg.add_one('a')
    bg.add_one('b')
    bg.add_i('ma', 2.0)
    bg.add_i('mb', 5.0)
    bg.add_r_field(
        'coupling', lambda fa, fb: (R[0, 0] * fa + R[0, 1] * fb, R[1, 0] * fa + R[1, 1] * fb)
    )
    bg.connect('a', 'ma')
    bg.connect('b', 'mb')
    bg.connect('a', 'coupling')
    bg.connect('b', 'coupling')
    model = compile_model(bg)
    x = np.array([4.0, -10.0])
    v = x / [2.0, 5.0]
    np.testing.assert_allclose(model.rhs(0.0, x), -R @ v, rtol=1e-14)
    assert model.dissipated_power(0.0, x) == pytest.approx(v @ R @ v, rel=1e-14)
    assert model.storage_power(0.0, x) == pytest.approx(-(v @ R @ v), rel=1e-14)


def test_signal_block_chain_modulates_a_source() -> None:
    """Se = gain * (setpoint - measured velocity): a proportional speed controller."""
    bg = BondGraph('controller')
    bg.add_input('setpoint', default=2.0)
    bg.add_one('v')
    bg.add_i('m', 4.0)
    bg.add_r('drag', 0.5)
    bg.connect('v', 'm', name='mass_bond')
    bg.connect('v', 'drag')
    bg.add_flow_sensor('speed', 'mass_bond')
    bg.add_block('error', lambda t, ref, v: ref - v, signals=('setpoint', 'speed'))
    bg.add_block('command', lambda t, err: 10.0 * err, signals=('error',))
    bg.add_se('motor', lambda t, f: f, signals=('command',))
    bg.connect('motor', 'v')
    model = compile_model(bg)
    # Steady state: 10 (2 - v) = 0.5 v -> v = 20 / 10.5; p = m v.
    v_ss = 20.0 / 10.5
    x = model.initial_state({'m': 4.0 * v_ss})
    assert model.rhs(0.0, x)[0] == pytest.approx(0.0, abs=1e-12)
    out = model.outputs(0.0, x)
    assert out['command'] == pytest.approx(0.5 * v_ss, rel=1e-12)


def test_model_helpers_validate_names_and_shapes() -> None:
    bg = BondGraph('helpers')
    bg.add_input('f', default=1.5)
    bg.add_se('F', lambda t, f: f, signals=('f',))
    bg.add_one('j')
    bg.add_i('m', 2.0)
    bg.add_c('k', 0.1)
    bg.connect('F', 'j')
    bg.connect('j', 'm')
    bg.connect('j', 'k')
    model = compile_model(bg)
    np.testing.assert_array_equal(model.input_vector(), [1.5])
    np.testing.assert_array_equal(model.initial_state({'k': 0.3, 'm.p': 1.0}), [1.0, 0.3])
    # Empty u means the declared defaults.
    np.testing.assert_array_equal(model.rhs(0.0, np.array([1.0, 0.3])), [1.5 - 3.0, 0.5])
    np.testing.assert_array_equal(model.bind()(0.0, np.array([1.0, 0.3])), [1.5 - 3.0, 0.5])
    with pytest.raises(UnknownNameError):
        model.initial_state({'nope': 1.0})
    with pytest.raises(UnknownNameError):
        model.input_vector({'nope': 1.0})
    with pytest.raises(ShapeError):
        model.rhs_batch(0.0, np.zeros(2))
    with pytest.raises(ShapeError, match='1 inputs'):
        model.bind([1.0, 2.0])
    assert 'def rhs(' in model.source_code
    assert model.output_names[-3:] == ('P.sources', 'P.dissipated', 'P.stored')
    assert model.stored_energy(np.array([2.0, 0.5])) == pytest.approx(4.0 / 4.0 + 0.25 / 0.2)


def test_scalar_calls_hand_plain_python_floats_to_every_callable() -> None:
    """Laws may dispatch on ``arg.__class__ is float`` for a fast scalar path."""
    seen: list[type] = []

    def record(*args: float) -> float:
        seen.extend(type(a) for a in args)
        return 0.1 * args[0]

    bg = BondGraph('types')
    bg.add_input('k', default=2.0)
    bg.add_se('F', lambda t, k: record(t, k), signals=('k',))
    bg.add_one('j')
    bg.add_i('m', law=lambda p: record(p), energy=lambda p: 0.05 * p * p)
    bg.add_r('d', law=lambda f, v: record(f, v), signals=('v',))
    bg.connect('F', 'j')
    bg.connect('j', 'm', name='mb')
    bg.connect('j', 'd')
    bg.add_flow_sensor('v', 'mb')
    model = compile_model(bg)
    x = np.array([1.5])
    for call in (
        lambda: model.rhs(0.5, x, np.array([3.0])),
        lambda: model.rhs(0.5, x),
        lambda: model.bind([3.0])(0.5, x),
        lambda: model.output_vector(0.5, x, np.array([3.0])),
        lambda: model.source_power(0.5, x, np.array([3.0])),
    ):
        seen.clear()
        call()
        assert seen and all(kind is float for kind in seen), seen
