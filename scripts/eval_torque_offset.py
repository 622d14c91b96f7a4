#!/usr/bin/env python3
"""Engine-torque offset learnt in neutral on the engine path, against a map that is off (#16).

For each case (nominal map; engine torque signal +10 / -10 N m; +125 kg with +10 N m), with
ideal sensors and with the encoder + speed noise of scripts/eval_mass_adaptation.py plus
0.2 rad/s (~2 rpm) of white noise on the engine speed (a CAN engine speed is filtered; with
1 rad/s the engine path's clutch check, 2 rad/s, rejects most samples): simulates the TRUE
car and runs the compiled cascade on the ENGINE path (engine torque, gear, engine speed;
the vehicle file's drivetrain) twice, with ``torque_offset_adaptation`` off and on, and prints:

* the offset estimate at the end, the worst error after it converged, when it converged and
  how many neutral episodes (shifts) it had used by then;
* slope RMS, Fx RMS (sum of the four wheels, % of the true car's weight) and mu RMS, whole
  run and after convergence, off and on.

The window is scripts/eval_estimators.py's (t >= 1 s, +-0.5 s around slope steps and gear
shifts excluded) where the slope is valid, without the samples where the driver brakes: the
engine path cannot see the brakes (docs/estimation.md, 3.6), which the offset does not change.

Usage:
    python scripts/eval_torque_offset.py [--scenario PATH ...] [--cases nominal,torque+10]
        [--sensors ideal,noisy]
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'scripts'))
sys.path.insert(0, str(ROOT / 'src' / 'vd_observer_node'))
sys.path.insert(0, str(ROOT / 'src' / 'vd_sim_node'))
sys.path.insert(0, str(ROOT / 'src' / 'vd_common'))

from eval_estimators import evaluation_mask, rms  # noqa: E402
from eval_mass_adaptation import SCENARIOS, VEHICLE_FILE, simulate_case  # noqa: E402
from eval_mass_adaptation import _cascade as mass_cascade  # noqa: E402
from vd_common.vehicle.params import load_vehicle  # noqa: E402
from vd_observer_node.estimation.cascade import CascadeResult  # noqa: E402
from vd_observer_node.estimation.drivetrain import Drivetrain  # noqa: E402
from vd_observer_node.estimation.vehicle import EstimatorVehicle  # noqa: E402
from vd_sim_node.vehicle.scenario import load_scenario  # noqa: E402
from vd_sim_node.vehicle.simulation import SimResult  # noqa: E402

#: this script's case -> (eval_mass_adaptation case of the true car, its true offset [N m]);
#: '+125kg&torque+10' is built here (the load and the map together).
CASES = {
    'nominal': ('nominal', 0.0),
    'torque+10': ('torque+10', 10.0),
    'torque-10': ('torque-10', -10.0),
    '+125kg&torque+10': ('+125kg', 10.0),
}
#: engine-speed noise of the noisy sensors, [rad/s] (std; the simulator's is exact)
ENGINE_SPEED_NOISE = {'ideal': 0.0, 'noisy': 0.2}


def _simulate(scenario_path: Path, case: str, sensors: str) -> tuple[float, SimResult]:
    """The true car's run and its weight [N]."""
    nominal = load_vehicle(VEHICLE_FILE)
    base, offset = CASES[case]
    true_vp, sim = simulate_case(nominal, load_scenario(scenario_path), base, sensors)
    if case == '+125kg&torque+10':
        from vd_sim_node.vehicle.simulation import with_torque_offset

        sim = with_torque_offset(sim, true_vp, offset)
    noise = ENGINE_SPEED_NOISE[sensors]
    if noise:
        rng = np.random.default_rng(7)
        sim = dataclasses.replace(
            sim, engine_speed=sim.engine_speed + noise * rng.standard_normal(sim.t.size)
        )
    return true_vp.chassis.mass * true_vp.environment.gravity, sim


def _cascade(sim: SimResult, sensors: str, adapt: bool) -> CascadeResult:
    """The compiled cascade of the nominal file on the engine path."""
    nominal = load_vehicle(VEHICLE_FILE)
    return mass_cascade(
        sim,
        EstimatorVehicle.from_params(nominal),
        sensors,
        Drivetrain.from_params(nominal),
        torque_offset_adaptation=adapt,
    )


def _errors(res: CascadeResult, sim: SimResult, weight: float, window: np.ndarray) -> str:
    """Slope, Fx-sum and mu RMS over ``window`` where the slope is valid."""
    mask = window & res.slope_valid
    slope = math.degrees(rms(res.slope[mask] - sim.slope[mask]))
    fx = 100.0 * rms((res.fx.sum(axis=1) - sim.fx.sum(axis=1))[mask] / weight)
    excited = mask[:, None] & res.mu_valid & (np.abs(sim.fx) > 0.05 * sim.fz)
    mu = rms((res.mu - sim.mu)[excited])
    return f'slope {slope:.3f} deg, Fx sum {fx:.2f} % of weight, mu {mu:.4f}'


def report(scenario_path: Path, case: str, sensors: str) -> None:
    """Print one case's lines."""
    weight, sim = _simulate(scenario_path, case, sensors)
    true_offset = CASES[case][1]
    braking = np.abs(sim.brake_torque).sum(axis=1) > 0.0
    window = evaluation_mask(sim.t, sim.events) & ~braking
    off, on = _cascade(sim, sensors, False), _cascade(sim, sensors, True)
    conv = np.flatnonzero(on.torque_offset_converged)
    print(f'== {load_scenario(scenario_path).name} / {sensors} / {case}')
    if conv.size:
        k0 = int(conv[0])
        worst = float(np.max(np.abs(on.torque_offset[k0:] - true_offset)))
        print(
            f'  offset final {on.torque_offset[-1]:+.3f} N m (true {true_offset:+.1f}, std '
            f'{on.torque_offset_std[-1]:.3f}), worst after conv. {worst:.3f} N m, converged at '
            f'{sim.t[k0]:.2f} s after {on.torque_offset_episodes[k0]} neutral episodes '
            f'({on.torque_offset_episodes[-1]} in all), clamped '
            f'{on.faults["engine.torque_offset_clamped"]}'
        )
        after = window & (sim.t >= sim.t[k0])
    else:
        print(f'  offset never converged ({on.torque_offset_episodes[-1]} neutral episodes)')
        after = np.zeros_like(window)
    for name, res in (('off', off), ('on', on)):
        print(f'  [{name:3s}] whole run: {_errors(res, sim, weight, window)}')
        if after.any():
            print(f'        after conv.: {_errors(res, sim, weight, after)}')
    sys.stdout.flush()


def main() -> None:
    """Parse arguments, run every case, print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--scenario', type=Path, action='append')
    parser.add_argument('--cases', default=','.join(CASES))
    parser.add_argument('--sensors', default='ideal,noisy')
    args = parser.parse_args()
    load = os.getloadavg()
    print(
        f'eval_torque_offset {time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}, '
        f'load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}'
    )
    for path in args.scenario or SCENARIOS:
        for sensors in args.sensors.split(','):
            for case in args.cases.split(','):
                report(path, case, sensors)


if __name__ == '__main__':
    main()
