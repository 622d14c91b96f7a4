#!/usr/bin/env python3
"""Benchmark the bond-graph core: generated RHS vs walking the graph on a 19-state model.

The model is vehicle-like and nonlinear: chassis longitudinal momentum, heave and pitch;
per corner an unsprung mass, a progressive suspension spring with a damper, a tyre vertical
spring, a wheel spin inertia and a modulated tyre R (force from slip velocity, chassis speed,
normal load from the tyre-spring effort sensor and a road-friction input). Prints figures
only; nothing here is asserted.

Usage: python scripts/bench_bondgraph.py [--seconds 1.0]
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'src' / 'vd_sim_node'))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'src' / 'vd_common'))

from vd_sim_node.bondgraph import (
    BondGraph,
    CompiledModel,
    GraphWalker,
    compile_model,
)

GRAVITY = 9.81
CORNERS = ('FL', 'FR', 'RL', 'RR')


def tyre_force(v_slip: float, v_x: float, fz: float, mu: float) -> float:
    """Smooth saturating tyre force [N]; operators only, so it is scalar- and numpy-safe."""
    speed = (v_x * v_x + 0.25) ** 0.5
    kappa = 8.0 * v_slip / speed
    return mu * fz * kappa / (1.0 + kappa * kappa) ** 0.5


def build_vehicle_like() -> BondGraph:
    """19-state nonlinear half-vehicle-per-corner model (see module docstring)."""
    mass, heave_mass, pitch_inertia = 905.0, 780.0, 1050.0
    lever = {'FL': 0.95, 'FR': 0.95, 'RL': -1.52, 'RR': -1.52}
    bg = BondGraph('vehicle_like')
    bg.add_input('drive_torque')
    bg.add_input('slope')
    bg.add_input('mu', default=1.0)
    bg.add_one('chassis_x')
    bg.add_i('body_x', mass)
    bg.add_r('aero', law=lambda v: 0.5 * 1.225 * 0.33 * 1.85 * v * abs(v))
    bg.add_se('grade', lambda t, a: -mass * GRAVITY * a, signals=('slope',))
    bg.connect('chassis_x', 'body_x', name='body_x_bond')
    bg.connect('chassis_x', 'aero')
    bg.connect('grade', 'chassis_x')
    bg.add_flow_sensor('v_x', 'body_x_bond')
    bg.add_one('heave')
    bg.add_i('body_z', heave_mass)
    bg.add_se('g_body', -heave_mass * GRAVITY)
    bg.connect('heave', 'body_z')
    bg.connect('g_body', 'heave')
    bg.add_one('pitch')
    bg.add_i('body_pitch', pitch_inertia)
    bg.connect('pitch', 'body_pitch')
    for corner in CORNERS:
        front = corner[0] == 'F'
        wheel, node, susp, tyre = (f'{s}_{corner}' for s in ('wheel', 'node', 'susp', 'tyre'))
        # Vertical: unsprung mass on its own 1-junction, tyre spring from the road.
        bg.add_one(wheel)
        bg.add_i(f'unsprung_{corner}', 32.0 if front else 25.0)
        bg.add_se(f'g_{corner}', -(32.0 if front else 25.0) * GRAVITY)
        bg.connect(wheel, f'unsprung_{corner}')
        bg.connect(f'g_{corner}', wheel)
        bg.add_sf(f'road_{corner}', 0.0)
        bg.add_zero(tyre)
        bg.add_c(
            f'kt_{corner}',
            law=lambda q: 160000.0 * q + 4e6 * q**3,
            energy=lambda q: 80000.0 * q * q + 1e6 * q**4,
        )
        bg.connect(f'road_{corner}', tyre)
        bg.connect(tyre, f'kt_{corner}', name=f'kt_bond_{corner}')
        bg.connect(tyre, wheel)
        bg.add_effort_sensor(f'Fz_{corner}', f'kt_bond_{corner}')
        # Suspension: relative velocity wheel - (heave + lever * pitch rate).
        bg.add_zero(node)
        bg.add_one(susp)
        k = 19000.0 if front else 17000.0
        bg.add_c(
            f'ks_{corner}',
            law=lambda q, k=k: k * q + 50.0 * k * q**3,
            energy=lambda q, k=k: 0.5 * k * q * q + 12.5 * k * q**4,
        )
        bg.add_r(f'cs_{corner}', law=lambda v: 1500.0 * v + 300.0 * v * abs(v))
        bg.connect(wheel, node)
        bg.connect(node, susp)
        bg.connect(susp, f'ks_{corner}')
        bg.connect(susp, f'cs_{corner}')
        bg.connect(node, 'heave')
        bg.add_tf(f'lever_{corner}', 1.0 / lever[corner])
        bg.connect(node, f'lever_{corner}')
        bg.connect(f'lever_{corner}', 'pitch')
        # Longitudinal: wheel spin, radius TF, contact 0-junction, modulated tyre R.
        spin, contact = f'spin_{corner}', f'contact_{corner}'
        bg.add_one(spin)
        bg.add_i(f'Iw_{corner}', 0.75 if front else 0.6)
        bg.connect(spin, f'Iw_{corner}')
        if front:
            bg.add_se(f'drive_{corner}', lambda t, tq: 0.5 * tq, signals=('drive_torque',))
            bg.connect(f'drive_{corner}', spin)
        bg.add_tf(f'radius_{corner}', 0.26)
        bg.add_zero(contact)
        bg.add_r(f'tyre_x_{corner}', law=tyre_force, signals=('v_x', f'Fz_{corner}', 'mu'))
        bg.connect(spin, f'radius_{corner}')
        bg.connect(f'radius_{corner}', contact)
        bg.connect(contact, f'tyre_x_{corner}')
        bg.connect(contact, 'chassis_x')
    return bg


def calls_per_second(fn: Callable[[], object], seconds: float) -> float:
    """Repeat ``fn`` for about ``seconds`` and return calls per second (best of 3)."""
    best = 0.0
    for _ in range(3):
        count, start = 0, time.perf_counter()
        while True:
            for _ in range(200):
                fn()
            count += 200
            elapsed = time.perf_counter() - start
            if elapsed >= seconds / 3:
                break
        best = max(best, count / elapsed)
    return best


def rk4_real_time_factor(
    model: CompiledModel, x0: np.ndarray, u: np.ndarray, dt: float, sim_seconds: float
) -> float:
    """Simulated seconds per wall second of a fixed-step RK4 loop calling model.rhs."""
    rhs = model.rhs
    x = x0.copy()
    steps = int(sim_seconds / dt)
    start = time.perf_counter()
    t = 0.0
    for _ in range(steps):
        k1 = rhs(t, x, u)
        k2 = rhs(t + 0.5 * dt, x + 0.5 * dt * k1, u)
        k3 = rhs(t + 0.5 * dt, x + 0.5 * dt * k2, u)
        k4 = rhs(t + dt, x + dt * k3, u)
        x = x + dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        t += dt
    return sim_seconds / (time.perf_counter() - start)


def print_accuracy(model: CompiledModel, u: np.ndarray) -> None:
    """Power-balance residual of the 19-state model and MSD error vs its closed form."""
    from scipy.integrate import solve_ivp

    rng = np.random.default_rng(1)
    worst = 0.0
    for _ in range(200):
        x = rng.normal(size=model.n_states) * 0.05
        p_src = model.source_power(0.0, x, u)
        p_diss = model.dissipated_power(0.0, x, u)
        p_store = model.storage_power(0.0, x, u)
        scale = abs(p_src) + abs(p_diss) + abs(p_store)
        worst = max(worst, abs(p_store - (p_src - p_diss)) / scale)
    print(f'power balance |dE/dt - (P_src - P_diss)| / scale, worst of 200 states: {worst:.1e}')

    m, d, k, force = 2.0, 3.0, 50.0, 10.0
    bg = BondGraph('msd')
    bg.add_se('F', force)
    bg.add_one('v')
    bg.add_i('m', m)
    bg.add_c('k', 1.0 / k)
    bg.add_r('d', d)
    for element in ('m', 'k', 'd'):
        bg.connect('v', element)
    bg.connect('F', 'v')
    msd = compile_model(bg)
    t = np.linspace(0.0, 5.0, 501)
    sol = solve_ivp(
        msd.rhs, (0.0, 5.0), msd.initial_state(), method='DOP853', rtol=1e-12, atol=1e-14, t_eval=t
    )
    wn, zeta = np.sqrt(k / m), d / (2.0 * np.sqrt(k * m))
    wd = wn * np.sqrt(1.0 - zeta**2)
    exact = (
        force
        / k
        * (
            1.0
            - np.exp(-zeta * wn * t)
            * (np.cos(wd * t) + zeta / np.sqrt(1.0 - zeta**2) * np.sin(wd * t))
        )
    )
    error = np.max(np.abs(sol.y[1] - exact)) / (force / k)
    print(
        f'mass-spring-damper step vs closed form (DOP853, rtol 1e-12): max error '
        f'{error:.1e} of the static deflection, {sol.nfev} RHS calls'
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--seconds', type=float, default=1.0, help='time per measurement')
    args = parser.parse_args()

    start = time.perf_counter()
    bg = build_vehicle_like()
    model = compile_model(bg)
    compile_ms = 1e3 * (time.perf_counter() - start)
    walker = GraphWalker(bg, model.causality)
    rng = np.random.default_rng(0)
    x = rng.normal(size=model.n_states) * 0.1
    u = model.input_vector({'drive_torque': 300.0, 'slope': 0.02, 'mu': 0.9})
    assert np.allclose(model.rhs(0.0, x, u), walker.rhs(0.0, x, u), rtol=1e-12, atol=1e-9)

    generated = calls_per_second(lambda: model.rhs(0.0, x, u), args.seconds)
    walked = calls_per_second(lambda: walker.rhs(0.0, x, u), args.seconds)
    outputs = calls_per_second(lambda: model.output_vector(0.0, x, u), args.seconds)
    n_batch = 10_000
    X = rng.normal(size=(model.n_states, n_batch)) * 0.1
    t0 = time.perf_counter()
    model.output_vector(np.zeros(n_batch), X, u)
    batch_rate = n_batch / (time.perf_counter() - t0)
    t0 = time.perf_counter()
    model.rhs_batch(0.0, X, u)
    rhs_batch_rate = n_batch / (time.perf_counter() - t0)

    print(
        f'model: {model.n_states} states, {len(bg.bonds)} bonds, {model.n_outputs} outputs, '
        f'{len(model.source_code.splitlines())} generated lines, compiled in {compile_ms:.1f} ms'
    )
    print(f'generated rhs      : {generated:12,.0f} calls/s  ({1e6 / generated:6.2f} us/call)')
    print(f'graph-walking rhs  : {walked:12,.0f} calls/s  ({1e6 / walked:6.2f} us/call)')
    print(f'code-generation gain: {generated / walked:.1f}x')
    print(f'all outputs (scalar): {outputs:12,.0f} calls/s')
    print(f'outputs, batch of {n_batch}: {batch_rate:12,.0f} samples/s')
    print(f'rhs_batch of {n_batch}:      {rhs_batch_rate:12,.0f} samples/s')
    print_accuracy(model, u)
    for dt in (1e-3, 5e-4):
        rtf = rk4_real_time_factor(model, model.initial_state(), u, dt, 5.0)
        print(
            f'fixed-step RK4, dt = {dt * 1e3:.1f} ms: {rtf:7.1f}x real time '
            f'(rhs alone would allow {generated * dt / 4:7.1f}x)'
        )


if __name__ == '__main__':
    main()
