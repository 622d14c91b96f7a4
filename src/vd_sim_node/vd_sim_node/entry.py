"""Console-script entry point of the simulator node (see `vd_common.entry.guarded_main`).

Only the standard library and `vd_common.entry` are imported here, so the guard against a
stop signal during start-up is in place within milliseconds of the interpreter starting.
"""

from __future__ import annotations

from vd_common.entry import guarded_main

__all__ = ['sim_node']


def sim_node() -> int:
    """``ros2 run vd_sim_node sim_node``."""
    return guarded_main('vd_sim_node.sim_node')
