#!/usr/bin/env python3
"""`vd calibrate` on simulated cars that are not their file (issue #37).

Each variant is a Clio that differs from vd's Clio file (the base the calibration starts
from) in one or more ways: load (-50 ... +300 kg), tyre radius (-3 ... +1 %), drag area
(+-20 %), rolling resistance (+-30 %), another final drive. The simulator drives the TRUE car
on an everyday drive (`vd_sim_node.vehicle.everyday`: hills, 10-130 km/h, 96-count encoders,
0.05 m/s speed noise) of a seed never used while the calibration was written (the smoke runs
used seeds 300-301); the bag (vd's own topics with the truth) goes through the command's own
path (`run_calibrate`) with the Clio file as base, and the fitted values are compared with the
true car's. A value the drive does not determine is printed as 'n.d.' (and counted as a miss).

Each drive's IMU (the simulator's, on the sprung body) is written as a sensor mounted in a
random orientation (any roll and yaw, pitch within +-60 deg, seeded) would read it, and the
mapping names it without its mounting: the table's last columns are how far the forward and
the lateral axis of the mounting `vd calibrate` learns are from the true one (the drive's own
IMU pitch composed with the written rotation), in degrees.

Then the speed goal: a 10 min drive at 100 Hz, wall time of the whole command (read, fit,
write) against the 10 s goal, with the load average.

Usage:
    python scripts/eval_calibrate.py [--first 500] [--duration 180] [--rate 100]
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import io
import json
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'src' / 'vd_observer_node'))
sys.path.insert(0, str(ROOT / 'src' / 'vd_sim_node'))
sys.path.insert(0, str(ROOT / 'src' / 'vd_common'))

from vd_common.topics import SENSORS_IMU  # noqa: E402
from vd_common.vehicle.estimation import load_estimation_vehicle  # noqa: E402
from vd_common.vehicle.params import VehicleParams, default_vehicle_file, load_vehicle  # noqa: E402
from vd_observer_node.inputs.rotation import axis_angle_deg, mount_rotation  # noqa: E402
from vd_observer_node.testing.devbag import sim_topics, write_topic_arrays_bag  # noqa: E402
from vd_observer_node.tools.calibrate.cli import run_calibrate  # noqa: E402
from vd_sim_node.vehicle.everyday import EverydaySettings, everyday_scenario  # noqa: E402
from vd_sim_node.vehicle.scenario import VehicleVariant  # noqa: E402
from vd_sim_node.vehicle.simulation import simulate  # noqa: E402
from vd_sim_node.vehicle.variants import apply_variant  # noqa: E402

#: name -> (extra mass [kg], radius scale, drag area scale, c0 scale, final drive scale)
VARIANTS: dict[str, tuple[float, float, float, float, float]] = {
    'nominal': (0.0, 1.0, 1.0, 1.0, 1.0),
    'light, -50 kg': (-50.0, 1.0, 1.0, 1.0, 1.0),
    'loaded, +300 kg': (300.0, 1.0, 1.0, 1.0, 1.0),
    'worn tyres, r -3 %': (0.0, 0.97, 1.0, 1.0, 1.0),
    'big tyres, r +1 %': (0.0, 1.01, 1.0, 1.0, 1.0),
    'roof box, CdA +20 %, c0 +30 %': (75.0, 1.0, 1.2, 1.3, 1.0),
    'eco, CdA -20 %, c0 -30 %': (0.0, 1.0, 0.8, 0.7, 1.0),
    'other final drive, x 0.92': (150.0, 0.99, 1.0, 1.0, 0.92),
}
#: key -> (goal as a relative error, what the goal is)
GOALS = {
    'chassis.mass': 0.03,
    'aero.drag_coefficient': 0.10,
    'rolling_resistance.c0': 0.20,
    'wheel.effective_radius': 0.003,
    'gearbox.final_drive': 0.005,
}


def true_car(params: VehicleParams, change: tuple[float, float, float, float, float]) -> Any:
    """The simulated car's parameters and its variant (load and radius through the scenario)."""
    extra, radius, drag, c0, final = change
    car = dataclasses.replace(
        params,
        aero=dataclasses.replace(
            params.aero, drag_coefficient=params.aero.drag_coefficient * drag
        ),
        rolling_resistance=dataclasses.replace(
            params.rolling_resistance, c0=params.rolling_resistance.c0 * c0
        ),
        gearbox=dataclasses.replace(
            params.gearbox, final_drive=params.gearbox.final_drive * final
        ),
    )
    return car, VehicleVariant(extra_mass_kg=extra, tyre_radius_scale=radius)


def truth_values(car: VehicleParams) -> dict[str, float]:
    """The true car's values under the calibrated file's keys."""
    return {
        'chassis.mass': car.chassis.mass,
        'aero.drag_coefficient': car.aero.drag_coefficient,
        'rolling_resistance.c0': car.rolling_resistance.c0,
        'wheel.effective_radius': car.wheel.effective_radius,
        'gearbox.final_drive': car.gearbox.final_drive,
    }


def drive_bag(
    params: VehicleParams,
    car: VehicleParams,
    variant: VehicleVariant,
    seed: int,
    settings: EverydaySettings,
    bag: Path,
) -> np.ndarray:
    """Simulate the true car on an everyday drive and write vd's bag of it with the truth and
    its IMU in a random mounting; returns the true mounting's rows (body <- sensor)."""
    scenario = dataclasses.replace(everyday_scenario(seed, params, settings), true_vehicle=variant)
    sim = simulate(car, scenario, rate_hz=settings.rate_hz)
    rng = np.random.default_rng(seed)
    written = (rng.uniform(-180, 180), rng.uniform(-60, 60), rng.uniform(-180, 180))
    topics = sim_topics(sim, imu=True, imu_mount_rpy_deg=written)
    write_topic_arrays_bag(bag, np.round(sim.t * 1e9).astype(np.int64), topics)
    own = np.array(mount_rotation(0.0, scenario.sensors.imu_mount_pitch, 0.0))
    rows: np.ndarray = own @ np.array(mount_rotation(*np.radians(written)))
    return rows


def calibrated(
    bag: Path, out: Path, mapping: Path | None = None
) -> tuple[dict[str, float], float, dict[str, Any] | None]:
    """Run the command's path; the fitted values by key, the wall time [s] and the report's
    IMU mounting (None where not determined or without a mapping)."""
    # the report (its figures take a second) only where the mounting is read from it
    report = out.with_suffix('.report') if mapping is not None else None
    args = argparse.Namespace(
        bags=[bag], out=out, mapping=mapping, vehicle=None, report=report, level_road=False
    )
    started = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()):
        run_calibrate(args)
    wall = time.perf_counter() - started
    mounting = None
    if report is not None:
        mounting = json.loads((report / 'calibration.json').read_text())['imu_mounting']
    fitted = load_estimation_vehicle(out)
    text = out.read_text(encoding='utf-8')

    def fitted_line(key: str) -> bool:
        name = key.split('.')[1]
        return any(
            line.strip().startswith(f'{name}:') and '# fitted' in line
            for line in text.splitlines()
        )

    values = {
        'chassis.mass': fitted.chassis.mass,
        'aero.drag_coefficient': fitted.aero.drag_coefficient,
        'rolling_resistance.c0': fitted.rolling_resistance.c0,
        'wheel.effective_radius': fitted.wheel.effective_radius,
        'gearbox.final_drive': fitted.require_driveline().final_drive,
    }
    return {k: v for k, v in values.items() if fitted_line(k)}, wall, mounting


def _axes_off_deg(found: dict[str, Any] | None, true_rows: np.ndarray) -> str:
    """How far the learnt forward and lateral axes are from the true ones [deg]."""
    if found is None:
        return f'{"n.d.":>9} {"n.d.":>9}'
    rows = mount_rotation(*np.radians(found['mount_rpy_deg']))
    off = [axis_angle_deg(rows[k], true_rows[k]) for k in (0, 1)]
    return f'{off[0]:>9.2f} {off[1]:>9.2f}'


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--first', type=int, default=500, help='seed of the first drive')
    parser.add_argument('--duration', type=float, default=180.0, help='drive length [s]')
    parser.add_argument('--rate', type=float, default=100.0, help='sensor rate [Hz]')
    args = parser.parse_args(argv)
    params = load_vehicle(default_vehicle_file())
    settings = EverydaySettings(duration=args.duration, rate_hz=args.rate)
    print(
        f'vd calibrate on {len(VARIANTS)} simulated cars, everyday drives of '
        f'{args.duration:.0f} s '
        f'at {args.rate:.0f} Hz, seeds {args.first}..{args.first + len(VARIANTS) - 1}; '
        "error of each fitted value in % of the true car's (goal in brackets)"
    )
    keys = list(GOALS)
    header = ' '.join(f'{k.split(".")[1][:14]:>14}' for k in keys)
    print(f'{"variant":32} {header}  imu fwd°  imu lat°')
    misses = 0
    with tempfile.TemporaryDirectory() as tmp:
        mapping = Path(tmp) / 'imu_mapping.yaml'
        mapping.write_text(f'imu:\n  topic: {SENSORS_IMU}\n  type: sensor_msgs/msg/Imu\n')
        for n, (name, change) in enumerate(VARIANTS.items()):
            car, variant = true_car(params, change)
            bag = Path(tmp) / f'drive{n}'
            true_rows = drive_bag(params, car, variant, args.first + n, settings, bag)
            fitted, _, mounting = calibrated(bag, Path(tmp) / f'car{n}.yaml', mapping)
            truth = truth_values(apply_variant(car, variant))
            cells = []
            for key in keys:
                if key not in fitted:
                    cells.append(f'{"n.d.":>14}')
                    misses += 1
                    continue
                error = fitted[key] / truth[key] - 1.0
                misses += abs(error) > GOALS[key]
                cells.append(f'{100.0 * error:>+13.2f}%')
            print(f'{name:32} {" ".join(cells)} {_axes_off_deg(mounting, true_rows)}')
        print(
            'goal (|error| <=)                '
            + ' '.join(f'{100 * GOALS[k]:>13.1f}%' for k in keys)
        )
        print(
            f'values outside their goal or not determined: {misses} of {len(keys) * len(VARIANTS)}'
        )
        long = EverydaySettings(duration=600.0, rate_hz=100.0)
        car, variant = true_car(params, VARIANTS['loaded, +300 kg'])
        bag = Path(tmp) / 'ten_minutes'
        drive_bag(params, car, variant, args.first + len(VARIANTS), long, bag)
        load = os.getloadavg()[0]
        _, wall, _ = calibrated(bag, Path(tmp) / 'ten_minutes.yaml')
        print(
            f'10 min drive at 100 Hz: calibrated in {wall:.1f} s (goal <= 10 s), load {load:.2f}'
        )
    return 0


if __name__ == '__main__':
    sys.exit(main())
