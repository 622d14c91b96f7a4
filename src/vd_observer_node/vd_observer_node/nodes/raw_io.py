"""The nodes' raw message path: CDR bytes in, stamp matching, CDR bytes out (ROS-free).

What the estimator, alerts and pipeline nodes share around their subscriptions (taken with
``raw=True``) and publishers (given bytes): decoding each input with its
`bag.cdr_message.MessageCodec` into a `alignment.StampAligner`, and one encoder per output type
and ``frame_id`` (an output keeps the frame of the input it derives from).

The mapped sensor inputs (:mod:`vd_observer_node.inputs`) go through `mapped_input`: each
subscription's bytes are decoded by the mapping's `InputDecoder` to SI values, then either
matched by header stamp (`InputMatcher`, a `StampAligner`) or, for an input without header
stamp (Float64MultiArray, stamped on receipt by `ReceiptStamps`), held as its latest value and
added to each matched set. `InputWatch` notes every input's arrivals and reports a topic that
stopped; `MatchCheck` reports inputs whose stamps never meet.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any, Final

from vd_common.settings_log import settings_line

from vd_observer_node.bag.cdr_message import AlertsCodec, MessageCodec
from vd_observer_node.bag.errors import BagFormatError
from vd_observer_node.estimation.alignment import LatestAligner, StampAligner
from vd_observer_node.estimation.differentiator import LevantDifferentiator
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
    'MatchCheck',
    'ReceiptStamps',
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
    'wheel_lipschitz_value',
]


def wheel_lipschitz_value(wheels: LevantDifferentiator) -> str:
    """The diagnostics value of the L each wheel steps with now [rad/s^3], FL FR RL RR (it
    rises above ``wheel_lipschitz`` with the angles' resolution, `ObserverConfig`)."""
    return ' '.join(f'{value:.4g}' for value in wheels.lipschitz_in_use)


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
    clock_ns: Callable[[], int] | None = None,
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
        clock_ns: the node's clock [ns]; given, the input's stamps set the time base of the
            headerless inputs where it drives (`ReceiptStamps`).
    """
    decoder = MessageCodec(msgtype)
    receipts = None if isinstance(aligner, StampAligner) else aligner.receipts

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
        if receipts is not None and clock_ns is not None:
            receipts.note(key, stamp_ns, clock_ns())
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


#: [ns] A header stamp within this of the node clock at its receipt is on the node's clock: a
#: live sensor is never a second late, and a played bag without /clock is off by its age.
SAME_CLOCK_NS: Final = 1_000_000_000
#: [ns] How long every input may arrive without one matched set before `MatchCheck` reports
#: it (the nodes publish their status once per second: reported within 3 s). Sets match
#: within one period of the slowest input where the stamps meet, so 2 s is not a slow start.
MATCH_WAIT_NS: Final = 2_000_000_000


class ReceiptStamps:
    """The stamp of an input without header: its receipt, in the stamped inputs' time base.

    On a car the sensors stamp by the clock the node runs on: a headerless message is stamped
    with the node clock at receipt, as always. A played bag's header stamps are the bag's:
    unless the node follows the player's /clock (``use_sim_time:=true``) its clock is days or
    years away from them, and a receipt stamp by the node clock never falls among the wheel
    stamps ('latest' alignment: not one set). So when the reference input's header stamp is
    more than `SAME_CLOCK_NS` from the node clock at its receipt, a receipt is translated:
    the reference's newest stamp plus the node-clock time elapsed since its receipt. That is
    the receipt time on the bag's clock, late by the reference's delivery delay (a local
    player's: well under a millisecond) and, between two reference messages (10 ms at
    100 Hz), off by the play rate's difference from 1 times the time elapsed.

    Each input's stamps stay increasing: a translated stamp not after the input's last one
    (the reference arrived late) is moved just after it, unless it jumped back by more than
    `SAME_CLOCK_NS` (a looped bag: a new time line).

    Attributes:
        reference: the input whose header stamps give the time base (the driving one).
        offset_ns: [ns] the reference's last header stamp minus the node clock at its receipt
            (None before it arrived).
    """

    def __init__(self, reference: str, same_clock_ns: int = SAME_CLOCK_NS) -> None:
        """Create the stamper; nothing received yet (receipts stamped by the node clock)."""
        self.reference = reference
        self.same_clock_ns = same_clock_ns
        self.offset_ns: int | None = None
        self._ref: tuple[int, int] | None = None
        self._last: dict[str, int] = {}

    @property
    def translating(self) -> bool:
        """Whether receipts are stamped on the reference's clock, not the node's."""
        return self.offset_ns is not None and abs(self.offset_ns) > self.same_clock_ns

    def note(self, key: str, stamp_ns: int, clock_ns: int) -> None:
        """A message of the stamped input `key` with header stamp `stamp_ns` [ns] received at
        node clock `clock_ns` [ns] (only the reference's are kept)."""
        if key == self.reference:
            self._ref = (stamp_ns, clock_ns)
            self.offset_ns = stamp_ns - clock_ns

    def stamp(self, key: str, clock_ns: int) -> int:
        """[ns] The stamp of a message of the headerless input `key` received at node clock
        `clock_ns` [ns]."""
        ref = self._ref
        if ref is None or not self.translating:
            return clock_ns
        stamp = ref[0] + (clock_ns - ref[1])
        last = self._last.get(key)
        if last is not None and stamp <= last and last - stamp <= self.same_clock_ns:
            stamp = last + 1
        self._last[key] = stamp
        return stamp


class MatchCheck:
    """Notes the stamps a matcher receives and reports inputs that arrive but never match.

    Every input of the matcher arriving, and for `MATCH_WAIT_NS` not one matched set (since
    the first message of any input, or since the last set; and a quarter of that since the
    last input was first heard from) means their stamps do not meet: 'exact' alignment on
    topics with their own clocks, or stamps on different clocks (a played bag's inputs
    against the node clock's receipt stamps, a sensor stamping by its boot time). The
    report names each input's newest stamp against the driving input's and
    what to set; it is cleared by the next set.

    Attributes:
        names: the matched inputs, the driving one first.
        topics: input name -> topic, where known (`mapped_input` fills it).
        headerless: the inputs stamped on receipt.
    """

    def __init__(
        self,
        names: Sequence[str],
        alignment: str,
        max_age_ns: int | None = None,
        wait_ns: int = MATCH_WAIT_NS,
    ) -> None:
        """Create the check.

        Args:
            names: the matched inputs, the driving one first.
            alignment: 'exact' or 'latest' (the advice differs).
            max_age_ns: [ns] 'latest': the oldest a held sample may be.
            wait_ns: [ns] > 0, how long all inputs may arrive without a set.
        """
        self.names = tuple(names)
        self.alignment = alignment
        self.max_age_ns = max_age_ns
        self.wait_ns = wait_ns
        self.topics: dict[str, str] = {}
        self.headerless: set[str] = set()
        self._newest: dict[str, int] = {}
        self._pushed_at: dict[str, int] = {}  # the last push of each input (monotonic [ns])
        self._start: int | None = None  # the first push of any input
        self._all_at: int | None = None  # when the last input was first heard from
        self._since: int | None = None  # the last matched set

    def pushed(self, key: str, stamp_ns: int, now_ns: int, matched: bool) -> None:
        """Note a message of input `key` stamped `stamp_ns` [ns], pushed at `now_ns` [ns]
        (monotonic), and whether a set was matched."""
        first = key not in self._newest
        self._newest[key] = stamp_ns
        self._pushed_at[key] = now_ns
        if self._start is None:
            self._start = now_ns
        if first and len(self._newest) == len(self.names):
            self._all_at = now_ns
        if matched:
            self._since = now_ns

    def status(self, now_ns: int) -> str:
        """The report at `now_ns` [ns] (monotonic), '' while sets match, an input is not
        heard from yet, or one has not arrived for `wait_ns` (the `InputWatch` reports
        those)."""
        since = self._since if self._since is not None else self._start
        if since is None or self._all_at is None or len(self._newest) < len(self.names):
            return ''
        # a moment for the first set after the last input came
        if now_ns - since < self.wait_ns or now_ns - self._all_at < self.wait_ns // 4:
            return ''
        if any(now_ns - t > self.wait_ns for t in self._pushed_at.values()):
            return ''  # an input stopped: its own report
        driver = self.names[0]
        base = self._newest[driver]
        offsets = {k: (self._newest[k] - base) * 1e-9 for k in self.names[1:]}
        parts = ', '.join(f'{self._name(k)} {off:+.6g} s' for k, off in offsets.items())
        note = (
            f'no input set matched for {(now_ns - since) * 1e-9:.0f} s: the newest stamps of '
            f'{parts} from those of {self._name(driver)}'
        )
        limit = self.max_age_ns if self.max_age_ns is not None else SAME_CLOCK_NS
        if any(abs(off) * 1e9 > max(limit, SAME_CLOCK_NS) for off in offsets.values()):
            note += (
                '; they are not on one clock: with a played bag start the nodes with '
                "use_sim_time:=true (they follow the player's /clock); on a car make every "
                'input stamp by one clock'
            )
        elif self.alignment == 'exact':
            note += (
                "; 'exact' alignment needs equal stamps: for topics on their own clocks set "
                "the mapping's alignment: latest (inputs.alignment: latest)"
            )
        elif any(abs(off) * 1e9 > limit for off in offsets.values()):
            note += "; more than the mapping's max_age apart: raise max_age (inputs.max_age)"
        return note

    def _name(self, key: str) -> str:
        topic = self.topics.get(key)
        receipt = ', stamped on receipt' if key in self.headerless else ''
        return f'{key} ({topic}{receipt})' if topic else key


class InputMatcher:
    """Stamp-matched inputs (a `StampAligner`) plus held inputs (their latest value).

    A matched set is complete when every matched input delivered its stamp; the held inputs'
    latest values are added to it. A set is withheld (counted in `withheld_stale`) while a
    held input has sent nothing yet or its latest value is older than `max_age_ns` by the
    receive clock: a stopped torque topic must not feed old torques to fresh wheel speeds.

    Attributes:
        check: reports matched inputs whose stamps never meet (`MatchCheck`).
        receipts: the stamps of headerless inputs that are matched, not held (a headerless
            driver): `ReceiptStamps`.
        taps: by matched input, called with each of its samples (stamp [ns], values) before
            it is matched (pipeline_node's speed samples, `mapped_input`).
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
        self.check = MatchCheck(matched, 'exact')
        self.receipts = ReceiptStamps(matched[0])
        self.taps: dict[str, Callable[[int, tuple[float, ...]], None]] = {}
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
        self.check.pushed(key, stamp_ns, receive_ns, matched is not None)
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
    held by receive time (``held`` is empty); a headerless input is stamped on receipt
    (`receipts`: in the driving input's time base where that is not the node clock's).

    Attributes:
        check: reports inputs whose stamps never meet (`MatchCheck`).
        receipts: the stamps of the headerless inputs (`ReceiptStamps`).
        taps: by input, called with each of its samples (stamp [ns], values) before it is
            matched (pipeline_node's speed samples, `mapped_input`).
    """

    held: tuple[str, ...] = ()

    def __init__(
        self, names: Sequence[str], capacity: int, max_jump_back_ns: int | None, max_age_ns: int
    ) -> None:
        """Create the matcher; ``names`` the inputs, the wheels first (they drive)."""
        self.aligner = LatestAligner(names, max_age_ns, capacity, max_jump_back_ns)
        self.check = MatchCheck(names, 'latest', max_age_ns)
        self.receipts = ReceiptStamps(names[0])
        self.taps: dict[str, Callable[[int, tuple[float, ...]], None]] = {}

    def hold(self, key: str, receive_ns: int, payload: Any) -> None:
        """Never called: no input is held (``held`` is empty)."""
        raise AssertionError(f'{key}: the latest alignment holds no input')

    def push_all(
        self, key: str, stamp_ns: int, payload: Any, receive_ns: int
    ) -> list[tuple[int, dict[str, Any]]]:
        """Add one input's message; the sets it completes, oldest first."""
        # the samples are ordered by their stamps, not by their arrival
        sets = self.aligner.push(key, stamp_ns, payload)
        self.check.pushed(key, stamp_ns, receive_ns, bool(sets))
        return sets

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
        #: the node's matcher's check, reported with the topics (`mapped_input` sets it)
        self.check: MatchCheck | None = None
        #: the check's report when it is new (not in the last status): to be logged once
        self.new_report: str | None = None
        self._reported = False

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
        `capacity`), and inputs whose stamps never meet (`check`; `new_report` holds it the
        first time); ERROR the last mapping problem of a topic. Back to OK when every topic
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
        report = self.check.status(now_ns) if self.check is not None else ''
        self.new_report = report if report and not self._reported else None
        self._reported = bool(report)
        if report:
            notes.append(report)
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
    log: Callable[[str], object] | None = None,
) -> tuple[int, str, dict[str, object]]:
    """A node's diagnostic level and message with `watch`'s status added, and its values
    (`queues`, `capacity`: see `InputWatch.status`); `log` (a logger's warning) gets the
    report of inputs whose stamps never meet once, when it first appears."""
    watch_level, note, values = watch.status(now_ns, queues, capacity)
    if log is not None and watch.new_report is not None:
        log(watch.new_report)
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
        watch: notes each arrival (monotonic clock) and each unfit message; it reports the
            matcher's `MatchCheck`.
        clock_ns: the node's clock [ns]: the stamp of a message without header, translated
            by the matcher's `ReceiptStamps` where the stamped inputs run on another clock.
        key: the input's name in `matcher` (default ``spec.name``).
        radius: effective rolling radius [m], for wheel speeds in m/s or km/h.
    """
    decoder = InputDecoder(spec, radius)
    name = key or spec.name
    topic = spec.topic
    held = name in matcher.held
    headerless = not has_header(spec)
    receipts = matcher.receipts
    matcher.check.topics[name] = topic
    if headerless:
        matcher.check.headerless.add(name)
    watch.check = matcher.check

    def callback(data: bytes) -> None:
        now = time.monotonic_ns()
        watch.seen(topic, now)
        clock = clock_ns()
        try:
            stamp_ns, frame, values = decoder.decode(
                data, receipts.stamp(name, clock) if headerless else 0
            )
        except BagFormatError:
            counts['undecodable'] += 1
            return
        except MappingError as exc:
            counts['unfit'] = counts.get('unfit', 0) + 1
            watch.unfit(topic, str(exc))
            return
        if not headerless:
            watch.stamped(topic, stamp_ns, clock - stamp_ns)
            receipts.note(name, stamp_ns, clock)
        if held:
            matcher.hold(name, now, (frame, values))
            return
        tap = matcher.taps.get(name)
        if tap is not None:  # every sample, matched or not
            tap(stamp_ns, values)
        for stamp, matched in matcher.push_all(name, stamp_ns, (frame, values), now):
            on_matched(stamp, matched)

    return callback
