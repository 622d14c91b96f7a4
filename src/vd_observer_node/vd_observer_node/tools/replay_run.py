"""One replay's state from block to block: alignment, cascade, monitor, messages and totals.

`replay.replay_bag` reads the bag block by block and hands each block to a
:class:`ReplayRun`: it decodes the mapped inputs, aligns their stamps, runs the cascade (and
the situation monitor) over the block's stamps on a thread while the previous block's
messages are written, encodes the estimates and keeps the totals that become the
:class:`ReplayReport`. Split from `replay` so that each stays small enough to read (#40).
"""

import math
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from vd_common.topics import (
    ALERTS,
    ESTIMATES,
    ESTIMATES_ALERTS,
    ESTIMATES_TORQUE_OFFSET,
    OBSERVER,
)

from vd_observer_node.bag.alerts_cdr import encode_alerts_packed
from vd_observer_node.bag.cdr_batch import encode_packed
from vd_observer_node.bag.errors import ReplayInputError
from vd_observer_node.bag.reader import TopicArrays
from vd_observer_node.estimation.alignment import BlockAligner, SampleQueue
from vd_observer_node.estimation.cascade import (
    CascadeResult,
    CascadeSeries,
    CascadeSettings,
    CascadeState,
    offset_result_name,
)
from vd_observer_node.estimation.drivetrain import (
    TORQUE_SOURCES,
)
from vd_observer_node.estimation.estimator_step import SPEED_SAMPLES_MAX
from vd_observer_node.estimation.imu_regression import bias_pitch_deg
from vd_observer_node.estimation.imu_settings import RATE_FOLLOWING
from vd_observer_node.estimation.rate_settings import (
    SPEED_STAMPS_KEPT,
    RateMeter,
    follow_rate_hz,
)
from vd_observer_node.estimation.torque_offset import OFFSET_MESSAGE_FIELDS, publish_mask
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
)
from vd_observer_node.inputs.mount_learner import learnt_line, new_learner, project_held
from vd_observer_node.tools.merged_writer import MergedWriter
from vd_observer_node.tools.replay_topics import (
    estimate_topics,
    joined_results,
    situation_topics,
)

__all__ = [
    'ALERT_TOPICS',
    'ESTIMATE_TOPICS',
    'IMU_FUSION_PREFIX',
    'MAX_WAIT_S',
    'GapStats',
    'ReplayReport',
    'ReplayRun',
    'on_thread',
]

#: prefix of the IMU fusion's settings in `ReplayReport.rate_settings` (the mapping's keys)
IMU_FUSION_PREFIX = 'imu.fusion.'
ESTIMATE_TOPICS = {**OBSERVER, **ESTIMATES}
#: Written by the situation monitor phase (``situation=True``), as the alerts node publishes.
ALERT_TOPICS = dict(ALERTS)
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
            (repeated stamps, ``stale`` ones) and the other inputs' messages never held; a
            body-speed sample is used where a wheel stamp took it at its own stamp (all but
            those that came too late, or beyond `estimator_step.SPEED_SAMPLES_MAX` a stamp).
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
        imu: what the IMU fusion used and learnt, one line ('' without an IMU): the share of
            the stamps whose grade used the angular rate, the bias learnt [m/s^2] and the
            mounting pitch it amounts to, when it was trusted.
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
    imu: str = ''

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


class GapStats:
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


def on_thread(work: Callable[[], None], meanwhile: Callable[[], None], name: str) -> None:
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


class ReplayRun:
    """The replay's state from block to block: alignment, cascade, monitor and the totals."""

    def __init__(
        self,
        *,
        mapping: InputMapping,
        cascade: Callable[..., CascadeResult],
        settings: CascadeSettings,
        monitor: Any,
    ) -> None:
        """Args:
        mapping: the input mapping.
        cascade: `cascade.run_cascade` (or a function of its signature, for tests).
        settings: the cascade's settings (they fit the mapping); those left to the input
            rate are fixed after the first stamps (`rate_settings.follow_rate_hz`).
        monitor: the situation monitor, or None.
        """
        self.mapping = mapping
        self.used = mapping.used_specs  # wheels, body speed, and the torque input of the path
        self.cascade = cascade
        self.settings = settings
        self.vehicle = settings.vehicle
        self.monitor = monitor
        self.state = CascadeState()
        self.aligner = BlockAligner(
            len(self.used), mapping.alignment, mapping.max_age, max_wait=MAX_WAIT_S
        )
        # every body-speed sample reaches the speed observer at its own stamp, also those
        # whose wheel stamp was lost (as pipeline_node's queue)
        self.speed_samples = SampleQueue(SPEED_SAMPLES_MAX)
        max_gap = settings.observer.max_gap
        self.gaps = [GapStats(s, max_gap) for s in self.used]
        # the held inputs (the IMU) are counted like the others (not aligned: held at each
        # stamp)
        self.held_gaps = {spec.name: GapStats(spec, max_gap) for spec in mapping.held_specs}
        self.mounting = new_learner(mapping, self.vehicle.effective_radius)
        self.frame_id: str | None = None
        self.samples = 0
        self.sensor_messages = 0
        self.sensor_log = (np.iinfo(np.int64).max, np.iinfo(np.int64).min)
        self.torque_valid = 0
        self.imu_gyro = 0  # stamps whose IMU grade used the angular rate
        self.imu_trusted_at = math.nan  # [s] after the first stamp
        self.first_stamp_s = math.nan
        self.cascade_time = 0.0
        self.situation_time = 0.0
        self.result: CascadeResult | None = None
        self.input_rate_hz = math.nan
        self.rate_settings: dict[str, float] = {}
        # what the settings left to the rate follow (rate_settings.follow_rate_hz): the
        # estimator's slope filter and the IMU fusion's low-passes
        imu_config = settings.imu
        imu_unset = imu_config is not None and any(
            getattr(imu_config, name) is None for name in RATE_FOLLOWING
        )
        unset = settings.estimator.slope_filter_tau is None or imu_unset
        self.wheel_meter: RateMeter | None = RateMeter() if unset else None
        speed = self.used[1]
        self.speed_meter = RateMeter(SPEED_STAMPS_KEPT) if unset and has_header(speed) else None
        # (episodes, converged) of the last engine-torque offset written: it is written
        # where it changes, as pipeline_node publishes it
        self.offset_last: tuple[int, bool] | None = None
        # per held input, its samples of the blocks so far that later stamps may still take:
        # the newest not later than the last stamp estimated, and every one after it (a block
        # read by log time holds samples of the next block's stamps): stamps [ns], values
        self.held_carry: dict[str, tuple[np.ndarray, np.ndarray]] = {}

    def held(self, arrays: Mapping[str, TopicArrays], common: np.ndarray) -> dict[str, np.ndarray]:
        """Every held input (``InputMapping.held_specs``) at the stamps ``common`` [ns]:
        shape (N, 1 + width) each, the stamp [s] of the newest sample not later than the
        stamp (nan: none yet) and its values (sample and hold, as a live node sees it; the
        part that reads it judges the age)."""
        return {spec.name: self._held(spec, arrays, common) for spec in self.mapping.held_specs}

    def _held(
        self, spec: InputSpec, arrays: Mapping[str, TopicArrays], common: np.ndarray
    ) -> np.ndarray:
        series = self._decode(spec, arrays)
        self.held_gaps[spec.name].add(series.stamp_ns)
        stamps, values = series.stamp_ns, series.values
        if self.mounting is not None and spec.learns_mounting:
            self.mounting.imu_many(stamps, values)
        carry = self.held_carry.get(spec.name)
        if carry is not None:
            stamps = np.concatenate([carry[0], stamps])
            values = np.concatenate([carry[1], values])
        order = np.argsort(stamps, kind='stable')
        stamps, values = stamps[order], values[order]
        out = np.full((common.shape[0], 1 + values.shape[1]), np.nan)
        if stamps.size:
            idx = np.searchsorted(stamps, common, side='right') - 1
            have = idx >= 0
            out[have, 0] = stamps[idx[have]] * 1e-9
            out[have, 1:] = values[idx[have]]
            keep = max(int(idx[-1]), 0) if common.size else 0
            self.held_carry[spec.name] = (stamps[keep:], values[keep:])
        if self.mounting is not None and spec.learns_mounting:
            return project_held(self.mounting.learnt, out)
        return out

    def _follow_rate(self, wheel_stamps: list[int]) -> None:
        """Fix the estimator's settings left to the rate, from the next stamp on."""
        speed = self.speed_meter.stamps if self.speed_meter is not None else None
        self.input_rate_hz = follow_rate_hz(wheel_stamps, speed)
        self.wheel_meter = None
        estimator, self.rate_settings = self.settings.estimator.at_rate(self.input_rate_hz)
        self.settings = replace(self.settings, estimator=estimator)
        parts = self.state.parts
        if parts is not None:  # None for an injected cascade that keeps no parts
            parts.estimator.follow_rate(self.input_rate_hz)
        imu_config = self.settings.imu
        if self.mapping.imu is not None and imu_config is not None:
            # the fusion's grade takes the speed's derivative as the slope filter does
            # (`imu_settings.tau_for_rate`); a fusion made later starts with the fixed values
            imu_config, fixed = imu_config.at_rate(self.input_rate_hz)
            self.settings = replace(self.settings, imu=imu_config)
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
        self.speed_samples.add_many(decoded[1].stamp_ns, decoded[1].values[:, 0])
        speed_at, speed_values = self.speed_samples.take(common)
        # as many columns as a stamp of the block has samples (most have one)
        width = max(1, int(np.count_nonzero(~np.isnan(speed_at), axis=1).max(initial=0)))
        speed_at, speed_values = speed_at[:, :width], speed_values[:, :width]
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
        brake = picked[3]['v'] if self.mapping.brake is not None and len(picked) > 3 else None
        if self.mounting is not None:  # the stamps the chain estimates, before the IMU's
            self.mounting.wheels_many(common, wheel_angle)
        held = self.held(arrays, common)

        def run(rows: slice) -> CascadeResult:
            # the block's rows where it is split (the settings follow the rate from there)
            series = CascadeSeries(
                t[rows],
                wheel_angle[rows],
                body_speed[rows],
                wheel_torque[rows],
                engine=engine[rows] if engine is not None else None,
                brake=brake[rows] if brake is not None else None,
                held={name: columns[rows] for name, columns in held.items()},
                speed_samples=(speed_at[rows], speed_values[rows]),
            )
            return self.cascade(series, self.settings, self.state)

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
            if math.isnan(self.first_stamp_s) and n:
                self.first_stamp_s = float(result.t[0])
            if result.imu_trusted.size:
                self.imu_gyro += int(np.count_nonzero(result.imu_gyro))
                if math.isnan(self.imu_trusted_at) and result.imu_trusted.any():
                    first = int(np.argmax(result.imu_trusted))
                    self.imu_trusted_at = float(result.t[first] - self.first_stamp_s)

        if meanwhile is None:
            cascade()
        else:
            on_thread(cascade, meanwhile, 'replay-cascade')
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
            for topic, values in estimate_topics(
                result, observed, self.settings.estimator
            ).items():
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
            on_thread(situation, encode, 'replay-monitor')
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
            # the body speed's samples count where the speed path took them (every one that
            # came in time), the others' where a set held them
            unmatched=self.sensor_messages
            - self.samples
            - self.speed_samples.taken
            - sum(self.aligner.used[2:]),
            situation_time_s=self.situation_time,
            stale=self.aligner.stale,
            faults=dict(result.faults),
            inputs=tuple(g.stats() for g in [*self.gaps, *self.held_gaps.values()]),
            torque_source=TORQUE_SOURCES[result.torque_source],
            torque_valid_fraction=self.torque_valid / self.samples if self.samples else 0.0,
            input_rate_hz=self.input_rate_hz,
            rate_settings=dict(self.rate_settings),
            imu=self._imu_line(result),
        )

    def _imu_line(self, result: CascadeResult) -> str:
        """`ReplayReport.imu` from the last block's result and the totals."""
        if not result.imu_bias.size:
            return ''
        mounting = self.mounting  # the mounting learnt online, where it is
        learnt = ''
        if mounting is not None:
            learnt = learnt_line(mounting.learnt, mounting.reason, self.first_stamp_s)
            if mounting.learnt is None:  # the IMU was never read
                return learnt
            learnt = f'; {learnt}'
        bias = float(result.imu_bias[-1])
        mount = bias_pitch_deg(bias, self.vehicle.gravity)
        trusted = (
            f'trusted after {self.imu_trusted_at:.1f} s'
            if math.isfinite(self.imu_trusted_at)
            else 'never trusted (the force balance did not teach it; the IMU alone invalid)'
        )
        share = 100.0 * self.imu_gyro / self.samples if self.samples else 0.0
        return (
            f'angular rate used on {share:.1f} % of the stamps; bias {bias:+.3f} m/s^2 '
            f'(a sensor pitched {mount:+.2f} deg, nose up +), {trusted}{learnt}'
        )
