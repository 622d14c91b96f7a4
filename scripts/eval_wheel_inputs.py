#!/usr/bin/env python3
"""Wheel angles or wheel speeds as the observer's input: accuracy at 100 Hz and 1 kHz (issue 15).

One simulator run (default paper_table1) gives both inputs on the same stamps:

* angles: the scenario's encoder (96 counts/rev) on the true wheel angle, the second-order
  Levant differentiator (vd's default);
* speeds: what an ABS sensor reports, the mean wheel speed over the last sample period plus
  white noise (``--wheel-noise``, rad/s), the first-order differentiator
  (``ObserverConfig.wheel_input='speed'``).

Body speed (0.05 m/s noise) and torques are the same in both. At 100 Hz every signal is the
1 kHz run taken every 10th sample (the ABS mean over 10 ms). The figures are those of
scripts/eval_estimators.py (same evaluation window), plus the observer's omega_dot RMS.

Usage:
    python scripts/eval_wheel_inputs.py [--scenario PATH] [--wheel-noise 0.05]
        [--speed-lipschitz-list 300,100]
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'scripts'))
sys.path.insert(0, str(ROOT / 'src' / 'vd_observer_node'))
sys.path.insert(0, str(ROOT / 'src' / 'vd_sim_node'))
sys.path.insert(0, str(ROOT / 'src' / 'vd_common'))

from eval_estimators import (  # noqa: E402
    SCENARIO_FILE,
    TUNED,
    VEHICLE_FILE,
    evaluation_mask,
    figures,
)
from vd_observer_node.estimation.cascade import CascadeSeries, CascadeSettings, run_cascade  # noqa: E402
from vd_observer_node.estimation.estimator import EstimatorConfig  # noqa: E402
from vd_observer_node.estimation.observer import ObserverConfig  # noqa: E402
from vd_observer_node.estimation.vehicle import load_estimator_vehicle  # noqa: E402
from vd_observer_node.testing.standard_bags import abs_wheel_speeds  # noqa: E402

SHOWN = ('slope_rms_deg', 'mu_rms', 'fx_rms_pct', 'fz_rms_pct', 'omega_rel_pct', 'omega_dot_rms')


def every(sim: Any, step: int) -> Any:
    """The run taken every ``step``-th sample (every per-sample array sliced)."""
    n = sim.t.shape[0]
    return dataclasses.replace(
        sim,
        **{
            f.name: value[::step]
            for f in dataclasses.fields(sim)
            if isinstance(value := getattr(sim, f.name), np.ndarray) and value.shape[:1] == (n,)
        },
    )


def main() -> None:
    """Simulate once, run both inputs at both rates, print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--scenario', type=Path, default=SCENARIO_FILE)
    parser.add_argument('--wheel-noise', type=float, default=0.05)
    parser.add_argument('--speed-lipschitz-list', default='300,100')
    args = parser.parse_args()

    from vd_common.vehicle.params import load_vehicle
    from vd_sim_node.vehicle.scenario import load_scenario
    from vd_sim_node.vehicle.simulation import simulate

    vehicle = load_estimator_vehicle(VEHICLE_FILE)
    scenario = load_scenario(args.scenario)
    sensors = dataclasses.replace(
        scenario.sensors, rate_hz=1000.0, encoder_counts_per_rev=96, speed_noise_std=0.05
    )
    sim = simulate(load_vehicle(VEHICLE_FILE), dataclasses.replace(scenario, sensors=sensors))
    rng = np.random.default_rng(11)
    print(
        f'== {scenario.name}: {sim.t.size} samples at 1 kHz, encoder 96 counts/rev, ABS speed '
        f'noise {args.wheel_noise} rad/s, body speed noise 0.05 m/s; '
        f'load average {os.getloadavg()[0]:.1f}'
    )
    estimator = EstimatorConfig(slope_filter_tau=TUNED['noisy']['slope_filter_tau'])
    columns = ' '.join(f'{k:>14s}' for k in SHOWN)
    print(f'   {"input":8s} {"rate":>6s} {"L_wheel":>8s} {columns}')
    for rate, step in (('1 kHz', 1), ('100 Hz', 10)):
        run = every(sim, step)
        period = step * 1e-3
        speeds = abs_wheel_speeds(sim.t, sim.angle_true, run.t, period)
        speeds[run.t < sim.t[0] + period] = speeds[run.t >= sim.t[0] + period][0]
        speeds = speeds + rng.normal(0.0, args.wheel_noise, speeds.shape)
        mask = evaluation_mask(run.t, run.events)
        cases: list[tuple[str, float, np.ndarray, str]] = [
            ('angles', TUNED['noisy']['wheel_lipschitz'], run.wheel_angle, 'angle')
        ]
        for lip in args.speed_lipschitz_list.split(','):
            cases.append(('speeds', float(lip), speeds, 'speed'))
        for name, lip, wheels, wheel_input in cases:
            observer = ObserverConfig(
                wheel_lipschitz=lip,
                speed_lipschitz=TUNED['noisy']['speed_lipschitz'],
                wheel_input=wheel_input,
            )
            est = run_cascade(
                CascadeSeries(run.t, wheels, run.body_speed, run.wheel_torque),
                CascadeSettings(vehicle, observer=observer, estimator=estimator),
            )
            result = figures(run, est, vehicle, mask)
            print(
                f'   {name:8s} {rate:>6s} {lip:8g} '
                + ' '.join(f'{result[k]:14.4g}' for k in SHOWN)
            )


if __name__ == '__main__':
    main()
