"""The optional inertia merge turns a derivative-causality error into a well-posed model."""

from __future__ import annotations

import numpy as np
import pytest
from vd_sim_node.bondgraph import (
    BondGraph,
    DerivativeCausalityError,
    ElementDefinitionError,
    compile_model,
    merge_rigid_inertias,
)


def _geared_pair(ratio: float) -> BondGraph:
    """Engine inertia, a constant gear, and a wheel inertia with a damper: dependent storage."""
    bg = BondGraph('geared')
    bg.add_se('torque', 50.0)
    bg.add_one('engine')
    bg.add_i('J_engine', 0.2)
    bg.add_tf('gear', ratio)  # wheel speed = ratio * engine speed
    bg.add_one('wheel')
    bg.add_one('hub')
    bg.add_i('J_wheel', 1.5)
    bg.add_i('J_hub', 0.5)
    bg.add_r('loss', 0.8)
    bg.connect('torque', 'engine')
    bg.connect('engine', 'J_engine')
    bg.connect('engine', 'gear')
    bg.connect('gear', 'wheel', name='axle')
    bg.connect('wheel', 'hub')  # 1-1 bond: same flow
    bg.connect('hub', 'J_hub')
    bg.connect('J_wheel', 'wheel')  # orientation does not matter for the reflected mass
    bg.connect('wheel', 'loss')
    bg.add_flow_sensor('wheel_speed', 'axle')
    return bg


def test_merge_reflects_inertias_through_constant_transformers() -> None:
    ratio = 0.25
    bg = _geared_pair(ratio)
    with pytest.raises(DerivativeCausalityError):
        compile_model(bg)
    result = merge_rigid_inertias(bg)
    assert result.merged == {'J_engine+J_wheel+J_hub': ('J_engine', 'J_wheel', 'J_hub')}
    j_eq = 0.2 + (1.5 + 0.5) * ratio**2
    assert result.inertia['J_engine+J_wheel+J_hub'] == pytest.approx(j_eq, rel=1e-15)
    model = compile_model(result.graph)
    assert model.state_names == ('J_engine+J_wheel+J_hub.p',)
    # Engine speed w: J_eq w' = T - ratio * (loss * ratio * w).
    w = 30.0
    dx = model.rhs(0.0, np.array([j_eq * w]))
    assert dx[0] == pytest.approx(50.0 - ratio * 0.8 * ratio * w, rel=1e-13)
    out = model.outputs(0.0, np.array([j_eq * w]))
    assert out['wheel_speed'] == pytest.approx(ratio * w, rel=1e-14)
    # The original graph is untouched.
    assert 'J_wheel' in bg.elements


def test_merge_leaves_independent_inertias_alone_and_protects_sensors() -> None:
    bg = BondGraph('independent')
    bg.add_se('F', 1.0)
    bg.add_one('a')
    bg.add_i('m', 1.0)
    bg.connect('F', 'a')
    bg.connect('a', 'm')
    assert merge_rigid_inertias(bg).graph is bg
    bg2 = BondGraph('sensed')
    bg2.add_one('a')
    bg2.add_i('m1', 1.0)
    bg2.add_i('m2', 2.0)
    bg2.connect('a', 'm1', name='b1')
    bg2.connect('a', 'm2')
    bg2.add_effort_sensor('force_on_m1', 'b1')
    with pytest.raises(ElementDefinitionError, match='force_on_m1'):
        merge_rigid_inertias(bg2)
