"""Engine-torque offset learnt in neutral (issue 16): the estimator, its step on records, the
engine path and the cascade on a simulated car whose torque map is off."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from vd_common.vehicle.params import load_vehicle
from vd_observer_node.chain import Chain
from vd_observer_node.errors import ConfigurationError
from vd_observer_node.estimation.cascade import (
    CascadeResult,
    CascadeSeries,
    CascadeSettings,
    run_cascade,
)
from vd_observer_node.estimation.drivetrain import Drivetrain
from vd_observer_node.estimation.estimator import EstimatorConfig
from vd_observer_node.estimation.faults import WARN
from vd_observer_node.estimation.torque_offset import (
    TorqueOffset,
    TorqueOffsetConfig,
    TorqueOffsetEstimator,
    new_offset_estimate,
    new_offset_state,
    offset_from_record,
    offset_params,
    torque_offset_step,
)
from vd_observer_node.estimation.vehicle import EstimatorVehicle
from vd_observer_node.situation.chain_settings import ChainSettings
from vd_observer_node.situation.friction_potential import TyreCurves
from vd_sim_node.vehicle.scenario import SensorSettings, VehicleVariant, load_scenario
from vd_sim_node.vehicle.simulation import SimResult, simulate

CONFIG = Path(__file__).resolve().parents[2] / 'vd_sim_node' / 'config'
PARAMS = load_vehicle(CONFIG.parents[1] / 'vd_common' / 'config' / 'clio_rl_1_1.yaml')
VEHICLE = EstimatorVehicle.from_params(PARAMS)
DRIVETRAIN = Drivetrain.from_params(PARAMS)
J_E = DRIVETRAIN.engine_inertia
SETTINGS = TorqueOffsetConfig()
ON = EstimatorConfig(torque_offset_adaptation=True)
OFF = EstimatorConfig(torque_offset_adaptation=False)


def _synthetic(
    offset: float,
    episodes: int,
    *,
    dt: float = 0.001,
    neutral_s: float = 0.3,
    in_gear_s: float = 2.0,
    seed: int = 3,
    speed_noise: float = 0.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Stamps [s], torque signal [N m], gear, engine speed [rad/s]: in gear, then neutral
    episodes where the engine decelerates on its drag (signal = true net torque + offset)."""
    rng = np.random.default_rng(seed)
    period = in_gear_s + neutral_s
    t = np.arange(0.0, episodes * period + in_gear_s, dt)
    phase = np.mod(t, period)
    gear = np.where(phase < in_gear_s, 2, 0)
    net = np.where(
        gear == 0, -15.0 - 5.0 * np.sin(7.0 * t), 40.0 + 10.0 * rng.standard_normal(t.size)
    )
    # the engine speed integrates the true net torque in neutral (its own inertia only)
    speed = 300.0 + np.concatenate(([0.0], np.cumsum(0.5 * (net[1:] + net[:-1]) * dt))) / J_E
    speed += speed_noise * rng.standard_normal(t.size)
    return t, net + offset, gear, speed


def _run(
    config: TorqueOffsetConfig,
    t: np.ndarray,
    torque: np.ndarray,
    gear: np.ndarray,
    speed: np.ndarray,
) -> tuple[list[TorqueOffset], TorqueOffsetEstimator]:
    estimator = TorqueOffsetEstimator(config, J_E)
    out = [
        estimator.update(float(tk), float(tq), int(g), float(w))
        for tk, tq, g, w in zip(t, torque, gear, speed, strict=True)
    ]
    return out, estimator


def test_neutral_episodes_give_the_offset_and_it_is_used_once_converged() -> None:
    t, torque, gear, speed = _synthetic(7.5, 5)
    out, estimator = _run(SETTINGS, t, torque, gear, speed)
    converged = np.array([o.converged for o in out])
    k0 = int(np.argmax(converged))
    assert converged[-1] and out[k0].episodes == SETTINGS.min_episodes
    assert all(o.used == 0.0 for o in out[:k0])
    # the trapezoid integral of a smooth torque: exact to the rule's error
    assert out[-1].offset == pytest.approx(7.5, abs=1e-3)
    assert out[-1].used == out[-1].offset and out[-1].std < 1e-3
    assert out[-1].episodes == 5 and not out[-1].clamped
    assert estimator.state.clamped == 0.0


def test_a_noisy_engine_speed_still_gives_the_offset_within_its_std() -> None:
    t, torque, gear, speed = _synthetic(-10.0, 12, speed_noise=0.5, dt=0.01)
    out, _ = _run(SETTINGS, t, torque, gear, speed)
    # the speed noise enters at the two ends of each episode only: J_e*0.5*sqrt(2)/0.3 ~ 0.3
    assert out[-1].converged
    assert abs(out[-1].offset + 10.0) <= 3.0 * out[-1].std + 1e-6
    assert abs(out[-1].offset + 10.0) < 0.5


def test_never_in_neutral_keeps_the_signal_and_says_so() -> None:
    t, torque, gear, speed = _synthetic(7.5, 5)
    out, _ = _run(SETTINGS, t, torque, np.full_like(gear, 3), speed)
    assert out[-1] == TorqueOffset(0.0, SETTINGS.max_offset, False, 0.0, 0, False)
    # without the engine speed nothing is learnt either
    out, _ = _run(SETTINGS, t, torque, gear, np.full_like(speed, math.nan))
    assert not out[-1].converged and out[-1].episodes == 0


def test_short_episodes_are_skipped() -> None:
    t, torque, gear, speed = _synthetic(7.5, 6, neutral_s=0.05)
    out, _ = _run(SETTINGS, t, torque, gear, speed)
    assert out[-1].episodes == 0 and out[-1].used == 0.0


def test_a_wrong_map_is_bounded_and_counted() -> None:
    t, torque, gear, speed = _synthetic(80.0, 5)
    out, estimator = _run(SETTINGS, t, torque, gear, speed)
    assert out[-1].offset == SETTINGS.max_offset and out[-1].clamped
    assert out[-1].used == SETTINGS.max_offset  # converged: the spread is 0
    assert estimator.state.clamped > 0


def test_a_time_jump_restarts_the_learning_but_keeps_the_fault_total() -> None:
    t, torque, gear, speed = _synthetic(80.0, 4)
    _, estimator = _run(SETTINGS, t, torque, gear, speed)
    clamped = estimator.state.clamped
    assert estimator.estimate.converged
    after = estimator.update(float(t[-1]) - 10.0, 0.0, 2, 300.0)  # a looped bag
    assert after.episodes == 0 and not after.converged and after.used == 0.0
    assert estimator.state.clamped == clamped
    # a repeated stamp is held, not a restart
    estimator2 = _run(SETTINGS, t, torque, gear, speed)[1]
    held = estimator2.update(float(t[-1]), 0.0, 2, 300.0)
    assert held == estimator2.estimate and held.converged


def test_step_on_records_and_wrapper_agree() -> None:
    rng = np.random.default_rng(11)
    t, torque, gear, speed = _synthetic(4.0, 8, speed_noise=0.3, dt=0.002, seed=5)
    # time jumps, repeated stamps, non-finite values
    t = t.copy()
    t[3000:] += 0.8
    t[6000] = t[5999]
    torque[rng.integers(0, t.size, 20)] = math.nan
    config = TorqueOffsetConfig(min_episodes=2, converged_std=0.5)
    prm, s, row = offset_params(config), new_offset_state(), new_offset_estimate()
    wrapper = TorqueOffsetEstimator(config, J_E)
    for tk, tq, g, w in zip(t, torque, gear, speed, strict=True):
        torque_offset_step(prm, J_E, s, float(tk), float(tq), float(g), float(w), row)
        assert wrapper.update(float(tk), float(tq), int(g), float(w)) == offset_from_record(row)
        np.testing.assert_array_equal(
            np.array(s.tolist(), dtype=float), np.array(wrapper.state.tolist(), dtype=float)
        )
    assert wrapper.estimate.episodes >= 2 and wrapper.state.last_t == t[-1]


@pytest.mark.parametrize(
    ('key', 'value'),
    [('min_episode_time', 0.0), ('max_offset', -1.0), ('max_gap', math.inf), ('min_episodes', 1),
     ('min_episodes', 2.5)],
)  # fmt: skip
def test_bad_settings_are_refused(key: str, value: float) -> None:
    with pytest.raises(ConfigurationError, match=key):
        TorqueOffsetConfig(**{key: value})
    with pytest.raises(ConfigurationError, match=key):
        EstimatorConfig.from_mapping({f'torque_offset.{key}': value})


_SIMS: dict[float, SimResult] = {}


def _drive(offset: float) -> SimResult:
    """mass_drive's first 100 s at 200 Hz with encoder and speed noise, the engine map
    ``offset`` N m off (cached)."""
    if offset not in _SIMS:
        scenario = load_scenario(CONFIG / 'scenarios' / 'mass_drive.yaml')
        _SIMS[offset] = simulate(
            PARAMS,
            dataclasses.replace(
                scenario,
                duration=100.0,
                sensors=SensorSettings(
                    rate_hz=200.0, seed=4, encoder_counts_per_rev=96, speed_noise_std=0.05
                ),
                true_vehicle=VehicleVariant(engine_torque_offset_nm=offset),
            ),
        )
    return _SIMS[offset]


def _engine_cascade(sim: SimResult, config: EstimatorConfig) -> CascadeResult:
    return run_cascade(
        CascadeSeries(
            sim.t,
            sim.wheel_angle,
            sim.body_speed,
            sim.wheel_torque,
            engine=np.stack([sim.engine_torque, sim.gear.astype(float), sim.engine_speed], axis=1),
        ),
        CascadeSettings(VEHICLE, estimator=config, torque_source='engine', drivetrain=DRIVETRAIN),
    )


def _slope_rms(res: CascadeResult, sim: SimResult, after: float) -> float:
    """Slope RMS [rad] where valid after ``after`` [s], brakes off (the engine path cannot
    see the brakes, docs/estimation.md)."""
    braking = np.abs(sim.brake_torque).sum(axis=1) > 0.0
    mask = res.slope_valid & (sim.t >= after) & ~braking
    return float(np.sqrt(np.mean((res.slope - sim.slope)[mask] ** 2)))


@pytest.mark.parametrize('offset', [10.0, -10.0])
def test_an_offset_map_is_learnt_in_the_shifts_and_the_slope_recovers(offset: float) -> None:
    sim, exact = _drive(offset), _drive(0.0)
    on = _engine_cascade(sim, ON)
    off = _engine_cascade(sim, OFF)
    assert on.torque_offset_converged[-1]
    k0 = int(np.argmax(on.torque_offset_converged))
    assert sim.t[k0] < 30.0  # the first shifts of the drive
    assert np.max(np.abs(on.torque_offset[k0:] - offset)) < 0.2
    np.testing.assert_array_equal(on.torque_offset_used[:k0], 0.0)
    after = float(sim.t[k0]) + 1.0
    # after convergence the slope is as good as with an exact map, far better than without
    reference = _slope_rms(_engine_cascade(exact, OFF), exact, after)
    assert _slope_rms(on, sim, after) < 1.1 * reference
    assert _slope_rms(off, sim, after) > 2.0 * reference
    assert on.faults['engine.torque_offset_clamped'] == 0
    # the measured path and the off switch leave the result without offset fields
    assert off.torque_offset.shape == (0,) and 'engine.torque_offset_clamped' not in off.faults


def test_the_live_chain_stamp_by_stamp_equals_the_cascade_on_the_record() -> None:
    sim = _drive(10.0)
    n = 14000  # 70 s: the offset converges inside
    cut = dataclasses.replace(
        sim, **{f: getattr(sim, f)[:n] for f in ('t', 'wheel_angle', 'body_speed', 'wheel_torque',
                                                  'engine_torque', 'gear', 'engine_speed')}
    )  # fmt: skip
    ref = _engine_cascade(cut, ON)
    assert ref.torque_offset_converged[-1]
    settings = ChainSettings(
        vehicle=VEHICLE,
        curves=TyreCurves.from_tire(PARAMS.tire),
        estimator=ON,
        torque_source='engine',
        drivetrain=DRIVETRAIN,
    )
    chain = Chain(settings)
    for k in range(0, n):
        row = (cut.engine_torque[k], float(cut.gear[k]), cut.engine_speed[k])
        out = chain.update(float(cut.t[k]), cut.wheel_angle[k], float(cut.body_speed[k]),
                           cut.wheel_torque[k], row)  # fmt: skip
        assert out.estimates.slope == ref.slope[k]
        assert out.torque_offset is not None
        assert out.torque_offset.used == ref.torque_offset_used[k]
    assert out.torque_offset.offset == ref.torque_offset[-1]


def test_the_chain_reports_a_clamped_offset_on_its_diagnostics() -> None:
    sim = _drive(10.0)
    n = 6000  # 30 s: the offset converges at the third shift, beyond a 5 N m bound
    bounded = dataclasses.replace(ON, torque_offset=TorqueOffsetConfig(max_offset=5.0))
    chain = Chain(
        ChainSettings(
            vehicle=VEHICLE,
            curves=TyreCurves.from_tire(PARAMS.tire),
            estimator=bounded,
            torque_source='engine',
            drivetrain=DRIVETRAIN,
        )
    )
    assert chain.fault_report().counts['engine.torque_offset_clamped'] == 0
    clamped = 0
    for k in range(n):
        row = (sim.engine_torque[k], float(sim.gear[k]), sim.engine_speed[k])
        out = chain.update(float(sim.t[k]), sim.wheel_angle[k], float(sim.body_speed[k]),
                           sim.wheel_torque[k], row)  # fmt: skip
        assert out.torque_offset is not None
        clamped += out.torque_offset.clamped
    assert out.torque_offset.offset == 5.0
    report = chain.fault_report()
    assert 'engine.torque_offset_clamped' in report.active and report.level == WARN
    assert report.counts['engine.torque_offset_clamped'] == clamped > 0
    # the measured path has no engine part
    plain = Chain(ChainSettings(vehicle=VEHICLE, curves=TyreCurves.from_tire(PARAMS.tire)))
    assert not any(k.startswith('engine.') for k in plain.fault_report().counts)
