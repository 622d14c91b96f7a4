#!/usr/bin/env python3
"""vd side by side with peer packages from PyPI, in the same process (prints figures).

1. Our Levant differentiator (`vd_observer_node.estimation.differentiator`) vs `opensmc`'s
   `opensmc.estimators.LevantDifferentiator` (order 2, explicit Euler, Levant's gains
   2.0 / 1.5 / 1.1 like ours): the same signal f = sin(t) (|f'''| <= 1, L = 1.5), the same
   step tau, both started from z = 0. Errors are max |z_i - f^(i)| after convergence
   (t > 5 s of 10 s; from z = 0 the transient ends between 3 and 4 s); speed is
   microseconds per sample on ONE channel, so the per-call overheads are compared (ours
   differentiates 4 wheels in one vectorised call).
2. Our vehicle model's right-hand side (`VehicleModel.rhs`, the compiled bond graph of the
   Clio: longitudinal + pitch + heave, 4 wheels with MF tyres, engine, clutch, gearbox) vs
   the multi-body model of `commonroad-vehicle-models` (`vehiclemodels.vehicle_dynamics_mb`,
   29 states, BMW 320i parameters): evaluations per second of one state, each at a state
   from inside its own envelope (ours: 15 s into the paper scenario; theirs: the state of
   their own unit test).

The peers are in requirements/bench.in (pinned); without them the script says so and
measures only our side.

Usage:
    python scripts/bench_peers.py [--quick] [--repeat 3] [--seconds 0.5]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from collections.abc import Callable
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'src' / 'vd_observer_node'))
sys.path.insert(0, str(ROOT / 'src' / 'vd_sim_node'))
sys.path.insert(0, str(ROOT / 'src' / 'vd_common'))

from vd_common.vehicle.params import default_vehicle_file, load_vehicle  # noqa: E402
from vd_observer_node.estimation.differentiator import (  # noqa: E402
    DifferentiatorSettings,
    LevantDifferentiator,
    levant_params,
)
from vd_observer_node.estimation.levant_step import euler_step  # noqa: E402
from vd_sim_node.vehicle.scenario import load_scenario  # noqa: E402
from vd_sim_node.vehicle.simulation import Simulator  # noqa: E402

__all__ = ['main']

CONFIG = ROOT / 'src' / 'vd_sim_node' / 'config'
LIPSCHITZ = 1.5  # [1/s^3] bound on |d^3 sin(t)/dt^3| = 1, with margin
DURATION = 10.0  # [s] of signal
CONVERGED_AFTER = 5.0  # [s]; from z = 0 with L = 1.5 the transient ends between 3 and 4 s


def _version(dist: str) -> str:
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return 'not installed'


def _truth(t: np.ndarray) -> np.ndarray:
    return np.stack((np.sin(t), np.cos(t), -np.sin(t)), axis=1)


def _max_errors(t: np.ndarray, z: np.ndarray) -> np.ndarray:
    keep = t > CONVERGED_AFTER
    out: np.ndarray = np.abs(z[keep] - _truth(t)[keep]).max(axis=0)
    return out


def ours(disc: str, tau: float) -> tuple[np.ndarray, float]:
    """Max errors (f, f', f'') and s per sample of our stateful differentiator, 1 channel."""
    t = np.arange(int(DURATION / tau) + 1) * tau
    f = np.sin(t)
    diff = LevantDifferentiator(
        LIPSCHITZ, n_channels=1, settings=DifferentiatorSettings(discretization=disc, init='zero')
    )
    z = np.empty((len(t), 3))
    start = time.perf_counter()
    for k in range(len(t)):
        est = diff.update(float(t[k]), f[k])
        z[k, 0], z[k, 1], z[k, 2] = est.value[0], est.first[0], est.second[0]
    per_sample = (time.perf_counter() - start) / len(t)
    return _max_errors(t, z), per_sample


def ours_pure_euler(tau: float) -> tuple[np.ndarray, float]:
    """The same with the pure `euler_step` function (no bookkeeping), 1 channel."""
    t = np.arange(int(DURATION / tau) + 1) * tau
    f = np.sin(t)
    z = np.zeros((len(t), 3))
    params = levant_params(DifferentiatorSettings(discretization='euler', init='zero'), np.inf)
    start = time.perf_counter()
    for k in range(1, len(t)):
        z[k] = euler_step(params, z[k - 1], f[k - 1], tau, LIPSCHITZ, False)
    per_sample = (time.perf_counter() - start) / (len(t) - 1)
    return _max_errors(t, z), per_sample


def theirs(tau: float) -> tuple[np.ndarray, float]:
    """The same signal through opensmc's LevantDifferentiator (order 2, explicit Euler)."""
    from opensmc.estimators import LevantDifferentiator as OpenSmcLevant

    t = np.arange(int(DURATION / tau) + 1) * tau
    f = np.sin(t)
    diff = OpenSmcLevant(order=2, L=LIPSCHITZ, dt=tau)
    z = np.zeros((len(t), 3))
    start = time.perf_counter()
    for k in range(1, len(t)):
        # estimate() returns the old z2 and advances one Euler step with the sample f[k-1]
        diff.estimate(float(t[k - 1]), None, 0.0, y=f[k - 1])
        z[k] = diff.derivatives
    per_sample = (time.perf_counter() - start) / (len(t) - 1)
    return _max_errors(t, z), per_sample


def calls_per_second(fn: Callable[[], Any], seconds: float) -> float:
    """Calls of `fn` per wall second, in batches until `seconds` have passed."""
    fn()
    calls, start, batch = 0, time.perf_counter(), 100
    while (elapsed := time.perf_counter() - start) < seconds:
        for _ in range(batch):
            fn()
        calls += batch
    return calls / elapsed


def _median_spread(values: list[float], fmt: str) -> str:
    return (
        f'{format(statistics.median(values), fmt)} '
        f'({format(min(values), fmt)}..{format(max(values), fmt)})'
    )


def bench_differentiators(repeat: int, taus: list[float]) -> None:
    have_peer = _version('opensmc') != 'not installed'
    print(
        f'\n== Levant differentiator, f = sin(t), L = {LIPSCHITZ}, from z = 0, {DURATION:g} s; '
        f'errors after t > {CONVERGED_AFTER:g} s; us/sample median (min..max) of {repeat} runs'
    )
    print(f'   opensmc {_version("opensmc")}')
    rows: list[tuple[str, Callable[[float], tuple[np.ndarray, float]]]] = [
        ('vd implicit (default)', lambda tau: ours('implicit', tau)),
        ('vd euler_taylor', lambda tau: ours('euler_taylor', tau)),
        ('vd euler', lambda tau: ours('euler', tau)),
        ('vd euler_step (pure fn)', ours_pure_euler),
    ]
    if have_peer:
        rows.append(('opensmc (euler)', theirs))
    else:
        print('   opensmc is not installed: pip install -r requirements/bench.in')
    print(
        f'   {"tau":>6s}  {"implementation":24s} {"|f-z0|":>9s} {"|df-z1|":>9s} '
        f'{"|ddf-z2|":>9s}  us/sample'
    )
    for tau in taus:
        for name, fn in rows:
            results = [fn(tau) for _ in range(repeat)]
            e = results[0][0]
            us = [1e6 * r[1] for r in results]
            print(
                f'   {tau:6.0e}  {name:24s} {e[0]:9.2e} {e[1]:9.2e} {e[2]:9.2e}  '
                f'{_median_spread(us, ".1f")}',
                flush=True,
            )
        if have_peer:
            a, b = ours_pure_euler(tau)[0], theirs(tau)[0]
            print(
                f'   {tau:6.0e}  same-method check: |vd euler_step - opensmc| error diff '
                f'{np.abs(a - b).max():.1e}'
            )


def _our_state() -> tuple[Any, float, np.ndarray, np.ndarray]:
    scenario = load_scenario(CONFIG / 'scenarios' / 'paper_table1.yaml')
    sim = Simulator(load_vehicle(default_vehicle_file()), scenario, rate_hz=100.0)
    while sim.t < 15.0:  # full throttle on the 5 deg slope, a gear or two up
        sim.step()
    # private members: the benchmark needs the integrator's state and inputs at that time
    x = np.array(sim._x, dtype=float)
    u = np.array(sim._inputs(sim._t, sim._drv), dtype=float)
    return sim.model, float(sim._t), x, u


def bench_models(repeat: int, seconds: float) -> None:
    print(
        f'\n== vehicle model right-hand side: evaluations/s, median (min..max) of {repeat} runs '
        f'of {seconds:g} s each'
    )
    model, t, x, u = _our_state()
    rates = [calls_per_second(lambda: model.rhs(t, x, u), seconds) for _ in range(repeat)]
    print(
        f'   vd VehicleModel.rhs (Clio, {model.n_states} states)        : '
        f'{_median_spread(rates, ",.0f")} /s'
    )
    # the simulator evaluates whole blocks of states at once (CompiledModel.rhs_batch)
    batch = np.repeat(x[:, None], 1000, axis=1)
    if np.allclose(model.compiled.rhs_batch(t, batch, u)[:, 0], model.rhs(t, x, u)):
        rates = [
            1000 * calls_per_second(lambda: model.compiled.rhs_batch(t, batch, u), seconds)
            for _ in range(repeat)
        ]
        print(
            f'   vd CompiledModel.rhs_batch, 1000 states per call       : '
            f'{_median_spread(rates, ",.0f")} states/s'
        )
    if _version('commonroad-vehicle-models') == 'not installed':
        print(
            '   commonroad-vehicle-models is not installed: pip install -r requirements/bench.in'
        )
        return
    from vehiclemodels.parameters_vehicle2 import parameters_vehicle2
    from vehiclemodels.vehicle_dynamics_mb import vehicle_dynamics_mb

    p = parameters_vehicle2()
    # the state and input of their unit test (test_derivatives.test_mb): 18 m/s, cornering
    x_mb = [
        10.8808433066274794,
        0.5371850187869442,
        0.0980442671005920,
        18.0711398687457745,
        0.1649995631003776,
        0.6158755000936103,
        -0.1198403612262477,
        -0.2762672756169581,
        0.0131909920269115,
        -0.0718483683742141,
        -0.3428324595054725,
        0.0103233373083297,
        -0.0399590564140291,
        -0.0246468320579360,
        -0.0551575051990853,
        0.5798277643297529,
        0.0172059354801703,
        0.0067890113155477,
        -0.0184269459410162,
        -0.0408207136116175,
        -1.0064484829203018,
        0.0166808347900582,
        -0.0049188492004049,
        53.6551710641082451,
        50.7045242506744316,
        56.7917911784219598,
        200.7079633169796296,
        -0.0939969123691911,
        -0.0881514621614376,
    ]
    u_mb = [0.15, 0.63 * 9.81]
    rates = [
        calls_per_second(lambda: vehicle_dynamics_mb(x_mb, u_mb, p), seconds)
        for _ in range(repeat)
    ]
    print(
        f'   commonroad {_version("commonroad-vehicle-models")} vehicle_dynamics_mb '
        f'({len(x_mb)} states): {_median_spread(rates, ",.0f")} /s'
    )


def main(argv: list[str] | None = None) -> int:
    """Run the comparisons, print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--quick', action='store_true', help='1 run, tau 1e-3 only, 0.1 s')
    parser.add_argument('--repeat', type=int, default=3)
    parser.add_argument('--seconds', type=float, default=0.5, help='per speed measurement')
    args = parser.parse_args(argv)
    taus = [1e-3, 5e-4]
    if args.quick:
        args.repeat, args.seconds, taus = 1, 0.1, [1e-3]
    print(
        f'peers: {os.cpu_count()} cores, load (1 min) {os.getloadavg()[0]:.2f}; '
        f'Python {sys.version.split()[0]}, numpy {np.__version__}'
    )
    bench_differentiators(args.repeat, taus)
    bench_models(args.repeat, args.seconds)
    return 0


if __name__ == '__main__':
    sys.exit(main())
