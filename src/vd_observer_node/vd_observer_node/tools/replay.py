"""Offline replay: run the ROS-free observer/estimator cascade over a bag, write a new bag.

Pipeline (arrays, no per-message decoding in Python), block by block of the bag so that memory
stays bounded (`BLOCK_MESSAGES`; the state of every step carries over to the next block):

1. read the three sensor topics and every ``/vd/truth/*`` topic as raw CDR;
2. batch-decode the sensors to numpy (:mod:`.cdr_batch`);
3. align them on exact header stamps (a stamp present on all three topics, as the live
   estimator node's ``StampAligner`` does) and call
:func:`vd_observer_node.estimation.cascade.run_cascade`;
4. run :class:`vd_observer_node.situation.monitor.SituationMonitor` per aligned stamp on the
   sensors and the cascade's wheel speed, μ and loads, as the live alerts node does: the friction
   potential (``/vd/estimates/friction_potential``) and the 12 alert records
   (``/vd/estimates/alerts``). The tyre curves come from the same vehicle file as the
   estimator vehicle;
5. batch-encode the estimates (and the observer's filtered speed on
   ``/vd/observer/body_velocity``, as the live observer node publishes it), stamped with the
   wheel-angle header stamp they derive from and logged at that message's log time;
6. write inputs (raw), truth (raw) and estimates, merged in log-time order, to OUT_BAG (each
   message as soon as nothing logged earlier can come any more).

Inputs' own ``/vd/estimates/*`` and ``/vd/observer/*`` topics (a live recording) are not
copied: the output holds the replayed ones only.

Beside it: the settings file (`settings_file`), the output messages from a cascade result
(`replay_topics`) and the writer that merges them in log-time order (`merged_writer`).
"""

from __future__ import annotations

import os
import shutil
import sys
import time
from collections.abc import Callable, Mapping
from dataclasses import replace
from functools import partial
from pathlib import Path
from typing import Any

from tqdm import tqdm
from vd_common.topics import (
    SENSORS,
    TRUTH_NAMESPACE,
)

from vd_observer_node.bag.cdr_batch import upgrade_batch
from vd_observer_node.bag.errors import BagExistsError, ReplayInputError
from vd_observer_node.bag.read_ahead import read_ahead
from vd_observer_node.bag.reader import BagReader, TopicArrays
from vd_observer_node.bag.writer import BagWriter
from vd_observer_node.errors import ConfigurationError
from vd_observer_node.estimation.cascade import (
    CascadeResult,
    run_cascade,
)
from vd_observer_node.inputs.mapping import (
    InputMapping,
    InputSpec,
    default_mapping,
)
from vd_observer_node.situation.chain_settings import (
    ChainSettings,
    chain_settings,
    check_settings_fit,
)
from vd_observer_node.situation.monitor import (
    SituationMonitor,
)
from vd_observer_node.tools.merged_writer import MergedWriter, OutOfOrderError
from vd_observer_node.tools.replay_run import (
    ALERT_TOPICS,
    ESTIMATE_TOPICS,
    MAX_WAIT_S,
    ReplayReport,
    ReplayRun,
)
from vd_observer_node.tools.replay_topics import (
    estimate_topics,
    situation_topics,
)

__all__ = [
    'ALERT_TOPICS',
    'BLOCK_MESSAGES',
    'ESTIMATE_TOPICS',
    'MAX_WAIT_S',
    'SENSOR_TOPICS',
    'TRUTH_PREFIX',
    'ReplayReport',
    'estimate_topics',
    'replay_bag',
    'situation_topics',
]
SENSOR_TOPICS = SENSORS
TRUTH_PREFIX = TRUTH_NAMESPACE
#: messages read per block by default: bounds the replay's memory (docs/replay.md)
BLOCK_MESSAGES = 1 << 17


def check_input_topic(
    bag: str | os.PathLike[str],
    topics: Mapping[str, Any],
    spec: InputSpec,
    source: str | None = None,
) -> None:
    """Refuse an input the bag cannot deliver: its topic absent, empty or of another type.

    Args:
        bag: the bag's path (for the message).
        topics: the bag's topics by name (`BagReader.topics`: ``message_count``, ``msgtype``).
        spec: the input (sensor or IMU) of the mapping.
        source: the mapping's file (for the message), or None.

    Raises:
        ReplayInputError: one line naming the input, and the bag's topics where the topic is
            not there (a typo).
    """
    origin = f' ({source}: {spec.name})' if source else f' ({spec.name})'
    info = topics.get(spec.topic)
    if info is None:
        listed = ', '.join(sorted(topics)) or 'none'
        raise ReplayInputError(
            f'{bag}: no messages on sensor topic {spec.topic}{origin}: the bag has no such '
            f'topic (its topics: {listed})'
        )
    if info.message_count == 0:
        raise ReplayInputError(
            f'{bag}: no messages on sensor topic {spec.topic}{origin}: the topic is empty'
        )
    if info.msgtype != spec.msgtype:
        raise ReplayInputError(
            f'{bag}: {spec.topic} has type {info.msgtype}, need {spec.msgtype}{origin}'
        )


def replay_bag(
    in_bag: str | os.PathLike[str],
    out_bag: str | os.PathLike[str],
    settings: ChainSettings | None = None,
    *,
    mapping: InputMapping | None = None,
    situation: bool = True,
    progress: bool = True,
    cascade: Callable[..., CascadeResult] | None = None,
    block_messages: int | None = BLOCK_MESSAGES,
) -> ReplayReport:
    """Replay a bag's sensor topics through the cascade and write inputs, truth and estimates.

    The bag is processed in blocks of messages (`BagReader.topic_array_blocks`) and the output
    written as they go, so memory is bounded by the block size, not the bag length; the
    alignment, cascade, monitor and summary carry their state from block to block, and the
    output is the same whatever the block size (tested) for bags in log-time order whose
    inputs' stamps do not go back in time.

    Args:
        in_bag: input bag folder or .mcap file.
        out_bag: output bag folder (must not exist).
        settings: the chain's settings for ``mapping`` (`situation.chain_settings`, or
            `SettingsFile.settings` of a settings file: the vehicle file's estimator
            vehicle, tyre, drivetrain and brakes, the observers', estimator's, alerts' and
            IMU fusion's settings); None: the defaults for ``mapping`` and the Clio file.
        mapping: which topics, types, joints, units and signs are the wheel angles (or
            speeds), body speed and wheel torques (or the engine torque and gear, by the
            mapping's ``torque_source``), and how their samples are aligned
            (:mod:`vd_observer_node.inputs.mapping`); default vd's own ``/vd/sensors/*``
            topics.
        situation: also compute and write the friction potential and the alerts
            (:data:`ALERT_TOPICS`) with :class:`SituationMonitor`, as the alerts node does
            (not with a vehicle file without tyre: a note says so).
        progress: show a tqdm progress bar on stderr.
        cascade: the array cascade (injectable for tests); signature of ``run_cascade``,
            called once per block with a `CascadeState` to carry; default `run_cascade`.
        block_messages: input and truth messages read per block (>= 1; about 20 s of a
            1 kHz drive by default); None: the whole bag in one block.

    Raises:
        ReplayInputError: a sensor topic is missing or has the wrong type.
        MappingError: the messages do not fit the mapping (a joint or element absent).
        ConfigurationError: settings made for another mapping
            (`situation.chain_settings.check_settings_fit`).
        BagError: reading or writing failed (see .errors).
        VehicleParameterError: the vehicle file is unreadable or invalid.
    """
    started = time.perf_counter()
    if block_messages is not None and block_messages < 1:
        raise ConfigurationError(f'block_messages must be >= 1, got {block_messages}')
    if cascade is None:
        cascade = run_cascade
    target = Path(out_bag)
    if target.exists() and (not target.is_dir() or any(target.iterdir())):
        # Fail before minutes of work, not when the output is finally written.
        raise BagExistsError(f'{target}: already exists (choose a new bag name)')
    mapping = mapping or default_mapping()
    settings = settings or chain_settings(mapping)
    check_settings_fit(settings, mapping)
    reader = BagReader(in_bag)
    topics = reader.topics
    # the IMU too: a mapping that names one asks for the fusion, so a typo in its topic or
    # a silent sensor must not quietly give the force balance's slope instead
    imu_specs = [mapping.imu] if mapping.imu is not None else []
    for spec in [*mapping.used_specs, *imu_specs]:
        check_input_topic(in_bag, topics, spec, mapping.source)
    imu_topics = [mapping.imu.topic] if mapping.imu is not None else []
    inputs = list(dict.fromkeys([*(spec.topic for spec in mapping.used_specs), *imu_topics]))
    truth = [t for t in topics if t.startswith(TRUTH_PREFIX)]
    notes: list[str] = []
    curves = settings.curves
    if situation and curves is None:
        # an estimation-only vehicle file: everything but the friction potential and alerts
        situation = False
        notes.append(f'friction potential and alerts {settings.situation_off or "off"}')
    make_monitor: Any = SituationMonitor

    def new_monitor() -> Any:
        if not situation:
            return None
        return make_monitor(
            curves,
            settings.vehicle.static_wheel_loads[[0, 2]],
            settings.vehicle.effective_radius,
            observer=settings.observer,
            alerts=settings.alerts,
            friction=settings.friction,
            situation=settings.situation,
        )

    def new_run() -> ReplayRun:
        return ReplayRun(
            mapping=mapping, cascade=cascade, settings=settings, monitor=new_monitor()
        )

    raw_topics = [*inputs, *truth]
    total_in = sum(topics[t].message_count for t in raw_topics)
    bar = tqdm(
        total=2 * total_in,
        unit='msg',
        unit_scale=True,
        desc='replay',
        disable=not progress,
        file=sys.stderr,
    )
    # The per-stamp monitor costs ~20x a message read or written: a bar of its own in
    # samples (at most one per wheel message), so the message bar's rate stays true.
    phase = tqdm(
        total=topics[mapping.wheels.topic].message_count if situation else 0,
        unit='sample',
        unit_scale=True,
        desc='alerts',
        disable=not progress or not situation,
        file=sys.stderr,
        position=1,
        leave=False,
    )
    existed = target.exists()

    def clear() -> None:
        # no half-written output: a new attempt must not find the folder taken
        shutil.rmtree(target, ignore_errors=True)
        if existed:
            target.mkdir(parents=True, exist_ok=True)

    try:
        with bar, phase:
            run = new_run()
            try:
                written = _stream(reader, out_bag, run, raw_topics, bar, phase, block_messages)
            except OutOfOrderError:
                # The files are not in log-time order (e.g. a topic appended after the rest):
                # what was written cannot take what comes. Start again with the whole bag in
                # one block, as before streaming (memory then grows with the bag).
                clear()
                bar.reset(total=2 * total_in)
                phase.reset(total=phase.total)
                run = new_run()
                written = _stream(reader, out_bag, run, raw_topics, bar, phase, None)
    except BaseException:
        clear()
        raise
    wall = time.perf_counter() - started
    parts = run.state.parts
    brakes = settings.brakes
    if brakes is not None and brakes.learn and parts is not None:
        learnt = parts.brake_parts.state[0]
        gain, braking, converged = learnt.gain, learnt.excited_time, learnt.converged
        notes.append(
            f'brake gain learnt online: {gain:.3g} N m per unit of the brake pressure after '
            f'{braking:.1f} s of braking ({"converged" if converged else "not converged"})'
        )
    return replace(
        run.report(written, wall),
        vehicle=settings.vehicle_label,
        notes=tuple(notes),
    )


def _stream(
    reader: BagReader,
    out_bag: str | os.PathLike[str],
    run: ReplayRun,
    raw_topics: list[str],
    bar: Any,
    phase: Any,
    block_messages: int | None,
) -> int:
    """Replay the bag block by block into `out_bag`; the number of messages written.

    Raises:
        OutOfOrderError: the bag's files are not in log-time order (with more than one block).
    """
    topics = reader.topics
    with BagWriter(out_bag, background=True) as writer:
        merged = MergedWriter(writer, topics, len(raw_topics), bar)
        for topic in raw_topics:
            merged.declare(topic, topics[topic].msgtype)
        # what the blocks before left to write: written while the next block's cascade runs
        before: int | None = None

        def write_before(arrays: Mapping[str, TopicArrays]) -> None:
            if before is not None:
                merged.flush(before)
            for topic in raw_topics:
                arr = arrays.get(topic)
                if arr is not None:
                    # a bag recorded before a vd_msgs field was added: copied in today's
                    # layout, so the output holds one definition per type
                    datas = upgrade_batch(arr.msgtype, arr.decoding_type, arr.datas)
                    merged.add(topic, arr.msgtype, arr.log_time_ns, datas)

        # the next block is read on a thread while this one runs (bag.read_ahead)
        blocks = reader.topic_array_blocks(raw_topics, block_messages=block_messages)
        for arrays in read_ahead(blocks):
            bar.update(sum(len(a.datas) for a in arrays.values()))
            run.block(arrays, merged, phase, final=False, meanwhile=partial(write_before, arrays))
            # what comes next is logged at or after the newest log time read (bags are in
            # log-time order; checked by `merged.add`), the estimates of the carried stamps at
            # their wheel message's log time: everything before both is final
            before = min(run.carried_log_ns(), merged.newest_ns)
        run.block({}, merged, phase, final=True, meanwhile=partial(write_before, {}))
        merged.flush(None)
    return merged.written
