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

Beside it: the settings file (`replay_config`), the output messages from a cascade result
(`replay_topics`) and the writer that merges them in log-time order (`merged_writer`).
"""

from __future__ import annotations

import math
import os
import shutil
import sys
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm
from vd_common.topics import (
    ALERTS,
    ESTIMATES,
    ESTIMATES_ALERTS,
    ESTIMATES_TORQUE_OFFSET,
    OBSERVER,
    SENSORS,
    TRUTH_NAMESPACE,
)
from vd_common.vehicle.estimation import EstimationVehicleParams

from vd_observer_node.bag.alerts_cdr import encode_alerts_packed
from vd_observer_node.bag.cdr_batch import encode_packed, upgrade_batch
from vd_observer_node.bag.errors import BagExistsError, ReplayInputError
from vd_observer_node.bag.read_ahead import read_ahead
from vd_observer_node.bag.reader import BagReader, TopicArrays
from vd_observer_node.bag.writer import BagWriter
from vd_observer_node.errors import ConfigurationError
from vd_observer_node.estimation.alignment import BlockAligner
from vd_observer_node.estimation.brakes import Brakes
from vd_observer_node.estimation.cascade import (
    CascadeResult,
    CascadeState,
    offset_result_name,
    run_cascade,
)
from vd_observer_node.estimation.drivetrain import (
    TORQUE_SOURCES,
    Drivetrain,
    torque_source_code,
)
from vd_observer_node.estimation.estimator import (
    EstimatorConfig,
)
from vd_observer_node.estimation.imu_grade import (
    RATE_FOLLOWING,
    ImuGradeConfig,
    imu_grade_config,
    vehicle_pitch_compliance,
)
from vd_observer_node.estimation.observer import ObserverConfig
from vd_observer_node.estimation.rate_settings import (
    SPEED_STAMPS_KEPT,
    RateMeter,
    follow_rate_hz,
)
from vd_observer_node.estimation.torque_offset import OFFSET_MESSAGE_FIELDS, publish_mask
from vd_observer_node.estimation.vehicle import EstimatorVehicle, load_vehicle_params
from vd_observer_node.inputs.decode import (
    InputSeries,
    InputStats,
    decode_brake,
    decode_engine,
    decode_input,
    has_header,
)
from vd_observer_node.inputs.health import StreamHealth
from vd_observer_node.inputs.mapping import (
    BRAKE_INPUT,
    ENGINE_INPUT,
    InputMapping,
    InputSpec,
    default_mapping,
)
from vd_observer_node.situation.alerts import AlertConfig
from vd_observer_node.situation.friction_potential import FrictionPotentialConfig, TyreCurves
from vd_observer_node.situation.monitor import (
    SituationConfig,
    SituationMonitor,
)
from vd_observer_node.tools.merged_writer import MergedWriter, OutOfOrderError
from vd_observer_node.tools.replay_config import ReplayConfig, load_replay_config
from vd_observer_node.tools.replay_topics import (
    estimate_topics,
    joined_results,
    situation_topics,
)

__all__ = [
    'ALERT_TOPICS',
    'BLOCK_MESSAGES',
    'ESTIMATE_TOPICS',
    'MAX_WAIT_S',
    'SENSOR_TOPICS',
    'TRUTH_PREFIX',
    'ReplayConfig',
    'ReplayReport',
    'estimate_topics',
    'load_replay_config',
    'replay_bag',
    'situation_topics',
]

SENSOR_TOPICS = SENSORS
#: prefix of the IMU fusion's settings in `ReplayReport.rate_settings` (the mapping's keys)
IMU_FUSION_PREFIX = 'imu.fusion.'
TRUTH_PREFIX = TRUTH_NAMESPACE
ESTIMATE_TOPICS = {**OBSERVER, **ESTIMATES}
#: Written by the situation monitor phase (``situation=True``), as the alerts node publishes.
ALERT_TOPICS = dict(ALERTS)
#: messages read per block by default: bounds the replay's memory (docs/replay.md)
BLOCK_MESSAGES = 1 << 17
#: [s] an input whose stamps fall this far behind another's (stopped) holds the others no
#: longer (`BlockAligner` max_wait): bounds the carry between blocks
MAX_WAIT_S = 10.0


@dataclass(frozen=True)
class ReplayReport:
    """Figures of one offline replay.

    Attributes:
        samples: aligned sensor stamps the cascade ran on.
        sensor_messages: sensor messages read (all three topics).
        messages_written: messages in the output bag.
        bag_duration_s: log-time span of the sensor data [s].
        wall_time_s: replay wall time [s]; cascade_time_s of it in the cascade.
        cascade_time_s: [s] wall time of the cascade.
        unmatched: sensor messages not used: with 'exact' alignment, those whose stamp is
            missing on another sensor topic; with 'latest', the wheel messages dropped
            (repeated stamps, ``stale`` ones) and the other inputs' messages never held.
        stale: with 'latest' alignment, wheel stamps dropped because another input had no
            sample yet or only one older than the mapping's ``max_age``.
        situation_time_s: [s] wall time of the situation monitor (alerts and friction
            potential; 0 when not run).
        faults: the cascade's fault totals per kind (``CascadeResult.faults``: keys
            'wheel.<kind>', 'speed.<kind>', 'estimator.<kind>', as on /diagnostics).
        inputs: per input, in mapping order (the IMU last, where fused): messages, longest
            gap between stamps and gaps longer than the observers' ``max_gap`` (a topic that
            stopped arriving).
        torque_source: the torque path: 'measured', 'engine' or 'none'.
        torque_valid_fraction: share of the samples where the torque path held (1 when
            measured, 0 with none, below 1 on the engine path while the clutch slipped).
        vehicle: the vehicle file's name and path, e.g. 'clio_rl_1_1 (/.../clio_rl_1_1.yaml)'.
        notes: what the replay left out and why (one line each).
        input_rate_hz: [Hz] rate of the slower of the wheel and body-speed inputs, measured
            on the first `rate_settings.FOLLOW_AFTER` wheel stamps (nan if none was left
            to the rate, or the bag had fewer stamps).
        rate_settings: the settings left unset that followed `input_rate_hz` from the next
            stamp on, by name (the estimator's ``'slope_filter_tau'``; the IMU fusion's
            ``'imu.fusion.tau'``, ``'imu.fusion.step_tau'``), with the value used.
    """

    samples: int
    sensor_messages: int
    messages_written: int
    bag_duration_s: float
    wall_time_s: float
    cascade_time_s: float
    unmatched: int
    situation_time_s: float = 0.0
    stale: int = 0
    faults: dict[str, int] = field(default_factory=dict)
    inputs: tuple[InputStats, ...] = ()
    torque_source: str = 'measured'
    torque_valid_fraction: float = 1.0
    vehicle: str = ''
    notes: tuple[str, ...] = ()
    input_rate_hz: float = math.nan
    rate_settings: dict[str, float] = field(default_factory=dict)

    @property
    def real_time_factor(self) -> float:
        """Bag duration over wall time (how many times faster than real time)."""
        return self.bag_duration_s / self.wall_time_s if self.wall_time_s > 0 else float('inf')

    @property
    def samples_per_second(self) -> float:
        """Sensor messages processed per wall-clock second."""
        return self.sensor_messages / self.wall_time_s if self.wall_time_s > 0 else float('inf')

    @property
    def situation_us_per_sample(self) -> float:
        """[us] situation-monitor wall time per aligned sample (0 when not run)."""
        return 1e6 * self.situation_time_s / self.samples if self.samples else 0.0


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
    *,
    vehicle: EstimatorVehicle | None = None,
    observer_config: ObserverConfig | None = None,
    estimator_config: EstimatorConfig | None = None,
    progress: bool = True,
    cascade: Callable[..., CascadeResult] | None = None,
    cascade_kwargs: Mapping[str, Any] | None = None,
    vehicle_file: str | os.PathLike[str] | None = None,
    situation: bool = True,
    alert_config: AlertConfig | None = None,
    friction_config: FrictionPotentialConfig | None = None,
    situation_config: SituationConfig | None = None,
    mapping: InputMapping | None = None,
    torque_source: str | None = None,
    drivetrain: Drivetrain | None = None,
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
        vehicle: estimator vehicle; default the one of ``vehicle_file``.
        observer_config: observer settings; default ObserverConfig().
        estimator_config: estimator settings; default EstimatorConfig().
        progress: show a tqdm progress bar on stderr.
        cascade: the array cascade (injectable for tests); signature of ``run_cascade``,
            called once per block with ``state=`` (a `CascadeState` to carry); default
            `run_cascade`.
        cascade_kwargs: further keyword arguments of the cascade (settings added to
            ``run_cascade`` later, so the replay can match the live nodes' parameters).
        vehicle_file: vehicle YAML of the estimator vehicle (unless ``vehicle`` is given) and
            of the tyre curves of the friction potential; default the Clio file
            (:func:`vd_common.vehicle.params.default_vehicle_file`). Pass the file
            ``vehicle`` was read from, or the tyre of the default file is used with it.
        situation: also compute and write the friction potential and the alerts
            (:data:`ALERT_TOPICS`) with :class:`SituationMonitor`, as the alerts node does.
        alert_config: alert settings; default AlertConfig().
        friction_config: friction-potential settings; default FrictionPotentialConfig().
        situation_config: fast-observer settings; default SituationConfig().
        mapping: which topics, types, joints, units and signs are the wheel angles (or
            speeds), body speed and wheel torques, and how their samples are aligned
            (:mod:`vd_observer_node.inputs.mapping`); default vd's own ``/vd/sensors/*``
            topics. With wheel speeds the observers run with ``wheel_input='speed'``
            whatever ``observer_config`` says.
        torque_source: 'measured' (the wheel torques), 'engine' (wheel torques from the
            engine torque and gear of the mapping's ``engine_torque`` input, by default
            vd's WheelTorques topic, through `drivetrain`) or 'none' (no torque topic is
            read; Fx, mu and slope invalid); None: the mapping's ``torque_source``.
        drivetrain: the engine path's driveline; default that of ``vehicle_file``
            (`Drivetrain.from_params`).
        block_messages: input and truth messages read per block (>= 1; about 20 s of a
            1 kHz drive by default); None: the whole bag in one block.

    Raises:
        ReplayInputError: a sensor topic is missing or has the wrong type.
        MappingError: the messages do not fit the mapping (a joint or element absent).
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
    reader = BagReader(in_bag)
    topics = reader.topics
    mapping = mapping or default_mapping()
    if torque_source is not None:
        torque_source_code(torque_source)  # refuses an unknown name
        mapping = replace(mapping, torque_source=torque_source)
    source = mapping.torque_source
    # the IMU too: a mapping that names one asks for the fusion, so a typo in its topic or
    # a silent sensor must not quietly give the force balance's slope instead
    imu_specs = [mapping.imu] if mapping.imu is not None else []
    for spec in [*mapping.used_specs, *imu_specs]:
        check_input_topic(in_bag, topics, spec, mapping.source)
    imu_topics = [mapping.imu.topic] if mapping.imu is not None else []
    inputs = list(dict.fromkeys([*(spec.topic for spec in mapping.used_specs), *imu_topics]))
    observer_config = replace(observer_config or ObserverConfig(), wheel_input=mapping.wheel_input)
    truth = [t for t in topics if t.startswith(TRUTH_PREFIX)]
    # One read of the file gives the estimator vehicle and the tyre alike (a millisecond).
    params = load_vehicle_params(vehicle_file)
    estimator_vehicle = vehicle or EstimatorVehicle.from_params(params)
    if source == 'engine' and drivetrain is None:
        drivetrain = Drivetrain.from_params(params)
    brakes = replay_brakes(mapping, params)
    notes: list[str] = []
    if situation and params.tire is None:
        # an estimation-only vehicle file: everything but the friction potential and alerts
        situation = False
        notes.append(
            f'vehicle file {params.source} has no tire section: friction potential and '
            'alerts not computed'
        )
    curves = TyreCurves.from_tire(params.tire) if params.tire is not None else None
    make_monitor: Any = SituationMonitor

    def new_monitor() -> Any:
        if not situation:
            return None
        return make_monitor(
            curves,
            estimator_vehicle.static_wheel_loads[[0, 2]],
            estimator_vehicle.effective_radius,
            observer=observer_config,
            alerts=alert_config,
            friction=friction_config,
            situation=situation_config,
        )

    extra = dict(cascade_kwargs or {})
    clash = sorted(
        {'torque_source', 'engine', 'drivetrain', 'state', 'brake', 'brakes'} & set(extra)
    )
    if clash:
        raise ConfigurationError(
            f'cascade settings: {clash[0]} is set by the torque source, not the config'
        )
    if mapping.imu is not None and 'imu_config' not in extra:
        # the body's pitch under the ground force, from a full vehicle file's springs
        # and the sensor's own settings from the mapping
        extra['imu_config'] = imu_grade_config(
            vehicle_pitch_compliance(vehicle_file), mapping.imu.fusion
        )
    torque_kwargs: dict[str, Any] = {}
    if source != 'measured':  # the default call stays as it was (injected cascades)
        torque_kwargs = {'torque_source': source, 'drivetrain': drivetrain}
    if brakes is not None:
        torque_kwargs['brakes'] = brakes

    def new_run() -> _Run:
        return _Run(
            mapping=mapping,
            cascade=cascade,
            vehicle=estimator_vehicle,
            observer_config=observer_config,
            estimator_config=estimator_config,
            cascade_kwargs={**torque_kwargs, **extra},
            drivetrain=drivetrain if source == 'engine' else None,
            monitor=new_monitor(),
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
    if brakes is not None and brakes.learn and parts is not None:
        learnt = parts.brake_parts.state[0]
        gain, braking, converged = learnt.gain, learnt.excited_time, learnt.converged
        notes.append(
            f'brake gain learnt online: {gain:.3g} N m per unit of the brake pressure after '
            f'{braking:.1f} s of braking ({"converged" if converged else "not converged"})'
        )
    return replace(
        run.report(written, wall),
        vehicle=f'{params.name} ({params.source})',
        notes=tuple(notes),
    )


def replay_brakes(mapping: InputMapping, params: EstimationVehicleParams) -> Brakes | None:
    """The brake input of a mapping with the vehicle file's gains (None: no brake input, or
    no torque to take it from).

    Raises:
        ConfigurationError: a pressure without the file's gains (`Brakes.from_params`).
    """
    if mapping.brake is None or mapping.torque_source == 'none':
        return None
    return Brakes.from_params(mapping.brake.signal, params, mapping.source)


def _stream(
    reader: BagReader,
    out_bag: str | os.PathLike[str],
    run: _Run,
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


class _GapStats:
    """`input_stats` of one input accumulated block by block (equal with in-order stamps)."""

    def __init__(self, spec: InputSpec, max_gap_s: float) -> None:
        self._spec = spec
        self._max_gap_s = max_gap_s
        self._limit = round(max_gap_s * 1e9)
        self._last: int | None = None
        self._messages = 0
        self._longest = 0
        self._long = 0
        #: stamps expected and lost, for an input with header (`input_stats`)
        self._health = StreamHealth() if has_header(spec) else None

    def add(self, stamp_ns: np.ndarray) -> None:
        """Count one block's stamps [ns] (shape (N,), int64)."""
        if not stamp_ns.size:
            return
        stamps = np.sort(stamp_ns)
        if self._last is not None:
            stamps = np.concatenate([[self._last], stamps])
        gaps = np.diff(stamps)
        if gaps.size:
            self._longest = max(self._longest, int(gaps.max()))
            self._long += int(np.count_nonzero(gaps > self._limit))
        self._messages += len(stamp_ns)
        self._last = int(stamps[-1])
        if self._health is not None:
            self._health.add_many(stamps)

    def stats(self) -> InputStats:
        """The figures so far (`input_stats`; call once, at the end: it closes the count)."""
        expected = lost = None
        if self._health is not None:
            window = self._health.window()
            expected, lost = window.expected, window.expected - window.received
        return InputStats(
            name=self._spec.name,
            topic=self._spec.topic,
            messages=self._messages,
            longest_gap_s=self._longest * 1e-9,
            long_gaps=self._long,
            max_gap_s=self._max_gap_s,
            expected=expected,
            lost=lost,
        )


def _on_thread(work: Callable[[], None], meanwhile: Callable[[], None], name: str) -> None:
    """Run `work` on a thread of its own while `meanwhile` runs on this one; both are done
    when this returns. An error of `meanwhile` is raised first, then one of `work`."""
    failure: list[BaseException] = []

    def guarded() -> None:
        try:
            work()
        except BaseException as exc:  # re-raised on the caller's thread after the join
            failure.append(exc)

    worker = threading.Thread(target=guarded, name=name)
    worker.start()
    try:
        meanwhile()
    finally:
        worker.join()
    if failure:
        raise failure[0]


class _Run:
    """The replay's state from block to block: alignment, cascade, monitor and the totals."""

    def __init__(
        self,
        *,
        mapping: InputMapping,
        cascade: Callable[..., CascadeResult],
        vehicle: EstimatorVehicle,
        observer_config: ObserverConfig,
        estimator_config: EstimatorConfig | None,
        cascade_kwargs: dict[str, Any],
        drivetrain: Drivetrain | None,
        monitor: Any,
    ) -> None:
        self.mapping = mapping
        self.used = mapping.used_specs  # wheels, body speed, and the torque input of the path
        self.cascade = cascade
        self.vehicle = vehicle
        self.observer_config = observer_config
        self.estimator_config = estimator_config
        self.cascade_kwargs = cascade_kwargs
        self.drivetrain = drivetrain
        self.monitor = monitor
        self.state = CascadeState()
        self.aligner = BlockAligner(
            len(self.used), mapping.alignment, mapping.max_age, max_wait=MAX_WAIT_S
        )
        self.gaps = [_GapStats(s, observer_config.max_gap) for s in self.used]
        # the IMU is counted like the other inputs (it is not aligned: held at each stamp)
        self.imu_gaps = (
            _GapStats(mapping.imu, observer_config.max_gap) if mapping.imu is not None else None
        )
        self.frame_id: str | None = None
        self.samples = 0
        self.sensor_messages = 0
        self.sensor_log = (np.iinfo(np.int64).max, np.iinfo(np.int64).min)
        self.torque_valid = 0
        self.cascade_time = 0.0
        self.situation_time = 0.0
        self.result: CascadeResult | None = None
        self.input_rate_hz = math.nan
        self.rate_settings: dict[str, float] = {}
        # what the settings left to the rate follow (rate_settings.follow_rate_hz): the
        # estimator's slope filter and the IMU fusion's low-passes
        imu_config = cascade_kwargs.get('imu_config')
        imu_unset = isinstance(imu_config, ImuGradeConfig) and any(
            getattr(imu_config, name) is None for name in RATE_FOLLOWING
        )
        unset = (estimator_config or EstimatorConfig()).slope_filter_tau is None or imu_unset
        self.wheel_meter: RateMeter | None = RateMeter() if unset else None
        speed = self.used[1]
        self.speed_meter = RateMeter(SPEED_STAMPS_KEPT) if unset and has_header(speed) else None
        # (episodes, converged) of the last engine-torque offset written: it is written
        # where it changes, as pipeline_node publishes it
        self.offset_last: tuple[int, bool] | None = None
        # the newest IMU sample of the blocks so far: stamp [ns], forward specific force
        self.imu_last: tuple[int, float] | None = None

    def held_imu(self, arrays: Mapping[str, TopicArrays], common: np.ndarray) -> np.ndarray:
        """Shape (N, 2): for each stamp of ``common`` [ns] the stamp [s] of the newest IMU
        sample not later than it (nan: none yet) and its forward specific force [m/s^2]
        (sample and hold, as a live node sees it; the fusion judges the age)."""
        spec = self.mapping.imu
        assert spec is not None  # called with an IMU only
        series = self._decode(spec, arrays)
        if self.imu_gaps is not None:
            self.imu_gaps.add(series.stamp_ns)
        order = np.argsort(series.stamp_ns, kind='stable')
        stamps = series.stamp_ns[order]
        values = series.values[order, 0]
        if self.imu_last is not None:
            stamps = np.concatenate([[self.imu_last[0]], stamps])
            values = np.concatenate([[self.imu_last[1]], values])
        out = np.full((common.shape[0], 2), np.nan)
        if stamps.size:
            idx = np.searchsorted(stamps, common, side='right') - 1
            have = idx >= 0
            out[have, 0] = stamps[idx[have]] * 1e-9
            out[have, 1] = values[idx[have]]
            self.imu_last = (int(stamps[-1]), float(values[-1]))
        return out

    def _follow_rate(self, wheel_stamps: list[int]) -> None:
        """Fix the estimator's settings left to the rate, from the next stamp on."""
        speed = self.speed_meter.stamps if self.speed_meter is not None else None
        self.input_rate_hz = follow_rate_hz(wheel_stamps, speed)
        self.wheel_meter = None
        config = self.estimator_config or EstimatorConfig()
        self.estimator_config, self.rate_settings = config.at_rate(self.input_rate_hz)
        parts = self.state.parts
        if parts is not None:  # None for an injected cascade that keeps no parts
            parts.estimator.follow_rate(self.input_rate_hz)
        imu_config = self.cascade_kwargs.get('imu_config')
        if self.mapping.imu is not None and isinstance(imu_config, ImuGradeConfig):
            # the fusion's grade takes the speed's derivative as the slope filter does
            # (`imu_grade.tau_for_rate`); a fusion made later starts with the fixed values
            self.cascade_kwargs['imu_config'], fixed = imu_config.at_rate(self.input_rate_hz)
            self.rate_settings.update({f'{IMU_FUSION_PREFIX}{k}': v for k, v in fixed.items()})
            if parts is not None and parts.imu_on:
                parts.imu_grade.follow_rate(self.input_rate_hz)

    def offset_messages(
        self, result: CascadeResult, stamp_ns: np.ndarray
    ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """The stamps' selection and fields of the vd_msgs/TorqueOffsetEstimate messages of a
        block (none where the engine path does not learn the offset)."""
        if result.torque_offset.shape[0] == 0:
            return np.zeros(stamp_ns.shape[0], dtype=bool), {}
        episodes, converged = result.torque_offset_episodes, result.torque_offset_converged
        mask = publish_mask(episodes, converged, self.offset_last)
        if episodes.shape[0]:
            self.offset_last = (int(episodes[-1]), bool(converged[-1]))
        values = {
            field: getattr(result, offset_result_name(attr))[mask]
            for field, attr in OFFSET_MESSAGE_FIELDS
        }
        return mask, values

    def carried_log_ns(self) -> int:
        """[ns] the earliest log time of a wheel message carried to the next block."""
        held = self.aligner.held(0).get('log')
        return int(held.min()) if held is not None and held.size else np.iinfo(np.int64).max

    def _decode(self, spec: InputSpec, arrays: Mapping[str, TopicArrays]) -> InputSeries:
        arr = arrays.get(spec.topic)
        if arr is None or not arr.datas:
            width = spec.width
            return InputSeries(
                np.zeros(0, dtype=np.int64), np.zeros((0, width)), np.zeros(0, dtype=np.bytes_)
            )
        if spec.name == ENGINE_INPUT:
            return decode_engine(spec, arr)
        if spec.name == BRAKE_INPUT:
            return decode_brake(spec, arr)
        return decode_input(spec, arr, self.vehicle.effective_radius)

    def block(
        self,
        arrays: Mapping[str, TopicArrays],
        merged: MergedWriter,
        phase: Any,
        *,
        final: bool,
        meanwhile: Callable[[], None] | None = None,
    ) -> None:
        """Decode, align, run and encode one block; hand its estimates to `merged`.

        Args:
            meanwhile: work of the caller's that does not touch this run (writing what the
                blocks before gave): done on this thread while the compiled cascade, which
                releases the GIL, runs on a second one.
        """
        used = self.used
        decoded = [self._decode(s, arrays) for s in used]
        for gaps, d in zip(self.gaps, decoded, strict=True):
            gaps.add(d.stamp_ns)
        self.sensor_messages += sum(len(d.stamp_ns) for d in decoded)
        for spec in used:
            arr = arrays.get(spec.topic)
            if arr is not None and arr.log_time_ns.size:
                low, high = self.sensor_log
                log = arr.log_time_ns
                self.sensor_log = (min(low, int(log.min())), max(high, int(log.max())))
        wheels_log = arrays[used[0].topic].log_time_ns if used[0].topic in arrays else None
        columns: list[dict[str, np.ndarray]] = [
            {'v': decoded[0].values, 'frame': decoded[0].frame_ids,
             'log': wheels_log if wheels_log is not None else np.zeros(0, dtype=np.int64)},
            *({'v': d.values} for d in decoded[1:]),
        ]  # fmt: skip
        common, picked = self.aligner.push([d.stamp_ns for d in decoded], columns, final)
        n = len(common)
        if n and self.frame_id is None:
            self.frame_id = picked[0]['frame'][0].decode()
        if self.speed_meter is not None:
            self.speed_meter.add_many(decoded[1].stamp_ns)
        frame_id = self.frame_id or ''
        cascade_start = time.perf_counter()
        t = common.astype(np.float64) * 1e-9
        wheel_angle = picked[0]['v']
        body_speed = picked[1]['v'][:, 0]
        source = self.mapping.torque_source
        wheel_torque = picked[2]['v'] if source == 'measured' else np.zeros((n, 4))
        engine = picked[2]['v'] if source == 'engine' else None
        kwargs = dict(self.cascade_kwargs)
        if engine is not None:
            kwargs['engine'] = engine
        brake = picked[3]['v'] if self.mapping.brake is not None and len(picked) > 3 else None
        if brake is not None:
            kwargs['brake'] = brake
        if self.mapping.imu is not None:
            kwargs['imu'] = self.held_imu(arrays, common)
        # the inputs given per stamp, sliced with the stamps where the block is split
        per_stamp = [key for key in ('engine', 'brake', 'imu') if key in kwargs]

        def run(rows: slice) -> CascadeResult:
            part: dict[str, Any] = dict(kwargs)
            part.update({key: kwargs[key][rows] for key in per_stamp})
            return self.cascade(
                t[rows],
                wheel_angle[rows],
                body_speed[rows],
                wheel_torque[rows],
                self.vehicle,
                self.observer_config,
                self.estimator_config,
                state=self.state,
                **part,
            )

        def cascade() -> None:
            meter = self.wheel_meter
            k = meter.size - meter.count if meter is not None else n + 1
            if meter is None or k > n:
                result = run(slice(0, n))
            else:
                # the settings left to the rate follow it after the FOLLOW_AFTER-th stamp, as
                # the live nodes do (rate_settings)
                result = run(slice(0, k))
                meter.add_many(common[:k])
                self._follow_rate(meter.stamps)
                if k < n:
                    result = joined_results(result, run(slice(k, n)))
            if meter is not None and self.wheel_meter is not None:
                meter.add_many(common)
            self.cascade_time += time.perf_counter() - cascade_start
            self.result = result
            self.samples += n
            self.torque_valid += int(np.count_nonzero(result.torque_valid))

        if meanwhile is None:
            cascade()
        else:
            _on_thread(cascade, meanwhile, 'replay-cascade')
        result = self.result
        assert result is not None  # set by cascade()
        braked = brake is not None
        if (engine is not None or braked) and result.wheel_torque_used.shape[0] == n:
            # the situation monitor gets the torques the engine path and brakes gave the estimator
            # (0 where the path had none: a gear the box lacks)
            given = result.wheel_torque_used
            wheel_torque = np.where(np.isfinite(given), given, 0.0)
        situation_values: dict[str, dict[str, np.ndarray]] = {}

        def situation() -> None:
            situation_start = time.perf_counter()
            situation_values.update(
                situation_topics(
                    wheel_angle, body_speed, wheel_torque, result, self.monitor, phase.update
                )
            )
            self.situation_time += time.perf_counter() - situation_start

        log_ns = picked[0]['log']
        # the sensor's angles as the observer node publishes them; with speeds, the observer's
        observed = result.angle if self.mapping.wheel_input == 'speed' else wheel_angle

        def encode() -> None:
            for topic, values in estimate_topics(result, observed, self.estimator_config).items():
                datas = encode_packed(ESTIMATE_TOPICS[topic], common, frame_id, values)
                merged.add(topic, ESTIMATE_TOPICS[topic], log_ns, datas)
            changed, values = self.offset_messages(result, common)
            if values:
                msgtype = ESTIMATE_TOPICS[ESTIMATES_TORQUE_OFFSET]
                datas = encode_packed(msgtype, common[changed], frame_id, values)
                merged.add(ESTIMATES_TORQUE_OFFSET, msgtype, log_ns[changed], datas)

        if self.monitor is None:
            encode()
        else:
            # The compiled monitor releases the GIL: it runs on the second core while this
            # thread encodes the cascade's topics.
            _on_thread(situation, encode, 'replay-monitor')
        if n == 0:  # a block that aligned no stamp (a headerless input held, 'exact')
            situation_values.clear()
        for topic, values in situation_values.items():
            msgtype = ALERT_TOPICS[topic]
            if topic == ESTIMATES_ALERTS:
                datas = encode_alerts_packed(common, frame_id, values)
            else:
                datas = encode_packed(msgtype, common, frame_id, values)
            merged.add(topic, msgtype, log_ns, datas)

    def report(self, written: int, wall: float) -> ReplayReport:
        """The replay's figures once every block ran."""
        result = self.result
        if result is None:  # not reached: the final block always runs the cascade
            raise ReplayInputError('replay ended before its last block')
        low, high = self.sensor_log
        return ReplayReport(
            samples=self.samples,
            sensor_messages=self.sensor_messages,
            messages_written=written,
            bag_duration_s=float(high - low) * 1e-9 if high >= low else 0.0,
            wall_time_s=wall,
            cascade_time_s=self.cascade_time,
            unmatched=self.sensor_messages - self.samples - sum(self.aligner.used[1:]),
            situation_time_s=self.situation_time,
            stale=self.aligner.stale,
            faults=dict(result.faults),
            inputs=tuple(g.stats() for g in [*self.gaps, *filter(None, [self.imu_gaps])]),
            torque_source=TORQUE_SOURCES[result.torque_source],
            torque_valid_fraction=self.torque_valid / self.samples if self.samples else 0.0,
            input_rate_hz=self.input_rate_hz,
            rate_settings=dict(self.rate_settings),
        )
