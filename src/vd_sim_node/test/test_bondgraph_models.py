"""Reference models with closed-form or hand-derived answers: MSD, DC motor, quarter car, lever."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy.integrate import solve_ivp
from vd_sim_node.bondgraph import BondGraph, CompiledModel, GraphWalker, compile_model

RTOL = 1e-10
ATOL = 1e-12
GRAVITY = 9.81


def _simulate(
    model: CompiledModel, u: NDArray[np.float64], t_end: float, n: int = 401
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    t_eval = np.linspace(0.0, t_end, n)
    sol = solve_ivp(
        model.bind(u),
        (0.0, t_end),
        model.initial_state(),
        method='DOP853',
        rtol=RTOL,
        atol=ATOL,
        t_eval=t_eval,
    )
    assert sol.success
    return sol.t, sol.y


def _msd_step(t: NDArray[np.float64], m: float, d: float, k: float, force: float):
    """Closed-form displacement of an underdamped m x'' + d x' + k x = F step from rest."""
    wn = np.sqrt(k / m)
    zeta = d / (2.0 * np.sqrt(k * m))
    assert zeta < 1.0
    wd = wn * np.sqrt(1.0 - zeta**2)
    decay = np.exp(-zeta * wn * t)
    return (
        force / k * (1.0 - decay * (np.cos(wd * t) + zeta / np.sqrt(1 - zeta**2) * np.sin(wd * t)))
    )


def _msd_graph(m: float, d: float, k: float) -> BondGraph:
    bg = BondGraph('msd')
    bg.add_input('force')
    bg.add_se('F', effort=lambda t, f: f, signals=('force',))
    bg.add_one('v')
    bg.add_i('m', m)
    bg.add_c('k', 1.0 / k)
    bg.add_r('d', d)
    bg.connect('F', 'v')
    bg.connect('v', 'm')
    bg.connect('v', 'k', name='spring')
    bg.connect('v', 'd')
    bg.add_effort_sensor('spring_force', 'spring')
    bg.add_flow_sensor('velocity', 'v->m')
    return bg


def test_mass_spring_damper_step_matches_closed_form() -> None:
    m, d, k, force = 2.0, 3.0, 50.0, 10.0
    model = compile_model(_msd_graph(m, d, k))
    assert model.state_names == ('m.p', 'k.q')
    u = model.input_vector({'force': force})
    t, y = _simulate(model, u, 5.0)
    out = model.outputs(t, y, u)
    x_exact = _msd_step(t, m, d, k, force)
    np.testing.assert_allclose(y[1], x_exact, atol=1e-8 * force / k)
    np.testing.assert_allclose(out['spring_force'], k * x_exact, atol=1e-8 * force)
    # Velocity sensor = derivative of the closed form (central difference is too coarse; use
    # the momentum state instead, p = m v, which is independent of the sensor code path).
    np.testing.assert_allclose(out['velocity'], y[0] / m, rtol=0, atol=1e-15)


def test_mass_spring_damper_energy_balance_over_time() -> None:
    m, d, k, force = 2.0, 3.0, 50.0, 10.0
    model = compile_model(_msd_graph(m, d, k))
    u = model.input_vector({'force': force})
    t, y = _simulate(model, u, 3.0, n=3001)
    energy = model.stored_energy(y)
    net = model.source_power(t, y, u) - model.dissipated_power(t, y, u)
    # Trapezoid integral of the net power on a fine grid vs the stored energy change.
    integral = np.concatenate(([0.0], np.cumsum(0.5 * (net[1:] + net[:-1]) * np.diff(t))))
    np.testing.assert_allclose(energy - energy[0], integral, atol=2e-5)


def _dc_motor(V: float, R: float, L: float, K: float, J: float, b: float) -> BondGraph:
    bg = BondGraph('dc_motor')
    bg.add_se('V', V)
    bg.add_one('i')
    bg.add_r('Ra', R)
    bg.add_i('La', L)
    bg.add_gy('K', K)
    bg.add_one('w')
    bg.add_i('J', J)
    bg.add_r('b', b)
    bg.connect('V', 'i')
    bg.connect('i', 'Ra')
    bg.connect('i', 'La')
    bg.connect('i', 'K', name='electric')
    bg.connect('K', 'w', name='shaft')
    bg.connect('w', 'J')
    bg.connect('w', 'b')
    bg.add_flow_sensor('current', 'electric')
    bg.add_flow_sensor('speed', 'shaft')
    bg.add_effort_sensor('torque', 'shaft')
    return bg


def test_dc_motor_steady_state_and_time_constants() -> None:
    V, R, L, K, J, b = 12.0, 1.2, 0.5e-3, 0.05, 2e-4, 1e-4
    model = compile_model(_dc_motor(V, R, L, K, J, b))
    assert model.state_names == ('La.p', 'J.p')
    # The model is linear: its Jacobian is exact from unit states.
    zero = model.rhs(0.0, np.zeros(2))
    A = np.column_stack([model.rhs(0.0, np.eye(2)[k]) - zero for k in range(2)])
    # Characteristic polynomial L J s^2 + (L b + R J) s + (R b + K^2).
    roots = np.sort(np.roots([L * J, L * b + R * J, R * b + K**2]).real)
    np.testing.assert_allclose(np.sort(np.linalg.eigvals(A).real), roots, rtol=1e-9)
    speed_ss = K * V / (R * b + K**2)
    tau_mech = J * R / (R * b + K**2)
    t, y = _simulate(model, np.zeros(0), 10.0 * tau_mech, n=2001)
    out = model.outputs(t, y)
    # Start from rest: w(t) = w_ss (1 + (s2 e^{s1 t} - s1 e^{s2 t}) / (s1 - s2)).
    s1, s2 = roots
    exact = speed_ss * (1.0 + (s2 * np.exp(s1 * t) - s1 * np.exp(s2 * t)) / (s1 - s2))
    np.testing.assert_allclose(out['speed'], exact, atol=1e-7 * speed_ss)
    assert out['speed'][-1] == pytest.approx(speed_ss * (1 - np.exp(-10.0)), rel=1e-3)
    assert out['current'][-1] == pytest.approx(b * speed_ss / K, rel=1e-2)
    np.testing.assert_allclose(out['torque'], K * out['current'], rtol=1e-12)
    # The slow root is the mechanical time constant when L is small (L/R << tau_mech).
    assert -1.0 / roots[1] == pytest.approx(tau_mech, rel=2e-2)


def _quarter_car(ms: float, mu: float, ks: float, cs: float, kt: float) -> BondGraph:
    bg = BondGraph('quarter_car')
    bg.add_input('road_velocity')
    bg.add_sf('road', lambda t, v: v, signals=('road_velocity',))
    bg.add_se('g_s', -ms * GRAVITY)
    bg.add_se('g_u', -mu * GRAVITY)
    for name in ('body', 'wheel'):
        bg.add_one(name)
    bg.add_zero('susp')
    bg.add_zero('tyre')
    bg.add_one('susp_rel')
    bg.add_i('ms', ms)
    bg.add_i('mu', mu)
    bg.add_c('ks', 1.0 / ks)
    bg.add_r('cs', cs)
    bg.add_c('kt', 1.0 / kt)
    # Tyre: the 0-junction splits the road velocity into wheel velocity and kt compression.
    bg.connect('road', 'tyre')
    bg.connect('tyre', 'kt', name='tyre_spring')
    bg.connect('tyre', 'wheel')
    bg.connect('g_u', 'wheel')
    bg.connect('wheel', 'mu')
    # Suspension between wheel and body.
    bg.connect('wheel', 'susp')
    bg.connect('susp', 'susp_rel')
    bg.connect('susp_rel', 'ks', name='susp_spring')
    bg.connect('susp_rel', 'cs')
    bg.connect('susp', 'body')
    bg.connect('g_s', 'body')
    bg.connect('body', 'ms')
    bg.add_effort_sensor('susp_force', 'susp_spring')
    bg.add_effort_sensor('tyre_force', 'tyre_spring')
    return bg


def test_quarter_car_matches_hand_equations_and_static_loads() -> None:
    ms, mu, ks, cs, kt = 300.0, 35.0, 19000.0, 1500.0, 160000.0
    bg = _quarter_car(ms, mu, ks, cs, kt)
    model = compile_model(bg)
    assert set(model.state_names) == {'ms.p', 'mu.p', 'ks.q', 'kt.q'}
    idx = model.state_index
    rng = np.random.default_rng(7)
    for _ in range(20):
        x = rng.normal(size=4) * [300.0, 30.0, 0.05, 0.01]
        vr = rng.normal()
        dx = model.rhs(0.0, x, [vr])
        ps, pu, qs, qt = x[idx['ms.p']], x[idx['mu.p']], x[idx['ks.q']], x[idx['kt.q']]
        vs, vu = ps / ms, pu / mu
        fs = ks * qs + cs * (vu - vs)  # suspension compression rate = vu - vs
        ft = kt * qt
        expected = {
            'ms.p': fs - ms * GRAVITY,
            'mu.p': ft - fs - mu * GRAVITY,
            'ks.q': vu - vs,
            'kt.q': vr - vu,
        }
        for name, value in expected.items():
            assert dx[idx[name]] == pytest.approx(value, rel=1e-12, abs=1e-9)
    t, y = _simulate(model, model.input_vector(), 20.0, n=201)
    out = model.outputs(t, y)
    assert out['susp_force'][-1] == pytest.approx(ms * GRAVITY, rel=1e-6)
    assert out['tyre_force'][-1] == pytest.approx((ms + mu) * GRAVITY, rel=1e-6)
    walker = GraphWalker(bg)
    np.testing.assert_allclose(walker.rhs(0.3, y[:, 50]), model.rhs(0.3, y[:, 50]), rtol=1e-13)


@pytest.mark.parametrize('mass_on_input_side', [True, False])
def test_lever_reflects_mass_and_stiffness_through_tf(mass_on_input_side: bool) -> None:
    """Lever with arms a (input) and b (output): v_out = (b/a) v_in, F_in = (b/a) F_out."""
    a, b, m, k, d, force = 0.4, 0.8, 3.0, 200.0, 4.0, 5.0
    n = b / a
    bg = BondGraph('lever')
    bg.add_se('F', force)
    bg.add_one('input')
    bg.add_tf('lever', n)
    bg.add_one('output')
    bg.add_c('k', 1.0 / k)
    bg.add_r('d', d)
    bg.connect('F', 'input')
    bg.connect('input', 'lever', name='arm_in')
    bg.connect('lever', 'output', name='arm_out')
    bg.connect('output', 'k')
    bg.connect('output', 'd')
    # Reflected to the input side the system is an MSD with k n^2 and d n^2 (mass m on the
    # input side) or m n^2 ... on the output side: m_out = m / n^2 keeps the same dynamics.
    if mass_on_input_side:
        bg.add_i('m', m)
        bg.connect('input', 'm')
    else:
        bg.add_i('m', m / n**2)
        bg.connect('output', 'm')
    bg.add_flow_sensor('v_in', 'arm_in')
    bg.add_flow_sensor('v_out', 'arm_out')
    bg.add_effort_sensor('f_in', 'arm_in')
    bg.add_effort_sensor('f_out', 'arm_out')
    model = compile_model(bg)
    setter = model.causality.effort_setter['arm_in']
    # The I fixes its junction's flow, so that junction receives the effort from the lever.
    assert setter == ('lever' if mass_on_input_side else 'input')
    t, y = _simulate(model, np.zeros(0), 3.0)
    out = model.outputs(t, y)
    x_in = _msd_step(t, m, d * n**2, k * n**2, force)
    q = y[model.state_index['k.q']]
    np.testing.assert_allclose(q, n * x_in, atol=1e-9)
    np.testing.assert_allclose(out['v_out'], n * out['v_in'], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(out['f_in'], n * out['f_out'], rtol=1e-12, atol=1e-12)
    assert q[-1] == pytest.approx(force * a / (b * k), rel=1e-3)
