"""The compiled per-sample kernel (numba): observers, estimator and situation monitor.

Every piece mirrors a pure-Python reference of the package and is tested equal to it
(outputs to 1e-9, fault counters exactly); the Python path stays selectable everywhere
(``kernel`` parameter of the nodes, ``--kernel`` of ``vd replay``). See docs/performance.md.
"""

from __future__ import annotations

__all__: list[str] = []
