"""Console-script entry points: a stop signal during start-up ends the process cleanly.

Importing rclpy, numpy and a node module takes about a second. A SIGINT in that time would end
the process with a KeyboardInterrupt traceback, a SIGTERM with the signal's default exit code;
`guarded_main` notes the signal, lets the imports finish and exits with one line and code 0,
or hands over to the node's ``main``, whose `ros.lifecycle.run_node` installs its own handlers at
once and picks up a signal noted in between. Only the standard
library is imported here, so the guard is in place within milliseconds of the interpreter
starting (what remains unguarded is Python's own start-up).
"""

from __future__ import annotations

import contextlib
import faulthandler
import importlib
import signal
import sys

__all__ = ['guarded_main']


#: Stop signals received before the node's own handlers took over (`ros.lifecycle.StopSignals`
#: reads it, so none is lost in between).
received: list[int] = []


def _early(signum: int, _frame: object) -> None:
    # Only note it: raising here could land inside a C extension's initialisation (rclpy's),
    # which turns any exception into an ImportError with a traceback.
    received.append(signum)


def _stopped() -> int:
    name = signal.Signals(received[0]).name
    print(f'stopped by {name} while starting', file=sys.stderr, flush=True)
    return 0


def guarded_main(module: str, args: list[str] | None = None) -> int:
    """Import node module `module` and return its ``main(args)``; a stop signal meanwhile: 0.

    Args:
        module: e.g. 'vd_sim_node.sim_node'.
        args: command-line arguments for ``main`` (None: sys.argv).
    """
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, _early)
    # SIGUSR1 writes every thread's Python stack to stderr, from a C handler that needs no
    # GIL: a node that hangs (in the middleware, say) can be asked where; the tests do so.
    with contextlib.suppress(RuntimeError, OSError, ValueError):  # no usable stderr
        faulthandler.register(signal.SIGUSR1, all_threads=True)
    try:
        main = importlib.import_module(module).main
    except ImportError:
        if received:  # an import cut short by the signal: stopping was asked for anyway
            return _stopped()
        raise
    if received:
        return _stopped()
    result: int = main(args)
    return result
