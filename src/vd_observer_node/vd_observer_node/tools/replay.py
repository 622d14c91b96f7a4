"""Offline replay: run the ROS-free observer/estimator cascade over a bag, write a new bag.

Pipeline (whole arrays, no per-message decoding in Python):

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
6. write inputs (raw), truth (raw) and estimates, merged in log-time order, to OUT_BAG.

Inputs' own ``/vd/estimates/*`` and ``/vd/observer/*`` topics (a live recording) are not
copied: the output holds the replayed ones only.
"""

from __future__ import annotations

import os
import sys
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from tqdm import tqdm
from vd_sim_node.topics import (
    ALERTS,
    ESTIMATES,
    ESTIMATES_ALERTS,
    ESTIMATES_FRICTION,
    ESTIMATES_FRICTION_POTENTIAL,
    ESTIMATES_MASS,
    ESTIMATES_RESISTANCES,
    ESTIMATES_ROLLING_RADIUS,
    ESTIMATES_SLOPE,
    ESTIMATES_TIRE_FORCES,
    OBSERVER,
    OBSERVER_BODY_ACCEL,
    OBSERVER_BODY_VELOCITY,
    OBSERVER_WHEEL_STATES,
    SENSORS,
    TRUTH_NAMESPACE,
)

from vd_observer_node.bag.alerts_cdr import encode_alerts
from vd_observer_node.bag.cdr_batch import encode_batch, upgrade_batch
from vd_observer_node.bag.errors import BagExistsError, ReplayInputError
from vd_observer_node.bag.reader import BagReader, TopicArrays
from vd_observer_node.bag.writer import BagWriter
from vd_observer_node.errors import ConfigurationError
from vd_observer_node.estimation.alignment import align_stamps
from vd_observer_node.estimation.cascade import CascadeResult, run_cascade
from vd_observer_node.estimation.drivetrain import (
    TORQUE_SOURCES,
    Drivetrain,
    engine_wheel_torques_record,
    torque_source_code,
)
from vd_observer_node.estimation.estimator import (
    MASS_MESSAGE_FIELDS,
    RADIUS_MESSAGE_FIELDS,
    EstimatorConfig,
)
from vd_observer_node.estimation.observer import ObserverConfig
from vd_observer_node.estimation.vehicle import EstimatorVehicle, load_vehicle_params
from vd_observer_node.inputs.decode import (
    InputStats,
    decode_engine,
    decode_input,
    input_stats,
)
from vd_observer_node.inputs.mapping import ENGINE_INPUT, InputMapping, default_mapping
from vd_observer_node.situation.alerts import AlertConfig
from vd_observer_node.situation.friction_potential import FrictionPotentialConfig, TyreCurves
from vd_observer_node.situation.monitor import (
    SituationConfig,
    SituationMonitor,
    SituationSeries,
    run_situation,
)

__all__ = [
    'ALERT_TOPICS',
    'ESTIMATE_TOPICS',
    'SENSOR_TOPICS',
    'TRUTH_PREFIX',
    'ReplayConfig',
    'ReplayReport',
    'load_replay_config',
    'replay_bag',
    'situation_topics',
]

SENSOR_TOPICS = SENSORS
TRUTH_PREFIX = TRUTH_NAMESPACE
ESTIMATE_TOPICS = {**OBSERVER, **ESTIMATES}
#: Written by the situation monitor phase (``situation=True``), as the alerts node publishes.
ALERT_TOPICS = dict(ALERTS)
_WRITE_BLOCK = 65536  # messages per vectorized write (and progress-bar update)
_SITUATION_BLOCK = 1000  # samples per progress-bar update of the situation phase


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
        inputs: per input, in mapping order: messages, longest gap between stamps and gaps
            longer than the observers' ``max_gap`` (a topic that stopped arriving).
        torque_source: the torque path: 'measured', 'engine' or 'none'.
        torque_valid_fraction: share of the samples where the torque path held (1 when
            measured, 0 with none, below 1 on the engine path while the clutch slipped).
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


@dataclass(frozen=True)
class ReplayConfig:
    """Cascade and alert settings of an offline replay (None: the defaults)."""

    observer: ObserverConfig | None = None
    estimator: EstimatorConfig | None = None
    cascade_kwargs: dict[str, Any] | None = None
    alerts: AlertConfig | None = None
    friction: FrictionPotentialConfig | None = None
    situation: SituationConfig | None = None


_SECTIONS = ('observer', 'estimator', 'cascade', 'alerts', 'friction_potential', 'situation')


def load_replay_config(path: str | os.PathLike[str]) -> ReplayConfig:
    """Read replay settings from YAML: optional ``observer``, ``estimator``, ``cascade``,
    ``alerts``, ``friction_potential`` and ``situation`` mappings (flat, the keys of
    ``ObserverConfig.from_mapping`` / ``EstimatorConfig.from_mapping`` / extra ``run_cascade``
    keyword arguments / ``AlertConfig`` / ``FrictionPotentialConfig`` / ``SituationConfig``).

    Raises:
        ConfigurationError: unreadable file, not a mapping, or unknown keys.
    """
    try:
        data = yaml.safe_load(Path(path).read_text(encoding='utf-8')) or {}
    except (OSError, yaml.YAMLError, UnicodeDecodeError) as exc:
        raise ConfigurationError(f'{path}: cannot read replay settings: {exc}') from exc
    if not isinstance(data, dict) or set(data) - set(_SECTIONS):
        raise ConfigurationError(
            f'{path}: expected a mapping with sections among {" / ".join(_SECTIONS)}'
        )
    sections = {}
    for key in _SECTIONS:
        value = data.get(key)
        if value is not None and not isinstance(value, dict):
            raise ConfigurationError(f'{path}: {key} must be a mapping')
        sections[key] = value
    return ReplayConfig(
        observer=ObserverConfig.from_mapping(sections['observer'])
        if sections['observer'] is not None
        else None,
        estimator=EstimatorConfig.from_mapping(sections['estimator'])
        if sections['estimator'] is not None
        else None,
        cascade_kwargs=sections['cascade'],
        alerts=AlertConfig.from_mapping(sections['alerts'])
        if sections['alerts'] is not None
        else None,
        friction=FrictionPotentialConfig.from_mapping(sections['friction_potential'])
        if sections['friction_potential'] is not None
        else None,
        situation=SituationConfig.from_mapping(sections['situation'])
        if sections['situation'] is not None
        else None,
    )


def _estimates(result: CascadeResult, angles: np.ndarray) -> dict[str, dict[str, np.ndarray]]:
    n = result.t.shape[0]
    zeros = np.zeros(n)
    source = np.full(n, result.torque_source, dtype=np.uint8)
    return {
        OBSERVER_WHEEL_STATES: {
            'angle': angles,
            'omega': result.omega,
            'omega_dot': result.omega_dot,
        },
        OBSERVER_BODY_ACCEL: {
            'accel.linear.x': result.accel,
            'accel.linear.y': zeros,
            'accel.linear.z': zeros,
            'accel.angular.x': zeros,
            'accel.angular.y': zeros,
            'accel.angular.z': zeros,
        },
        OBSERVER_BODY_VELOCITY: {
            'twist.linear.x': result.speed,
            'twist.linear.y': zeros,
            'twist.linear.z': zeros,
            'twist.angular.x': zeros,
            'twist.angular.y': zeros,
            'twist.angular.z': zeros,
        },
        ESTIMATES_TIRE_FORCES: {'fx': result.fx, 'fz': result.fz, 'torque_source': source},
        ESTIMATES_FRICTION: {
            'mu': result.mu,
            'slip': result.slip,
            'valid': result.mu_valid,
            'torque_source': source,
        },
        ESTIMATES_RESISTANCES: {'rolling': result.rolling, 'aero': result.aero},
        ESTIMATES_SLOPE: {
            'angle': result.slope,
            'valid': result.slope_valid,
            'torque_source': source,
        },
        ESTIMATES_MASS: {field: getattr(result, attr) for field, attr in MASS_MESSAGE_FIELDS},
        ESTIMATES_ROLLING_RADIUS: {
            field: getattr(result, attr) for field, attr in RADIUS_MESSAGE_FIELDS
        },
    }


def _stamp_ns(seconds: np.ndarray) -> np.ndarray:
    """[s] -> int64 [ns] as the alerts node stamps onset/detected (0 while nan)."""
    finite = np.isfinite(seconds)
    out: np.ndarray = np.where(finite, np.round(np.where(finite, seconds, 0.0) * 1e9), 0)
    return out.astype(np.int64)


def _rows(result: CascadeResult, start: int, stop: int) -> CascadeResult:
    """The cascade result on stamps [start, stop) (every per-stamp array sliced)."""
    n = result.t.shape[0]
    sliced: dict[str, Any] = {
        f.name: value[start:stop]
        for f in fields(result)
        if isinstance(value := getattr(result, f.name), np.ndarray) and value.shape[:1] == (n,)
    }
    return replace(result, **sliced)


def situation_topics(
    wheel_angle: np.ndarray,
    speed: np.ndarray,
    wheel_torque: np.ndarray,
    result: CascadeResult,
    monitor: SituationMonitor | Any,
    progress: Callable[[int], object] | None = None,
    runner: Callable[..., SituationSeries] = run_situation,
    block: int = _SITUATION_BLOCK,
) -> dict[str, dict[str, np.ndarray]]:
    """Friction potential and alerts of every stamp, as the alerts node computes them.

    Runs :func:`vd_observer_node.situation.monitor.run_situation` in blocks of stamps (the
    monitor's state carries across them), so a progress bar can follow.

    Args:
        wheel_angle: shape (N, 4), [rad] measured wheel angles.
        speed: shape (N,), [m/s] MEASURED body speed (what the node receives).
        wheel_torque: shape (N, 4), [N m] measured wheel torques.
        result: the cascade on the same N stamps (t, omega, mu, mu_valid, fz used).
        monitor: a fresh (or reset) situation monitor (`runner`'s kind).
        progress: called with the number of stamps done since its last call.
        runner: `run_situation`, or the compiled
            :func:`vd_observer_node.kernel.chain.run_situation_compiled` with a
            :class:`~vd_observer_node.kernel.situation.CompiledSituationMonitor`.
        block: stamps per call of `runner` (per progress-bar update).

    Returns:
        Topic values: ``/vd/estimates/alerts`` ('level', 'onset_ns', 'detected_ns', each
        (N, 3, 4)) and ``/vd/estimates/friction_potential`` ('mu_max', 'slip_peak',
        'confidence' (N, 2) float, 'road_class' (N, 2) uint8, 'vehicle_road_class' (N,)).
    """
    n = result.t.shape[0]
    parts = []
    # one (empty) block when n == 0: the shapes of the outputs still come out right
    for start in range(0, max(n, 1), block):
        stop = min(start + block, n)
        parts.append(
            runner(
                monitor,
                wheel_angle[start:stop],
                speed[start:stop],
                wheel_torque[start:stop],
                _rows(result, start, stop),
            )
        )
        if progress is not None:
            progress(stop - start)

    def cat(name: str) -> np.ndarray:
        return np.concatenate([getattr(p, name) for p in parts])

    return {
        ESTIMATES_ALERTS: {
            'level': cat('level').astype(np.uint8),
            'onset_ns': _stamp_ns(cat('onset')),
            'detected_ns': _stamp_ns(cat('detected')),
        },
        ESTIMATES_FRICTION_POTENTIAL: {
            'mu_max': cat('mu_max'),
            'slip_peak': cat('slip_peak'),
            'confidence': cat('confidence'),
            'road_class': cat('road_class').astype(np.uint8),
            'vehicle_road_class': cat('vehicle_road_class').astype(np.uint8),
        },
    }


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
    kernel: str = 'compiled',
    mapping: InputMapping | None = None,
    torque_source: str | None = None,
    drivetrain: Drivetrain | None = None,
) -> ReplayReport:
    """Replay a bag's sensor topics through the cascade and write inputs, truth and estimates.

    Args:
        in_bag: input bag folder or .mcap file.
        out_bag: output bag folder (must not exist).
        vehicle: estimator vehicle; default the one of ``vehicle_file``.
        observer_config: observer settings; default ObserverConfig().
        estimator_config: estimator settings; default EstimatorConfig().
        progress: show a tqdm progress bar on stderr.
        cascade: the array cascade (injectable for tests); signature of ``run_cascade``;
            default the one of `kernel`.
        cascade_kwargs: further keyword arguments of the cascade (settings added to
            ``run_cascade`` later, so the replay can match the live nodes' parameters).
        vehicle_file: vehicle YAML of the estimator vehicle (unless ``vehicle`` is given) and
            of the tyre curves of the friction potential; default the Clio file
            (:func:`vd_sim_node.vehicle.params.default_vehicle_file`). Pass the file
            ``vehicle`` was read from, or the tyre of the default file is used with it.
        situation: also compute and write the friction potential and the alerts
            (:data:`ALERT_TOPICS`) with :class:`SituationMonitor`, as the alerts node does.
        alert_config: alert settings; default AlertConfig().
        friction_config: friction-potential settings; default FrictionPotentialConfig().
        situation_config: fast-observer settings; default SituationConfig().
        kernel: 'compiled' (the numba kernel, :mod:`vd_observer_node.kernel`) or 'python'
            (the reference implementation; equal results, ~30x the time).
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

    Raises:
        ReplayInputError: a sensor topic is missing or has the wrong type.
        MappingError: the messages do not fit the mapping (a joint or element absent).
        BagError: reading or writing failed (see .errors).
        VehicleParameterError: the vehicle file is unreadable or invalid.
    """
    started = time.perf_counter()
    if kernel not in ('compiled', 'python'):
        raise ConfigurationError(f"kernel must be 'compiled' or 'python', got {kernel!r}")
    compiled = kernel == 'compiled'
    if cascade is None:
        if compiled:
            from vd_observer_node.kernel.chain import run_cascade_compiled

            cascade = run_cascade_compiled
        else:
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
    for spec in mapping.used_specs:
        info = topics.get(spec.topic)
        origin = f' ({mapping.source}: {spec.name})' if mapping.source else ''
        if info is None or info.message_count == 0:
            raise ReplayInputError(f'{in_bag}: no messages on sensor topic {spec.topic}{origin}')
        if info.msgtype != spec.msgtype:
            raise ReplayInputError(
                f'{in_bag}: {spec.topic} has type {info.msgtype}, need {spec.msgtype}{origin}'
            )
    inputs = list(dict.fromkeys(spec.topic for spec in mapping.used_specs))
    observer_config = replace(observer_config or ObserverConfig(), wheel_input=mapping.wheel_input)
    truth = [t for t in topics if t.startswith(TRUTH_PREFIX)]
    # One read of the file gives the estimator vehicle and the tyre alike (a millisecond).
    params = load_vehicle_params(vehicle_file)
    estimator_vehicle = vehicle or EstimatorVehicle.from_params(params)
    if source == 'engine' and drivetrain is None:
        drivetrain = Drivetrain.from_params(params)
    monitor = None
    if situation:
        tire = params.tire
        monitor_class: Any = SituationMonitor
        if compiled:
            from vd_observer_node.kernel.chain import warm_up
            from vd_observer_node.kernel.situation import CompiledSituationMonitor

            monitor_class = CompiledSituationMonitor
            warm_up(TyreCurves.from_tire(tire))
        monitor = monitor_class(
            TyreCurves.from_tire(tire),
            estimator_vehicle.static_wheel_loads[[0, 2]],
            estimator_vehicle.effective_radius,
            observer=observer_config,
            alerts=alert_config,
            friction=friction_config,
            situation=situation_config,
        )
    total_in = sum(topics[t].message_count for t in [*inputs, *truth])
    bar = tqdm(
        total=2 * total_in,
        unit='msg',
        unit_scale=True,
        desc='replay',
        disable=not progress,
        file=sys.stderr,
    )
    with bar:
        arrays: dict[str, TopicArrays] = {}
        for topic, arr in reader.topic_arrays([*inputs, *truth]).items():
            arrays[topic] = arr
            bar.update(len(arr.datas))
        radius = estimator_vehicle.effective_radius
        used = mapping.used_specs  # wheels, body speed, and the torque input of the path
        decoded = [
            decode_engine(s, arrays[s.topic])
            if s.name == ENGINE_INPUT
            else decode_input(s, arrays[s.topic], radius)
            for s in used
        ]
        max_gap_s = observer_config.max_gap
        input_summary = tuple(
            input_stats(s, d, max_gap_s) for s, d in zip(used, decoded, strict=True)
        )
        angles, speed = decoded[0], decoded[1]
        aligned = align_stamps([d.stamp_ns for d in decoded], mapping.alignment, mapping.max_age)
        common, index = aligned.stamp_ns, aligned.indexes
        sensor_count = sum(len(d.stamp_ns) for d in decoded)
        bar.set_postfix_str(f'cascade on {len(common)} samples')
        cascade_start = time.perf_counter()
        t = common.astype(np.float64) * 1e-9
        ia = index[0]
        wheel_angle = angles.values[ia]
        body_speed = speed.values[index[1], 0]
        wheel_torque = (
            decoded[2].values[index[2]] if source == 'measured' else np.zeros((len(t), 4))
        )
        engine = decoded[2].values[index[2]] if source == 'engine' else None
        extra = dict(cascade_kwargs or {})
        clash = sorted({'torque_source', 'engine', 'drivetrain'} & set(extra))
        if clash:
            raise ConfigurationError(
                f'cascade settings: {clash[0]} is set by the torque source, not the config'
            )
        torque_kwargs: dict[str, Any] = {}
        if source != 'measured':  # the default call stays as it was (injected cascades)
            torque_kwargs = {'torque_source': source, 'engine': engine, 'drivetrain': drivetrain}
        result = cascade(
            t,
            wheel_angle,
            body_speed,
            wheel_torque,
            estimator_vehicle,
            observer_config,
            estimator_config,
            **torque_kwargs,
            **extra,
        )
        cascade_time = time.perf_counter() - cascade_start
        if engine is not None and drivetrain is not None:
            # the situation monitor gets the torques the engine path gave the estimator
            # (0 where the path had none: a gear the box lacks)
            derived = engine_wheel_torques_record(engine, drivetrain, result.omega_dot)
            wheel_torque = np.where(np.isfinite(derived), derived, 0.0)
        situation_values: dict[str, dict[str, np.ndarray]] = {}
        situation_time = [0.0]
        failure: list[BaseException] = []

        def run_monitor() -> None:
            # The per-stamp loop costs ~20x a message read or written: a bar of its own in
            # samples, so the message bar's rate and remaining time stay true.
            situation_start = time.perf_counter()
            try:
                with tqdm(
                    total=len(common),
                    unit='sample',
                    unit_scale=True,
                    desc='alerts',
                    disable=not progress,
                    file=sys.stderr,
                    position=1,
                    leave=False,
                ) as phase:
                    runner: dict[str, Any] = {}
                    if compiled:
                        from vd_observer_node.kernel.chain import run_situation_compiled

                        # larger blocks: a compiled call's cost is mostly its fixed Python overhead
                        runner = {'runner': run_situation_compiled, 'block': 20 * _SITUATION_BLOCK}
                    situation_values.update(
                        situation_topics(
                            wheel_angle,
                            body_speed,
                            wheel_torque,
                            result,
                            monitor,
                            phase.update,
                            **runner,
                        )
                    )
            except BaseException as exc:  # re-raised by the caller after the join
                failure.append(exc)
            situation_time[0] = time.perf_counter() - situation_start

        worker = None
        if monitor is not None:
            bar.set_postfix_str(f'alerts on {len(common)} samples')
            if compiled:
                # The compiled monitor releases the GIL: it runs on the second core while this
                # thread encodes the cascade's topics.
                worker = threading.Thread(target=run_monitor, name='replay-monitor')
                worker.start()
            else:
                run_monitor()
        frames = angles.frame_ids[ia]
        frame_id = frames[0].decode() if len(frames) else ''
        log_ns = arrays[mapping.wheels.topic].log_time_ns[ia]
        outputs: list[tuple[str, str, np.ndarray, list[bytes]]] = []
        for topic in [*inputs, *truth]:
            arr = arrays[topic]
            # a bag recorded before a vd_msgs field was added: copied in today's layout, so
            # the output holds one definition per type
            datas = upgrade_batch(arr.msgtype, arr.decoding_type, arr.datas)
            outputs.append((topic, arr.msgtype, arr.log_time_ns, datas))
        # the sensor's angles as the observer node publishes them; with speeds, the observer's
        observed_angle = result.angle if mapping.wheel_input == 'speed' else wheel_angle
        for topic, values in _estimates(result, observed_angle).items():
            datas = encode_batch(ESTIMATE_TOPICS[topic], common, frame_id, values)
            outputs.append((topic, ESTIMATE_TOPICS[topic], log_ns, datas))
        if worker is not None:
            worker.join()
        if failure:
            raise failure[0]
        for topic, values in situation_values.items():
            msgtype = ALERT_TOPICS[topic]
            if topic == ESTIMATES_ALERTS:
                datas = encode_alerts(common, frame_id, values)
            else:
                datas = encode_batch(msgtype, common, frame_id, values)
            outputs.append((topic, msgtype, log_ns, datas))
        bar.set_postfix_str('writing')
        written = _write_merged(out_bag, reader, outputs, bar, total_in)
    wall = time.perf_counter() - started
    sensor_log = np.concatenate([arrays[t].log_time_ns for t in inputs])
    return ReplayReport(
        samples=len(common),
        sensor_messages=sensor_count,
        messages_written=written,
        bag_duration_s=float(sensor_log.max() - sensor_log.min()) * 1e-9,
        wall_time_s=wall,
        cascade_time_s=cascade_time,
        unmatched=sensor_count - len(common) - sum(len(np.unique(i)) for i in index[1:]),
        situation_time_s=situation_time[0],
        stale=aligned.stale,
        faults=dict(result.faults),
        inputs=input_summary,
        torque_source=TORQUE_SOURCES[result.torque_source],
        torque_valid_fraction=float(np.mean(result.torque_valid)) if len(common) else 0.0,
    )


def _write_merged(
    out_bag: str | os.PathLike[str],
    reader: BagReader,
    outputs: list[tuple[str, str, np.ndarray, list[bytes]]],
    bar: Any,
    progress_budget: int,
) -> int:
    """Write all topics interleaved in log-time order (stable: input order within a time)."""
    log = np.concatenate([o[2] for o in outputs])
    which = np.concatenate([np.full(len(o[3]), k, dtype=np.int64) for k, o in enumerate(outputs)])
    order = np.argsort(log, kind='stable')
    topics = reader.topics
    total = len(order)
    with BagWriter(out_bag) as writer:
        for name, msgtype, _, _ in outputs:
            info = topics.get(name)
            qos = info.qos_profiles_yaml if info is not None else ''
            writer.add_topic(name, msgtype, qos)
        names = [o[0] for o in outputs]
        datas = [d for o in outputs for d in o[3]]
        done = 0
        for start in range(0, total, _WRITE_BLOCK):
            sel = order[start : start + _WRITE_BLOCK]
            writer.write_interleaved(names, which[sel], [datas[k] for k in sel.tolist()], log[sel])
            stop = start + len(sel)
            bar.update(stop * progress_budget // total - done * progress_budget // total)
            done = stop
    return total
