"""The nodes' raw message path: CDR bytes in, stamp matching, CDR bytes out (ROS-free).

What the estimator, alerts and pipeline nodes share around their subscriptions (taken with
``raw=True``) and publishers (given bytes): decoding each input with its
`bag.cdr_message.MessageCodec` into a `alignment.StampAligner`, and one encoder per output type
and ``frame_id`` (an output keeps the frame of the input it derives from).

The mapped sensor inputs (:mod:`vd_observer_node.inputs`) go through `mapped_input`: each
subscription's bytes are decoded by the mapping's `InputDecoder` to SI values, then either
matched by header stamp (`InputMatcher`, a `StampAligner`) or, for an input without header
stamp (Float64MultiArray, stamped with its receive time), held as its latest value and added
to each matched set. `InputWatch` notes every input's arrivals and reports a topic that stopped.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from vd_common.settings_log import settings_line

from vd_observer_node.bag.cdr_message import AlertsCodec, MessageCodec
from vd_observer_node.bag.errors import BagFormatError
from vd_observer_node.estimation.alignment import LatestAligner, StampAligner
from vd_observer_node.estimation.estimator import (
    MASS_MESSAGE_FIELDS,
    RADIUS_MESSAGE_FIELDS,
    Estimates,
    Estimator,
)
from vd_observer_node.estimation.faults import ERROR, OK, WARN
from vd_observer_node.estimation.rate_settings import (
    SPEED_STAMPS_KEPT,
    RateMeter,
    follow_rate_hz,
)
from vd_observer_node.estimation.torque_offset import OFFSET_MESSAGE_FIELDS, TorqueOffset
from vd_observer_node.inputs.decode import InputDecoder, has_header
from vd_observer_node.inputs.errors import MappingError
from vd_observer_node.inputs.health import HealthLimits, StreamHealth, health_notes
from vd_observer_node.inputs.mapping import InputMapping, InputSpec

__all__ = [
    'Encoders',
    'InputMatcher',
    'InputWatch',
    'LatestMatcher',
    'aligned_input',
    'follow_input_rate',
    'input_matcher',
    'mapped_input',
    'mass_values',
    'matched_inputs',
    'merge_status',
    'offset_values',
    'queued_by_topic',
    'radius_values',
]


def mass_values(est: Estimates) -> list[float | bool]:
    """The vd_msgs/MassEstimate fields of one estimate, in CDR order (`MessageCodec.encode`):
    mass [kg], mass_std [kg], mass_used [kg], converged, excited."""
    return [getattr(est, attr) for _, attr in MASS_MESSAGE_FIELDS]


def offset_values(estimate: TorqueOffset) -> list[float | bool | int]:
    """The vd_msgs/TorqueOffsetEstimate fields of one estimate, in CDR order: offset [N m],
    offset_std [N m], offset_used [N m], converged, clamped, episodes."""
    return [getattr(estimate, attr) for _, attr in OFFSET_MESSAGE_FIELDS]


def radius_values(est: Estimates) -> list[float | bool | int]:
    """The vd_msgs/RollingRadiusEstimate fields of one estimate, in CDR order: radius [m],
    radius_std [m], radius_used [m], converged, free_wheels."""
    return [getattr(est, attr) for _, attr in RADIUS_MESSAGE_FIELDS]


class Encoders:
    """One encoder per (message type, frame_id), made on first use."""

    def __init__(self) -> None:
        """Start with none."""
        self._codecs: dict[tuple[str, bytes], MessageCodec] = {}
        self._alerts: dict[bytes, AlertsCodec] = {}

    def __call__(self, msgtype: str, frame: bytes) -> MessageCodec:
        """The encoder of `msgtype` writing header.frame_id `frame`."""
        codec = self._codecs.get((msgtype, frame))
        if codec is None:
            codec = MessageCodec(msgtype, frame.decode(errors='replace'))
            self._codecs[(msgtype, frame)] = codec
        return codec

    def alerts(self, frame: bytes) -> AlertsCodec:
        """The vd_msgs/msg/Alerts encoder writing header.frame_id `frame`."""
        codec = self._alerts.get(frame)
        if codec is None:
            codec = AlertsCodec(frame.decode(errors='replace'))
            self._alerts[frame] = codec
        return codec


def aligned_input(
    msgtype: str,
    key: str,
    aligner: StampAligner | InputMatcher | LatestMatcher,
    on_matched: Callable[[int, dict[str, Any]], None],
    counts: dict[str, int],
) -> Callable[[bytes], None]:
    """Subscription callback: decode, match by stamp, call ``on_matched`` once a set is full.

    Args:
        msgtype: the input's type, e.g. 'vd_msgs/msg/WheelStates'.
        key: its name in `aligner`.
        aligner: the node's stamp matcher; it receives ``(frame_id, field values)``. An
            `InputMatcher` holds the inputs it holds (their latest value) instead.
        on_matched: called with (stamp [ns], {key: (frame_id, values)}) for every full set.
        counts: its 'undecodable' entry counts messages that are not valid CDR of `msgtype`
            (dropped, never a crash).
    """
    decoder = MessageCodec(msgtype)

    def callback(data: bytes) -> None:
        try:
            stamp_ns, frame, values = decoder.decode(data)
        except BagFormatError:
            counts['undecodable'] += 1
            return
        if isinstance(aligner, StampAligner):
            matched = aligner.push(key, stamp_ns, (frame, values))
            if matched is not None:
                on_matched(stamp_ns, matched)
            return
        if key in aligner.held:
            aligner.hold(key, time.monotonic_ns(), (frame, values))
            return
        for stamp, full in aligner.push_all(key, stamp_ns, (frame, values), time.monotonic_ns()):
            on_matched(stamp, full)

    return callback


def matched_inputs(mapping: InputMapping, names: Sequence[str]) -> tuple[str, ...]:
    """Which of the inputs `names` a node matches by header stamp; the others are held.

    The first of `names` (the wheel angles) drives: the outputs carry its stamps. Inputs with
    a header stamp are matched with it when it has one too. An input without header
    (Float64MultiArray, stamped with its receive time) matches nothing: it is held (its
    latest value joins each matched set); so is every other input when the driver has none.
    """
    brake = (mapping.brake,) if mapping.brake is not None else ()
    specs = {s.name: s for s in (*mapping.specs, mapping.engine, *brake)}
    if not has_header(specs[names[0]]):
        return (names[0],)
    return tuple(n for n in names if has_header(specs[n]))


class InputMatcher:
    """Stamp-matched inputs (a `StampAligner`) plus held inputs (their latest value).

    A matched set is complete when every matched input delivered its stamp; the held inputs'
    latest values are added to it. A set is withheld (counted in `withheld_stale`) while a
    held input has sent nothing yet or its latest value is older than `max_age_ns` by the
    receive clock: a stopped torque topic must not feed old torques to fresh wheel speeds.
    """

    def __init__(
        self,
        matched: Sequence[str],
        held: Sequence[str],
        capacity: int,
        max_jump_back_ns: int | None,
        max_age_ns: int,
    ) -> None:
        """Create the matcher.

        Args:
            matched: inputs matched by header stamp (at least one).
            held: inputs taken at their latest value.
            capacity: messages buffered per matched input (`StampAligner`).
            max_jump_back_ns: see `StampAligner`.
            max_age_ns: [ns] > 0, oldest usable held value, by the receive clock.
        """
        self.aligner = StampAligner(matched, capacity=capacity, max_jump_back_ns=max_jump_back_ns)
        self.held = tuple(held)
        self.max_age_ns = max_age_ns
        self._latest: dict[str, tuple[int, Any]] = {}
        self.withheld_stale = 0

    def hold(self, key: str, receive_ns: int, payload: Any) -> None:
        """Keep the latest value of the held input `key` (received at `receive_ns`)."""
        self._latest[key] = (receive_ns, payload)

    def push(
        self, key: str, stamp_ns: int, payload: Any, receive_ns: int
    ) -> dict[str, Any] | None:
        """Add a matched input's message; return the full set {input: payload} or None."""
        matched = self.aligner.push(key, stamp_ns, payload)
        if matched is None or not self.held:
            return matched
        for name in self.held:
            latest = self._latest.get(name)
            if latest is None or receive_ns - latest[0] > self.max_age_ns:
                self.withheld_stale += 1
                return None
            matched[name] = latest[1]
        return matched

    def push_all(
        self, key: str, stamp_ns: int, payload: Any, receive_ns: int
    ) -> list[tuple[int, dict[str, Any]]]:
        """`push` as the list of (stamp [ns], set) it completes (the matchers' common form)."""
        matched = self.push(key, stamp_ns, payload, receive_ns)
        return [] if matched is None else [(stamp_ns, matched)]

    def counts(self) -> dict[str, int]:
        """The aligner's totals and the sets withheld for a missing or old held input."""
        return {**self.aligner.counts(), 'withheld_held_input_old': self.withheld_stale}

    def queued(self) -> dict[str, int]:
        """Messages waiting per matched input (a held input's latest value is not counted)."""
        return self.aligner.queued()


class LatestMatcher:
    """The mapping's 'latest' alignment live (`LatestAligner`): each wheel stamp with the
    newest not-later sample of every other input, the sets the replay computes. Nothing is
    held by receive time (``held`` is empty); a headerless input is stamped on receipt.
    """

    held: tuple[str, ...] = ()

    def __init__(
        self, names: Sequence[str], capacity: int, max_jump_back_ns: int | None, max_age_ns: int
    ) -> None:
        """Create the matcher; ``names`` the inputs, the wheels first (they drive)."""
        self.aligner = LatestAligner(names, max_age_ns, capacity, max_jump_back_ns)

    def hold(self, key: str, receive_ns: int, payload: Any) -> None:
        """Never called: no input is held (``held`` is empty)."""
        raise AssertionError(f'{key}: the latest alignment holds no input')

    def push_all(
        self, key: str, stamp_ns: int, payload: Any, receive_ns: int
    ) -> list[tuple[int, dict[str, Any]]]:
        """Add one input's message; the sets it completes, oldest first."""
        del receive_ns  # the samples are ordered by their stamps, not by their arrival
        return self.aligner.push(key, stamp_ns, payload)

    def counts(self) -> dict[str, int]:
        """The aligner's totals."""
        return self.aligner.counts()

    def queued(self) -> dict[str, int]:
        """Messages waiting per input (`LatestAligner.queued`)."""
        return self.aligner.queued()


def input_matcher(
    mapping: InputMapping,
    names: Sequence[str],
    capacity: int,
    max_jump_back_ns: int | None,
    max_age_ns: int,
    held: Sequence[str] | None = None,
) -> InputMatcher | LatestMatcher:
    """The matcher of the mapping's alignment for the inputs ``names`` (the wheels first).

    'exact': stamp-matched inputs with the others held: ``held``, by default the headerless
    ones (`matched_inputs`; a node whose inputs are not the mapping's names gives its own);
    'latest': `LatestMatcher` with the mapping's ``max_age`` (nothing held).
    """
    if mapping.alignment == 'latest':
        return LatestMatcher(names, capacity, max_jump_back_ns, round(mapping.max_age * 1e9))
    if held is None:
        matched = matched_inputs(mapping, names)
        held = [n for n in names if n not in matched]
    return InputMatcher(
        [n for n in names if n not in held],
        held,
        capacity=capacity,
        max_jump_back_ns=max_jump_back_ns,
        max_age_ns=max_age_ns,
    )


class InputWatch:
    """Arrivals of each mapped input topic: one that stopped or does not fit, and how well
    each stamped one arrives (`health.StreamHealth`: share of expected stamps, lag).

    Attributes:
        timeout_ns: [ns] an input whose last message is older than this has stopped.
        limits: when an input's window is reported (WARN).
    """

    def __init__(
        self, topics: Sequence[str], timeout_ns: int, limits: HealthLimits | None = None
    ) -> None:
        """Watch `topics` (none seen yet)."""
        self.timeout_ns = timeout_ns
        self.limits = limits or HealthLimits()
        self.messages = dict.fromkeys(topics, 0)
        self._last: dict[str, int] = {}
        self._problem: dict[str, str] = {}
        self._health: dict[str, StreamHealth] = {}
        self._first: dict[str, RateMeter] = {}

    def seen(self, topic: str, now_ns: int) -> None:
        """Note a message of `topic` received at `now_ns` (monotonic clock)."""
        self.messages[topic] += 1
        self._last[topic] = now_ns

    def stamped(self, topic: str, stamp_ns: int, lag_ns: int) -> None:
        """Note the header stamp [ns] of a decoded message of `topic` and its lag [ns] (the
        node clock at arrival minus the stamp). Inputs stamped on receipt are not noted."""
        health = self._health.get(topic)
        if health is None:
            health = self._health[topic] = StreamHealth()
            self._first[topic] = RateMeter(SPEED_STAMPS_KEPT)
        health.add(stamp_ns, lag_ns)
        self._first[topic].add(stamp_ns)

    def first_stamps(self, topic: str | None) -> list[int] | None:
        """[ns] the first header stamps of a stamped input (`SPEED_STAMPS_KEPT`), in arrival
        order; None for an input stamped on receipt, not heard from, or no topic."""
        meter = self._first.get(topic) if topic is not None else None
        return meter.stamps if meter is not None else None

    def unfit(self, topic: str, problem: str) -> None:
        """Note a message of `topic` the mapping cannot read (the last problem is reported)."""
        self._problem[topic] = problem

    def status(
        self, now_ns: int, queues: dict[str, int] | None = None, capacity: int | None = None
    ) -> tuple[int, str, dict[str, object]]:
        """Level (OK, WARN or ERROR), message and per-topic values at `now_ns`; closes the
        stamped inputs' health window.

        WARN names each topic silent for longer than `timeout_ns` (or never heard from while
        another input arrives) and how long, and each stamped topic that lost more than
        `limits` allow, lags or fills the matcher (`queues`: messages waiting per topic, of
        `capacity`); ERROR the last mapping problem of a topic. Back to OK when every topic
        arrives again.
        """
        notes: list[str] = []
        level = OK
        values: dict[str, object] = {}
        for topic, count in self.messages.items():
            values[f'{topic} messages'] = count
            last = self._last.get(topic)
            if last is None:
                if self._last:
                    notes.append(f'no message on {topic} yet')
                    level = max(level, WARN)
                continue
            age = (now_ns - last) * 1e-9
            values[f'{topic} last_message_age_s'] = round(age, 3)
            if now_ns - last > self.timeout_ns:
                notes.append(f'{topic} stopped: no message for {age:.1f} s')
                level = max(level, WARN)
        for topic, health in self._health.items():
            queue = queues.get(topic) if queues is not None else None
            warned, numbers = health_notes(topic, health.window(), self.limits, queue, capacity)
            values.update(numbers)
            if warned:
                notes.extend(warned)
                level = max(level, WARN)
        for topic, problem in self._problem.items():
            notes.append(f'{topic}: {problem}')
            level = ERROR
        self._problem.clear()
        return level, '; '.join(notes), values


def merge_status(
    level: int,
    message: str,
    watch: InputWatch,
    now_ns: int,
    queues: dict[str, int] | None = None,
    capacity: int | None = None,
) -> tuple[int, str, dict[str, object]]:
    """A node's diagnostic level and message with `watch`'s status added, and its values
    (`queues`, `capacity`: see `InputWatch.status`)."""
    watch_level, note, values = watch.status(now_ns, queues, capacity)
    if note:
        message = note if level == OK else f'{message}; {note}'
        level = max(level, watch_level)
    return level, message, values


def queued_by_topic(
    matcher: InputMatcher | LatestMatcher, topics: Mapping[str, str]
) -> dict[str, int]:
    """The matcher's waiting messages per input, keyed by the inputs' topics (`topics`:
    input name -> topic; inputs not in the matcher are left out)."""
    queued = matcher.queued()
    return {topics[name]: n for name, n in queued.items() if name in topics}


def follow_input_rate(
    estimator: Estimator,
    wheel_stamps: list[int],
    speed_stamps: list[int] | None,
    node: Any,
) -> None:
    """Fix the estimator's settings left to the inputs' rate, after its `FOLLOW_AFTER`-th
    wheel stamp, as `vd replay` does at the same stamp (`rate_settings.follow_rate_hz`).

    Args:
        estimator: the node's estimator (`Estimator.follow_rate`).
        wheel_stamps: [ns] the first `FOLLOW_AFTER` wheel stamps estimated.
        speed_stamps: [ns] the body speed's first header stamps (`InputWatch.first_stamps`);
            None where the speed has none of its own.
        node: logs what was fixed (INFO, once).
    """
    rate = follow_rate_hz(wheel_stamps, speed_stamps)
    fixed = estimator.follow_rate(rate)
    if fixed:
        node.get_logger().info(f'settings: {settings_line({}, "", fixed, rate, rest=False)}')


def mapped_input(
    spec: InputSpec,
    matcher: InputMatcher | LatestMatcher,
    on_matched: Callable[[int, dict[str, Any]], None],
    counts: dict[str, int],
    watch: InputWatch,
    clock_ns: Callable[[], int],
    key: str | None = None,
    radius: float | None = None,
) -> Callable[[bytes], None]:
    """Subscription callback of a mapped input: decode to SI values, then match or hold.

    Args:
        spec: the input's mapping; its decoder is made here.
        matcher: the node's matcher; it receives ``(frame_id, values)``, values a tuple of
            ``spec.width`` floats in SI units with the mapping's signs.
        on_matched: called with (stamp [ns], {input: (frame_id, values)}) for a full set.
        counts: 'undecodable' counts bytes that are not a message of the type, 'unfit'
            messages the mapping cannot read (a joint absent): dropped, never a crash.
        watch: notes each arrival (monotonic clock) and each unfit message.
        clock_ns: the node's clock [ns]: the stamp of a message without header.
        key: the input's name in `matcher` (default ``spec.name``).
        radius: effective rolling radius [m], for wheel speeds in m/s or km/h.
    """
    decoder = InputDecoder(spec, radius)
    name = key or spec.name
    topic = spec.topic
    held = name in matcher.held
    headerless = not has_header(spec)

    def callback(data: bytes) -> None:
        now = time.monotonic_ns()
        watch.seen(topic, now)
        try:
            stamp_ns, frame, values = decoder.decode(data, clock_ns() if headerless else 0)
        except BagFormatError:
            counts['undecodable'] += 1
            return
        except MappingError as exc:
            counts['unfit'] = counts.get('unfit', 0) + 1
            watch.unfit(topic, str(exc))
            return
        if not headerless:
            watch.stamped(topic, stamp_ns, clock_ns() - stamp_ns)
        if held:
            matcher.hold(name, now, (frame, values))
            return
        for stamp, matched in matcher.push_all(name, stamp_ns, (frame, values), now):
            on_matched(stamp, matched)

    return callback
