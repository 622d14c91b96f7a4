"""The bond-graph tyre law: the same force as the Magic Formula of vd_common, scalar or array."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from vd_common.vehicle.params import default_vehicle_file, load_vehicle
from vd_common.vehicle.tire import tire_force_from_slip_velocity
from vd_sim_node.vehicle.laws import make_tire_law

TP = load_vehicle(default_vehicle_file()).tire


@settings(max_examples=200, deadline=None)
@given(
    vs=st.floats(-40.0, 40.0),
    vg=st.floats(-50.0, 50.0),
    fz=st.floats(0.0, 6000.0),
    mu=st.floats(0.05, 1.5),
)
def test_scalar_and_vector_paths_agree(vs: float, vg: float, fz: float, mu: float) -> None:
    law = make_tire_law(TP)
    # ground-point flow differs from the body speed by a pitch-rate term: slip is w.r.t. v
    vgr = vg - 0.03
    scalar = law(float(vs) + vg - vgr, float(vgr), float(vg), float(fz), float(mu))
    arrays = [np.array([x]) for x in (vs + vg - vgr, vgr, vg, fz, mu)]
    vector = float(law(*arrays)[0])
    reference = tire_force_from_slip_velocity(float(vs), float(vg), float(fz), float(mu), TP)
    assert scalar == pytest.approx(vector, rel=1e-12, abs=1e-9)
    assert scalar == pytest.approx(reference, rel=1e-12, abs=1e-9)
