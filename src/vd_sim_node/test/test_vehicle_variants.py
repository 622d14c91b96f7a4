"""The TRUE-vehicle variants: loaded car, scaled tyre radius, torque-signal offset."""

from __future__ import annotations

import dataclasses
import math
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from vd_common.errors import ParameterError
from vd_common.vehicle.params import VehicleParams, load_vehicle
from vd_sim_node.errors import ScenarioError, SimulationError
from vd_sim_node.vehicle.model import Geometry, VehicleModel
from vd_sim_node.vehicle.scenario import VehicleVariant, parse_scenario
from vd_sim_node.vehicle.simulation import SimResult, Simulator, simulate, with_torque_offset
from vd_sim_node.vehicle.variants import (
    DEFAULT_LOAD_POSITION,
    apply_variant,
    load_position_for_cg_shift,
    loaded,
    tyre_radius_scale,
)

ROOT = Path(__file__).resolve().parents[1]
VP = load_vehicle(ROOT.parent / 'vd_common' / 'config' / 'clio_rl_1_1.yaml')
G = VP.environment.gravity


def _sprung_moment_about_front_axle(vp: VehicleParams) -> tuple[float, float]:
    """(sprung mass [kg], its first moment about the front axle [kg m])."""
    geo = Geometry.of(vp)
    return geo.m_s, geo.m_s * geo.a_s


def test_loaded_adds_the_mass_and_moves_the_cg_to_the_weighted_mean() -> None:
    heavy = loaded(VP, 400.0)
    c, c0 = heavy.chassis, VP.chassis
    assert c.mass == pytest.approx(c0.mass + 400.0, rel=1e-12)
    expected_a = (c0.mass * c0.cg_to_front_axle + 400.0 * DEFAULT_LOAD_POSITION) / c.mass
    assert c.cg_to_front_axle == pytest.approx(expected_a, rel=1e-12)
    assert c.cg_to_front_axle > c0.cg_to_front_axle  # the load sits behind the CG
    assert c.cg_height == pytest.approx(c0.cg_height, rel=1e-12)  # load at CG height
    # The unsprung corners, the wheelbase and everything else are untouched.
    restored = dataclasses.replace(
        c, mass=c0.mass, cg_to_front_axle=c0.cg_to_front_axle, pitch_inertia=c0.pitch_inertia
    )
    assert restored == c0
    assert heavy.wheel == VP.wheel and heavy.tire == VP.tire
    assert '+400 kg' in heavy.name


def test_the_load_belongs_to_the_sprung_mass() -> None:
    heavy = loaded(VP, 125.0, load_position_m=1.9)
    m_s0, moment0 = _sprung_moment_about_front_axle(VP)
    m_s1, moment1 = _sprung_moment_about_front_axle(heavy)
    assert m_s1 == pytest.approx(m_s0 + 125.0, rel=1e-12)
    assert moment1 == pytest.approx(moment0 + 125.0 * 1.9, rel=1e-12)


def test_cg_shift_places_the_load_where_it_moves_the_cg_by_that_much() -> None:
    for dm, shift in ((400.0, 0.2), (125.0, 0.05), (-50.0, 0.01)):
        v = loaded(VP, dm, cg_shift_m=shift)
        assert v.chassis.cg_to_front_axle == pytest.approx(
            VP.chassis.cg_to_front_axle + shift, abs=1e-12
        )
        x = load_position_for_cg_shift(VP, dm, shift)
        assert loaded(VP, dm, load_position_m=x) == v


def test_pitch_inertia_follows_the_parallel_axis_theorem() -> None:
    # Sprung CG height with the unsprung masses at the wheel centre (the function's rule).
    geo = Geometry.of(VP)
    c = VP.chassis
    z_s = (c.mass * c.cg_height - (geo.m_uf + geo.m_ur) * VP.wheel.unloaded_radius) / geo.m_s
    # A load placed exactly at the sprung CG adds nothing to the inertia about that
    # (unchanged) CG.
    same = loaded(VP, 80.0, load_position_m=geo.a_s, load_height_m=z_s)
    assert same.chassis.pitch_inertia == pytest.approx(c.pitch_inertia, rel=1e-12)
    # Behind it, at its height, the inertia grows by m_s d_s^2 + dm d_l^2 about the new
    # sprung CG.
    dm, x = 200.0, 2.5
    far = loaded(VP, dm, load_position_m=x, load_height_m=z_s)
    a_s_new = (geo.m_s * geo.a_s + dm * x) / (geo.m_s + dm)
    expected = c.pitch_inertia + geo.m_s * (geo.a_s - a_s_new) ** 2
    expected += dm * (x - a_s_new) ** 2
    assert far.chassis.pitch_inertia == pytest.approx(expected, rel=1e-12)
    assert Geometry.of(far).a_s == pytest.approx(a_s_new, rel=1e-12)


@settings(max_examples=60, deadline=None)
@given(
    dm=st.floats(-150.0, 600.0).filter(lambda x: abs(x) > 1e-3),
    x=st.floats(0.2, 2.3),
    z=st.floats(0.2, 1.0),
)
def test_adding_then_removing_the_same_load_gives_the_nominal_car_back(
    dm: float, x: float, z: float
) -> None:
    there = loaded(VP, dm, load_position_m=x, load_height_m=z)
    back = loaded(there, -dm, load_position_m=x, load_height_m=z)
    c, c0 = back.chassis, VP.chassis
    assert c.mass == pytest.approx(c0.mass, rel=1e-12)
    assert c.cg_to_front_axle == pytest.approx(c0.cg_to_front_axle, rel=1e-9)
    assert c.cg_height == pytest.approx(c0.cg_height, rel=1e-9)
    assert c.pitch_inertia == pytest.approx(c0.pitch_inertia, rel=1e-9)
    assert there.chassis.pitch_inertia > 0.0


def test_static_axle_loads_of_the_model_follow_the_new_mass_and_cg() -> None:
    for dm in (-50.0, 125.0, 400.0):
        vp = loaded(VP, dm)
        model = VehicleModel(vp)
        x0 = model.static_state(0.0, 0.0)
        names = model.compiled.state_names
        kt2 = 2.0 * vp.wheel.tyre_vertical_stiffness
        front = -x0[names.index('tyre_c_front.q')] * kt2
        rear = -x0[names.index('tyre_c_rear.q')] * kt2
        c = vp.chassis
        assert front + rear == pytest.approx(c.mass * G, rel=1e-12)
        b = c.wheelbase - c.cg_to_front_axle
        assert front == pytest.approx(c.mass * G * b / c.wheelbase, rel=1e-12)


@lru_cache(maxsize=1)
def _loaded_run() -> tuple[VehicleParams, SimResult]:
    vp = loaded(VP, 400.0)
    scenario = parse_scenario(
        {
            'duration': 6.0,
            'signals': {
                'throttle': [[0, 1.0], [4.0, 0.0]],
                'brake': [[0, 0.0], [4.0, 0.5]],
                'slope_deg': [[0, 3.0]],
            },
            'hold_brake': False,
        }
    )
    return vp, simulate(vp, scenario)


def test_a_loaded_run_obeys_the_longitudinal_balance_with_the_true_mass() -> None:
    vp, r = _loaded_run()
    m = vp.chassis.mass
    resid = (
        r.fx.sum(axis=1)
        - r.rolling.sum(axis=1) * np.sign(r.speed_true)
        - r.aero
        - m * G * np.sin(r.slope)
        - m * r.accel_true
    )
    moving = np.abs(r.speed_true) > 0.5
    assert moving.sum() > 1000
    # The same balance with the NOMINAL mass misses by (dm)(a + g sin alpha): hundreds of N.
    assert np.max(np.abs(resid[moving])) < 1.0
    # Vertical: the loads carry the true weight (pitch and heave settle within the run).
    total_fz = r.fz.sum(axis=1)
    assert total_fz[0] == pytest.approx(m * G * math.cos(r.slope[0]), rel=2e-3)


def test_tyre_radius_scale_changes_only_r_eff() -> None:
    worn = tyre_radius_scale(VP, 0.97)
    assert worn.wheel.effective_radius == pytest.approx(0.97 * VP.wheel.effective_radius)
    assert worn.wheel.unloaded_radius == VP.wheel.unloaded_radius
    assert dataclasses.replace(worn, wheel=VP.wheel, name=VP.name) == VP
    big = tyre_radius_scale(VP, 1.05)  # beyond the unloaded radius: raised with it
    assert big.wheel.unloaded_radius == big.wheel.effective_radius
    with pytest.raises(ParameterError, match='tyre radius scale'):
        tyre_radius_scale(VP, float('nan'))
    with pytest.raises(ParameterError, match='tyre radius scale'):
        tyre_radius_scale(VP, 2.0)


def test_torque_offset_goes_through_the_gear_ratio_to_the_driven_wheels_only() -> None:
    vp, r = _loaded_run()
    off = with_torque_offset(r, vp, 10.0)
    np.testing.assert_array_equal(off.engine_torque, r.engine_torque + 10.0)
    np.testing.assert_array_equal(off.wheel_torque[:, 2:], r.wheel_torque[:, 2:])
    gb = vp.gearbox
    for k in np.flatnonzero(np.diff(r.gear, prepend=-1))[:5]:  # one sample per gear stretch
        gear = int(r.gear[k])
        expected = 0.0 if gear == 0 else 5.0 * gb.ratios[gear - 1] * gb.final_drive
        np.testing.assert_allclose(off.wheel_torque[k, :2] - r.wheel_torque[k, :2], expected)
    # The physics (truth) is untouched; the result is a copy.
    np.testing.assert_array_equal(off.fx, r.fx)
    assert off.wheel_torque is not r.wheel_torque
    with pytest.raises(ParameterError, match='finite'):
        with_torque_offset(r, vp, float('inf'))


@pytest.mark.parametrize(
    ('kwargs', 'match'),
    [
        ({'extra_mass_kg': -800.0}, 'no sprung mass'),
        ({'extra_mass_kg': 400.0, 'load_position_m': 9.0}, 'outside the wheelbase'),
        ({'extra_mass_kg': 400.0, 'load_height_m': -5.0}, 'not above ground'),
        ({'extra_mass_kg': 100.0, 'cg_shift_m': 0.1, 'load_position_m': 1.0}, 'not both'),
        ({'extra_mass_kg': float('nan')}, 'finite'),
        ({'extra_mass_kg': 0.0, 'cg_shift_m': 0.1}, 'non-zero'),
    ],
)
def test_loaded_refuses_a_non_physical_car(kwargs: dict[str, float], match: str) -> None:
    with pytest.raises(ParameterError, match=match):
        loaded(VP, **kwargs)


def test_no_load_is_the_nominal_car() -> None:
    assert loaded(VP, 0.0) is VP


# -- the scenario's true_vehicle section -------------------------------------------------

_SHORT = {
    'duration': 3.0,
    'signals': {'throttle': [[0, 1.0], [2.0, 0.0]], 'slope_deg': [[0, 2.0]]},
    'hold_brake': False,
}


def test_a_scenario_can_drive_a_loaded_car_with_a_lying_torque_signal() -> None:
    truth = {'extra_mass_kg': 125.0, 'cg_shift_m': 0.05, 'tyre_radius_scale': 0.98}
    scenario = parse_scenario({**_SHORT, 'true_vehicle': truth})
    assert scenario.true_vehicle == VehicleVariant(125.0, 0.05, None, None, 0.98, 0.0)
    by_hand = tyre_radius_scale(loaded(VP, 125.0, cg_shift_m=0.05), 0.98)
    assert apply_variant(VP, scenario.true_vehicle) == by_hand
    run = simulate(VP, scenario)
    reference = simulate(by_hand, parse_scenario(_SHORT))
    for name in ('speed_true', 'fx', 'fz', 'wheel_torque', 'engine_torque'):
        np.testing.assert_array_equal(getattr(run, name), getattr(reference, name), name)

    offset = parse_scenario({**_SHORT, 'true_vehicle': {'engine_torque_offset_nm': -10.0}})
    lying = simulate(VP, offset)
    honest = simulate(VP, parse_scenario(_SHORT))
    np.testing.assert_array_equal(lying.speed_true, honest.speed_true)  # physics unchanged
    expected = with_torque_offset(honest, VP, -10.0)
    np.testing.assert_allclose(lying.wheel_torque, expected.wheel_torque, rtol=0, atol=1e-9)
    np.testing.assert_allclose(lying.engine_torque, expected.engine_torque, rtol=0, atol=1e-9)
    assert np.any(lying.wheel_torque[:, 0] != honest.wheel_torque[:, 0])


def test_a_compiled_model_is_refused_for_a_variant_that_changes_the_physics() -> None:
    scenario = parse_scenario({**_SHORT, 'true_vehicle': {'extra_mass_kg': 100.0}})
    with pytest.raises(SimulationError, match='true_vehicle'):
        Simulator(VehicleModel(VP), scenario)
    # A torque offset alone keeps the compiled model usable.
    only_signal = parse_scenario({**_SHORT, 'true_vehicle': {'engine_torque_offset_nm': 5.0}})
    assert not only_signal.true_vehicle.changes_physics
    Simulator(VehicleModel(VP), only_signal)


@pytest.mark.parametrize(
    ('truth', 'match'),
    [
        ({'extra_mass_kg': 5000.0}, 'extra_mass_kg must be <= 2000'),
        ({'tyre_radius_scale': 2.0}, 'tyre_radius_scale must be < 1.5'),
        ({'extra_mass_kg': 10.0, 'cg_shift_m': 0.1, 'load_position_m': 1.0}, 'not both'),
        ({'cg_shift_m': 0.1}, 'non-zero extra_mass_kg'),
        ({'engine_torque_offset_nm': 'ten'}, 'engine_torque_offset_nm must be a number'),
    ],
)
def test_a_bad_true_vehicle_section_is_refused_by_name(truth: dict[str, Any], match: str) -> None:
    with pytest.raises(ScenarioError, match=match):
        parse_scenario({**_SHORT, 'true_vehicle': truth})
