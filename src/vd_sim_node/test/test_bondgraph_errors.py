"""Each structural or causal problem raises its own error naming the elements and bonds."""

from __future__ import annotations

import numpy as np
import pytest
from vd_sim_node.bondgraph import (
    AlgebraicLoopError,
    BondGraph,
    BondGraphError,
    CausalConflictError,
    DerivativeCausalityError,
    DuplicateNameError,
    ElementDefinitionError,
    InvalidConnectionError,
    MissingLawError,
    ShapeError,
    UnconnectedPortError,
    UnknownNameError,
    assign_causality,
    compile_model,
)


def test_two_effort_sources_on_one_zero_junction_conflict() -> None:
    bg = BondGraph('two_se')
    bg.add_se('battery_a', 12.0)
    bg.add_se('battery_b', 9.0)
    bg.add_zero('node')
    bg.add_r('load', 10.0)
    bg.connect('battery_a', 'node', name='wire_a')
    bg.connect('battery_b', 'node', name='wire_b')
    bg.connect('node', 'load')
    with pytest.raises(CausalConflictError) as info:
        assign_causality(bg)
    message = str(info.value)
    for name in ('node', 'battery_a', 'battery_b', 'wire_a', 'wire_b'):
        assert name in message
    assert {'battery_a', 'battery_b'} <= set(info.value.elements)
    assert {'wire_a', 'wire_b'} <= set(info.value.bonds)


def test_two_flow_sources_on_one_one_junction_conflict() -> None:
    bg = BondGraph('two_sf')
    bg.add_sf('pump_a', 1.0)
    bg.add_sf('pump_b', 2.0)
    bg.add_one('pipe')
    bg.add_r('valve', 3.0)
    bg.connect('pump_a', 'pipe')
    bg.connect('pump_b', 'pipe')
    bg.connect('pipe', 'valve')
    with pytest.raises(CausalConflictError) as info:
        assign_causality(bg)
    assert 'pipe' in str(info.value)
    assert {'pump_a', 'pump_b'} <= set(info.value.elements)


def test_source_forced_against_its_nature_is_a_conflict() -> None:
    """Sf -> TF -> Sf: the TF passes the imposed flow on to a flow source."""
    bg = BondGraph('sf_tf_sf')
    bg.add_sf('drive', 1.0)
    bg.add_tf('gear', 3.0)
    bg.add_sf('load', 2.0)
    bg.connect('drive', 'gear')
    bg.connect('gear', 'load', name='gear_out')
    with pytest.raises(CausalConflictError) as info:
        assign_causality(bg)
    assert 'gear_out' in str(info.value)


def test_two_rigidly_coupled_masses_need_derivative_causality() -> None:
    bg = BondGraph('rigid')
    bg.add_se('push', 1.0)
    bg.add_one('common_v')
    bg.add_i('front_mass', 1.0)
    bg.add_i('rear_mass', 2.0)
    bg.connect('push', 'common_v')
    bg.connect('common_v', 'front_mass')
    bg.connect('common_v', 'rear_mass', name='rear_bond')
    with pytest.raises(DerivativeCausalityError) as info:
        assign_causality(bg)
    error = info.value
    assert error.element == 'rear_mass'
    assert error.bond == 'rear_bond'
    assert error.forced_by == 'front_mass'
    assert 'rear_mass' in str(error) and 'rear_bond' in str(error) and 'front_mass' in str(error)


def test_flow_source_driving_a_capacitor_through_zero_junction_is_derivative() -> None:
    """Sf on a 0-junction with a C and nothing else is fine; Se on it makes C derivative."""
    bg = BondGraph('se_c')
    bg.add_se('supply', 5.0)
    bg.add_zero('rail')
    bg.add_c('cap', 1e-3)
    bg.connect('supply', 'rail')
    bg.connect('rail', 'cap')
    with pytest.raises(DerivativeCausalityError) as info:
        assign_causality(bg)
    assert info.value.element == 'cap'
    assert info.value.forced_by == 'supply'


def test_two_resistors_in_series_without_storage_form_an_algebraic_loop() -> None:
    bg = BondGraph('divider')
    bg.add_se('E', 10.0)
    bg.add_one('series')
    bg.add_r('R1', law=lambda f: 2.0 * f + f**3)
    bg.add_r('R2', law=lambda f: 5.0 * f, conductance_law=lambda e: e / 5.0)
    bg.connect('E', 'series')
    bg.connect('series', 'R1', name='b_R1')
    bg.connect('series', 'R2', name='b_R2')
    causality = assign_causality(bg)  # SCAP itself succeeds ...
    assert causality.r_modes == {'R1': 'resistance', 'R2': 'conductance'}
    with pytest.raises(AlgebraicLoopError) as info:  # ... the equations cannot be ordered.
        compile_model(bg, causality)
    assert {'R1', 'R2', 'series'} <= set(info.value.elements)
    assert {'b_R1', 'b_R2'} <= set(info.value.bonds)
    assert 'R1' in str(info.value) and 'b_R2' in str(info.value)


def test_signal_feedback_without_storage_is_an_algebraic_loop() -> None:
    """A modulated source reading the flow it causes through an R closes a loop."""
    bg = BondGraph('feedback')
    bg.add_se('E', lambda t, f: 1.0 - f, signals=('current',))
    bg.add_one('loop')
    bg.add_r('R', 2.0)
    bg.add_c('C', 1.0)
    bg.connect('E', 'loop')
    bg.connect('loop', 'C')
    bg.connect('loop', 'R', name='r_bond')
    bg.add_flow_sensor('current', 'r_bond')
    with pytest.raises(AlgebraicLoopError) as info:
        compile_model(bg)
    assert 'current' in str(info.value)


def test_resistor_forced_into_conductance_without_that_law() -> None:
    bg = BondGraph('missing_law')
    bg.add_se('V', 1.0)
    bg.add_zero('rail')
    bg.add_r('diode', law=lambda f: 0.1 * np.sinh(f))
    bg.connect('V', 'rail')
    bg.connect('rail', 'diode', name='diode_bond')
    with pytest.raises(MissingLawError) as info:
        assign_causality(bg)
    assert 'diode' in str(info.value) and 'conductance' in str(info.value)


def test_stored_energy_of_nonlinear_storage_needs_energy_callable() -> None:
    bg = BondGraph('no_energy')
    bg.add_c('spring', law=lambda q: q + q**3)
    bg.add_r('damper', 1.0)
    bg.add_one('j')
    bg.connect('j', 'spring')
    bg.connect('j', 'damper')
    model = compile_model(bg)
    with pytest.raises(MissingLawError, match='spring'):
        model.stored_energy(np.ones(1))


def test_unconnected_element_and_half_connected_transformer() -> None:
    bg = BondGraph('loose')
    bg.add_se('F', 1.0)
    bg.add_i('m', 1.0)
    bg.add_c('lonely', 1.0)
    bg.connect('F', 'm')
    with pytest.raises(UnconnectedPortError, match='lonely'):
        assign_causality(bg)
    bg2 = BondGraph('half_tf')
    bg2.add_se('F', 1.0)
    bg2.add_tf('lever', 2.0)
    bg2.connect('F', 'lever')
    with pytest.raises(UnconnectedPortError, match='lever'):
        assign_causality(bg2)


def test_invalid_connections() -> None:
    bg = BondGraph('bad')
    bg.add_se('F', 1.0)
    bg.add_i('m', 1.0)
    bg.add_i('m2', 1.0)
    bg.add_tf('lever', 2.0)
    bg.add_c('k', 1.0)
    bg.connect('m2', 'k')
    bg.connect('F', 'lever')
    bg.connect('m', 'lever')  # both bonds point into the TF
    with pytest.raises(InvalidConnectionError, match='lever'):
        assign_causality(bg)
    with pytest.raises(InvalidConnectionError, match='k'):
        bg.connect('F', 'k')  # F is a 1-port that already has its bond
    with pytest.raises(InvalidConnectionError):
        bg.connect('k', 'k')


def test_building_mistakes() -> None:
    bg = BondGraph('names')
    bg.add_i('m', 1.0)
    with pytest.raises(DuplicateNameError, match='m'):
        bg.add_c('m', 1.0)
    with pytest.raises(UnknownNameError, match='nowhere'):
        bg.connect('m', 'nowhere')
    with pytest.raises(UnknownNameError, match='no_bond'):
        bg.add_flow_sensor('v', 'no_bond')
    with pytest.raises(ElementDefinitionError):
        bg.add_i('both', 1.0, law=lambda p: p)
    with pytest.raises(ElementDefinitionError):
        bg.add_c('neither')
    with pytest.raises(ElementDefinitionError):
        bg.add_one('two\nlines')  # names end up in generated-code comments
    with pytest.raises(ElementDefinitionError):
        bg.add_se('const_with_signals', 1.0, signals=('u',))
    bg.add_one('j')
    bg.add_r('tyre', law=lambda f, mu: mu * f, signals=('mu_undeclared',))
    bg.connect('j', 'm')
    bg.connect('j', 'tyre')
    with pytest.raises(UnknownNameError, match='mu_undeclared'):
        compile_model(bg)


def test_every_error_is_a_bond_graph_error() -> None:
    for error in (
        AlgebraicLoopError,
        CausalConflictError,
        DerivativeCausalityError,
        DuplicateNameError,
        ElementDefinitionError,
        InvalidConnectionError,
        MissingLawError,
        ShapeError,
        UnconnectedPortError,
        UnknownNameError,
    ):
        assert issubclass(error, BondGraphError)
