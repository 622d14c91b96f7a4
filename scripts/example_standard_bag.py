#!/usr/bin/env python3
"""A car's bag on standard ROS types only, replayed with a mapping file, against vd's own topics.

Issue 15's example, end to end:

1. simulate a scenario (default paper_table1, 150 s) once;
2. write it as vd's own 1 kHz sensor topics (96 counts/rev encoder, 0.05 m/s speed noise, as
   ``make demo`` records) and replay that bag;
3. write the same drive as a car logs it, with standard types only
   (:mod:`vd_observer_node.testing.standard_bags`: ABS wheel speeds in a JointState at 100 Hz,
   odometry at 50 Hz, CAN torques in a Float64MultiArray at 100 Hz, each on its own clock,
   with noise) and replay it with the shipped mapping
   ``src/vd_observer_node/config/input_mapping_abs_example.yaml`` and the shipped settings
   for 100 Hz data, ``replay_100hz_example.yaml``;
4. print slope, mu and Fx errors of both against the simulator's truth, their ratio (the
   issue's target: the standard bag within 1.5x of vd's topics), and plot the slope;
5. replay the standard bag once more with no settings at all (the slope filter follows the
   measured input rate, `rate_settings`) and print its slope RMS against the run with the
   100 Hz settings file (issue 26's target: within 1.15x).

Usage:
    python scripts/example_standard_bag.py [--scenario PATH] [--out DIR] [--plot PNG]
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'scripts'))
sys.path.insert(0, str(ROOT / 'src' / 'vd_observer_node'))
sys.path.insert(0, str(ROOT / 'src' / 'vd_sim_node'))
sys.path.insert(0, str(ROOT / 'src' / 'vd_common'))

from eval_estimators import SCENARIO_FILE, VEHICLE_FILE, evaluation_mask, rms  # noqa: E402
from vd_common.topics import ESTIMATES_SLOPE, ESTIMATES_TIRE_FORCES  # noqa: E402
from vd_observer_node.bag import BagReader  # noqa: E402
from vd_observer_node.bag.cdr_batch import decode_batch  # noqa: E402
from vd_observer_node.inputs.mapping import load_input_mapping  # noqa: E402
from vd_observer_node.testing.devbag import sim_topics, write_topic_arrays_bag  # noqa: E402
from vd_observer_node.testing.standard_bags import CarSensors, write_standard_bag  # noqa: E402
from vd_observer_node.tools.replay import (  # noqa: E402
    ESTIMATE_TOPICS,
    replay_bag,
)
from vd_observer_node.tools.settings_file import load_settings_file  # noqa: E402

CONFIG = ROOT / 'src' / 'vd_observer_node' / 'config'
MAPPING_FILE = CONFIG / 'input_mapping_abs_example.yaml'
#: the replay settings shipped for ~100 Hz data (longer slope filter, smaller wheel L)
REPLAY_FILE = CONFIG / 'replay_100hz_example.yaml'
TARGET_RATIO = 1.5
#: issue 26: the same bag with no settings file, against the 100 Hz settings file
DEFAULTS_RATIO = 1.15


def _estimates(bag: Path) -> dict[str, Any]:
    """Stamps [s] and the slope and force arrays of a replayed bag."""
    reader = BagReader(bag)
    wanted = (ESTIMATES_SLOPE, ESTIMATES_TIRE_FORCES)
    arrays = reader.topic_arrays(list(wanted))
    out: dict[str, Any] = {}
    for topic in wanted:
        fields = decode_batch(ESTIMATE_TOPICS[topic], arrays[topic].datas)
        out[topic] = (fields.stamp_ns * 1e-9, fields.values)
    return out


def _errors(sim: Any, est: dict[str, Any]) -> dict[str, float]:
    """Errors against the simulator's truth at the estimates' stamps (eval window)."""
    t, slope = est[ESTIMATES_SLOPE]
    mask = evaluation_mask(t, sim.events)
    true_slope = np.interp(t, sim.t, sim.slope)
    t_f, forces = est[ESTIMATES_TIRE_FORCES]
    mask_f = evaluation_mask(t_f, sim.events)
    true_fx = np.stack([np.interp(t_f, sim.t, sim.fx[:, i]) for i in range(4)], 1)
    true_fz = np.stack([np.interp(t_f, sim.t, sim.fz[:, i]) for i in range(4)], 1)
    true_mu = true_fx / np.maximum(true_fz, 1.0)
    excited = mask_f[:, None] & (np.abs(true_fx) > 0.05 * true_fz)
    mu_hat = forces['fx'] / np.maximum(forces['fz'], 1.0)
    fx_max = float(np.abs(true_fx[mask_f]).max())
    return {
        'samples': float(t.size),
        'slope_rms_deg': float(np.degrees(rms((slope['angle'] - true_slope)[mask]))),
        'mu_rms': rms((mu_hat - true_mu)[excited]),
        'fx_rms_pct': 100.0 * rms((forces['fx'] - true_fx)[mask_f]) / fx_max,
        'fz_rms_N': rms((forces['fz'] - true_fz)[mask_f]),
    }


def _plot(path: Path, sim: Any, ours: dict[str, Any], theirs: dict[str, Any]) -> None:
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(10, 4))
    ax.plot(sim.t, np.degrees(sim.slope), 'k', lw=2, label='truth')
    for label, est in (('vd topics, 1 kHz encoder', ours), ('standard types, ABS 100 Hz', theirs)):
        t, slope = est[ESTIMATES_SLOPE]
        ax.plot(t, np.degrees(slope['angle']), lw=0.8, label=label)
    ax.set_xlabel('t [s]')
    ax.set_ylabel('slope [deg]')
    ax.legend()
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main() -> None:
    """Simulate, write both bags, replay both, print and plot the comparison."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--scenario', type=Path, default=SCENARIO_FILE)
    parser.add_argument('--out', type=Path, default=None, help='folder for the four bags')
    parser.add_argument('--plot', type=Path, default=None, help='slope plot (PNG)')
    args = parser.parse_args()

    from vd_common.vehicle.params import load_vehicle
    from vd_sim_node.vehicle.scenario import load_scenario
    from vd_sim_node.vehicle.simulation import simulate

    scenario = load_scenario(args.scenario)
    noisy = dataclasses.replace(
        scenario.sensors, rate_hz=1000.0, encoder_counts_per_rev=96, speed_noise_std=0.05
    )
    sim = simulate(load_vehicle(VEHICLE_FILE), dataclasses.replace(scenario, sensors=noisy))
    out = args.out or Path(tempfile.mkdtemp(prefix='vd-example-'))
    out.mkdir(parents=True, exist_ok=True)
    vd_bag, standard_bag = out / 'vd_topics', out / 'standard_types'
    stamp_ns = np.round(sim.t * 1e9).astype(np.int64)
    write_topic_arrays_bag(vd_bag, stamp_ns, sim_topics(sim, truth=False))
    sensors = CarSensors()
    write_standard_bag(standard_bag, sim, sensors)
    mapping = load_input_mapping(MAPPING_FILE)
    ours = replay_bag(vd_bag, out / 'vd_topics_replayed', progress=False)
    settings = load_settings_file(REPLAY_FILE).settings(mapping)
    theirs = replay_bag(
        standard_bag, out / 'standard_replayed', settings, mapping=mapping, progress=False
    )
    # the same bag without settings: what follows the rate follows the measured one
    plain = replay_bag(standard_bag, out / 'standard_defaults', progress=False, mapping=mapping)
    e_ours = _estimates(out / 'vd_topics_replayed')
    e_theirs = _estimates(out / 'standard_replayed')
    a, b = _errors(sim, e_ours), _errors(sim, e_theirs)
    c = _errors(sim, _estimates(out / 'standard_defaults'))
    print(f'== {scenario.name}, {sim.t[-1]:.0f} s; load average {os.getloadavg()[0]:.1f}')
    print(f'   vd topics:      {ours.samples} samples, 1 kHz, encoder 96/rev, speed 0.05 m/s')
    print(
        f'   standard types: {theirs.samples} samples ({theirs.stale} stale), wheel speeds '
        f'{sensors.wheel_rate_hz:g} Hz +- {sensors.wheel_noise_std} rad/s, odometry '
        f'{sensors.odom_rate_hz:g} Hz +- {sensors.speed_noise_std} m/s, torques '
        f'{sensors.torque_rate_hz:g} Hz +- {sensors.torque_noise_std} N m ({MAPPING_FILE.name}, '
        f'{REPLAY_FILE.name})'
    )
    print(f'   {"figure":16s} {"vd topics":>10s} {"standard":>10s} {"ratio":>7s}')
    for key in ('slope_rms_deg', 'mu_rms', 'fx_rms_pct', 'fz_rms_N'):
        ratio = b[key] / a[key] if a[key] > 0 else float('inf')
        verdict = 'within' if ratio <= TARGET_RATIO else 'OUTSIDE'
        print(
            f'   {key:16s} {a[key]:10.4g} {b[key]:10.4g} {ratio:7.2f}  {verdict} {TARGET_RATIO}x'
        )
    derived = ', '.join(f'{k} {v:.3f} s' for k, v in plain.rate_settings.items()) or 'none'
    ratio = c['slope_rms_deg'] / b['slope_rms_deg']
    print(
        f'   standard types without --config (input rate {plain.input_rate_hz:.1f} Hz; followed '
        f'the rate: {derived}): slope RMS {c["slope_rms_deg"]:.4g} deg, {ratio:.2f}x the '
        f'{REPLAY_FILE.name} run ({"within" if ratio <= DEFAULTS_RATIO else "OUTSIDE"} '
        f'{DEFAULTS_RATIO}x)'
    )
    if args.plot:
        _plot(args.plot, sim, e_ours, e_theirs)
        print(f'   plot: {args.plot}')
    print(f'   bags in {out}')


if __name__ == '__main__':
    main()
