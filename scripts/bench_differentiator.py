#!/usr/bin/env python3
"""Speed and accuracy of the Levant differentiator discretizations (prints figures).

For each discretization: time per `LevantDifferentiator.update` on four channels (the
wheel observer), and the accuracy laws on f = sin(t) (|f'''| <= 1, L = 1.5) for a few
steps tau, with and without +-50 % jitter of the steps, plus the chattering amplitude of
f'' on a quadratic signal (which a perfect differentiator reproduces exactly).

Usage:
    python scripts/bench_differentiator.py [--samples 20000]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'src' / 'vd_observer_node'))
sys.path.insert(0, str(ROOT / 'src' / 'vd_common'))

from vd_observer_node.estimation.differentiator import (  # noqa: E402
    DISCRETIZATIONS,
    DifferentiatorSettings,
    LevantDifferentiator,
)


def _time_per_update(disc: str, samples: int) -> float:
    diff = LevantDifferentiator(
        300.0, n_channels=4, settings=DifferentiatorSettings(discretization=disc)
    )
    t = np.arange(samples) * 1e-3
    f = np.stack([np.sin(t), np.cos(t), t, t**2], axis=1)
    start = time.perf_counter()
    for k in range(samples):
        diff.update(t[k], f[k])
    return (time.perf_counter() - start) / samples


def _errors(disc: str, tau: float, jitter: float) -> np.ndarray:
    rng = np.random.default_rng(0)
    steps = tau * (1.0 + jitter * rng.uniform(-1.0, 1.0, int(8.0 / tau)))
    t = np.concatenate(([0.0], np.cumsum(steps)))
    diff = LevantDifferentiator(
        1.5, n_channels=1, settings=DifferentiatorSettings(discretization=disc)
    )
    out = np.array([diff.update(tk, np.sin(tk))[:3] for tk in t])[:, :, 0]
    truth = np.stack((np.sin(t), np.cos(t), -np.sin(t)), axis=1)
    keep = t > 3.0
    errors: np.ndarray = np.abs(out[keep] - truth[keep]).max(axis=0)
    return errors


def _chattering(disc: str) -> float:
    t = np.arange(0.0, 5.0, 1e-3)
    diff = LevantDifferentiator(
        20.0, n_channels=1, settings=DifferentiatorSettings(discretization=disc)
    )
    out = np.array([diff.update(tk, -1.5 * tk**2).second[0] for tk in t])
    return float(np.abs(out[t > 3.0] + 3.0).max())


def main() -> None:
    """Run the benchmark."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--samples', type=int, default=20000)
    args = parser.parse_args()
    print("discretization  us/update(4 ch)  f''-chatter(quadratic, L=20, 1 ms)")
    for disc in DISCRETIZATIONS:
        us = 1e6 * _time_per_update(disc, args.samples)
        print(f'{disc:14s}  {us:15.1f}  {_chattering(disc):.3e}')
    print("\nmax errors after convergence on sin(t), L = 1.5: |f - z0|, |f' - z1|, |f'' - z2|")
    for disc in DISCRETIZATIONS:
        for jitter in (0.0, 0.5):
            for tau in (4e-3, 2e-3, 1e-3):
                e = _errors(disc, tau, jitter)
                print(
                    f'{disc:14s} jitter {jitter:3.1f} tau {tau:.0e}: '
                    f'{e[0]:.2e} {e[1]:.2e} {e[2]:.2e}'
                )


if __name__ == '__main__':
    main()
