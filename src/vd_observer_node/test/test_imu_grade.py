"""The IMU fusion (`estimation.imu_grade`) on simulated everyday drives: the grade against the
simulator's road, the mass and bias against the true car and sensor, and its behaviour when
the IMU drops out, saturates or has a bias."""

from __future__ import annotations

import dataclasses
import math
from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest
from adaptation_setup import PARAMS, VEHICLE
from vd_common.topics import ESTIMATES_SLOPE, SENSORS_IMU
from vd_observer_node.bag.cdr_batch import decode_batch
from vd_observer_node.bag.reader import BagReader
from vd_observer_node.chain import Chain
from vd_observer_node.errors import ConfigurationError, InputShapeError
from vd_observer_node.estimation.body_pitch import vehicle_body_pitch
from vd_observer_node.estimation.cascade import (
    CascadeResult,
    CascadeSeries,
    CascadeSettings,
    run_cascade,
)
from vd_observer_node.estimation.estimator import EstimatorConfig
from vd_observer_node.estimation.imu_grade import SOURCE_FORCE, SOURCE_IMU
from vd_observer_node.estimation.imu_settings import (
    REFERENCE_RATE_FOLLOWING,
    ImuGradeConfig,
    imu_grade_config,
)
from vd_observer_node.inputs.mapping import mapping_from_dict
from vd_observer_node.situation.chain_settings import ChainSettings, chain_settings
from vd_observer_node.situation.friction_potential import TyreCurves
from vd_observer_node.testing.devbag import sim_topics, write_topic_arrays_bag
from vd_observer_node.tools.replay import replay_bag
from vd_sim_node.vehicle.everyday import EverydaySettings, everyday_scenario
from vd_sim_node.vehicle.simulation import SimResult, simulate

RATE_HZ = 200.0
# the shipped Clio's body (its pitch compliance and mode), as the replay reads its file
CONFIG = imu_grade_config(vehicle_body_pitch(None))


@lru_cache(maxsize=2)
def _drive(seed: int = 0, bias: float = 0.1) -> SimResult:
    settings = EverydaySettings(duration=90.0, rate_hz=RATE_HZ, imu_bias=bias)
    scenario = everyday_scenario(seed, PARAMS, settings)
    # the bias exactly as given (the generator draws it within +-bias)
    sensors = dataclasses.replace(scenario.sensors, imu_bias=bias, imu_mount_pitch=0.0)
    return simulate(PARAMS, dataclasses.replace(scenario, sensors=sensors))


def _imu(sim: SimResult) -> np.ndarray:
    return np.column_stack([sim.t, sim.imu[:, 0]])


def _run(sim: SimResult, imu: np.ndarray | None, config: ImuGradeConfig = CONFIG) -> CascadeResult:
    return run_cascade(
        CascadeSeries(sim.t, sim.wheel_angle, sim.body_speed, sim.wheel_torque, imu=imu),
        CascadeSettings(VEHICLE, imu=config),
    )


@lru_cache(maxsize=1)
def _plain() -> CascadeResult:
    return _run(_drive(), None)


@lru_cache(maxsize=1)
def _fused() -> CascadeResult:
    return _run(_drive(), _imu(_drive()))


def _rms_deg(x: np.ndarray) -> float:
    return math.degrees(float(np.sqrt(np.mean(x * x))))


def test_the_fused_grade_beats_the_force_balance_and_learns_the_bias_and_the_mass() -> None:
    sim = _drive()
    plain, fused = _plain(), _fused()
    true_mass = PARAMS.chassis.mass + _drive_scenario_extra(0)
    moving = sim.speed_true > 1.0
    trusted = fused.imu_trusted & moving
    assert trusted.sum() > 0.5 * moving.sum()
    imu_error = _rms_deg((fused.slope - sim.slope)[trusted])
    force_error = _rms_deg((plain.slope - sim.slope)[trusted])
    assert imu_error < 0.25 and imu_error < 0.3 * force_error
    assert np.all(fused.slope_sources[trusted] == SOURCE_FORCE | SOURCE_IMU)
    # the bias the sensor was given, and the mass the force balance sees (its torques are
    # divided by the file's radius, the car rolls on another: F scales by their ratio)
    assert fused.imu_bias[-1] == pytest.approx(0.1, abs=0.015)
    radius_scale = everyday_scenario(0, PARAMS).true_vehicle.tyre_radius_scale
    assert fused.imu_fitted[-1]
    assert fused.imu_mass[-1] == pytest.approx(true_mass * radius_scale, rel=0.02)


def _drive_scenario_extra(seed: int) -> float:
    return everyday_scenario(seed, PARAMS).true_vehicle.extra_mass_kg


def test_without_feedback_the_fusion_changes_the_slope_and_the_published_mass_only() -> None:
    sim = _drive()
    plain = _plain()
    fused = _run(sim, _imu(sim), dataclasses.replace(CONFIG, mass_feedback=False))
    untouched = {'slope', 'slope_valid', 'slope_sources', 'slope_imu', 'imu_bias', 'imu_mass'}
    untouched |= {'imu_mass_std', 'imu_fitted', 'imu_trusted', 'imu_gyro', 'faults'}
    # the published mass is the regression's once it has data
    untouched |= {'mass', 'mass_std', 'mass_converged'}
    for field in dataclasses.fields(CascadeResult):
        if field.name in untouched:
            continue
        a, b = getattr(plain, field.name), getattr(fused, field.name)
        np.testing.assert_array_equal(a, b, err_msg=field.name)
    np.testing.assert_array_equal(fused.mass[fused.imu_fitted], fused.imu_mass[fused.imu_fitted])
    np.testing.assert_array_equal(fused.mass_converged, fused.imu_fitted)
    # without an IMU the sources say: the force balance where its slope is valid
    np.testing.assert_array_equal(plain.slope_sources, np.where(plain.slope_valid, 1, 0))
    np.testing.assert_array_equal(fused.slope_force, plain.slope)


def test_the_imu_mass_feeds_the_force_balance_when_the_file_is_wrong() -> None:
    sim = _drive()
    plain, fused = _plain(), _fused()
    true_mass = PARAMS.chassis.mass + _drive_scenario_extra(0)
    assert abs(VEHICLE.mass / true_mass - 1.0) > 0.1  # the file is off by a load
    fitted = np.flatnonzero(fused.imu_fitted)
    assert fitted.size > 0.3 * len(sim.t)  # fitted within 60 s
    first = fitted[0]
    # before the regression's mass is fitted the estimator has its own; from the next stamp
    # on, the regression's of the stamp before
    np.testing.assert_array_equal(fused.mass_used[: first + 1], plain.mass_used[: first + 1])
    np.testing.assert_array_equal(fused.mass_used[first + 1 :], fused.imu_mass[first:-1])
    # against the simulator's truth: the force balance's slope and the tyre loads
    later = np.zeros(len(sim.t), dtype=bool)
    later[first + int(5.0 * RATE_HZ) :] = True  # its filters past the change of mass
    rated = later & fused.torque_valid & (sim.speed_true > 2.0)
    with_imu = _rms_deg((fused.slope_force - sim.slope)[rated])
    without = _rms_deg((plain.slope - sim.slope)[rated])
    assert with_imu < 0.5 * without
    fz_with = np.sqrt(np.mean((fused.fz - sim.fz)[rated] ** 2))
    fz_without = np.sqrt(np.mean((plain.fz - sim.fz)[rated] ** 2))
    assert fz_with < 0.5 * fz_without


def test_an_imu_that_never_delivers_gives_the_force_balance_bit_for_bit() -> None:
    sim = _drive()
    plain = _plain()
    silent = _run(sim, np.full((len(sim.t), 2), np.nan))
    np.testing.assert_array_equal(silent.slope, plain.slope)
    np.testing.assert_array_equal(silent.slope_valid, plain.slope_valid)
    np.testing.assert_array_equal(silent.slope_sources, plain.slope_sources)


@pytest.mark.parametrize('kind', ['dropout', 'saturation'])
def test_a_dropout_or_saturation_falls_back_to_the_force_balance_and_recovers(kind: str) -> None:
    sim = _drive()
    fused = _fused()
    imu = _imu(sim)
    lost = (sim.t >= 60.0) & (sim.t < 65.0)
    if kind == 'dropout':
        imu[lost, 0] = 29.9  # the last sample before, held: stale after max_age
        imu[lost, 1] = imu[np.searchsorted(sim.t, 29.9), 1]
    else:
        imu[lost, 1] = CONFIG.saturation  # the sensor's full scale
    out = _run(sim, imu)
    # before: the same as the full IMU; during (past max_age): the force balance's slope
    before = sim.t < 60.0
    np.testing.assert_array_equal(out.slope[before], fused.slope[before])
    # (the force balance with the regression's mass, which it keeps)
    during = lost & (sim.t >= 60.0 + CONFIG.max_age + 1e-9)
    np.testing.assert_array_equal(out.slope[during], out.slope_force[during])
    assert np.all(out.slope_sources[during] == np.where(out.slope_valid[during], 1, 0))
    assert np.all(out.imu_fitted[during])
    np.testing.assert_array_equal(out.mass_used[during], out.imu_mass[np.flatnonzero(during)[0]])
    # after: the filters restart (no jump from the stale state), the bias is kept
    later = sim.t > 65.0 + 6 * CONFIG.tau_in_use + 0.5
    np.testing.assert_array_equal(out.imu_bias[during], np.full(during.sum(), out.imu_bias[
        np.flatnonzero(during)[0]]))  # fmt: skip
    moving = later & (sim.speed_true > 1.0)
    error = _rms_deg((out.slope - sim.slope)[moving])
    assert error < 0.25
    assert np.all(out.slope_sources[moving] & SOURCE_IMU)


def test_a_large_bias_is_learnt_and_does_not_reach_the_grade() -> None:
    sim = _drive(1, bias=0.4)  # 0.4 m/s^2: 2.3 deg of grade if it were not learnt
    out = _run(sim, _imu(sim))
    assert out.imu_bias[-1] == pytest.approx(0.4, abs=0.02)
    trusted = out.imu_trusted & (sim.speed_true > 1.0)
    assert trusted.sum() > 0.25 * len(sim.t)
    assert _rms_deg((out.slope - sim.slope)[trusted]) < 0.25


def test_the_imu_alone_is_valid_only_once_its_bias_is_known() -> None:
    """No torque for the first 12 s (a braking on a switch, a shift): the IMU's grade alone,
    its 0.4 m/s^2 bias (2.3 deg) not learnt yet, is published invalid; with `alone_bias_std`
    well above the prior's deviation it would be valid and degrees off. Once the bias is
    learnt, a later stretch without torque is covered by the IMU, valid."""
    sim = _drive(1, bias=0.4)
    torque = sim.wheel_torque.copy()
    first = sim.t < 12.0
    later = (sim.t >= 60.0) & (sim.t < 63.0)
    torque[first | later] = np.nan

    def run(config: ImuGradeConfig) -> CascadeResult:
        return run_cascade(
            CascadeSeries(sim.t, sim.wheel_angle, sim.body_speed, torque, imu=_imu(sim)),
            CascadeSettings(VEHICLE, imu=config),
        )

    out = run(CONFIG)
    moving = sim.speed_true > 1.0
    alone = first & moving & (out.slope_sources == SOURCE_IMU)
    assert alone.sum() > 0.9 * (first & moving).sum()
    assert not out.slope_valid[first].any()
    assert np.all(out.imu_trusted[later]) and np.all(out.slope_valid[later & moving])
    assert _rms_deg((out.slope - sim.slope)[later & moving]) < 1.0
    careless = run(dataclasses.replace(CONFIG, alone_bias_std=5.0))
    assert np.all(careless.slope_valid[alone])
    assert _rms_deg((careless.slope - sim.slope)[alone]) > 2.0
    np.testing.assert_array_equal(careless.slope[alone], out.slope[alone])


def test_the_imu_record_and_settings_are_checked() -> None:
    sim = _drive()
    with pytest.raises(InputShapeError, match='imu must have shape'):
        _run(sim, np.zeros((len(sim.t), 4)))
    with pytest.raises(InputShapeError, match='imu must have shape'):
        _run(sim, np.zeros((len(sim.t) - 1, 3)))
    with pytest.raises(ConfigurationError, match=r'imu\.tau'):
        ImuGradeConfig(tau=0.0)
    with pytest.raises(ConfigurationError, match=r'imu\.max_slope'):
        ImuGradeConfig(max_slope=2.0)


@pytest.mark.parametrize('gyro', [False, True], ids=['specific-force', 'whole-imu'])
def test_the_live_chain_fuses_as_the_cascade_does(gyro: bool) -> None:
    sim = _drive()
    n = int(40.0 * RATE_HZ)  # past the bias's convergence
    imu = (np.column_stack([_imu(sim), sim.gyro]) if gyro else _imu(sim))[:n]
    imu[2000:2100] = np.nan  # half a second without IMU messages (none held yet is nan too)
    offline = run_cascade(
        CascadeSeries(
            sim.t[:n], sim.wheel_angle[:n], sim.body_speed[:n], sim.wheel_torque[:n], imu=imu
        ),
        CascadeSettings(VEHICLE, imu=CONFIG),
    )
    chain = Chain(
        ChainSettings(vehicle=VEHICLE, curves=TyreCurves.from_tire(PARAMS.tire), imu=CONFIG)
    )
    slope = np.empty(n)
    mass_used = np.empty(n)
    sources = np.empty(n, dtype=np.uint8)
    for k in range(n):
        held = None if np.isnan(imu[k, 0]) else tuple(float(x) for x in imu[k])
        out = chain.update(
            float(sim.t[k]), sim.wheel_angle[k], float(sim.body_speed[k]), sim.wheel_torque[k],
            held={'imu': held},
        )  # fmt: skip
        slope[k] = out.estimates.slope
        mass_used[k] = out.estimates.mass_used
        sources[k] = out.slope_sources
    np.testing.assert_array_equal(slope, offline.slope)
    np.testing.assert_array_equal(mass_used, offline.mass_used)  # the IMU's mass fed back
    np.testing.assert_array_equal(sources, offline.slope_sources)
    assert np.any(sources == SOURCE_FORCE | SOURCE_IMU)
    # what it has learnt, as the pipeline node logs and publishes it on /diagnostics
    learnt = chain.imu_learnt()
    assert learnt is not None
    assert learnt.bias == offline.imu_bias[-1] and learnt.trusted == offline.imu_trusted[-1]
    assert learnt.gyro is gyro and learnt.trusted
    assert learnt.pitch_deg == pytest.approx(math.degrees(math.asin(learnt.bias / 9.81)))
    curves = TyreCurves.from_tire(PARAMS.tire)
    assert Chain(ChainSettings(vehicle=VEHICLE, curves=curves)).imu_learnt() is None


def test_replay_reads_the_mapped_imu_and_marks_the_slope_sources(tmp_path: Path) -> None:
    sim = _drive()
    n = int(40.0 * RATE_HZ)
    part = SimResult(
        **{
            f.name: (getattr(sim, f.name)[:n] if f.name != 'events' else sim.events)
            for f in dataclasses.fields(SimResult)
        }
    )
    stamps = np.round(part.t * 1e9).astype(np.int64)
    write_topic_arrays_bag(tmp_path / 'in', stamps, sim_topics(part, truth=False, imu=True))
    # the fusion's low-passes set as the cascade's reference values (unset, the replay follows
    # the bag's rate after 200 stamps: test_imu_input)
    # the simulator's IMU is aligned with the body (stated: else the mounting is learnt first)
    imu = {
        'topic': SENSORS_IMU, 'type': 'sensor_msgs/msg/Imu', 'mount_rpy_deg': [0, 0, 0],
        'fusion': REFERENCE_RATE_FOLLOWING,
    }  # fmt: skip
    mapping = mapping_from_dict({'imu': imu})
    # the slope filter set: left unset, the replay follows the bag's rate after 200 stamps
    # (rate_settings; tested in test_bag_replay)
    fixed = EstimatorConfig(slope_filter_tau=0.1)
    settings = dataclasses.replace(chain_settings(mapping), estimator=fixed)
    report = replay_bag(
        tmp_path / 'in', tmp_path / 'out', settings, mapping=mapping, situation=False
    )
    arrays = BagReader(tmp_path / 'out').topic_arrays([ESTIMATES_SLOPE])[ESTIMATES_SLOPE]
    slope = decode_batch('vd_msgs/msg/Slope', arrays.datas)
    t = stamps * 1e-9  # the replay's stamps: the header's nanoseconds
    expected = run_cascade(
        CascadeSeries(
            t,
            part.wheel_angle,
            part.body_speed,
            part.wheel_torque,
            imu=np.column_stack([t, part.imu[:, 0], part.gyro]),
        ),
        CascadeSettings(VEHICLE, estimator=fixed, imu=CONFIG),
    )
    np.testing.assert_array_equal(slope.values['angle'], expected.slope)
    np.testing.assert_array_equal(slope.values['sources'], expected.slope_sources)
    assert np.any(slope.values['sources'] == SOURCE_FORCE | SOURCE_IMU)
    # the summary says what the fusion used and learnt: the simulator's gyro at every stamp
    # after the warm-up, the bias it was given (0.1 m/s^2, no mounting), when it was trusted
    used = float(report.imu.split('angular rate used on ')[1].split(' %')[0])
    bias = float(report.imu.split('bias ')[1].split(' m/s^2')[0])
    trusted = float(report.imu.split('trusted after ')[1].split(' s')[0])
    first = int(np.argmax(expected.imu_trusted))
    assert used == pytest.approx(100.0 * expected.imu_gyro.mean(), abs=0.05) and used > 95.0
    assert bias == pytest.approx(expected.imu_bias[-1], abs=5e-4)
    assert abs(bias - 0.1) < 0.02
    assert trusted == pytest.approx(t[first] - t[0], abs=0.05)
