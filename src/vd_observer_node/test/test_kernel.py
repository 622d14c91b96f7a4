"""The compiled kernel against the pure-Python reference: equal outputs, equal fault counts.

Every installed scenario with ideal and encoder sensors, injected faults (NaN and inf values,
NaN stamps, gaps, duplicates, out-of-order stamps, a looped record, overflowing values), every
discretization and initialisation, the estimator's configuration branches, the monitor's
variants, per-stamp (N = 1, the live path) against whole-record calls (offline), and random
fault injections (hypothesis). Tolerance: 1e-9 relative plus 1e-9 times the signal's scale;
levels, classes, validity flags and fault counters exactly.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from vd_common.vehicle.params import load_vehicle
from vd_observer_node.chain import ChainSettings, PythonChain
from vd_observer_node.errors import InputShapeError
from vd_observer_node.estimation.cascade import CascadeResult, run_cascade
from vd_observer_node.estimation.differentiator import (
    DISCRETIZATIONS,
    INIT_POLICIES,
    LevantDifferentiator,
)
from vd_observer_node.estimation.drivetrain import (
    TORQUE_SOURCES,
    Drivetrain,
    engine_wheel_torques_record,
)
from vd_observer_node.estimation.estimator import Estimator, EstimatorConfig
from vd_observer_node.estimation.observer import ObserverConfig
from vd_observer_node.estimation.vehicle import load_estimator_vehicle
from vd_observer_node.kernel.chain import (
    CompiledChain,
    run_cascade_compiled,
    run_situation_compiled,
)
from vd_observer_node.kernel.estimation import CompiledEstimator
from vd_observer_node.kernel.levant import CompiledDifferentiator
from vd_observer_node.kernel.situation import CompiledSituationMonitor
from vd_observer_node.situation.alerts import AlertConfig
from vd_observer_node.situation.friction_potential import FrictionPotentialConfig, TyreCurves
from vd_observer_node.situation.monitor import SituationConfig, SituationMonitor, run_situation
from vd_sim_node.vehicle.scenario import SensorSettings, load_scenario
from vd_sim_node.vehicle.simulation import simulate

CONFIG = Path(__file__).resolve().parents[2] / 'vd_sim_node' / 'config'
VEHICLE_FILE = CONFIG.parents[1] / 'vd_common' / 'config' / 'clio_rl_1_1.yaml'
VEHICLE = load_estimator_vehicle(VEHICLE_FILE)
CURVES = TyreCurves.from_tire(load_vehicle(VEHICLE_FILE).tire)
SCENARIOS = sorted(p.stem for p in (CONFIG / 'scenarios').glob('*.yaml'))
RATE_HZ = 200.0
MAX_DURATION = 14.0  # [s] of each scenario: its launch or braking event, a few seconds each
ENCODER = SensorSettings(rate_hz=RATE_HZ, seed=3, encoder_counts_per_rev=96, speed_noise_std=0.05)
RTOL = 1e-9


@dataclasses.dataclass(frozen=True)
class Record:
    """Sensor arrays at common stamps."""

    t: np.ndarray
    angle: np.ndarray
    speed: np.ndarray
    torque: np.ndarray


_RECORDS: dict[tuple[str, str], Record] = {}


def scenario_record(name: str, sensors: str) -> Record:
    """The first MAX_DURATION s of an installed scenario at RATE_HZ (cached per module)."""
    key = (name, sensors)
    if key not in _RECORDS:
        scenario = load_scenario(CONFIG / 'scenarios' / f'{name}.yaml')
        chosen = (
            ENCODER
            if sensors == 'encoder'
            else dataclasses.replace(
                scenario.sensors,
                rate_hz=RATE_HZ,
                encoder_counts_per_rev=0,
                speed_noise_std=0.0,
                torque_noise_std=0.0,
            )
        )
        short = dataclasses.replace(
            scenario, duration=min(scenario.duration, MAX_DURATION), sensors=chosen
        )
        sim = simulate(load_vehicle(VEHICLE_FILE), short)
        _RECORDS[key] = Record(sim.t, sim.wheel_angle, sim.body_speed, sim.wheel_torque)
    return _RECORDS[key]


def assert_close(actual: Any, desired: Any, what: str) -> None:
    """Equal within RTOL relative and RTOL times the desired array's scale (NaN where NaN)."""
    a = np.asarray(actual)
    d = np.asarray(desired)
    assert a.shape == d.shape, what
    if d.dtype == bool or np.issubdtype(d.dtype, np.integer):
        np.testing.assert_array_equal(a, d, err_msg=what)
        return
    finite = d[np.isfinite(d)]
    scale = float(np.max(np.abs(finite))) if finite.size else 1.0
    np.testing.assert_allclose(a, d, rtol=RTOL, atol=RTOL * max(scale, 1e-300), err_msg=what)


def assert_same_cascade(compiled: CascadeResult, reference: CascadeResult) -> None:
    for f in dataclasses.fields(reference):
        if f.name == 'faults':
            assert compiled.faults == reference.faults
        else:
            assert_close(getattr(compiled, f.name), getattr(reference, f.name), f.name)


def assert_same_situation(compiled: Any, reference: Any) -> None:
    for f in dataclasses.fields(reference):
        assert_close(getattr(compiled, f.name), getattr(reference, f.name), f.name)


def monitors(**kw: Any) -> tuple[SituationMonitor, CompiledSituationMonitor]:
    args = (CURVES, VEHICLE.static_wheel_loads[[0, 2]], VEHICLE.effective_radius)
    return SituationMonitor(*args, **kw), CompiledSituationMonitor(*args, **kw)


def check_record(rec: Record, **settings_kw: Any) -> CascadeResult:
    """Cascade and monitor, compiled against reference, on one record."""
    observer = settings_kw.get('observer')
    estimator = settings_kw.get('estimator')
    speed = settings_kw.get('estimator_speed', 'measured')
    args = (rec.t, rec.angle, rec.speed, rec.torque, VEHICLE, observer, estimator, speed)
    reference = run_cascade(*args)
    compiled = run_cascade_compiled(*args)
    assert_same_cascade(compiled, reference)
    python, fast = monitors(
        observer=observer,
        alerts=settings_kw.get('alerts'),
        friction=settings_kw.get('friction'),
        situation=settings_kw.get('situation'),
    )
    assert_same_situation(
        run_situation_compiled(fast, rec.angle, rec.speed, rec.torque, reference),
        run_situation(python, rec.angle, rec.speed, rec.torque, reference),
    )
    return reference


@pytest.mark.parametrize('sensors', ['ideal', 'encoder'])
@pytest.mark.parametrize('name', SCENARIOS)
def test_every_scenario_gives_the_same_estimates_and_alerts(name: str, sensors: str) -> None:
    reference = check_record(scenario_record(name, sensors))
    # the records exercise the estimator: mu valid on some samples, the slope on most
    assert reference.mu_valid.any()
    assert reference.slope_valid.mean() > 0.3


def inject_faults(rec: Record, rng: np.random.Generator) -> Record:
    """Every input fault the core handles, at random places of a copy of `rec`."""
    t, angle = rec.t.copy(), rec.angle.copy()
    speed, torque = rec.speed.copy(), rec.torque.copy()
    n = len(t)
    pick = rng.choice(np.arange(50, n - 50), size=40, replace=False)
    angle[pick[0:4], rng.integers(0, 4, 4)] = np.nan
    angle[pick[4], :] = np.inf
    speed[pick[5:8]] = np.nan
    torque[pick[8:10], 1] = -np.inf
    t[pick[10:13]] = np.nan
    t[pick[13:16]] = t[pick[13:16] - 1]  # duplicates
    for k in pick[16:19]:  # a slightly older stamp
        t[k] = t[k - 1] - 0.5 / RATE_HZ
    angle[pick[19]] = 1e300  # overflows the differentiator and the estimator
    torque[pick[20]] = 1e300
    keep = np.ones(n, dtype=bool)
    keep[pick[21] : pick[21] + int(RATE_HZ)] = False  # a 1 s gap, longer than max_gap
    t, angle, speed, torque = t[keep], angle[keep], speed[keep], torque[keep]
    # a looped record: the first second again at the end
    loop = slice(0, int(RATE_HZ))
    return Record(
        np.concatenate([t, rec.t[loop]]),
        np.concatenate([angle, rec.angle[loop]]),
        np.concatenate([speed, rec.speed[loop]]),
        np.concatenate([torque, rec.torque[loop]]),
    )


@pytest.mark.parametrize('sensors', ['ideal', 'encoder'])
def test_injected_faults_give_the_same_outputs_and_counts(sensors: str) -> None:
    rec = inject_faults(scenario_record('launch_low_mu', sensors), np.random.default_rng(5))
    reference = check_record(rec)
    counted = {k.split('.')[1] for k, v in reference.faults.items() if v > 0}
    assert {
        'non_finite_stamp',
        'non_finite_value',
        'duplicate_stamp',
        'out_of_order',
        'gap',
        'time_jump_back',
        'non_finite_output',
    } <= counted


@pytest.mark.parametrize(
    ('discretization', 'init'), list(itertools.product(DISCRETIZATIONS, INIT_POLICIES))
)
def test_every_discretization_and_init(discretization: str, init: str) -> None:
    rec = inject_faults(scenario_record('launch_low_mu', 'encoder'), np.random.default_rng(9))
    observer = ObserverConfig(discretization=discretization, init=init)
    check_record(rec, observer=observer, estimator_speed='observer')


@pytest.mark.parametrize(
    'estimator',
    [
        EstimatorConfig(load_transfer_source='acceleration'),
        EstimatorConfig(slope_accel_source='observer', force_filter_tau=0.02),
        EstimatorConfig(slope_filter_tau=0.0, filter_order=1),
    ],
)
def test_estimator_configurations(estimator: EstimatorConfig) -> None:
    check_record(scenario_record('braking_low_mu', 'encoder'), estimator=estimator)


@pytest.mark.parametrize('sensors', ['ideal', 'encoder'])
def test_wheel_speed_input_gives_the_same_estimates_and_alerts(sensors: str) -> None:
    """The first-order wheel observer (``wheel_input='speed'``) in the cascade and the monitor."""
    rec = scenario_record('braking_low_mu_hard', sensors)
    # what an ABS sensor reports: the mean speed over the last sample period
    speeds = np.vstack((np.zeros((1, 4)), np.diff(rec.angle, axis=0) / np.diff(rec.t)[:, None]))
    speeds[0] = speeds[1]
    observer = ObserverConfig(wheel_input='speed')
    reference = check_record(dataclasses.replace(rec, angle=speeds), observer=observer)
    assert np.all(np.isfinite(reference.omega_dot)) and reference.wheel_valid[50:].all()


def test_monitor_variants() -> None:
    check_record(
        scenario_record('braking_low_mu_hard', 'ideal'),
        situation=SituationConfig(max_observer_disagreement=0.5, alert_wheel_lipschitz=5000.0),
        friction=FrictionPotentialConfig(shrink_to_prior=False, evidence_hold_time=0.0),
        alerts=AlertConfig(raise_hold=0.0, release_hold=0.05),
    )


def test_per_stamp_chain_equals_the_reference_chain_and_the_block_kernels() -> None:
    """The live path (N = 1 per call) against the reference objects and the offline blocks."""
    rec = inject_faults(scenario_record('launch_low_mu', 'encoder'), np.random.default_rng(1))
    settings_ = ChainSettings(vehicle=VEHICLE, curves=CURVES)
    python = PythonChain(settings_)
    compiled = CompiledChain(settings_)
    block = run_cascade_compiled(rec.t, rec.angle, rec.speed, rec.torque, VEHICLE)
    _, fast = monitors()
    series = run_situation_compiled(fast, rec.angle, rec.speed, rec.torque, block)
    for k in range(len(rec.t)):
        args = (float(rec.t[k]), rec.angle[k], float(rec.speed[k]), rec.torque[k])
        a, b = python.update(*args), compiled.update(*args)
        for name in ('angle', 'omega', 'omega_dot', 'valid'):
            assert_close(getattr(b.wheel, name), getattr(a.wheel, name), name)
        assert_close(np.array(b.speed), np.array(a.speed), 'speed')
        for f in dataclasses.fields(a.estimates):
            assert_close(getattr(b.estimates, f.name), getattr(a.estimates, f.name), f.name)
        for f in dataclasses.fields(a.situation.potential):
            x, y = getattr(a.situation.potential, f.name), getattr(b.situation.potential, f.name)
            assert_close(y, x, f.name)
        assert b.situation.alerts == a.situation.alerts or all(
            (p.level, p.active) == (q.level, q.active)
            and (p.onset == q.onset or (math.isnan(p.onset) and math.isnan(q.onset)))
            for p, q in zip(a.situation.alerts, b.situation.alerts, strict=True)
        )
        # the per-stamp compiled chain is the block kernel, stamp by stamp
        assert_close(b.estimates.fx, block.fx[k], 'block fx')
        assert_close(b.situation.potential.mu_max, series.mu_max[k], 'block mu_max')
    assert python.fault_report().counts == compiled.fault_report().counts


_ENGINE_SIM: list[Any] = []


def engine_sim() -> Any:
    """paper_table1's launch and first upshift (13 s at RATE_HZ, ideal sensors: an encoder's
    quantized speed keeps the clutch check failing; cached)."""
    if not _ENGINE_SIM:
        scenario = load_scenario(CONFIG / 'scenarios' / 'paper_table1.yaml')
        ideal = dataclasses.replace(
            scenario.sensors,
            rate_hz=RATE_HZ,
            encoder_counts_per_rev=0,
            speed_noise_std=0.0,
            torque_noise_std=0.0,
        )
        short = dataclasses.replace(scenario, duration=13.0, sensors=ideal)
        _ENGINE_SIM.append(simulate(load_vehicle(VEHICLE_FILE), short))
    return _ENGINE_SIM[0]


@pytest.mark.parametrize('source', ['engine', 'none'])
def test_per_stamp_chain_on_the_engine_and_no_torque_paths(source: str) -> None:
    """The live chain on the engine and no-torque paths: PythonChain is run_cascade stamp for
    stamp (the same objects, the same bits), its monitor fed as the replay feeds it, and
    CompiledChain equals PythonChain; the record has the launch (clutch slip), an upshift
    and a gear the box lacks."""
    sim = engine_sim()
    engine = np.stack([sim.engine_torque, sim.gear.astype(float), sim.engine_speed], axis=1)
    engine[2000, 1] = 2.5  # no gear at all: nan torques, a fault, the path invalid
    engine[2150, 0] = math.nan
    drivetrain = Drivetrain.from_params(load_vehicle(VEHICLE_FILE))
    settings_ = ChainSettings(
        vehicle=VEHICLE, curves=CURVES, torque_source=source, drivetrain=drivetrain
    )
    python = PythonChain(settings_)
    compiled = CompiledChain(settings_)
    n = len(sim.t)
    # what the replay runs: no wheel torques read, the engine record on the engine path
    reference = run_cascade(
        sim.t, sim.wheel_angle, sim.body_speed, np.zeros((n, 4)), VEHICLE,
        torque_source=source, engine=engine, drivetrain=drivetrain,
    )  # fmt: skip
    monitor_torque = np.zeros((n, 4))
    if source == 'engine':
        derived = engine_wheel_torques_record(engine, drivetrain, reference.omega_dot)
        monitor_torque = np.where(np.isfinite(derived), derived, 0.0)
        # the record holds what the path must handle: the launch's clutch slip, then valid
        # torques, a faulty sample, an upshift (invalid from its first stamp)
        valid = reference.torque_valid
        shift = int(np.flatnonzero(np.diff(sim.gear))[0]) + 1
        assert not valid[: n // 2].any() and valid[1990] and not valid[2000]
        assert valid[shift - 1] and not valid[shift]
        assert reference.faults['estimator.non_finite_value'] >= 2
    series = run_situation(
        monitors()[0], sim.wheel_angle, sim.body_speed, monitor_torque, reference
    )
    code = TORQUE_SOURCES.index(source)
    for k in range(n):
        # the measured wheel torques are given and must be ignored on both paths
        args = (float(sim.t[k]), sim.wheel_angle[k], float(sim.body_speed[k]), sim.wheel_torque[k])
        a, b = python.update(*args, engine[k]), compiled.update(*args, engine[k])
        assert a.estimates.torque_source == b.estimates.torque_source == code
        for name in ('fx', 'fz', 'mu', 'mu_valid', 'slip', 'rolling'):
            np.testing.assert_array_equal(getattr(a.estimates, name), getattr(reference, name)[k])
        assert (a.estimates.slope, a.estimates.slope_valid) == (
            reference.slope[k],
            reference.slope_valid[k],
        )
        np.testing.assert_array_equal(a.situation.potential.mu_max, series.mu_max[k])
        assert [p.level for p in a.situation.alerts] == series.level[k].ravel().tolist()
        for f in dataclasses.fields(a.estimates):
            assert_close(getattr(b.estimates, f.name), getattr(a.estimates, f.name), f.name)
        for f in dataclasses.fields(a.situation.potential):
            x, y = getattr(a.situation.potential, f.name), getattr(b.situation.potential, f.name)
            assert_close(y, x, f.name)
        assert [p.level for p in b.situation.alerts] == [p.level for p in a.situation.alerts]
    assert python.fault_report().counts == compiled.fault_report().counts
    if source == 'engine':
        for chain in (python, compiled):
            for bad in (None, [1.0]):
                with pytest.raises(InputShapeError, match='engine'):
                    chain.update(20.0, np.zeros(4), 1.0, np.zeros(4), bad)


def test_wrappers_match_the_reference_classes() -> None:
    rng = np.random.default_rng(4)
    reference = LevantDifferentiator(300.0, n_channels=4, max_gap=0.5, init_baseline=0.02)
    compiled = CompiledDifferentiator(300.0, n_channels=4, max_gap=0.5, init_baseline=0.02)
    estimator, compiled_estimator = Estimator(VEHICLE), CompiledEstimator(VEHICLE)
    for k in range(600):
        t = k * 0.002 if k != 300 else math.nan
        f = np.sin(k * 0.01 * np.arange(1, 5)) * 30.0 + rng.normal(0.0, 1e-3, 4)
        a, b = reference.update(t, f), compiled.update(t, f)
        for x, y in zip(a, b, strict=True):
            assert_close(y, x, 'differentiator')
        e = (t, a.first, a.second, 12.0, 0.1, np.array([200.0, 200.0, 0.0, 0.0]))
        p, q = estimator.update(*e), compiled_estimator.update(*e)
        for f_ in dataclasses.fields(p):
            assert_close(getattr(q, f_.name), getattr(p, f_.name), f_.name)
    assert reference.faults.counts == compiled.faults.counts
    assert reference.rejected_count == compiled.rejected_count == 1
    assert estimator.faults.counts == compiled_estimator.faults.counts
    assert compiled.time == reference.time


@settings(max_examples=15)
@given(seed=st.integers(0, 2**32 - 1), faults=st.integers(1, 30))
def test_random_fault_injections(seed: int, faults: int) -> None:
    rng = np.random.default_rng(seed)
    base = scenario_record('launch_low_mu', 'ideal')
    n = 600
    t, angle = base.t[:n].copy(), base.angle[:n].copy()
    speed, torque = base.speed[:n].copy(), base.torque[:n].copy()
    for k in rng.integers(1, n, faults).tolist():
        kind = rng.integers(0, 6)
        if kind == 0:
            angle[k, rng.integers(0, 4)] = np.nan
        elif kind == 1:
            t[k] = t[k - 1]
        elif kind == 2:
            t[k] = t[k - 1] - rng.uniform(0.0, 2.0)
        elif kind == 3:
            t[k:] += rng.uniform(0.0, 1.5)
        elif kind == 4:
            speed[k] = np.inf
        else:
            torque[k] = rng.normal(0.0, 1e6, 4)
    check_record(Record(t, angle, speed, torque))
