"""ROS 2 plumbing shared by every vd node: QoS, stamps, declared parameters, diagnostics.

vd_common is the base package of the stack: the simulator's node and the estimator's nodes
import this module rather than repeating it. Nothing here computes anything physical: that
stays in the ROS-free cores.

QoS choices (see the README's topic contract):

* Sensor, observer, estimate and truth streams: RELIABLE, KEEP_LAST, depth 1000. Reliable
  publishers also serve best-effort subscribers (``qos_profile_sensor_data``), so users may
  pick either; our own subscribers ask for reliable delivery with room for a 1 s stall at
  1 kHz, because a lost wheel-angle sample is a corrupted derivative.
* ``/clock``: RELIABLE, depth 1, like ``ros2 bag play``.
* ``/diagnostics``: RELIABLE, depth 10 (the diagnostic_aggregator default).

A publish the middleware refuses (Fast DDS: ``RCLError: cannot publish data``, seen under
overload on a 2-core machine) never ends a node: every publisher is made through
`PublishRefusals`, which counts the refusal per topic, logs the first one of each topic and
puts a WARN on the node's ``/diagnostics`` (docs/faults.md).
"""

from __future__ import annotations

import contextlib
import dataclasses
import faulthandler
import gc
import importlib
import os
import re
import struct
import sys
import threading
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy._rclpy_pybind11 import RCLError
from rclpy.exceptions import ParameterException
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from vd_common.errors import VdError
from vd_common.params_file import params_file_problem
from vd_common.settings_log import settings_line

__all__ = [
    'CLOCK_QOS',
    'DIAGNOSTICS_QOS',
    'EXECUTORS',
    'STATE_QOS',
    'STREAM_QOS',
    'TEARDOWN_BACKSTOP_GRACE_S',
    'TEARDOWN_TIMEOUT_S',
    'GuardedPublisher',
    'InvalidParameterError',
    'NodeFinished',
    'ParamSpec',
    'PublishRefusals',
    'StopSignals',
    'SubscriberGate',
    'TeardownWatchdog',
    'dataclass_param_specs',
    'declare_parameters',
    'deliver_pending',
    'diagnostic_array',
    'finish',
    'given_parameters',
    'header_stamp_ns',
    'log_settings',
    'node_status',
    'ns_to_time',
    'ros_message_class',
    'run_node',
    'time_to_ns',
]

STREAM_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1000,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
CLOCK_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE
)
DIAGNOSTICS_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST, depth=10, reliability=ReliabilityPolicy.RELIABLE
)
#: Estimates published only where they change (the engine-torque offset): the last ones are
#: kept for subscribers that join later (transient local; volatile subscribers match too).
STATE_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)

_NS = 1_000_000_000


def ns_to_time(ns: int) -> Time:
    """Convert integer nanoseconds to a builtin_interfaces/Time (floor division, sec >= 0)."""
    sec, nanosec = divmod(int(ns), _NS)
    return Time(sec=sec, nanosec=nanosec)


def time_to_ns(stamp: Time) -> int:
    """Convert a builtin_interfaces/Time to integer nanoseconds."""
    return int(stamp.sec) * _NS + int(stamp.nanosec)


def header_stamp_ns(cdr: bytes) -> int | None:
    """``header.stamp`` [ns] of a serialized message that begins with a std_msgs/Header.

    Reads the 4-byte encapsulation (CDR little or big endian) and the stamp's sec and nanosec
    after it, without decoding the message; None where `cdr` is too short or not plain CDR.
    """
    if len(cdr) < 12 or cdr[0] != 0 or cdr[1] not in (0, 1):
        return None
    sec, nanosec = struct.unpack_from('<iI' if cdr[1] == 1 else '>iI', cdr, 4)
    return int(sec) * _NS + int(nanosec)


def ros_message_class(type_name: str) -> Any:
    """The rclpy message class of ``'pkg/msg/Type'`` (what rosidl_runtime_py.get_message does).

    Raises:
        ImportError: the interface package is not installed.
        AttributeError: the package has no such message.
    """
    package, _, name = type_name.rpartition('/')
    module = importlib.import_module(package.replace('/', '.'))
    return getattr(module, name)


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


class GuardedPublisher:
    """A publisher whose refused publishes are counted by its `PublishRefusals`, not raised.

    Everything but `publish` is the wrapped rclpy publisher's (``topic_name``,
    ``get_subscription_count``, ``wait_for_all_acked`` ...).
    """

    __slots__ = ('_publisher', '_refusals', 'topic_name')

    def __init__(self, publisher: Any, refusals: PublishRefusals) -> None:
        self._publisher = publisher
        self._refusals = refusals
        self.topic_name: str = publisher.topic_name

    def publish(self, msg: Any) -> bool:
        """Publish `msg` (a message or its CDR bytes); False if the middleware refused it."""
        try:
            self._publisher.publish(msg)
        except RCLError as exc:
            self._refusals.note(self.topic_name, exc)
            return False
        return True

    def __getattr__(self, name: str) -> Any:
        return getattr(self._publisher, name)


class PublishRefusals:
    """Makes a node's publishers and counts the publishes the middleware refused, per topic.

    A refused publish is a lost message, not a reason to stop: the node goes on with the next
    sample. The first refusal of each topic is logged (WARN) with the middleware's words; the
    counts go to ``/diagnostics`` through `status`.
    """

    def __init__(self, node: Node) -> None:
        """Publishers made by `publisher` are `node`'s; refusals are logged by its logger."""
        self._node = node
        #: refused publishes per topic, since the node started
        self.counts: dict[str, int] = {}
        self._reported = 0

    @property
    def total(self) -> int:
        """Refused publishes on all topics since the node started."""
        return sum(self.counts.values())

    def publisher(self, msg_type: Any, topic: str, qos: QoSProfile) -> GuardedPublisher:
        """``node.create_publisher(msg_type, topic, qos)``, guarded."""
        return self.guard(self._node.create_publisher(msg_type, topic, qos))

    def guard(self, publisher: Any) -> GuardedPublisher:
        """Wrap an rclpy publisher of the node."""
        return GuardedPublisher(publisher, self)

    def note(self, topic: str, exc: BaseException) -> None:
        """Count one refused publish on `topic`; log the first of the topic."""
        n = self.counts.get(topic, 0) + 1
        self.counts[topic] = n
        if n == 1:
            first_line = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            self._node.get_logger().warning(
                f'publish refused on {topic} ({first_line}): counted on /diagnostics, going on'
            )

    def status(self, level: int, message: str) -> tuple[int, str, dict[str, object]]:
        """A node's diagnostic level and message with the refusals since the last call added.

        Args:
            level: the node's level so far, 0 (OK), 1 (WARN), 2 (ERROR).
            message: its message so far ('ok' when level is 0).

        Returns:
            (level, message, values): WARN at least when publishes were refused since the
            previous call, the message naming how many and where; values holds the total
            ``refused_publishes`` and the count per topic.
        """
        total = self.total
        values: dict[str, object] = {'refused_publishes': total}
        values.update({f'refused_publishes[{topic}]': n for topic, n in self.counts.items()})
        new = total - self._reported
        self._reported = total
        if new:
            topics = ', '.join(sorted(self.counts))
            note = f'{new} publishes refused by the middleware ({topics})'
            message = note if level == 0 else f'{message}; {note}'
            level = max(level, 1)
        return level, message, values


class InvalidParameterError(Exception):
    """A parameter value was refused; the message names it and the allowed values."""


@dataclass(frozen=True)
class ParamSpec:
    """One declared parameter.

    Attributes:
        name: parameter name.
        default: default value; its Python type fixes the parameter type. None: unset by
            default and of any type (the caller checks the value, e.g. a nested setting
            that only a params file gives).
        description: shown by ``ros2 param describe``; give the unit in brackets.
        low: inclusive lower bound for numbers (None: unbounded).
        high: inclusive upper bound for numbers (None: unbounded).
        choices: allowed values for strings (empty: any).
        read_only: the node reads it once at start.
    """

    name: str
    default: Any
    description: str
    low: float | None = None
    high: float | None = None
    choices: Sequence[str] = ()
    read_only: bool = True

    def allowed(self) -> str:
        if self.default is None:
            return 'any value (unset by default)'
        if self.choices:
            return 'one of ' + ', '.join(repr(c) for c in self.choices)
        if self.low is not None or self.high is not None:
            lo = '-inf' if self.low is None else f'{self.low:g}'
            hi = 'inf' if self.high is None else f'{self.high:g}'
            return f'in [{lo}, {hi}]'
        return f'a {type(self.default).__name__}'


def _attribute_docs(cls: type) -> dict[str, str]:
    """Descriptions of the 'Attributes:' section of a Google-style class docstring."""
    doc = cls.__doc__ or ''
    section = doc.split('Attributes:', 1)[1] if 'Attributes:' in doc else ''
    docs: dict[str, str] = {}
    name = None
    for line in section.splitlines():
        match = re.match(r'^\s{4,8}(\w+):\s*(.*)$', line)
        if match and (name is None or len(line) - len(line.lstrip()) <= 8):
            name, text = match.groups()
            docs[name] = text.strip()
        elif name and line.strip():
            docs[name] += ' ' + line.strip()
    return docs


def dataclass_param_specs(
    cls: type,
    *,
    skip: Sequence[str] = (),
    choices: Mapping[str, Sequence[str]] | None = None,
) -> list[ParamSpec]:
    """One ParamSpec per field of the configuration dataclass `cls` (defaults from `cls()`).

    Descriptions come from the class docstring's 'Attributes:' section, so parameters cannot
    drift from the core's configuration; values are validated by the dataclass itself.
    """
    defaults = cls()
    docs = _attribute_docs(cls)
    return [
        ParamSpec(
            f.name,
            getattr(defaults, f.name),
            docs.get(f.name, f.name),
            choices=tuple((choices or {}).get(f.name, ())),
        )
        for f in dataclasses.fields(cls)
        if f.name not in skip
    ]


def _descriptor(spec: ParamSpec) -> ParameterDescriptor:
    desc = ParameterDescriptor(
        description=spec.description,
        read_only=spec.read_only,
        dynamic_typing=spec.default is None,
        additional_constraints=('allowed: ' + spec.allowed()) if spec.choices else '',
    )
    if spec.low is not None and spec.high is not None and not isinstance(spec.default, bool):
        if isinstance(spec.default, int):
            desc.integer_range = [
                IntegerRange(from_value=int(spec.low), to_value=int(spec.high), step=0)
            ]
        elif isinstance(spec.default, float):
            desc.floating_point_range = [
                FloatingPointRange(from_value=float(spec.low), to_value=float(spec.high), step=0.0)
            ]
    return desc


def declare_parameters(node: Node, specs: Sequence[ParamSpec]) -> dict[str, Any]:
    """Declare `specs` on `node` and return their values, checked against the specs.

    Raises:
        InvalidParameterError: a value has the wrong type or lies outside its range/choices; the
            message names the parameter, the value and what is allowed.
    """
    values: dict[str, Any] = {}
    for spec in specs:
        try:
            param = node.declare_parameter(spec.name, spec.default, _descriptor(spec))
        except ParameterException as exc:
            raise InvalidParameterError(
                f'parameter {spec.name!r} refused ({exc}); allowed: {spec.allowed()}'
            ) from None
        value = param.value
        if spec.default is None:  # unset (None) or any type: the caller checks it
            values[spec.name] = value
            continue
        if isinstance(spec.default, float) and isinstance(value, int):
            value = float(value)
        if type(value) is not type(spec.default):
            raise InvalidParameterError(
                f'parameter {spec.name!r} must be {type(spec.default).__name__}, got {value!r}'
            )
        bad_choice = spec.choices and value not in spec.choices
        below = spec.low is not None and isinstance(value, int | float) and value < spec.low
        above = spec.high is not None and isinstance(value, int | float) and value > spec.high
        if bad_choice or below or above:
            raise InvalidParameterError(
                f'parameter {spec.name!r} = {value!r} refused; allowed: {spec.allowed()}'
            )
        values[spec.name] = value
    return values


def given_parameters(specs: Sequence[ParamSpec], values: Mapping[str, Any]) -> dict[str, Any]:
    """The parameters of `values` (`declare_parameters`' result) that are not their defaults,
    by name: what a params file or ``-p`` set (a value equal to its default counts as the
    default; an unset parameter without default is left out), for the node's start-up log."""
    given: dict[str, Any] = {}
    for spec in specs:
        if spec.name not in values:
            continue
        value = values[spec.name]
        if spec.default is None:
            if value is not None:
                given[spec.name] = value
        elif value != spec.default:
            given[spec.name] = value
    return given


def log_settings(node: Node, specs: Sequence[ParamSpec], values: Mapping[str, Any]) -> None:
    """Log (INFO) the parameters that are not their defaults (`given_parameters`)."""
    line = settings_line(given_parameters(specs, values), 'parameters')
    node.get_logger().info(f'settings: {line}')


def diagnostic_array(
    stamp: Time,
    name: str,
    hardware_id: str,
    level: bytes | int,
    message: str,
    values: Mapping[str, object],
) -> DiagnosticArray:
    """One-status DiagnosticArray; `level` is DiagnosticStatus.OK/WARN/ERROR/STALE (bytes)."""
    status = DiagnosticStatus(
        level=level if isinstance(level, bytes) else bytes([level]),
        name=name,
        message=message,
        hardware_id=hardware_id,
        values=[KeyValue(key=str(k), value=str(v)) for k, v in values.items()],
    )
    return DiagnosticArray(header=_header(stamp), status=[status])


def node_status(
    node: Node,
    name: str,
    hardware_id: str,
    level: int,
    message: str,
    values: Mapping[str, object],
    refusals: PublishRefusals | None = None,
) -> DiagnosticArray:
    """`diagnostic_array` stamped with the node's clock now (the nodes' periodic status).

    With `refusals`, the publishes refused since the previous status are added to the level,
    message and values (`PublishRefusals.status`).
    """
    if refusals is not None:
        level, message, refused = refusals.status(level, message)
        values = {**values, **refused}
    return diagnostic_array(
        node.get_clock().now().to_msg(), name, hardware_id, level, message, values
    )


def _header(stamp: Time) -> Any:
    from std_msgs.msg import Header

    return Header(stamp=stamp)


class SubscriberGate:
    """Decides when a source node (simulator, player) may send its first message.

    Open once every given publisher has `min_subscribers` subscribers (one number for all, or
    one per publisher) and the counts have not changed for `settle_s` (a topic whose first
    subscriber, say the recorder, matched may still be waiting for its second, the observer),
    or once `deadline` (monotonic [s]) has passed.
    """

    def __init__(
        self,
        publishers: Sequence[Any],
        deadline: float,
        settle_s: float = 1.0,
        min_subscribers: int | Sequence[int] = 1,
    ):
        self.publishers = list(publishers)
        self.min_subscribers = (
            [min_subscribers] * len(self.publishers)
            if isinstance(min_subscribers, int)
            else list(min_subscribers)
        )
        if len(self.min_subscribers) != len(self.publishers):
            raise ValueError('min_subscribers: one number, or one per publisher')
        self.deadline = deadline
        self.settle_s = settle_s
        self._counts: tuple[int, ...] = ()
        self._since = 0.0
        self.missing: list[str] = []

    def ready(self, now: float) -> bool:
        """True when the source may start; `missing` then names topics short of subscribers."""
        counts = tuple(p.get_subscription_count() for p in self.publishers)
        if counts != self._counts:
            self._counts, self._since = counts, now
        self.missing = [
            p.topic_name
            for p, n, least in zip(self.publishers, counts, self.min_subscribers, strict=True)
            if n < least
        ]
        settled = not self.missing and now - self._since >= self.settle_s
        return settled or now >= self.deadline


def deliver_pending(node: Node, timeout_s: float = 2.0) -> bool:
    """Wait until every reliable subscriber has acknowledged what `node` published.

    Call before a node exits on its own: a process that ends right after its last publish
    would otherwise take messages still in flight with it.
    Returns True if everything was acknowledged within `timeout_s` (per publisher).
    """
    from rclpy.duration import Duration

    acked = True
    for publisher in node.publishers:
        acked = publisher.wait_for_all_acked(Duration(seconds=timeout_s)) and acked
    return acked


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
