"""Console-script entry points: a stop signal during start-up ends the process cleanly.

Importing rclpy, numpy and a node module takes about a second. A SIGINT in that time would end
the process with a KeyboardInterrupt traceback, a SIGTERM with the signal's default exit code;
`guarded_main` turns either into one line and exit code 0, then hands over to the node's
``main`` (whose `ros_common.run_node` installs its own handlers at once). Only the standard
library is imported here, so the guard is in place within milliseconds of the interpreter
starting (what remains unguarded is Python's own start-up).
"""

from __future__ import annotations

import importlib
import signal
import sys

__all__ = ['guarded_main', 'sim_node']


class _Stopped(Exception):  # noqa: N818 (a signal, not an error)
    """A stop signal arrived before the node's own handlers were installed."""


def _early(signum: int, _frame: object) -> None:
    raise _Stopped(signal.Signals(signum).name)


def guarded_main(module: str, args: list[str] | None = None) -> int:
    """Import node module `module` and return its ``main(args)``; a stop signal meanwhile: 0.

    Args:
        module: e.g. 'vd_sim_node.sim_node'.
        args: command-line arguments for ``main`` (None: sys.argv).
    """
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, _early)
    try:
        main = importlib.import_module(module).main
    except _Stopped as stopped:
        print(f'stopped by {stopped} while starting', file=sys.stderr, flush=True)
        return 0
    try:
        result: int = main(args)
    except _Stopped as stopped:  # between the import and run_node's own handlers
        print(f'stopped by {stopped} while starting', file=sys.stderr, flush=True)
        return 0
    return result


def sim_node() -> int:
    """``ros2 run vd_sim_node sim_node``."""
    return guarded_main('vd_sim_node.sim_node')
