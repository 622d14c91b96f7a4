"""A node's life: built, spun until a stop signal or `finish`, its outputs closed, the
middleware torn down under a watchdog, one exit code (`run_node`, docs/faults.md).
"""

from __future__ import annotations

import contextlib
import faulthandler
import gc
import os
import sys
import threading
import time
from typing import Any

from rclpy._rclpy_pybind11 import RCLError
from rclpy.node import Node

from vd_common.errors import VdError
from vd_common.params_file import params_file_problem
from vd_common.ros.parameters import InvalidParameterError

__all__ = [
    'EXECUTORS',
    'TEARDOWN_BACKSTOP_GRACE_S',
    'TEARDOWN_TIMEOUT_S',
    'NodeFinished',
    'StopSignals',
    'TeardownWatchdog',
    'finish',
    'run_node',
]


class NodeFinished(Exception):  # noqa: N818 (a signal, not an error)
    """Raised while a node is built when it has nothing to do: `run_node` exits with code 0.

    From a callback, call `finish` instead: rclpy's EventsExecutor logs every exception that
    leaves a callback as ``[FATAL] Exception in 'timers' callback`` with its traceback, which
    read like a crash at the normal end of every scenario.
    """


#: the attribute `finish` sets on a node; `run_node` ends its spin loop when it is true
_FINISHED = '_vd_finished'


def finish(node: Node) -> None:
    """Ask `run_node` to end `node` with exit code 0 once the running callback returns."""
    setattr(node, _FINISHED, True)


def _finished(node: Any) -> bool:
    return bool(getattr(node, _FINISHED, False))


EXECUTORS = ('events', 'single_threaded')
#: [s] longest wait of the spin loop for work: the reaction time to a stop signal.
_SPIN_TIMEOUT_S = 0.1


def _executor(kind: str) -> Any:
    if kind == 'events':
        from rclpy.experimental.events_executor import EventsExecutor

        return EventsExecutor()
    from rclpy.executors import SingleThreadedExecutor

    return SingleThreadedExecutor()


class StopSignals:
    """SIGINT/SIGTERM as a flag the spin loop checks, instead of rclpy's own handlers.

    rclpy's handlers shut the context down from inside the signal handler, while the executor
    may be building its wait set on that context: the race ended nodes with a traceback and
    exit code 1 ('failed to initialize wait set: the given context is not valid'). Here a
    signal only sets a flag; the loop in `run_node` stops, the node closes its outputs, and
    the context is shut down after the executor has let go of it.
    """

    def __init__(self) -> None:
        """Install the handlers (replacing any earlier ones, e.g. `entry.guarded_main`'s)."""
        import signal

        from vd_common import entry

        # a signal the entry point's guard noted before these handlers took over
        self.received: int | None = entry.received[0] if entry.received else None
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, self._on_signal)

    def _on_signal(self, signum: int, _frame: object) -> None:
        if self.received is None:
            self.received = signum

    @property
    def stop(self) -> bool:
        """True once a stop signal arrived."""
        return self.received is not None

    def name(self) -> str:
        """'SIGINT' or 'SIGTERM' (the first signal received)."""
        import signal

        return signal.Signals(self.received).name if self.received is not None else ''


#: [s] the middleware teardown after a node closed its outputs may take this long at most
TEARDOWN_TIMEOUT_S = 5.0
#: [s] after that, the backstop's grace: for a teardown stuck in C with the GIL held
TEARDOWN_BACKSTOP_GRACE_S = 2.0


class TeardownWatchdog:
    """Ends the process if the middleware teardown hangs, with the exit code it was to have.

    Runs around what `run_node` does after the node's outputs are closed (executor shutdown,
    node destruction, rclpy shutdown). On a 2-core machine with both cores busy, a recorder
    once closed its bag and logged its stop, then stayed inside that teardown until its
    supervisor killed it 10 s later. Nothing is left to lose by then, so a teardown that
    overruns `timeout_s` is cut short: one line naming where it was stuck, stdio flushed,
    ``os._exit(exit_code)`` (0 after a stop, 2 after a refusal or an error the node reported).

    That line is written by a Python thread, which needs the GIL, and rclpy's C++ calls hold
    it: a Fast DDS deadlock inside ``destroy_node`` would keep that thread waiting for good. So
    faulthandler's watchdog, a C thread that needs no GIL, is armed too,
    `TEARDOWN_BACKSTOP_GRACE_S` later: it writes every thread's Python stack to stderr and
    ends the process with exit code 1.
    """

    def __init__(self, timeout_s: float, exit_code: int = 0) -> None:
        """Count `timeout_s` [s] from `arm` (or from entering the ``with`` block)."""
        self.timeout_s = timeout_s
        self.exit_code = exit_code
        self._timer: threading.Timer | None = None
        self._main = threading.get_ident()

    def arm(self) -> None:
        """Start counting, if not yet started."""
        if self._timer is not None:
            return
        self._timer = threading.Timer(self.timeout_s, self._expire)
        self._timer.daemon = True
        self._timer.start()
        with contextlib.suppress(RuntimeError, OSError, ValueError):  # no usable stderr
            faulthandler.dump_traceback_later(
                self.timeout_s + TEARDOWN_BACKSTOP_GRACE_S, exit=True
            )

    def disarm(self) -> None:
        """Stop counting: the teardown is over."""
        if self._timer is not None:
            self._timer.cancel()
            faulthandler.cancel_dump_traceback_later()

    def __enter__(self) -> TeardownWatchdog:
        self.arm()
        return self

    def __exit__(self, *_exc: object) -> None:
        self.disarm()

    def _expire(self) -> None:
        frame = sys._current_frames().get(self._main)
        where = f'{frame.f_code.co_name} ({frame.f_code.co_filename})' if frame else 'unknown'
        print(
            f'teardown still running after {self.timeout_s:.0f} s, in {where}: exiting',
            file=sys.stderr,
            flush=True,
        )
        sys.stdout.flush()
        os._exit(self.exit_code)


def run_node(factory: Any, args: list[str] | None = None) -> int:
    """Init rclpy, build the node with `factory()`, spin until done; return the exit code.

    The executor is rclpy's experimental EventsExecutor (a few microseconds per message
    instead of ~50 us for the SingleThreadedExecutor, scripts/bench_message_path.py);
    ``VD_ROS_EXECUTOR=single_threaded`` selects the other. Both spin with ``spin_once`` in a
    loop that checks `StopSignals`, so SIGINT and SIGTERM at any moment end the node with
    exit code 0, one log line and its outputs closed (``close()`` of the node, e.g. the
    recorder's bag); a callback calling `finish` (or the factory raising `NodeFinished`) ends
    it with 0 too.

    A refused parameter or a bad configuration file ends the process with ONE line on stderr
    naming the problem (exit code 2), not a traceback, printed and flushed before the
    middleware teardown, which runs under `TeardownWatchdog` like any other: a node refused
    while being built is released with the exception, so the watchdog is armed before that.
    """
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    signals = StopSignals()
    kind = os.environ.get('VD_ROS_EXECUTOR', 'events')
    if kind not in EXECUTORS:
        print(f'error: VD_ROS_EXECUTOR={kind!r}; use one of {EXECUTORS}', file=sys.stderr)
        return 2
    problem = params_file_problem(sys.argv if args is None else args)
    if problem is not None:
        print(f'error: {problem}', file=sys.stderr, flush=True)
        return 2
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except RCLError as exc:  # e.g. a malformed --params-file: one line, not a traceback
        print(f'error: cannot start: {str(exc).splitlines()[0]}', file=sys.stderr, flush=True)
        return 2
    node = None
    executor = None
    teardown = TeardownWatchdog(TEARDOWN_TIMEOUT_S)
    try:
        if not signals.stop:
            node = factory()
        if node is not None and not signals.stop:
            # Everything built so far lives for the whole run: keep it out of the garbage
            # collector's scans, whose pauses would otherwise show as latency spikes.
            gc.freeze()
            executor = _executor(kind)
            executor.add_node(node)
            while not signals.stop and not _finished(node):
                executor.spin_once(timeout_sec=_SPIN_TIMEOUT_S)
            # A node that records (drain_on_stop_s > 0) first takes what the middleware has
            # already delivered to it, so a stop does not drop the messages just received.
            drain_until = time.monotonic() + float(getattr(node, 'drain_on_stop_s', 0.0))
            while time.monotonic() < drain_until:
                executor.spin_once(timeout_sec=0.02)
    except NodeFinished:
        pass
    except KeyboardInterrupt:  # a SIGINT before our handler was installed
        pass
    except (InvalidParameterError, VdError) as exc:
        # parameter, configuration or file problems: one line naming it, not a traceback
        print(f'error: {exc}', file=sys.stderr, flush=True)
        teardown.exit_code = 2
        if node is None:
            # Refused while being built: the half-built node goes with `exc`, at the end of
            # this block, and its middleware teardown (endpoints, participant) runs there.
            teardown.arm()
    except BaseException:
        teardown.exit_code = 1  # as for any uncaught exception, should the teardown hang
        raise
    finally:
        if node is not None:
            close = getattr(node, 'close', None)
            if callable(close):
                close()
            if signals.stop:
                node.get_logger().info(f'stopped by {signals.name()}')
        elif signals.stop:
            print(f'stopped by {signals.name()} while starting', file=sys.stderr, flush=True)
        with teardown:
            if node is not None:
                if executor is not None:
                    executor.remove_node(node)
                    executor.shutdown()
                node.destroy_node()
            rclpy.try_shutdown()
    return teardown.exit_code
