"""The assembled bond graph: statics, power balance, passivity, shared conventions."""

from __future__ import annotations

import math
from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from vd_common.vehicle.params import load_vehicle
from vd_sim_node.vehicle.model import WHEELS, Geometry, VehicleModel

CONFIG = Path(__file__).resolve().parents[2] / 'vd_common' / 'config' / 'clio_rl_1_1.yaml'
VP = load_vehicle(CONFIG)


@lru_cache(maxsize=1)
def model() -> VehicleModel:
    return VehicleModel(VP)


def test_geometry_recovers_whole_vehicle_cg() -> None:
    geo = Geometry.of(VP)
    L = VP.chassis.wheelbase
    assert geo.m_s + geo.m_uf + geo.m_ur == pytest.approx(geo.m)
    # moment of the parts about the front axle = whole mass at the published CG
    assert geo.m_s * geo.a_s + geo.m_ur * L == pytest.approx(geo.m * VP.chassis.cg_to_front_axle)


@pytest.mark.parametrize('slope_deg', [0.0, 10.0])
def test_static_axle_loads_match_geometry_and_state_is_at_rest(slope_deg: float) -> None:
    m = model()
    alpha = slope_deg * math.pi / 180.0
    x = m.static_state(alpha, 0.0)
    c = m.compiled
    u = m.input_vector(0.0, 0.0, alpha, 1.0, 10.0, 0.0)
    out = c.outputs(0.0, x, u)
    g = VP.environment.gravity
    L, a = VP.chassis.wheelbase, VP.chassis.cg_to_front_axle
    weight_normal = VP.chassis.mass * g * math.cos(alpha)
    assert float(out['fz_wheel_front']) == pytest.approx(
        weight_normal * (L - a) / L / 2, rel=1e-12
    )
    assert float(out['fz_wheel_rear']) == pytest.approx(weight_normal * a / L / 2, rel=1e-12)
    xdot = c.rhs(0.0, x, u)
    # every vertical/pitch momentum and deflection rate is zero: static equilibrium
    for name in (
        'mass_sprung.p',
        'pitch_inertia.p',
        'mass_unsprung_front.p',
        'mass_unsprung_rear.p',
        'spring_c_front.q',
        'tyre_c_rear.q',
    ):
        assert abs(xdot[c.state_index[name]]) < 1e-9, name
    # on the slope, without brakes, only gravity pulls the car (v = 0: no resistances)
    p_dot_x = xdot[c.state_index['mass_x.p']]
    assert p_dot_x == pytest.approx(-VP.chassis.mass * g * math.sin(alpha), abs=1e-9)


def _random_state(seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    m = model()
    x = m.static_state(rng.uniform(-0.2, 0.2), rng.uniform(80.0, 600.0))
    v = rng.uniform(-5.0, 45.0)
    x[m.idx_p_x] = VP.chassis.mass * v
    x[m.idx_p_spin] = m.inertia * (v / VP.wheel.effective_radius + rng.normal(0.0, 5.0, 4))
    x[m.compiled.state_index['mass_sprung.p']] = rng.normal(0.0, 50.0)
    x[m.compiled.state_index['pitch_inertia.p']] = rng.normal(0.0, 50.0)
    x[m.idx_angle] = rng.uniform(-100.0, 100.0, 4)
    u = m.input_vector(
        rng.uniform(0.0, 1.0),
        rng.uniform(0.0, 1.0),
        rng.uniform(-0.2, 0.2),
        rng.uniform(0.1, 1.2),
        float(rng.choice(VP.gearbox.ratios)) * VP.gearbox.final_drive,
        float(rng.integers(0, 3)),
    )
    return x, u


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31 - 1))
def test_power_balance_and_passivity(seed: int) -> None:
    m = model()
    c = m.compiled
    x, u = _random_state(seed)
    out = c.outputs(0.0, x, u)
    scale = abs(float(out['P.sources'])) + abs(float(out['P.dissipated'])) + 1.0
    assert float(out['P.stored']) == pytest.approx(
        float(out['P.sources']) - float(out['P.dissipated']), abs=1e-9 * scale
    )
    # every friction/damping R element dissipates
    resistors = [b for b in c.output_names if b.endswith('.e') and '->' in b]
    checked = 0
    for bond in resistors:
        head = bond[:-2].split('->')[1]
        if head.startswith(('brake_', 'clutch_', 'engine_drag', 'aero', 'spring_r_', 'tyre_r_')):
            power = float(out[bond]) * float(out[bond[:-2] + '.f'])
            assert power >= -1e-9, bond
            checked += 1
    assert checked == 11
    # tyres and rolling resistance oppose the motion relative to the body (their laws are
    # modulated by the body speed v, the hubs move with the body)
    v = float(out['v_body'])
    R = VP.wheel.effective_radius
    for n in WHEELS:
        slip_velocity = float(out[f'wheel_{n}->spin_{n}.f']) * R - v
        assert float(out[f'contact_{n}->tyre_{n}.e']) * slip_velocity >= 0.0
    for axle in ('front', 'rear'):
        assert float(out[f'ground->rolling_{axle}.e']) * v >= 0.0


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31 - 1))
def test_shared_conventions_hold_at_any_state(seed: int) -> None:
    m = model()
    c = m.compiled
    x, u = _random_state(seed)
    out = c.outputs(0.0, x, u)
    xdot = c.rhs(0.0, x, u)
    R = VP.wheel.effective_radius
    g = VP.environment.gravity
    fx = np.array([float(out[f'contact_{n}->tyre_{n}.e']) for n in WHEELS])
    brake = np.array([float(out[f'wheel_{n}->brake_{n}.e']) for n in WHEELS])
    drive = np.zeros(4)
    drive[:2] = [-float(out['drive_FL.e']), -float(out['drive_FR.e'])]
    omega_dot = xdot[m.idx_p_spin] / m.inertia
    # J omega_dot = T - R Fx, T = drive - brake
    np.testing.assert_allclose(m.inertia * omega_dot, drive - brake - R * fx, atol=1e-9)
    # m v_dot = sum Fx - sum F_r - F_aero - m g sin(alpha)
    rolling = float(out['ground->rolling_front.e']) + float(out['ground->rolling_rear.e'])
    rhs = fx.sum() - rolling - float(out['x->aero.e']) - VP.chassis.mass * g * math.sin(u[2])
    assert xdot[m.idx_p_x] == pytest.approx(rhs, abs=1e-9 * (1 + abs(rhs)))
    # open differential: equal drive torque on both front wheels
    assert drive[0] == drive[1]
    # the wheel-angle states integrate the wheel speeds
    np.testing.assert_allclose(xdot[m.idx_angle], x[m.idx_p_spin] / m.inertia, rtol=1e-15)
