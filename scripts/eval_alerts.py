#!/usr/bin/env python3
"""Detection delay, false alarms and friction-potential error of the alert core.

Simulates each scenario (default: launch_low_mu, braking_low_mu_hard, braking_low_mu,
paper_table1) with ideal sensors and with a 96 counts/rev encoder plus 0.05 m/s body-speed
noise, runs the observer / estimator cascade (`run_cascade`), then `SituationMonitor` (fast
wheel observer, friction potential, alerts) per stamp exactly as the alerts node and
`vd replay` do, and prints against the simulator's truth (definitions in docs/alerts.md):

* per (kind, wheel) with a true onset: true onset, detection stamp (alert becomes active),
  delay = detection - true onset (goal <= 100 ms), and the reported onset stamp ("already
  active" when the channel was active since more than 1 s before the onset: delay 0);
* activations with no relaxed truth (0.8 x the thresholds) within [-0.5, +0.1] s: false
  alarms (goal on paper_table1: none);
* per axle and road segment where the tyre was truly excited beyond half its peak: mu_max
  error against the Magic Formula peak at the true road_mu and load (goal |err| <= 0.1).

The truth (``SimResult.peak_mu`` / ``peak_slip``, from ``vd_sim_node.vehicle.friction_truth``)
and the metrics (``vd_observer_node.tools.report.alerts``) are the ones ``vd report`` uses on a
bag.

Usage:
    python scripts/eval_alerts.py [--scenarios launch_low_mu,braking_low_mu,paper_table1]
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
sys.path.insert(0, str(ROOT / 'src' / 'vd_common'))

from vd_common.vehicle.friction import axle_mean, road_class  # noqa: E402
from vd_observer_node.estimation.cascade import CascadeSeries, CascadeSettings, run_cascade  # noqa: E402
from vd_observer_node.estimation.estimator import EstimatorConfig  # noqa: E402
from vd_observer_node.estimation.observer import ObserverConfig  # noqa: E402
from vd_observer_node.estimation.vehicle import load_estimator_vehicle  # noqa: E402
from vd_observer_node.situation.alerts import ALERT_KINDS, AlertConfig  # noqa: E402
from vd_observer_node.situation.friction_potential import (  # noqa: E402
    ROAD_CLASS_NAMES,
    FrictionPotentialConfig,
    TyreCurves,
)
from vd_observer_node.situation.monitor import (  # noqa: E402
    SituationConfig,
    SituationMonitor,
    run_situation,
)
from vd_observer_node.tools.report.alerts import (  # noqa: E402
    AlertSettings,
    evaluate_alerts,
    truth_conditions,
)
from vd_observer_node.tools.report.mu_max import (  # noqa: E402
    axle_utilisation,
    mu_max_errors,
    segments_from_road,
)

VEHICLE_FILE = ROOT / 'src' / 'vd_common' / 'config' / 'clio_rl_1_1.yaml'
SCENARIO_DIR = ROOT / 'src' / 'vd_sim_node' / 'config' / 'scenarios'
#: name: (encoder counts per rev, body-speed noise std [m/s]).
CASES = {'ideal': (0, 0.0), 'noisy': (96, 0.05)}
#: Observer / estimator settings per case, as tuned in scripts/eval_estimators.py.
TUNED: dict[str, dict[str, float]] = {
    'ideal': {'wheel_lipschitz': 10000.0, 'speed_lipschitz': 2000.0, 'slope_filter_tau': 0.05},
    'noisy': {'wheel_lipschitz': 300.0, 'speed_lipschitz': 20.0, 'slope_filter_tau': 0.1},
}
#: Fast wheel observer of the slip alerts per case: ideal encoders allow a faster one.
ALERT_WHEEL_LIPSCHITZ = {'ideal': 10000.0, 'noisy': SituationConfig().alert_wheel_lipschitz}
#: Truth and metric definitions (docs/alerts.md 4.1), shared with `vd report`.
SETTINGS = AlertSettings()


def run_detectors(est: Any, sim: Any, monitor: SituationMonitor) -> dict[str, np.ndarray]:
    """Friction potential and alerts per stamp, as the alerts node computes them
    (`vd_observer_node.situation.monitor.run_situation`, the loop `vd replay` runs too).

    Args:
        est: the cascade on the simulator's sensors (t, omega, mu, mu_valid, fz used).
        sim: the simulator run (wheel_angle, the MEASURED body_speed, wheel_torque).
        monitor: a fresh situation monitor.

    Returns:
        'level' (N, 3, 4), 'detected' and 'onset' (N, 3, 4) [s] (nan while inactive),
        'mu_max', 'conf' (N, 2), 'road' (N, 2) codes.
    """
    series = run_situation(monitor, sim.wheel_angle, sim.body_speed, sim.wheel_torque, est)
    return {
        'level': series.level,
        'detected': series.detected,
        'onset': series.onset,
        'mu_max': series.mu_max,
        'conf': series.confidence,
        'road': series.road_class,
    }


def truth_and_relaxed(sim: Any) -> tuple[np.ndarray, np.ndarray]:
    """Truth and relaxed truth conditions (N, 3, 4) from the simulator's friction potential."""
    args = (sim.slip, sim.mu, sim.peak_slip, sim.peak_mu)
    ratio = SETTINGS.low_friction_ratio
    truth = truth_conditions(*args, low_friction_ratio=ratio)
    relaxed = truth_conditions(*args, scale=SETTINGS.relaxed_scale, low_friction_ratio=ratio)
    return truth, relaxed


def report_alerts(
    sim: Any, det: dict[str, np.ndarray], truth: np.ndarray, relaxed: np.ndarray
) -> dict[str, int]:
    """Print delays and false alarms per (kind, wheel); return counts.

    Definitions in docs/alerts.md 4.1, computed by the report's shared
    ``vd_observer_node.tools.report.alerts.evaluate_alerts``.
    """
    episodes, alarms = evaluate_alerts(sim.t, truth, relaxed, det['level'], det['onset'], SETTINGS)
    counts = {
        'delays_met': sum(e.status == 'met' for e in episodes),
        'delays_missed': sum(e.status == 'late' for e in episodes),
        'false_alarms': len(alarms),
        'missed': sum(e.status == 'missed' for e in episodes),
    }
    goal_ms = 1e3 * SETTINGS.delay_goal_s
    for name in ALERT_KINDS:
        for wheel in range(4):
            label = f'{name:12s} wheel {["FL", "FR", "RL", "RR"][wheel]}'
            false = [a.t_s for a in alarms if a.kind == name and a.wheel == wheel]
            if false:
                stamps = ', '.join(f'{a:.3f}' for a in false[:5])
                print(f'   {label}: FALSE ALARM x{len(false)} at {stamps} s')
            for e in episodes:
                if e.kind != name or e.wheel != wheel:
                    continue
                if e.detected_s is None or e.delay_s is None:
                    print(
                        f'   {label}: true onset {e.true_onset_s:.3f} s, NOT DETECTED within 1 s'
                    )
                    continue
                reported = math.nan if e.reported_onset_s is None else e.reported_onset_s
                if e.already_active:
                    print(
                        f'   {label}: true onset {e.true_onset_s:.3f} s, already active '
                        f'(delay 0, MET), reported onset {reported:.3f} s'
                    )
                    continue
                print(
                    f'   {label}: true onset {e.true_onset_s:.3f} s, '
                    f'detected {e.detected_s:.3f} s, '
                    f'delay {1e3 * e.delay_s:6.1f} ms '
                    f'({"MET" if e.status == "met" else "MISSED"} <= {goal_ms:.0f} ms), '
                    f'reported onset {reported:.3f} s'
                )
    return counts


def report_mu_max(sim: Any, det: dict[str, np.ndarray]) -> None:
    """Print the mu_max error per axle and road segment after true excitation, then over all
    of them (issue 38's figure: the share of the excited samples within 0.1, and the share
    known and wrong: a road class given and the error beyond 0.1)."""
    true_mu_max = axle_mean(sim.peak_mu)
    segments = mu_max_errors(
        sim.t,
        axle_utilisation(sim.mu, sim.peak_mu),
        true_mu_max,
        det['mu_max'],
        segments_from_road(sim.road_mu),
        confidence=det['conf'],
        road_classes=(det['road'], road_class(true_mu_max)),
        settings=SETTINGS,
    )
    for m in segments:
        recent_text = (
            f'while excited in the last {SETTINGS.excitation_window_s:g} s (from '
            f'+{SETTINGS.excitation_start_s:g} s): |err| rms {m.recent_rms:.3f}, '
            f'{m.recent_within_pct:.1f} % within {SETTINGS.mu_max_goal:g} '
            f'({m.recent_unknown_pct:.1f} % class unknown, '
            f'{m.recent_known_wrong_pct:.1f} % known and wrong); '
            if m.recent_samples
            else ''
        )
        print(
            f'   mu_max axle {"front" if m.axle == 0 else "rear"} road_mu '
            f'{sim.road_mu[m.start_index]:.2f} [{m.start_s:.2f}, {m.end_s:.2f}] s: excited at '
            f'{m.excited_s:.3f} s, true peak {m.true_mu_max:.3f}, {recent_text}all after: '
            f'estimate mean {m.estimate_mean:.3f}, |err| max {m.max_abs:.3f}, rms {m.rms:.3f}, '
            f'{m.within_pct:.1f} % within {SETTINGS.mu_max_goal:g} '
            f'(last miss {m.last_miss_s:.3f} s after excitation), '
            f'confidence mean {m.confidence_mean:.2f}, class {ROAD_CLASS_NAMES[m.road_class]}'
        )
    n = sum(m.recent_samples for m in segments)
    if n:

        def share(pct: str) -> float:
            return sum(m.recent_samples * getattr(m, pct) for m in segments) / n

        print(
            f'   mu_max while excited, all segments ({n} samples): '
            f'{share("recent_within_pct"):.1f} % within {SETTINGS.mu_max_goal:g} (goal 95), '
            f'{share("recent_known_wrong_pct"):.1f} % known and wrong, '
            f'{share("recent_unknown_pct"):.1f} % class unknown'
        )


def main() -> None:
    """Parse arguments, simulate, estimate, detect, print figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        '--scenarios', default='launch_low_mu,braking_low_mu_hard,braking_low_mu,paper_table1'
    )
    parser.add_argument('--cases', default='ideal,noisy')
    args = parser.parse_args()

    from vd_common.vehicle.params import load_vehicle
    from vd_sim_node.vehicle.scenario import load_scenario
    from vd_sim_node.vehicle.simulation import simulate

    sim_vehicle = load_vehicle(VEHICLE_FILE)
    vehicle = load_estimator_vehicle(VEHICLE_FILE)
    curves = TyreCurves.from_tire(sim_vehicle.tire)
    static_load = vehicle.static_wheel_loads[[0, 2]]
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
                CascadeSeries(sim.t, sim.wheel_angle, sim.body_speed, sim.wheel_torque),
                CascadeSettings(vehicle, observer=obs_cfg, estimator=est_cfg),
            )
            monitor = SituationMonitor(
                curves,
                static_load,
                vehicle.effective_radius,
                observer=obs_cfg,
                alerts=alert_cfg,
                friction=fric_cfg,
                situation=SituationConfig(alert_wheel_lipschitz=ALERT_WHEEL_LIPSCHITZ[case]),
            )
            t0 = time.perf_counter()
            det = run_detectors(est, sim, monitor)
            cost = (time.perf_counter() - t0) / sim.t.size
            truth, relaxed = truth_and_relaxed(sim)
            print(
                f'== {name} / {case}: encoder {counts or "ideal"} counts/rev, speed noise '
                f'{noise} m/s, {sim.t.size} samples; situation monitor (fast observer L '
                f'{ALERT_WHEEL_LIPSCHITZ[case]:g}, friction, alerts) {1e6 * cost:.0f} us/sample'
            )
            result = report_alerts(sim, det, truth, relaxed)
            report_mu_max(sim, det)
            for key, value in result.items():
                totals[f'{name}/{key}'] = totals.get(f'{name}/{key}', 0) + value
            print(f'   summary: {result}')
    print('== totals over cases:', totals)


if __name__ == '__main__':
    main()
