"""Sensor faults through the ROS-free core: outputs stay finite, faults are counted per kind,
the flags say what is invalid and the estimates recover (see docs/faults.md)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from vd_observer_node.estimation.alignment import StampAligner
from vd_observer_node.estimation.cascade import (
    CascadeResult,
    CascadeSeries,
    CascadeSettings,
    run_cascade,
)
from vd_observer_node.estimation.estimator import Estimates, Estimator, EstimatorConfig
from vd_observer_node.estimation.faults import (
    ERROR,
    ESTIMATOR_FAULTS,
    OBSERVER_FAULTS,
    OK,
    FaultCounter,
    merge_reports,
)
from vd_observer_node.estimation.observer import ObserverConfig, SpeedObserver, WheelObserver
from vd_observer_node.estimation.vehicle import load_estimator_vehicle
from vd_observer_node.testing.synthetic import SyntheticTrajectory, synthetic_trajectory

VEHICLE_FILE = Path(__file__).resolve().parents[2] / 'vd_common' / 'config' / 'clio_rl_1_1.yaml'
#: rigid, as the synthetic trajectories' loads are: a one-stamp braking lifts a wheel at once
VEHICLE = load_estimator_vehicle(VEHICLE_FILE).with_vertical(None)
DT = 1e-3
NO_FILTER = EstimatorConfig(slope_filter_tau=0.0, force_filter_tau=0.0)


def _traj(duration: float = 2.0) -> SyntheticTrajectory:
    return synthetic_trajectory(np.arange(0.0, duration, DT), VEHICLE)


def _finite_estimates(est: Estimates) -> bool:
    arrays = (est.fx, est.fz, est.mu, est.slip, est.rolling, est.aero, est.slope, est.t)
    return all(bool(np.all(np.isfinite(a))) for a in arrays)


def _feed(est: Estimator, traj: SyntheticTrajectory, k: int, **override: object) -> Estimates:
    values: dict[str, object] = {
        't': traj.t[k],
        'omega': traj.omega[k],
        'omega_dot': traj.omega_dot[k],
        'speed': traj.speed[k],
        'accel': traj.accel[k],
        'torque': traj.torque[k],
    }
    values.update(override)
    return est.update(**values)  # type: ignore[arg-type]


def _nonzero(counts: dict[str, int]) -> dict[str, int]:
    return {k: v for k, v in counts.items() if v}


# --- fault counters ----------------------------------------------------------------------


def test_counter_reports_active_kinds_once_and_keeps_totals() -> None:
    counter = FaultCounter(OBSERVER_FAULTS)
    first = counter.report()
    assert (first.level, first.active, first.message) == (OK, (), 'ok')
    assert set(first.counts) == set(OBSERVER_FAULTS)
    counter.count('gap')
    counter.count('non_finite_output', 2)
    second = counter.report()
    assert second.level == ERROR
    assert second.active == ('gap', 'non_finite_output')
    assert 'gap' in second.message and 'non_finite_output' in second.message
    third = counter.report()
    assert (third.level, third.active) == (OK, ())
    assert third.counts['non_finite_output'] == 2
    merged = merge_reports({'wheel': second, 'speed': third})
    assert merged.level == ERROR
    assert merged.active == ('wheel.gap', 'wheel.non_finite_output')
    assert merged.counts['speed.gap'] == 1


# --- observer (Levant differentiator) -----------------------------------------------------


def _wheel_run(
    t: np.ndarray, angles: np.ndarray, config: ObserverConfig | None = None
) -> tuple[WheelObserver, np.ndarray, np.ndarray]:
    obs = WheelObserver(config or ObserverConfig())
    omega = np.zeros((t.size, 4))
    valid = np.zeros((t.size, 4), dtype=bool)
    for k in range(t.size):
        state = obs.update(float(t[k]), angles[k])
        omega[k] = state.omega
        valid[k] = state.valid
        assert np.all(np.isfinite(state.angle))
        assert np.all(np.isfinite(state.omega)) and np.all(np.isfinite(state.omega_dot))
    return obs, omega, valid


def test_observer_non_finite_values_are_flagged_and_the_wheel_recovers() -> None:
    traj = _traj()
    angles = traj.angle.copy()
    angles[1000, 1] = np.nan
    angles[1001:1020, 2] = np.inf
    angles[1500, :] = -np.inf
    obs, omega, valid = _wheel_run(traj.t, angles)
    assert not valid[1000, 1] and valid[1000, 0]
    assert not valid[1001:1020, 2].any()
    assert not valid[1500].any()
    assert _nonzero(obs.faults.counts) == {'non_finite_value': 1 + 19 + 1}
    # The coasting wheel is back on the true speed within 0.2 s.
    np.testing.assert_allclose(omega[1300:1500], traj.omega[1300:1500], atol=0.05)
    np.testing.assert_allclose(omega[1800:], traj.omega[1800:], atol=0.05)
    assert valid[1800:].all()


def test_observer_drops_duplicate_and_out_of_order_stamps() -> None:
    traj = _traj(1.0)
    t = traj.t.copy()
    angles = traj.angle.copy()
    # A duplicate of sample 500 and a sample 20 ms late, inserted in the stream.
    order = [*range(0, 501), 500, *range(501, 700), 680, *range(700, t.size)]
    obs, omega, valid = _wheel_run(t[order], angles[order])
    assert _nonzero(obs.faults.counts) == {'duplicate_stamp': 1, 'out_of_order': 1}
    assert obs.rejected_count == 2
    assert not valid[501].any() and not valid[701].any()
    np.testing.assert_array_equal(omega[501], omega[500])  # the previous estimate, unchanged
    # Dropping a sample leaves the estimates as if the bad ones never came.
    _, clean, _ = _wheel_run(t, angles)
    np.testing.assert_array_equal(omega[-100:], clean[-100:])


def test_observer_gap_reinitialises_and_reconverges() -> None:
    traj = _traj(3.0)
    keep = (traj.t < 1.0) | (traj.t >= 1.6)  # a 0.6 s dropout > max_gap = 0.5 s
    obs, omega, valid = _wheel_run(traj.t[keep], traj.angle[keep])
    t = traj.t[keep]
    assert _nonzero(obs.faults.counts) == {'gap': 1}
    first_after = int(np.argmax(t >= 1.6))
    assert not valid[first_after].any()  # re-initialising
    late = t >= 2.0
    np.testing.assert_allclose(omega[late], traj.omega[keep][late], atol=0.05)
    assert valid[late].all()


def test_observer_backwards_time_jump_resets_and_replays_identically() -> None:
    traj = _traj(1.5)
    # A looped bag: the same record twice, stamps going back to the start.
    t = np.concatenate([traj.t, traj.t])
    angles = np.concatenate([traj.angle, traj.angle])
    obs, omega, valid = _wheel_run(t, angles)
    n = traj.t.size
    assert _nonzero(obs.faults.counts) == {'time_jump_back': 1}
    assert obs.rejected_count == 0
    # A full reset: the second pass computes exactly what the first did.
    np.testing.assert_array_equal(omega[n:], omega[:n])
    np.testing.assert_array_equal(valid[n:], valid[:n])
    assert valid[-1].all()


def test_observer_non_finite_stamp_and_overflow_keep_outputs_finite() -> None:
    speed = SpeedObserver(ObserverConfig())
    for k in range(200):
        speed.update(k * DT, 10.0 + k * DT)
    state = speed.update(float('nan'), 10.2)
    assert not state.valid
    state = speed.update(0.2, 1e300)  # absurd but finite: the step overflows
    assert np.isfinite(state.speed) and np.isfinite(state.accel) and not state.valid
    assert _nonzero(speed.faults.counts) == {'non_finite_stamp': 1, 'non_finite_output': 1}
    for k in range(201, 600):
        state = speed.update(k * DT, 10.0 + k * DT)
    assert state.valid
    assert state.accel == pytest.approx(1.0, abs=1e-6)


# --- estimator -------------------------------------------------------------------------


def test_estimator_stamp_faults_are_counted_and_dropped() -> None:
    traj = _traj(1.0)
    est = Estimator(VEHICLE, NO_FILTER)
    for k in range(300):
        last = _feed(est, traj, k)
    assert _feed(est, traj, 299) is last
    assert _feed(est, traj, 290) is last
    assert _feed(est, traj, 0, t=float('inf')) is last
    assert _nonzero(est.faults.counts) == {
        'duplicate_stamp': 1,
        'out_of_order': 1,
        'non_finite_stamp': 1,
    }
    assert est.rejected_count == 3


def test_estimator_gap_and_looped_bag_reset_and_recover() -> None:
    traj = _traj(2.0)
    n = traj.t.size
    config = EstimatorConfig()  # default filters: the reset must empty them
    est = Estimator(VEHICLE, config)
    first = [_feed(est, traj, k) for k in range(n)]
    second = [_feed(est, traj, k) for k in range(n)]  # stamps jump back by 2 s
    assert _nonzero(est.faults.counts) == {'time_jump_back': 1}
    for a, b in zip(first, second, strict=True):
        np.testing.assert_array_equal(a.fz, b.fz)
        assert (a.slope, a.slope_valid) == (b.slope, b.slope_valid)
    # A 0.7 s dropout: the filters restart from the new sample; slope is right again soon.
    est2 = Estimator(VEHICLE, config)
    for k in [*range(0, 800), *range(1500, n)]:
        out = _feed(est2, traj, k)
        assert _finite_estimates(out)
    assert _nonzero(est2.faults.counts) == {'gap': 1}
    assert out.slope_valid
    assert out.slope == pytest.approx(traj.slope[-1], abs=0.01)


def test_estimator_non_finite_inputs_hold_and_flag() -> None:
    traj = _traj(1.0)
    est = Estimator(VEHICLE, NO_FILTER)
    for k in range(500):
        _feed(est, traj, k)
    torque = traj.torque[500].copy()
    torque[3] = np.inf
    out = _feed(est, traj, 500, torque=torque, speed=np.nan)
    assert _finite_estimates(out)
    assert not out.mu_valid.any() and not out.slope_valid
    assert _nonzero(est.faults.counts) == {'non_finite_value': 1}
    for k in range(501, traj.t.size):
        out = _feed(est, traj, k)
    assert out.slope_valid and out.slope == pytest.approx(traj.slope[-1], abs=1e-6)


def test_wheel_lift_gives_zero_load_invalid_mu_and_recovers() -> None:
    traj = _traj(1.0)
    est = Estimator(VEHICLE, NO_FILTER)
    for k in range(400):
        _feed(est, traj, k)
    # Very hard braking on the front wheels: the transfer exceeds the rear axle's load.
    brake = traj.torque[400] + np.array([-6000.0, -6000.0, 0.0, 0.0])
    out = _feed(est, traj, 400, torque=brake)
    assert _finite_estimates(out)
    assert np.all(out.fz[2:] == 0.0) and np.all(out.fz[:2] > 0.0)
    assert not out.mu_valid[2:].any()
    assert est.faults.counts['wheel_lift'] == 1
    clean = Estimator(VEHICLE, NO_FILTER)
    for k in range(401, traj.t.size):
        out = _feed(est, traj, k)
        reference = _feed(clean, traj, k)
    np.testing.assert_allclose(out.fz, traj.fz[-1], rtol=1e-3)
    np.testing.assert_allclose(out.fz, reference.fz, rtol=1e-9)
    np.testing.assert_array_equal(out.mu_valid, reference.mu_valid)
    assert out.mu_valid[:2].all()
    assert est.faults.counts['wheel_lift'] == 1


def test_implausible_mu_is_flagged() -> None:
    traj = _traj(1.0)
    est = Estimator(VEHICLE, NO_FILTER)
    for k in range(400):
        _feed(est, traj, k)
    torque = traj.torque[400] + np.array([2500.0, 0.0, 0.0, 0.0])  # |Fx| ~ 3 Fz on FL
    out = _feed(est, traj, 400, torque=torque)
    assert not out.mu_valid[0] and out.mu[0] == 0.0
    assert out.mu_valid[1:].all()
    # The unbalanced torque also breaks the slope balance (sin(alpha) > 1) at that stamp.
    assert _nonzero(est.faults.counts) == {'mu_out_of_range': 1, 'arcsin_domain': 1}
    out = _feed(est, traj, 401)
    assert out.mu_valid[0] and out.slope_valid


@pytest.mark.parametrize(('accel_offset', 'kind'), [(-6.0, 'slope_out_of_range'),
                                                    (-15.0, 'arcsin_domain')])  # fmt: skip
def test_slope_out_of_range_and_arcsin_domain_hold_the_slope(
    accel_offset: float, kind: str
) -> None:
    traj = _traj(1.0)
    est = Estimator(VEHICLE, NO_FILTER)
    for k in range(400):
        good = _feed(est, traj, k)
    out = _feed(est, traj, 400, accel=traj.accel[400] + accel_offset)
    assert _finite_estimates(out)
    assert not out.slope_valid and out.slope == good.slope
    assert _nonzero(est.faults.counts) == {kind: 1}
    out = _feed(est, traj, 401)
    assert out.slope_valid and out.slope == pytest.approx(traj.slope[401], abs=1e-6)


def test_estimator_overflow_resets_instead_of_publishing_inf() -> None:
    traj = _traj(1.0)
    est = Estimator(VEHICLE, EstimatorConfig())
    for k in range(300):
        _feed(est, traj, k)
    out = _feed(est, traj, 300, omega_dot=np.full(4, 1e308), torque=np.full(4, -1e308))
    assert _finite_estimates(out)
    assert not out.mu_valid.any() and not out.slope_valid
    assert est.faults.counts['non_finite_output'] == 1
    for k in range(301, traj.t.size):
        out = _feed(est, traj, k)
    assert out.slope_valid and out.slope == pytest.approx(traj.slope[-1], abs=0.01)


# --- aligner and cascade ---------------------------------------------------------------


def test_aligner_restarts_on_a_jump_back_but_drops_small_ones() -> None:
    aligner = StampAligner(('a', 'b'), max_jump_back_ns=500_000_000)
    for stamp in (1, 2, 3):
        aligner.push('a', stamp * 10**9, stamp)
        assert aligner.push('b', stamp * 10**9, stamp) == {'a': stamp, 'b': stamp}
    assert aligner.push('a', 3 * 10**9 - 100_000_000, 'late') is None
    assert aligner.stale_count == 1
    aligner.push('b', 0, 'loop')
    assert aligner.jump_back_count == 1
    assert aligner.push('a', 0, 'loop') == {'a': 'loop', 'b': 'loop'}
    plain = StampAligner(('a',))
    plain.push('a', 10**10, 1)
    assert plain.push('a', 0, 2) is None and plain.stale_count == 1


def test_cascade_reports_fault_counts_and_replays_a_looped_record() -> None:
    traj = _traj(1.0)
    n = traj.t.size
    t = np.concatenate([traj.t, traj.t])
    angle = np.concatenate([traj.angle, traj.angle])
    speed = np.concatenate([traj.speed, traj.speed])
    torque = np.concatenate([traj.torque, traj.torque])
    result = run_cascade(CascadeSeries(t, angle, speed, torque), CascadeSettings(VEHICLE))
    assert _nonzero(result.faults) == {
        'wheel.time_jump_back': 1,
        'speed.time_jump_back': 1,
        'estimator.time_jump_back': 1,
    }
    np.testing.assert_array_equal(result.fz[n:], result.fz[:n])
    np.testing.assert_array_equal(result.slope[n:], result.slope[:n])


def _all_finite(result: CascadeResult) -> bool:
    return all(
        bool(np.all(np.isfinite(getattr(result, name))))
        for name in ('omega', 'omega_dot', 'speed', 'accel', 'fx', 'fz', 'mu', 'slip',
                     'rolling', 'aero', 'slope')
    )  # fmt: skip


_VALUES = st.one_of(
    st.floats(-1e3, 1e3),
    st.sampled_from([np.nan, np.inf, -np.inf, 1e300, -1e300]),
)


@settings(max_examples=40, deadline=None)
@given(
    steps=st.lists(
        st.one_of(st.floats(-2.0, 2.0), st.sampled_from([0.0, np.nan, -5.0])),
        min_size=2,
        max_size=40,
    ),
    data=st.data(),
)
def test_any_garbage_gives_finite_outputs_and_counted_faults(
    steps: list[float], data: st.DataObject
) -> None:
    n = len(steps)
    t = np.cumsum(np.nan_to_num(steps, nan=0.001))
    t[np.isnan(steps)] = np.nan
    draw = data.draw
    angle = np.array(draw(st.lists(_VALUES, min_size=4 * n, max_size=4 * n))).reshape(n, 4)
    speed = np.array(draw(st.lists(_VALUES, min_size=n, max_size=n)))
    torque = np.array(draw(st.lists(_VALUES, min_size=4 * n, max_size=4 * n))).reshape(n, 4)
    result = run_cascade(CascadeSeries(t, angle, speed, torque), CascadeSettings(VEHICLE))
    assert _all_finite(result)
    assert set(result.faults) == {
        *(f'wheel.{k}' for k in OBSERVER_FAULTS),
        *(f'speed.{k}' for k in OBSERVER_FAULTS),
        *(f'estimator.{k}' for k in ESTIMATOR_FAULTS),
    }
    if np.isnan(t).any():
        assert result.faults['estimator.non_finite_stamp'] >= 1


def test_classify_stamp_is_the_stamp_rule_of_the_online_estimators() -> None:
    from vd_observer_node.estimation.faults import classify_stamp

    assert classify_stamp(None, 1.0, 0.5) == (None, 0.0)
    assert classify_stamp(1.0, 1.25, 0.5) == (None, 0.25)
    assert classify_stamp(1.0, float('nan'), 0.5) == ('non_finite_stamp', None)
    assert classify_stamp(1.0, 1.0, 0.5) == ('duplicate_stamp', None)
    assert classify_stamp(1.0, 0.75, 0.5) == ('out_of_order', None)
    assert classify_stamp(1.0, 0.25, 0.5) == ('time_jump_back', 0.0)
    assert classify_stamp(1.0, 1.75, 0.5) == ('gap', 0.0)
