#!/usr/bin/env python3
"""Detection delay, false alarms and friction-potential error of the alert core.

Simulates each scenario (default: launch_low_mu, braking_low_mu_hard, paper_table1) with ideal
sensors and with a 96 counts/rev encoder plus 0.05 m/s body-speed noise, runs the observer /
estimator cascade (`run_cascade`), then `FrictionPotentialEstimator` and `AlertMonitor` per
stamp exactly as the node would, and prints against the simulator's truth (definitions in
docs/alerts.md):

* per (kind, wheel) with a true onset: true onset, detection stamp (alert becomes active),
  delay = detection - true onset (goal <= 100 ms), and the reported onset stamp;
* alerts that became active with no true onset on that (kind, wheel): false alarms
  (goal on paper_table1: none);
* per axle and road segment where the tyre was truly excited beyond half its peak: mu_max
  error against the Magic Formula peak at the true road_mu and load (goal |err| <= 0.1).

Usage:
    python scripts/eval_alerts.py [--scenarios launch_low_mu,braking_low_mu_hard,paper_table1]
        [--cases ideal,noisy]
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'src' / 'vd_observer_node'))
sys.path.insert(0, str(ROOT / 'src' / 'vd_sim_node'))

from vd_observer_node.alerts import (  # noqa: E402
    ALERT_KINDS,
    AlertConfig,
    AlertMonitor,
    slip_velocity,
)
from vd_observer_node.cascade import run_cascade  # noqa: E402
from vd_observer_node.estimator import EstimatorConfig  # noqa: E402
from vd_observer_node.friction_potential import (  # noqa: E402
    ROAD_CLASS_NAMES,
    FrictionPotentialConfig,
    FrictionPotentialEstimator,
)
from vd_observer_node.observer import ObserverConfig  # noqa: E402
from vd_observer_node.vehicle import load_estimator_vehicle  # noqa: E402

VEHICLE_FILE = ROOT / 'src' / 'vd_sim_node' / 'config' / 'clio_rl_1_1.yaml'
SCENARIO_DIR = ROOT / 'src' / 'vd_sim_node' / 'config' / 'scenarios'
#: name: (encoder counts per rev, body-speed noise std [m/s]).
CASES = {'ideal': (0, 0.0), 'noisy': (96, 0.05)}
#: Observer / estimator settings per case, as tuned in scripts/eval_estimators.py.
TUNED: dict[str, dict[str, float]] = {
    'ideal': {'wheel_lipschitz': 10000.0, 'speed_lipschitz': 2000.0, 'slope_filter_tau': 0.05},
    'noisy': {'wheel_lipschitz': 300.0, 'speed_lipschitz': 20.0, 'slope_filter_tau': 0.1},
}
#: Truth onset of low_friction: |mu| reaches this fraction of the true peak.
LOW_FRICTION_TRUTH_RATIO = 0.8
#: Truth excitation for the mu_max error: utilisation beyond this fraction of the peak.
EXCITATION_RATIO = 0.5
#: Scale of the truth thresholds below which an alert counts as a false alarm.
RELAXED_SCALE = 0.8
DELAY_GOAL = 0.1
MU_MAX_GOAL = 0.1


def unit_road_peaks(tire: Any, fz: np.ndarray) -> dict[str, np.ndarray]:
    """MF peak mu and slip at road_mu = 1 for loads fz (any shape), driving and braking side.

    With the road scale only in D (the slip stiffness unchanged), Fx(k; r) = r Fx(k / r; 1),
    so the peak mu and its slip both scale with the road_mu r.
    """
    from vd_sim_node.vehicle.tire import magic_formula_fx

    grid_fz = np.linspace(200.0, 6000.0, 59)
    kappa = np.linspace(0.0, 0.6, 6001)
    out: dict[str, list[float]] = {'mu_drive': [], 's_drive': [], 'mu_brake': [], 's_brake': []}
    for load in grid_fz:
        drive = magic_formula_fx(kappa, load, 1.0, tire) / load
        brake = -magic_formula_fx(-kappa, load, 1.0, tire) / load
        out['mu_drive'].append(float(drive.max()))
        out['s_drive'].append(float(kappa[np.argmax(drive)]))
        out['mu_brake'].append(float(brake.max()))
        out['s_brake'].append(float(kappa[np.argmax(brake)]))
    clipped = np.clip(fz, grid_fz[0], grid_fz[-1])
    return {k: np.interp(clipped, grid_fz, np.asarray(v)) for k, v in out.items()}


def run_detectors(
    est: Any,
    speed: np.ndarray,
    radius: float,
    alert_cfg: AlertConfig,
    fric_cfg: FrictionPotentialConfig,
) -> dict[str, np.ndarray]:
    """Friction potential and alerts per stamp, as the node would compute them.

    The slip velocity uses the measured body speed, the speed the estimator's slip uses.
    """
    fric = FrictionPotentialEstimator(fric_cfg)
    monitor = AlertMonitor(alert_cfg)
    n = est.t.size
    level = np.zeros((n, 3, 4), dtype=np.int64)
    detected = np.full((n, 3, 4), math.nan)
    onset = np.full((n, 3, 4), math.nan)
    mu_max = np.zeros((n, 2))
    conf = np.zeros((n, 2))
    road = np.zeros((n, 2), dtype=np.int64)
    for k in range(n):
        t = float(est.t[k])
        slip_vel = slip_velocity(est.omega[k], float(speed[k]), radius)
        fit_slip = fric.fit_slip(slip_vel, float(speed[k]))
        pot = fric.update(t, fit_slip, est.mu[k], est.mu_valid[k])
        alerts = monitor.update(
            t, est.slip[k], slip_vel, est.mu[k], est.mu_valid[k], pot.wheel_mu_max()
        )
        for a in alerts:
            kind = ALERT_KINDS.index(a.kind)
            level[k, kind, a.wheel] = a.level
            detected[k, kind, a.wheel] = a.detected
            onset[k, kind, a.wheel] = a.onset
        mu_max[k] = pot.mu_max
        conf[k] = pot.confidence
        road[k] = pot.road_class
    return {
        'level': level,
        'detected': detected,
        'onset': onset,
        'mu_max': mu_max,
        'conf': conf,
        'road': road,
    }


def truth_conditions(sim: Any, peaks: dict[str, np.ndarray], scale: float = 1.0) -> np.ndarray:
    """shape (N, 3, 4), bool: the truth condition of each alert kind per wheel.

    traction: true slip >= scale * slip at the MF peak (driving side); lock: true slip <=
    -scale * peak slip (braking side); low_friction: |true mu| >= scale * 0.8 * MF peak mu,
    all at the true road_mu and wheel load. scale < 1 gives the relaxed condition used to
    judge false alarms.
    """
    r = sim.road_mu[:, None]
    s_drive = r * peaks['s_drive']
    s_brake = r * peaks['s_brake']
    mu_peak = np.where(sim.fx >= 0.0, r * peaks['mu_drive'], r * peaks['mu_brake'])
    cond = np.zeros((sim.t.size, 3, 4), dtype=bool)
    cond[:, 0] = sim.slip >= scale * s_drive
    cond[:, 1] = sim.slip <= -scale * s_brake
    cond[:, 2] = np.abs(sim.mu) >= scale * LOW_FRICTION_TRUTH_RATIO * mu_peak
    return cond


def first_true(mask: np.ndarray, t: np.ndarray) -> float:
    """First stamp where mask holds (nan if never)."""
    idx = np.flatnonzero(mask)
    return float(t[idx[0]]) if idx.size else math.nan


def activations(det: np.ndarray, level: np.ndarray, t: np.ndarray) -> list[tuple[float, float]]:
    """(detected stamp, onset) of each OK -> active transition of one channel."""
    active = level > 0
    starts = np.flatnonzero(active & ~np.concatenate([[False], active[:-1]]))
    return [(float(t[i]), float(det[i])) for i in starts]


def report_alerts(
    sim: Any, det: dict[str, np.ndarray], truth: np.ndarray, relaxed: np.ndarray
) -> dict[str, int]:
    """Print delays and false alarms; return counts.

    A truth episode is a run of samples where the truth condition holds; its delay is the
    first activation at or after (onset - 1 s) minus the onset. An activation is a false alarm
    when the relaxed truth condition (the tyre near, not past, the limit) does not hold
    anywhere in [activation - 0.5 s, activation + 0.1 s].
    """
    t = sim.t
    counts = {'delays_met': 0, 'delays_missed': 0, 'false_alarms': 0, 'missed': 0}
    for kind, name in enumerate(ALERT_KINDS):
        for wheel in range(4):
            cond = truth[:, kind, wheel] & (t >= 0.5)
            acts = activations(det['detected'][:, kind, wheel], det['level'][:, kind, wheel], t)
            label = f'{name:12s} wheel {["FL", "FR", "RL", "RR"][wheel]}'
            false = [
                a
                for a in acts
                if not np.any(relaxed[(t >= a[0] - 0.5) & (t <= a[0] + 0.1), kind, wheel])
            ]
            if false:
                counts['false_alarms'] += len(false)
                stamps = ', '.join(f'{a[0]:.3f}' for a in false[:5])
                print(f'   {label}: FALSE ALARM x{len(false)} at {stamps} s')
            starts = np.flatnonzero(cond & ~np.concatenate([[False], cond[:-1]]))
            episodes = [float(t[i]) for i in starts]
            # merge episodes closer than 1 s (one event with a short dip)
            merged = [e for i, e in enumerate(episodes) if i == 0 or e - episodes[i - 1] > 1.0]
            for onset in merged:
                hits = [a for a in acts if a[0] >= onset - 1.0]
                if not hits:
                    counts['missed'] += 1
                    print(f'   {label}: true onset {onset:.3f} s, NOT DETECTED')
                    continue
                first = hits[0][0]
                delay = first - onset
                if delay > 1.0:
                    counts['missed'] += 1
                    print(f'   {label}: true onset {onset:.3f} s, NOT DETECTED within 1 s')
                    continue
                k = int(np.searchsorted(t, first))
                reported_onset = float(det['onset'][k, kind, wheel])
                ok = delay <= DELAY_GOAL
                counts['delays_met' if ok else 'delays_missed'] += 1
                print(
                    f'   {label}: true onset {onset:.3f} s, detected {first:.3f} s, '
                    f'delay {1e3 * delay:6.1f} ms ({"MET" if ok else "MISSED"} <= 100 ms), '
                    f'reported onset {reported_onset:.3f} s'
                )
    return counts


def report_mu_max(sim: Any, det: dict[str, np.ndarray], peaks: dict[str, np.ndarray]) -> None:
    """Print the mu_max error per axle and road segment after true excitation."""
    t = sim.t
    r = sim.road_mu
    util = np.abs(sim.mu) / np.maximum(
        np.where(sim.fx >= 0.0, peaks['mu_drive'], peaks['mu_brake']) * r[:, None], 1e-6
    )
    seg_edges = np.flatnonzero(np.diff(r) != 0.0) + 1
    segments = np.split(np.arange(t.size), seg_edges)
    for axle, wheels in ((0, [0, 1]), (1, [2, 3])):
        true_peak = (
            r
            * 0.5
            * (
                np.where(
                    sim.fx[:, wheels[0]] >= 0,
                    peaks['mu_drive'][:, wheels[0]],
                    peaks['mu_brake'][:, wheels[0]],
                )
                + np.where(
                    sim.fx[:, wheels[1]] >= 0,
                    peaks['mu_drive'][:, wheels[1]],
                    peaks['mu_brake'][:, wheels[1]],
                )
            )
        )
        for seg in segments:
            excited = np.flatnonzero(util[seg][:, wheels].max(axis=1) >= EXCITATION_RATIO)
            if excited.size == 0:
                continue
            idx = seg[excited[0] :]
            err = det['mu_max'][idx, axle] - true_peak[idx]
            within = np.abs(err) <= MU_MAX_GOAL
            bad = np.flatnonzero(~within)
            settle = float(t[idx[bad[-1]]] - t[idx[0]]) if bad.size else 0.0
            recent = _recently(util[seg][:, wheels].max(axis=1) >= EXCITATION_RATIO, t[seg], 0.5)
            recent_idx = seg[recent & (t[seg] >= t[idx[0]] + 0.1)]
            err_recent = det['mu_max'][recent_idx, axle] - true_peak[recent_idx]
            recent_text = (
                f'while excited in the last 0.5 s (from +0.1 s): |err| rms '
                f'{math.sqrt(float(np.mean(err_recent**2))):.3f}, '
                f'{100 * float(np.mean(np.abs(err_recent) <= MU_MAX_GOAL)):.1f} % within 0.1; '
                if recent_idx.size
                else ''
            )
            print(
                f'   mu_max axle {"front" if axle == 0 else "rear"} road_mu {r[seg[0]]:.2f} '
                f'[{t[seg[0]]:.2f}, {t[seg[-1]]:.2f}] s: excited at {t[idx[0]]:.3f} s, '
                f'true peak {np.mean(true_peak[idx]):.3f}, {recent_text}all after: estimate mean '
                f'{np.mean(det["mu_max"][idx, axle]):.3f}, |err| max {np.abs(err).max():.3f}, '
                f'rms {math.sqrt(float(np.mean(err**2))):.3f}, '
                f'{100 * within.mean():.1f} % within 0.1 '
                f'(last miss {settle:.3f} s after excitation), '
                f'confidence mean {np.mean(det["conf"][idx, axle]):.2f}, '
                f'class {ROAD_CLASS_NAMES[int(np.bincount(det["road"][idx, axle]).argmax())]}'
            )


def _recently(mask: np.ndarray, t: np.ndarray, window: float) -> np.ndarray:
    """shape (N,), bool: mask held at some stamp in [t - window, t]."""
    last = np.where(mask, t, -np.inf)
    last = np.maximum.accumulate(last)
    out: np.ndarray = t - last <= window
    return out


def main() -> None:
    """Parse arguments, simulate, estimate, detect, print figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--scenarios', default='launch_low_mu,braking_low_mu_hard,paper_table1')
    parser.add_argument('--cases', default='ideal,noisy')
    args = parser.parse_args()

    from vd_sim_node.vehicle.params import load_vehicle
    from vd_sim_node.vehicle.scenario import load_scenario
    from vd_sim_node.vehicle.simulation import simulate

    sim_vehicle = load_vehicle(VEHICLE_FILE)
    vehicle = load_estimator_vehicle(VEHICLE_FILE)
    alert_cfg = AlertConfig()
    fric_cfg = FrictionPotentialConfig()
    totals: dict[str, int] = {}
    for name in args.scenarios.split(','):
        scenario = load_scenario(SCENARIO_DIR / f'{name}.yaml')
        for case in args.cases.split(','):
            counts, noise = CASES[case]
            sensors = dataclasses.replace(
                scenario.sensors, encoder_counts_per_rev=counts, speed_noise_std=noise
            )
            sim = simulate(sim_vehicle, dataclasses.replace(scenario, sensors=sensors))
            tuned = TUNED[case]
            obs_cfg = ObserverConfig(
                wheel_lipschitz=tuned['wheel_lipschitz'],
                speed_lipschitz=tuned['speed_lipschitz'],
            )
            est_cfg = EstimatorConfig(slope_filter_tau=tuned['slope_filter_tau'])
            est = run_cascade(
                sim.t,
                sim.wheel_angle,
                sim.body_speed,
                sim.wheel_torque,
                vehicle,
                obs_cfg,
                est_cfg,
            )
            t0 = time.perf_counter()
            det = run_detectors(est, sim.body_speed, vehicle.effective_radius, alert_cfg, fric_cfg)
            cost = (time.perf_counter() - t0) / sim.t.size
            peaks = unit_road_peaks(sim_vehicle.tire, sim.fz)
            truth = truth_conditions(sim, peaks)
            relaxed = truth_conditions(sim, peaks, RELAXED_SCALE)
            print(
                f'== {name} / {case}: encoder {counts or "ideal"} counts/rev, speed noise '
                f'{noise} m/s, {sim.t.size} samples; friction + alerts '
                f'{1e6 * cost:.0f} us/sample'
            )
            result = report_alerts(sim, det, truth, relaxed)
            report_mu_max(sim, det, peaks)
            for key, value in result.items():
                totals[f'{name}/{key}'] = totals.get(f'{name}/{key}', 0) + value
            print(f'   summary: {result}')
    print('== totals over cases:', totals)


if __name__ == '__main__':
    main()
