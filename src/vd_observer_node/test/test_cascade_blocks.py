"""A record run block by block with a carried `CascadeState` equals one call on the whole record.

`run_cascade` (the one cascade loop, `cascade_step.cascade_block`, which the live chain runs
on one stamp at a time), every torque path (measured, engine with clutch slip and an upshift,
none), wheel angles and wheel speeds,
with faulty samples and a gap inside the record; blocks of uneven sizes, including empty ones
and one stamp. Bit for bit: the streamed replay relies on it.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from vd_common.vehicle.params import load_vehicle
from vd_observer_node.estimation.cascade import (
    CascadeResult,
    CascadeSeries,
    CascadeSettings,
    CascadeState,
    run_cascade,
)
from vd_observer_node.estimation.drivetrain import Drivetrain
from vd_observer_node.estimation.estimator import EstimatorConfig
from vd_observer_node.estimation.observer import ObserverConfig
from vd_observer_node.estimation.vehicle import load_estimator_vehicle
from vd_sim_node.vehicle.scenario import load_scenario
from vd_sim_node.vehicle.simulation import simulate

CONFIG = Path(__file__).resolve().parents[2] / 'vd_sim_node' / 'config'
VEHICLE_FILE = CONFIG.parents[1] / 'vd_common' / 'config' / 'clio_rl_1_1.yaml'
VEHICLE = load_estimator_vehicle(VEHICLE_FILE)
DRIVETRAIN = Drivetrain.from_params(load_vehicle(VEHICLE_FILE))
RATE_HZ = 200.0


@pytest.fixture(scope='module')
def record() -> dict[str, np.ndarray]:
    """paper_table1's launch and first upshift (13 s), with faults the observers count."""
    scenario = load_scenario(CONFIG / 'scenarios' / 'paper_table1.yaml')
    ideal = dataclasses.replace(
        scenario.sensors, rate_hz=RATE_HZ, encoder_counts_per_rev=0, speed_noise_std=0.0
    )
    sim = simulate(
        load_vehicle(VEHICLE_FILE), dataclasses.replace(scenario, duration=13.0, sensors=ideal)
    )
    keep = np.ones(len(sim.t), dtype=bool)
    keep[1200:1400] = False  # a 1 s gap: the observers restart
    t = sim.t[keep].copy()
    angle = sim.wheel_angle[keep].copy()
    speed = sim.body_speed[keep].copy()
    torque = sim.wheel_torque[keep].copy()
    engine = np.stack([sim.engine_torque, sim.gear.astype(float), sim.engine_speed], axis=1)
    engine = engine[keep].copy()
    omega = np.gradient(sim.wheel_angle, sim.t, axis=0)[keep]  # wheel speeds [rad/s]
    angle[500, 1] = math.nan
    speed[700] = math.inf
    engine[1800, 1] = 2.5  # a gear the box lacks
    t[900] = t[899]  # a repeated stamp
    return {'t': t, 'angle': angle, 'speed': speed, 'torque': torque, 'engine': engine,
            'omega': omega}  # fmt: skip


def _bounds(n: int, seed: int) -> list[int]:
    """Uneven block ends: empty blocks, single stamps and long runs."""
    rng = np.random.default_rng(seed)
    cuts = [0, 0, 1, 2, 2, *rng.integers(0, n, 40).tolist(), n - 1, n, n]
    return sorted(cuts)


def _assert_equal(got: CascadeResult, whole: CascadeResult) -> None:
    for f in dataclasses.fields(whole):
        a, b = getattr(got, f.name), getattr(whole, f.name)
        if isinstance(b, np.ndarray):
            np.testing.assert_array_equal(a, b, err_msg=f.name)
        else:
            assert a == b, f.name


def _concat(parts: list[CascadeResult]) -> CascadeResult:
    last = parts[-1]
    values: dict[str, Any] = {
        f.name: np.concatenate([getattr(p, f.name) for p in parts])
        for f in dataclasses.fields(last)
        if isinstance(getattr(last, f.name), np.ndarray)
    }
    return dataclasses.replace(last, **values)


@pytest.mark.parametrize(
    ('source', 'wheel_input'),
    [('measured', 'angle'), ('engine', 'angle'), ('none', 'angle'), ('measured', 'speed')],
)
@pytest.mark.parametrize('adaptation', ['off', 'mass', 'mass+radius'])
def test_blocks_with_a_carried_state_equal_the_whole_record(
    record: dict[str, np.ndarray], source: str, wheel_input: str,
    adaptation: str,
) -> None:  # fmt: skip
    wheels = record['angle'] if wheel_input == 'angle' else record['omega']
    # the online mass and radius live in the estimator's state: carried with it
    estimator = EstimatorConfig(
        mass_adaptation=adaptation != 'off', radius_adaptation='radius' in adaptation
    )
    settings = CascadeSettings(
        VEHICLE,
        ObserverConfig(wheel_input=wheel_input),
        estimator,
        torque_source=source,
        drivetrain=DRIVETRAIN if source != 'measured' else None,
    )
    n = len(record['t'])

    def call(sl: slice, state: CascadeState | None) -> CascadeResult:
        engine = record['engine'][sl] if source == 'engine' else None
        series = CascadeSeries(
            record['t'][sl], wheels[sl], record['speed'][sl], record['torque'][sl], engine
        )
        return run_cascade(series, settings, state)

    whole = call(slice(0, n), None)
    assert sum(whole.faults.values()) > 0  # the faults are counted, so carried
    if source == 'engine':
        assert whole.torque_valid.any() and not whole.torque_valid.all()
    if adaptation == 'mass' and source == 'measured':
        assert whole.mass_excited.any()  # the mass estimate moved: its state is carried
    if 'radius' in adaptation and source == 'measured':
        assert (whole.radius_free_wheels > 0).any()  # the radius estimate moved
    state = CascadeState()
    bounds = _bounds(n, seed=len(source) + len(wheel_input))
    parts = [call(slice(a, b), state) for a, b in itertools.pairwise(bounds)]
    assert state.parts is not None
    _assert_equal(_concat(parts), whole)
    # a fresh state per block is NOT the whole record: the test can fail
    fresh = [call(slice(a, b), CascadeState()) for a, b in itertools.pairwise(bounds)]
    assert not np.array_equal(_concat(fresh).speed, whole.speed)
