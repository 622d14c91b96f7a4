"""numba's jit with the project's settings (`_jit.jit`) and the key of its disk cache.

Every piece of per-sample math is one step function in its concept's module
(`estimation.levant_step`, `estimation.estimator_step`, `situation.monitor_step`, ...),
compiled with `_jit.jit`; ``VD_JIT=0`` runs the same source as plain Python. ``python -m
vd_observer_node.chain`` (run by ``make setup``) compiles them all into numba's cache.
"""

from __future__ import annotations

__all__: list[str] = []
