"""Set-ups shared by the online mass and rolling radius tests (issue 16).

The Clio of the vehicle file; a drive that obeys the estimator's own model (the standalone
and estimator-level tests); the simulator's mass_drive with a car that is not the file, run
through `run_cascade` and through the per-stamp chain the nodes run (the cascade tests); and
a replay configuration file's estimator settings.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from vd_common.vehicle.params import load_vehicle
from vd_observer_node.chain import Chain
from vd_observer_node.estimation.cascade import (
    CascadeResult,
    CascadeSeries,
    CascadeSettings,
    run_cascade,
)
from vd_observer_node.estimation.estimator import EstimatorConfig
from vd_observer_node.estimation.faults import FaultReport
from vd_observer_node.estimation.vehicle import load_estimator_vehicle
from vd_observer_node.situation.chain_settings import ChainSettings
from vd_observer_node.situation.friction_potential import TyreCurves
from vd_observer_node.tools.settings_file import load_settings_file
from vd_sim_node.vehicle.scenario import (
    PiecewiseConstant,
    Scenario,
    SensorSettings,
    VehicleVariant,
    load_scenario,
)
from vd_sim_node.vehicle.simulation import SimResult, simulate

FloatArray = NDArray[np.float64]

CONFIG = Path(__file__).resolve().parents[2] / 'vd_sim_node' / 'config'
VEHICLE_FILE = CONFIG.parents[1] / 'vd_common' / 'config' / 'clio_rl_1_1.yaml'
#: the simulator's vehicle and the estimators' view of it
PARAMS = load_vehicle(VEHICLE_FILE)
VEHICLE = load_estimator_vehicle(VEHICLE_FILE)
G = VEHICLE.gravity
#: [s] step of the model drives
DT = 1e-3
#: [Hz] sensor rate of the simulated drives
RATE_HZ = 200.0
SENSORS = SensorSettings(rate_hz=RATE_HZ, seed=4, encoder_counts_per_rev=96, speed_noise_std=0.05)


# -- drives that obey the estimator's model --------------------------------------------------


def model_drive(
    mass: float,
    duration: float = 60.0,
    force_steps: bool = True,
    grade_deg: float = 3.0,
    v0: float = 15.0,
    seed: int = 0,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """(t, sum_fx, speed, slope) of a car of ``mass`` obeying the estimator's model.

    The force steps every 3 s between levels that keep the speed within 8-25 m/s (or holds
    the force that keeps a constant speed); the grade is a slow sine of ``grade_deg``.
    """
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration, DT)
    slope = np.radians(grade_deg) * np.sin(2.0 * math.pi * t / 40.0)
    v = np.empty_like(t)
    fx = np.empty_like(t)
    v[0] = v0
    level = 0.0
    for k in range(t.size):
        speed = v[k]
        c_r = VEHICLE.rolling_c0 * (1.0 + VEHICLE.rolling_c1 * speed / 160.0)
        resist = VEHICLE.drag_factor * speed**2 + mass * G * (
            math.sin(slope[k]) + c_r * math.cos(slope[k])
        )
        if force_steps and k % 3000 == 0:
            # accelerate when slow, brake when fast, else a random step
            low, high = (
                (0.5, 2.5) if speed < 12.0 else (-2.0, -0.5) if speed > 22.0 else (-1.5, 2.0)
            )
            level = rng.uniform(low, high) * 1000.0
        fx[k] = resist + (level if force_steps else 0.0)
        if k + 1 < t.size:
            v[k + 1] = speed + DT * (fx[k] - resist) / mass
    return t, fx, v, slope


def series(out: Sequence[Any], name: str) -> FloatArray:
    """The estimate ``name`` of every stamp of `Estimator.update`'s outputs."""
    return np.array([getattr(e, name) for e in out], dtype=np.float64)


# -- simulated drives through the cascade and the chain --------------------------------------


def simulated_mass_drive(car: VehicleVariant, duration: float) -> SimResult:
    """The first `duration` s of mass_drive with the true car `car`, encoder and speed noise."""
    scenario = load_scenario(CONFIG / 'scenarios' / 'mass_drive.yaml')
    return simulate(
        PARAMS,
        dataclasses.replace(scenario, duration=duration, sensors=SENSORS, true_vehicle=car),
    )


def steady_drive(
    name: str, duration: float, throttle: float, gear: int, speed: float, car: VehicleVariant
) -> SimResult:
    """`duration` s at a constant ``throttle`` in ``gear`` from ``speed`` [m/s] on a flat
    road, with the true car `car`, encoder and speed noise."""
    scenario = Scenario(
        name=name,
        duration=duration,
        throttle=PiecewiseConstant.constant(throttle),
        initial_gear=gear,
        initial_speed=speed,
        sensors=SENSORS,
        true_vehicle=car,
    )
    return simulate(PARAMS, scenario)


def cascade(sim: SimResult, config: EstimatorConfig) -> CascadeResult:
    """`run_cascade` on the sensors of `sim` with the estimator settings `config`."""
    return run_cascade(
        CascadeSeries(sim.t, sim.wheel_angle, sim.body_speed, sim.wheel_torque),
        CascadeSettings(VEHICLE, estimator=config),
    )


def looped_record(sim: SimResult, seconds: float) -> CascadeSeries:
    """The record of `sim` as a looped bag holds it: its first ``seconds`` again at the end
    (a jump back in time)."""
    loop = sim.t < seconds
    return CascadeSeries(
        np.concatenate([sim.t, sim.t[loop]]),
        np.vstack([sim.wheel_angle, sim.wheel_angle[loop]]),
        np.concatenate([sim.body_speed, sim.body_speed[loop]]),
        np.vstack([sim.wheel_torque, sim.wheel_torque[loop]]),
    )


def chain_run(
    sim: SimResult, config: EstimatorConfig, name: str
) -> tuple[np.ndarray, list[FaultReport]]:
    """The per-stamp chain (what the pipeline node runs) over `sim`: the estimate `name` per
    stamp and the fault report once a second, as the nodes publish it."""
    settings = ChainSettings(
        vehicle=VEHICLE,
        curves=TyreCurves.from_tire(PARAMS.tire),
        estimator=config,
    )
    chain = Chain(settings)
    reports = []
    values = np.empty(sim.t.size)
    for k in range(sim.t.size):
        out = chain.update(
            float(sim.t[k]), sim.wheel_angle[k], float(sim.body_speed[k]), sim.wheel_torque[k]
        )
        values[k] = getattr(out.estimates, name)
        if k % int(RATE_HZ) == 0:  # the nodes report once a second
            reports.append(chain.fault_report())
    return values, reports


# -- settings ---------------------------------------------------------------------------------


def replay_estimator_config(folder: Path, text: str) -> EstimatorConfig:
    """The estimator settings `vd replay` reads from a configuration file holding ``text``."""
    path = folder / 'replay.yaml'
    path.write_text(text, encoding='utf-8')
    return load_settings_file(path).settings().estimator
