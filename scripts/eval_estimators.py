#!/usr/bin/env python3
"""Accuracy of the observer / estimator cascade against the simulator's truth.

Runs `vd_sim_node.vehicle.simulation.simulate` on a scenario (default paper_table1) with
ideal sensors and with a 96 counts/rev encoder plus body-speed noise, feeds the sensor
signals through `vd_observer_node.estimation.cascade.run_cascade` and prints the error figures of
the issue's accuracy targets. Evaluation window: t >= 1 s, excluding +-0.5 s around slope steps
and gear shifts (the scenario's events whose description mentions 'slope' or 'shift').

Then the same run through each torque path (issue 15): measured wheel torques, the engine
torque and gear through the drivetrain (`estimation.drivetrain`), and no torque: Fx, mu and
slope RMS where each path says its estimates are valid, their coverage, and the figures
while braking (the engine path cannot see the brakes).

Usage:
    python scripts/eval_estimators.py [--scenario PATH] [--cases ideal,noisy]
        [--discretization implicit] [--wheel-lipschitz 300] [--speed-lipschitz 20]
        [--slope-tau 0.05] [--force-tau 0.0] [--load-transfer tire_forces]
        [--torque-paths measured,engine,none] [--no-defaults]

Last, omega's relative RMS with every setting at its default (the wheel L follows the angles'
resolution, issue 38) on ideal angles and a 96 counts/rev encoder at 1 kHz and 100 Hz, beside
the same runs with L fixed at its floor.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'src' / 'vd_observer_node'))
sys.path.insert(0, str(ROOT / 'src' / 'vd_sim_node'))
sys.path.insert(0, str(ROOT / 'src' / 'vd_common'))

from vd_observer_node.estimation.body_pitch import vehicle_body_pitch  # noqa: E402
from vd_observer_node.estimation.cascade import (  # noqa: E402
    CascadeResult,
    CascadeSeries,
    CascadeSettings,
    run_cascade,
)
from vd_observer_node.estimation.drivetrain import Drivetrain  # noqa: E402
from vd_observer_node.estimation.estimator import EstimatorConfig  # noqa: E402
from vd_observer_node.estimation.imu_settings import imu_grade_config  # noqa: E402
from vd_observer_node.estimation.observer import ObserverConfig  # noqa: E402
from vd_observer_node.estimation.vehicle import EstimatorVehicle, load_estimator_vehicle  # noqa: E402

VEHICLE_FILE = ROOT / 'src' / 'vd_common' / 'config' / 'clio_rl_1_1.yaml'
SCENARIO_FILE = ROOT / 'src' / 'vd_sim_node' / 'config' / 'scenarios' / 'paper_table1.yaml'
CASES = {
    # name: (encoder counts per rev, body-speed noise std [m/s]); targets below.
    'ideal': (0, 0.0),
    'noisy': (96, 0.05),
}
TARGETS = {
    'ideal': {
        'slope_rms_deg': 0.2,
        'mu_rms': 0.01,
        'fx_rms_pct': 2.0,
        'fz_rms_pct': 1.0,
        'omega_rel_pct': 0.1,
    },
    'noisy': {'slope_rms_deg': 0.5, 'mu_rms': 0.03},
}


def evaluation_mask(t: np.ndarray, events: tuple[tuple[float, str], ...]) -> np.ndarray:
    """shape (N,), bool: t >= 1 s and not within 0.5 s of a slope step or gear shift."""
    mask = t >= 1.0
    for stamp, text in events:
        if 'slope' in text or 'shift' in text:
            mask &= np.abs(t - stamp) > 0.5
    return mask


def rms(x: np.ndarray) -> float:
    """Root mean square of all elements (nan if empty)."""
    return float(np.sqrt(np.mean(np.square(x)))) if x.size else float('nan')


def figures(
    sim: Any, est: CascadeResult, vehicle: EstimatorVehicle, mask: np.ndarray
) -> dict[str, float]:
    """Error figures over the evaluation mask."""
    out: dict[str, float] = {}
    out['slope_rms_deg'] = np.degrees(rms(est.slope[mask] - sim.slope[mask]))
    moving = mask & (np.abs(sim.speed_true) > 0.5)
    out['slope_rms_deg_moving'] = np.degrees(rms(est.slope[moving] - sim.slope[moving]))
    fz_hat = np.maximum(est.fz, 1.0)
    mu_hat = est.fx / fz_hat
    excited = mask[:, None] & (np.abs(sim.fx) > 0.05 * sim.fz)
    out['mu_rms'] = rms((mu_hat - sim.mu)[excited])
    out['mu_samples'] = float(excited.sum())
    out['mu_valid_coverage_pct'] = 100.0 * float(est.mu_valid[excited].mean())
    fx_max = float(np.abs(sim.fx[mask]).max())
    out['fx_rms_N'] = rms((est.fx - sim.fx)[mask])
    out['fx_rms_pct'] = 100.0 * out['fx_rms_N'] / fx_max
    static = vehicle.static_wheel_loads
    out['fz_rms_pct'] = 100.0 * rms(((est.fz - sim.fz) / static)[mask])
    out['fz_quasi_static_gap_pct'] = 100.0 * rms(
        ((_quasi_static_fz(sim, vehicle) - sim.fz) / static)[mask]
    )
    spinning = mask[:, None] & (np.abs(sim.omega) > 5.0)
    error = (est.omega - sim.omega)[spinning]
    # the report's definition (tools/report/evaluation.py): RMS of the error over RMS of the
    # truth on the spinning samples, not the RMS of per-sample ratios (which weighs slow
    # wheels more)
    out['omega_rel_pct'] = 100.0 * rms(error) / rms(sim.omega[spinning])
    rel = np.abs(error) / np.abs(sim.omega)[spinning]
    out['omega_rel_max_pct'] = 100.0 * float(rel.max()) if rel.size else float('nan')
    out['omega_dot_rms'] = rms((est.omega_dot - sim.omega_dot)[mask])
    out['accel_rms'] = rms((est.accel - sim.accel_true)[mask])
    return out


def torque_path_figures(
    sim: Any, est: CascadeResult, vehicle: EstimatorVehicle, mask: np.ndarray
) -> dict[str, float]:
    """Error figures of one torque path where its own validity flags allow.

    fx over the samples where the torque path held (torque_valid); mu where the wheel is
    excited (|Fx_true| > 0.05 Fz_true) and the estimate valid; slope where valid and moving.
    The braking figures take the samples with any brake torque (the hold brake at standstill
    included).
    """
    out: dict[str, float] = {}
    held = mask & est.torque_valid
    out['torque_valid_pct'] = 100.0 * float(held.sum()) / max(int(mask.sum()), 1)
    out['fx_rms_N'] = rms((est.fx - sim.fx)[held])
    out['fz_rms_pct'] = 100.0 * rms(((est.fz - sim.fz) / vehicle.static_wheel_loads)[mask])
    excited = mask[:, None] & (np.abs(sim.fx) > 0.05 * sim.fz)
    valid_mu = excited & est.mu_valid
    out['mu_rms'] = rms((est.mu - sim.mu)[valid_mu])
    out['mu_valid_coverage_pct'] = 100.0 * float(valid_mu.sum()) / max(int(excited.sum()), 1)
    moving = mask & (np.abs(sim.speed_true) > 0.5)
    valid_slope = moving & est.slope_valid
    out['slope_rms_deg'] = float(np.degrees(rms((est.slope - sim.slope)[valid_slope])))
    out['slope_valid_pct'] = 100.0 * float(valid_slope.sum()) / max(int(moving.sum()), 1)
    braking = mask & (sim.brake_torque.max(axis=1) > 0.0) & (np.abs(sim.speed_true) > 0.5)
    out['braking_samples'] = float(braking.sum())
    if braking.any():
        out['braking_fx_bias_N'] = float(np.mean((est.fx - sim.fx)[braking]))
        out['braking_mu_valid_pct'] = 100.0 * float(est.mu_valid[braking].mean())
        out['braking_slope_valid_pct'] = 100.0 * float(est.slope_valid[braking].mean())
        both = braking & est.slope_valid
        out['braking_slope_bias_deg'] = float(
            np.degrees(np.mean((est.slope - sim.slope)[both])) if both.any() else float('nan')
        )
    return out


def _quasi_static_fz(sim: Any, vehicle: EstimatorVehicle) -> np.ndarray:
    """Textbook loads from the TRUE accel and slope: the best any quasi-static Fz can do."""
    from vd_observer_node.estimation.formulas import wheel_loads

    ground = vehicle.mass * sim.accel_true + vehicle.mass * vehicle.gravity * np.sin(sim.slope)
    ground = ground + sim.aero * np.sign(sim.speed_true)
    return wheel_loads(ground, np.cos(sim.slope), vehicle)


def main() -> None:
    """Parse arguments, simulate, estimate, print figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--scenario', type=Path, default=SCENARIO_FILE)
    parser.add_argument('--vehicle', type=Path, default=VEHICLE_FILE)
    parser.add_argument('--cases', default='ideal,noisy')
    parser.add_argument('--discretization', default='implicit')
    parser.add_argument('--wheel-lipschitz', type=float, default=None)
    parser.add_argument('--speed-lipschitz', type=float, default=None)
    parser.add_argument('--slope-tau', type=float, default=None)
    parser.add_argument('--force-tau', type=float, default=None)
    parser.add_argument('--load-transfer', default=None)
    parser.add_argument('--torque-paths', default='measured,engine,none')
    parser.add_argument(
        '--no-defaults', action='store_true',
        help="skip omega's figures with every setting at its default (4 more simulations)",
    )  # fmt: skip
    parser.add_argument(
        '--imu', action='store_true',
        help='the car carries an IMU (0.05 m/s^2 noise, 0.08 m/s^2 bias; gyro 0.004 rad/s '
        'noise, 0.003 rad/s bias) and the cascade fuses it (estimation.imu_grade)',
    )  # fmt: skip
    parser.add_argument(
        '--no-gyro', action='store_true',
        help='with --imu: fuse its specific force alone (ImuGradeConfig.gyro = False)',
    )  # fmt: skip
    args = parser.parse_args()

    from vd_common.vehicle.params import load_vehicle
    from vd_sim_node.vehicle.scenario import load_scenario
    from vd_sim_node.vehicle.simulation import simulate

    sim_vehicle = load_vehicle(args.vehicle)
    vehicle = load_estimator_vehicle(args.vehicle)
    drivetrain = Drivetrain.from_params(sim_vehicle)
    scenario = load_scenario(args.scenario)
    for case in args.cases.split(','):
        counts, noise = CASES[case]
        obs_kw: dict[str, Any] = {'discretization': args.discretization}
        est_kw: dict[str, Any] = {}
        defaults = TUNED[case]
        obs_kw['wheel_lipschitz'] = args.wheel_lipschitz or defaults['wheel_lipschitz']
        obs_kw['speed_lipschitz'] = args.speed_lipschitz or defaults['speed_lipschitz']
        est_kw['slope_filter_tau'] = (
            defaults['slope_filter_tau'] if args.slope_tau is None else args.slope_tau
        )
        est_kw['force_filter_tau'] = (
            defaults['force_filter_tau'] if args.force_tau is None else args.force_tau
        )
        if args.load_transfer:
            est_kw['load_transfer_source'] = args.load_transfer
        sensors = dataclasses.replace(
            scenario.sensors, encoder_counts_per_rev=counts, speed_noise_std=noise
        )
        if args.imu:
            sensors = dataclasses.replace(
                sensors, imu=True, imu_noise_std=0.05, imu_bias=0.08, imu_gyro_noise_std=0.004,
                imu_gyro_bias=0.003,
            )  # fmt: skip
        t0 = time.perf_counter()
        sim = simulate(sim_vehicle, dataclasses.replace(scenario, sensors=sensors))
        t_sim = time.perf_counter() - t0
        obs_cfg = ObserverConfig(**obs_kw)
        est_cfg = EstimatorConfig(**est_kw)
        t0 = time.perf_counter()
        imu, imu_config = None, None
        if args.imu:
            # the whole sensor: specific force and pitch rate (`--no-gyro`: the first alone)
            imu = np.column_stack([sim.t, sim.imu[:, 0], sim.gyro])
            imu_config = dataclasses.replace(
                imu_grade_config(vehicle_body_pitch(args.vehicle)), gyro=not args.no_gyro
            )
        est = run_cascade(
            CascadeSeries(sim.t, sim.wheel_angle, sim.body_speed, sim.wheel_torque, imu=imu),
            CascadeSettings(vehicle, obs_cfg, est_cfg, imu=imu_config),
        )  # fmt: skip
        t_est = time.perf_counter() - t0
        mask = evaluation_mask(sim.t, sim.events)
        result = figures(sim, est, vehicle, mask)
        print(
            f'== {scenario.name} / {case}: encoder {counts or "ideal"} counts/rev, '
            f'speed noise {noise} m/s, {sim.t.size} samples'
        )
        print(f'   observer {obs_cfg}')
        print(f'   estimator {est_cfg}')
        print(
            f'   simulate {t_sim:.1f} s, cascade {t_est:.1f} s '
            f'({1e6 * t_est / sim.t.size:.0f} us/sample)'
        )
        for key, value in result.items():
            target = TARGETS.get(case, {}).get(key)
            verdict = (
                ''
                if target is None
                else (f'  target <= {target}: ' + ('MET' if value <= target else 'MISSED'))
            )
            print(f'   {key:26s} {value:12.5g}{verdict}')
        engine = np.stack([sim.engine_torque, sim.gear.astype(float), sim.engine_speed], axis=1)
        paths = [p for p in args.torque_paths.split(',') if p]
        if paths:
            print(f'   -- torque paths ({", ".join(paths)}), same run and settings:')
        per_path = {}
        for path in paths:
            path_est = run_cascade(
                CascadeSeries(
                    sim.t, sim.wheel_angle, sim.body_speed, sim.wheel_torque, engine=engine
                ),
                CascadeSettings(
                    vehicle,
                    observer=obs_cfg,
                    estimator=est_cfg,
                    torque_source=path,
                    drivetrain=drivetrain,
                ),
            )
            per_path[path] = torque_path_figures(sim, path_est, vehicle, mask)
        keys = list(next(iter(per_path.values()), {}))
        if keys:
            print('   ' + f'{"":26s}' + ''.join(f'{p:>12s}' for p in paths))
        for key in keys:
            row = ''.join(f'{per_path[p].get(key, float("nan")):12.5g}' for p in paths)
            print(f'   {key:26s}{row}')
    if not args.no_defaults:
        default_omega_figures(sim_vehicle, vehicle, scenario)


def default_omega_figures(sim_vehicle: Any, vehicle: EstimatorVehicle, scenario: Any) -> None:
    """omega's relative RMS with every setting at its default (issue 38: the wheel L
    follows the angles' resolution), ideal angles and a 96 counts/rev encoder, at 1 kHz
    and 100 Hz, each beside the same run with L fixed at its floor."""
    from vd_sim_node.vehicle.simulation import simulate

    target = TARGETS['ideal']['omega_rel_pct']
    print(f'== {scenario.name}: every setting at its default (the wheel L follows the resolution)')
    print(
        f'   {"sensors (body speed exact)":34s}{"omega_rel_pct":>14s}{"L fixed":>10s}'
        f'{"slope_deg":>11s}{"L fixed":>10s}'
    )
    for rate in (1000.0, 100.0):
        for counts in (0, 96):
            sensors = dataclasses.replace(
                scenario.sensors, encoder_counts_per_rev=counts, speed_noise_std=0.0,
                rate_hz=rate,
            )  # fmt: skip
            sim = simulate(sim_vehicle, dataclasses.replace(scenario, sensors=sensors))
            mask = evaluation_mask(sim.t, sim.events)
            row = {}
            for follow in (True, False):
                est = run_cascade(
                    CascadeSeries(sim.t, sim.wheel_angle, sim.body_speed, sim.wheel_torque),
                    CascadeSettings(vehicle, ObserverConfig(follow_resolution=follow)),
                )
                row[follow] = figures(sim, est, vehicle, mask)
            label = f'{rate:g} Hz, ' + (f'{counts} counts/rev' if counts else 'ideal angles')
            verdict = ''
            if rate == 1000.0 and not counts:
                met = row[True]['omega_rel_pct'] <= target
                verdict = f'  target <= {target}: ' + ('MET' if met else 'MISSED')
            print(
                f'   {label:34s}{row[True]["omega_rel_pct"]:14.5f}'
                f'{row[False]["omega_rel_pct"]:10.5f}{row[True]["slope_rms_deg"]:11.4f}'
                f'{row[False]["slope_rms_deg"]:10.4f}{verdict}'
            )


#: Settings chosen with this script (see docs/estimation.md, "Tuning").
TUNED: dict[str, dict[str, float]] = {
    # Ideal sensors: large L tracks torque steps and shifts closely (omega_dot, accel exact
    # to the discretization error); a short slope filter only smooths the shift transients.
    'ideal': {
        'wheel_lipschitz': 10000.0,
        'speed_lipschitz': 2000.0,
        'slope_filter_tau': 0.05,
        'force_filter_tau': 0.0,
    },
    # Encoder + speed noise: the ObserverConfig / EstimatorConfig defaults.
    'noisy': {
        'wheel_lipschitz': 300.0,
        'speed_lipschitz': 20.0,
        'slope_filter_tau': 0.1,
        'force_filter_tau': 0.0,
    },
}

if __name__ == '__main__':
    main()
