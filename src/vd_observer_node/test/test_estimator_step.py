"""The estimator's steps: the low-pass and mass steps on their records equal their wrappers
(filterpy style; the mass step also run as plain Python, ``.py_func``, as ``VD_JIT=0`` runs
it), and the whole estimator against the paper's closed forms on a steady climb."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
from adaptation_setup import VEHICLE, model_drive
from vd_observer_node.estimation.estimator import (
    Estimator,
)
from vd_observer_node.estimation.filters import (
    LOWPASS_META,
    LowPass,
    lowpass_derivative,
    lowpass_update,
)
from vd_observer_node.estimation.mass_grade import (
    MassGradeConfig,
    MassGradeEstimator,
    mass_params,
)
from vd_observer_node.estimation.mass_grade_step import MASS_STATE, mass_reset, mass_update
from vd_observer_node.kernel._jit import new_record

M0 = VEHICLE.mass


def _py(fn: Any) -> Any:
    """The plain-Python function of a compiled one (itself where nothing is compiled)."""
    return getattr(fn, 'py_func', fn)


def test_lowpass_step_on_arrays_equals_the_wrapper() -> None:
    rng = np.random.default_rng(1)
    lp = LowPass(0.05, order=3)
    stages, prev, meta = np.zeros((3, 2)), np.zeros((2, 2)), new_record(LOWPASS_META)
    out, rate = np.empty(2), np.empty(2)
    for k in range(200):
        dt = 0.001 + 0.004 * rng.random()
        x = rng.normal(size=2)
        lowpass_update(0.05, stages, prev, meta, dt, x, out)
        np.testing.assert_array_equal(lp.update(dt, x), out)
        lowpass_derivative(stages, prev, meta, rate)
        np.testing.assert_array_equal(lp.derivative(), rate if k else np.zeros(2))


def test_mass_step_on_records_equals_the_wrapper_compiled_and_not() -> None:
    t, fx, v, _ = model_drive(M0 + 200.0, duration=20.0)
    # 1 sigma within 2 %: converges within this 20 s drive (the convergence path is run)
    wrapper = MassGradeEstimator(VEHICLE, MassGradeConfig(converged_std_ratio=0.02))
    p = mass_params(VEHICLE, wrapper.config)
    compiled, plain = new_record(MASS_STATE), new_record(MASS_STATE)
    mass_reset(p, compiled)
    _py(mass_reset)(p, plain)
    for k in range(t.size):
        args = (float(t[k]), float(fx[k]), float(v[k]))
        out = wrapper.update(*args)
        mass_update(p, compiled, *args)
        _py(mass_update)(p, plain, *args)
        assert compiled.out.mass == plain.out.mass == out.mass, k
        assert compiled.out.slope == plain.out.slope == out.slope, k
    assert out.converged and abs(out.mass / (M0 + 200.0) - 1.0) < 0.02
    np.testing.assert_array_equal(compiled.counts, plain.counts)


@pytest.mark.parametrize(('sprung', 'stamps', 'rtol'), [(False, 4000, 1e-12), (True, 15000, 1e-9)])
def test_estimator_on_a_steady_climb_gives_the_closed_forms(
    sprung: bool, stamps: int, rtol: float
) -> None:
    """Oracle: the paper's equations written out here for a car climbing a 2 deg grade at a
    steady 20 m/s (omega = v / R, omega_dot = 0, dv/dt = 0), each wheel driving with the torque
    that holds the speed: Fx = T / R, the whole weight's normal part m g cos(alpha) on the
    wheels with the moment balance's transfer, mu = Fx / Fz, rolling c Fz, drag 1/2 rho Cx A v^2,
    and the slope alpha once the low-passes have settled. A rigid car after 4 s; a car on its
    springs (`axle_loads`) once its chassis has settled from the slope's start-up, 15 s."""
    veh = VEHICLE if sprung else VEHICLE.with_vertical(None)
    assert (veh.vertical is not None) == sprung
    alpha, v, radius = math.radians(2.0), 20.0, VEHICLE.effective_radius
    c_roll = veh.rolling_c0 * (1.0 + veh.rolling_c1 * v / 160.0)  # paper eq. 7 as vd takes it
    weight = veh.mass * veh.gravity
    drag = 0.5 * veh.air_density * veh.drag_coefficient * veh.frontal_area * v * v
    rolling_total = c_roll * weight * math.cos(alpha)
    fx_total = drag + rolling_total + weight * math.sin(alpha)
    torque = np.full(4, fx_total / 4.0 * radius)
    estimator = Estimator(veh)
    for k in range(stamps):  # at 1 kHz: many times the slope filter's settling time
        out = estimator.update(k * 1e-3, np.full(4, v / radius), np.zeros(4), v, 0.0, torque)
    np.testing.assert_allclose(out.fx, fx_total / 4.0, rtol=1e-12)
    ground = fx_total - rolling_total  # the moment balance's G: sum(Fx) net of rolling
    front = 0.5 * (weight * math.cos(alpha) * veh.cg_to_rear_axle - ground * veh.cg_height)
    rear = 0.5 * (weight * math.cos(alpha) * veh.cg_to_front_axle + ground * veh.cg_height)
    fz = np.array([front, front, rear, rear]) / veh.wheelbase
    # measured: the settled filters reproduce every closed form to the last bits (< 1e-15)
    np.testing.assert_allclose(out.fz, fz, rtol=rtol)
    np.testing.assert_allclose(out.mu, out.fx / out.fz, rtol=1e-12)
    np.testing.assert_allclose(out.aero, drag, rtol=1e-12)
    np.testing.assert_allclose(out.rolling.sum(), rolling_total, rtol=1e-12)
    assert out.slope_valid
    assert out.slope == pytest.approx(alpha, abs=1e-12)  # measured: 6e-16 rad
