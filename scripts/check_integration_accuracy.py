"""Accuracy of the simulator's default integration against a tight-tolerance reference.

For each scenario the default settings (LSODA, rtol 1e-7, per-state absolute tolerances)
are compared with a reference run at rtol 1e-10 and absolute tolerances 100 times tighter
(tighter still and LSODA refuses: the wheel angles reach 1e4 rad). Printed per scenario:
the largest wheel-speed error relative to max(|omega|, 1 rad/s) (target 1e-4), body-speed,
wheel-angle and omega_dot errors, and whether both runs took the same discrete decisions
(gear shifts happen at the same samples).

Usage::

    python scripts/check_integration_accuracy.py [SCENARIO ...]
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'src' / 'vd_sim_node'))
sys.path.insert(0, str(ROOT / 'src' / 'vd_common'))

from vd_common.vehicle.params import default_vehicle_file, load_vehicle  # noqa: E402
from vd_sim_node.vehicle.model import VehicleModel  # noqa: E402
from vd_sim_node.vehicle.scenario import load_scenario  # noqa: E402
from vd_sim_node.vehicle.simulation import simulate  # noqa: E402

CONFIG = ROOT / 'src' / 'vd_sim_node' / 'config'


def main() -> None:
    """Run default and reference for each scenario and print the errors."""
    names = sys.argv[1:] or sorted(p.stem for p in (CONFIG / 'scenarios').glob('*.yaml'))
    model = VehicleModel(load_vehicle(default_vehicle_file()))
    for name in names:
        scenario = load_scenario(CONFIG / 'scenarios' / f'{name}.yaml')
        t0 = time.perf_counter()
        fast = simulate(model, scenario)
        t_fast = time.perf_counter() - t0
        t0 = time.perf_counter()
        ref = simulate(model, scenario, rtol=1e-10, atol_scale=1e-2)
        t_ref = time.perf_counter() - t0
        omega_err = np.abs(fast.omega - ref.omega) / np.maximum(np.abs(ref.omega), 1.0)
        speed_err = np.abs(fast.speed_true - ref.speed_true)
        angle_err = np.abs(fast.angle_true - ref.angle_true)
        wdot_err = np.abs(fast.omega_dot - ref.omega_dot)
        same = fast.events == ref.events
        print(
            f'{name}: {scenario.duration:g} s, default {t_fast:.2f} s wall, '
            f'reference {t_ref:.2f} s wall'
        )
        print(
            f'  wheel speed  max |d omega| / max(|omega|, 1 rad/s) = {omega_err.max():.2e} '
            f'(target 1e-4: {"met" if omega_err.max() < 1e-4 else "MISSED"})'
        )
        print(f'  body speed   max |dv|          = {speed_err.max():.2e} m/s')
        print(f'  wheel angle  max |d angle|     = {angle_err.max():.2e} rad')
        print(
            f'  omega_dot    max |d omega_dot| = {wdot_err.max():.2e} rad/s^2 '
            f'(max |omega_dot| {np.abs(ref.omega_dot).max():.1f})'
        )
        print(f'  same discrete events (shifts, clutch) at the same samples: {same}')


if __name__ == '__main__':
    main()
