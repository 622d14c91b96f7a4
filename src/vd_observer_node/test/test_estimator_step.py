"""The estimator's compiled step functions driven directly on their records equal the stateful
wrappers on the same inputs (filterpy style), and the mass step run as plain Python
(``.py_func``, as ``VD_JIT=0`` runs it; its callees stay compiled) equals the compiled one."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
from adaptation_setup import VEHICLE, model_drive
from vd_observer_node.estimation.estimator import (
    Estimator,
    EstimatorConfig,
    EstimatorState,
    estimates_from_record,
    estimator_params,
)
from vd_observer_node.estimation.estimator_step import ESTIMATES, estimator_update
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


def test_estimator_step_on_records_equals_the_wrapper() -> None:
    config = EstimatorConfig(mass_adaptation=True, radius_adaptation=True)
    t, fx, v, _ = model_drive(M0, duration=5.0)
    accel = np.gradient(v, t)
    radius = VEHICLE.effective_radius
    omega = np.repeat((v / radius)[:, None], 4, axis=1)
    omega_dot = np.repeat((accel / radius)[:, None], 4, axis=1)
    torque = np.repeat((fx / 4.0 * radius)[:, None], 4, axis=1)
    wrapper = Estimator(VEHICLE, config)
    p = estimator_params(VEHICLE, config)
    state = EstimatorState(p, config.filter_order)
    est = new_record(ESTIMATES)
    for k in range(t.size):
        args = (float(t[k]), omega[k], omega_dot[k], float(v[k]), float(accel[k]), torque[k])
        out = wrapper.update(*args)
        estimator_update(p, *state.args, *args, True, est)
        direct = estimates_from_record(est)
        for f in dataclasses.fields(out):
            a, b = np.asarray(getattr(out, f.name)), np.asarray(getattr(direct, f.name))
            assert np.array_equal(a, b), (k, f.name)
    assert wrapper.faults.total == 0 and wrapper.last is out
