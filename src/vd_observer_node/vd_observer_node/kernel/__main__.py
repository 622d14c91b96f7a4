"""``python -m vd_observer_node.kernel``: compile every kernel into numba's disk cache now.

``make setup`` runs it after each build, so the first ``vd replay`` or node start of a fresh
set-up loads machine code instead of compiling for half a minute. Prints one line with the
time it took (about 0.5 s when the cache was already there).
"""

from __future__ import annotations

import sys
import time

__all__ = ['main']


def main() -> int:
    """Compile (or load) every kernel; exit code 0."""
    start = time.perf_counter()
    from vd_observer_node.chain import warm_up
    from vd_observer_node.estimation.vehicle import load_vehicle_params, vehicle_tire
    from vd_observer_node.kernel._jit import PACKAGE
    from vd_observer_node.situation.friction_potential import TyreCurves

    # the chain of every node and of the replay, its observers, estimator and monitor
    warm_up(TyreCurves.from_tire(vehicle_tire(load_vehicle_params())))
    print(
        f'kernels compiled into the __pycache__ folders of {PACKAGE} in '
        f'{time.perf_counter() - start:.1f} s',
        flush=True,
    )
    return 0


if __name__ == '__main__':
    sys.exit(main())
