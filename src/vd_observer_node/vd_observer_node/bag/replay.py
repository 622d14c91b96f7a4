"""Offline replay: run the ROS-free observer/estimator cascade over a bag, write a new bag.

Pipeline (whole arrays, no per-message decoding in Python):

1. read the three sensor topics and every ``/vd/truth/*`` topic as raw CDR;
2. batch-decode the sensors to numpy (:mod:`.cdr_batch`);
3. align them on exact header stamps (a stamp present on all three topics, as the live
   estimator node's ``StampAligner`` does) and call :func:`vd_observer_node.cascade.run_cascade`;
4. batch-encode the estimates (and the observer's filtered speed on
   ``/vd/observer/body_velocity``, as the live observer node publishes it), stamped with the
   wheel-angle header stamp they derive from and logged at that message's log time;
5. write inputs (raw), truth (raw) and estimates, merged in log-time order, to OUT_BAG.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from tqdm import tqdm
from vd_sim_node.topics import ESTIMATES, OBSERVER, SENSORS

from ..cascade import CascadeResult, run_cascade
from ..errors import ConfigurationError
from ..estimator import EstimatorConfig
from ..observer import ObserverConfig
from ..vehicle import EstimatorVehicle, load_estimator_vehicle
from .cdr_batch import decode_batch, encode_batch
from .errors import BagExistsError, BagNotFoundError, ReplayInputError
from .reader import BagReader, TopicArrays
from .writer import BagWriter

__all__ = [
    'ESTIMATE_TOPICS',
    'SENSOR_TOPICS',
    'TRUTH_PREFIX',
    'ReplayConfig',
    'ReplayReport',
    'default_vehicle_file',
    'load_replay_config',
    'replay_bag',
]

SENSOR_TOPICS = SENSORS
TRUTH_PREFIX = '/vd/truth/'
ESTIMATE_TOPICS = {**OBSERVER, **ESTIMATES}
_WRITE_BLOCK = 65536  # messages per vectorized write (and progress-bar update)


@dataclass(frozen=True)
class ReplayReport:
    """Figures of one offline replay.

    Attributes:
        samples: aligned sensor stamps the cascade ran on.
        sensor_messages: sensor messages read (all three topics).
        messages_written: messages in the output bag.
        bag_duration_s: log-time span of the sensor data [s].
        wall_time_s: replay wall time [s]; cascade_time_s of it in the cascade.
        unmatched: sensor messages whose stamp is missing on another sensor topic.
    """

    samples: int
    sensor_messages: int
    messages_written: int
    bag_duration_s: float
    wall_time_s: float
    cascade_time_s: float
    unmatched: int

    @property
    def real_time_factor(self) -> float:
        """Bag duration over wall time (how many times faster than real time)."""
        return self.bag_duration_s / self.wall_time_s if self.wall_time_s > 0 else float('inf')

    @property
    def samples_per_second(self) -> float:
        """Sensor messages processed per wall-clock second."""
        return self.sensor_messages / self.wall_time_s if self.wall_time_s > 0 else float('inf')


@dataclass(frozen=True)
class ReplayConfig:
    """Cascade settings of an offline replay (None: the defaults)."""

    observer: ObserverConfig | None = None
    estimator: EstimatorConfig | None = None
    cascade_kwargs: dict[str, Any] | None = None


def load_replay_config(path: str | os.PathLike[str]) -> ReplayConfig:
    """Read cascade settings from YAML: optional ``observer``, ``estimator`` and ``cascade``
    mappings (flat, the keys of ``ObserverConfig.from_mapping`` /
    ``EstimatorConfig.from_mapping`` / extra ``run_cascade`` keyword arguments).

    Raises:
        ConfigurationError: unreadable file, not a mapping, or unknown keys.
    """
    try:
        data = yaml.safe_load(Path(path).read_text(encoding='utf-8')) or {}
    except (OSError, yaml.YAMLError, UnicodeDecodeError) as exc:
        raise ConfigurationError(f'{path}: cannot read replay settings: {exc}') from exc
    if not isinstance(data, dict) or set(data) - {'observer', 'estimator', 'cascade'}:
        raise ConfigurationError(
            f'{path}: expected a mapping with observer / estimator / cascade sections'
        )
    sections = {}
    for key in ('observer', 'estimator', 'cascade'):
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
    )


def default_vehicle_file() -> Path:
    """The Clio parameter file: installed ``share/vd_sim_node/config`` or the source tree."""
    name = 'clio_rl_1_1.yaml'
    try:
        from ament_index_python.packages import get_package_share_directory

        installed = Path(get_package_share_directory('vd_sim_node')) / 'config' / name
        if installed.is_file():
            return installed
    except (ImportError, LookupError, ValueError, OSError):
        pass  # not installed / no ROS environment: use the source tree
    source = Path(__file__).resolve().parents[3] / 'vd_sim_node' / 'config' / name
    if source.is_file():
        return source
    raise BagNotFoundError(f'vehicle file {name} not found (not installed, no {source})')


def _align(stamps: list[np.ndarray]) -> tuple[np.ndarray, list[np.ndarray]]:
    """Stamps common to all topics (sorted, unique) and each topic's index of them."""
    common = stamps[0]
    for s in stamps[1:]:
        common = np.intersect1d(common, s)
    indexes = []
    for s in stamps:
        # Last message of each stamp wins, as a re-sent stamp replaces the buffered one live.
        order = np.argsort(s, kind='stable')
        last = order[np.searchsorted(s[order], common, side='right') - 1]
        indexes.append(last)
    return common, indexes


def _estimates(result: CascadeResult, angles: np.ndarray) -> dict[str, dict[str, np.ndarray]]:
    n = result.t.shape[0]
    zeros = np.zeros(n)
    return {
        '/vd/observer/wheel_states': {
            'angle': angles,
            'omega': result.omega,
            'omega_dot': result.omega_dot,
        },
        '/vd/observer/body_accel': {
            'accel.linear.x': result.accel,
            'accel.linear.y': zeros,
            'accel.linear.z': zeros,
            'accel.angular.x': zeros,
            'accel.angular.y': zeros,
            'accel.angular.z': zeros,
        },
        '/vd/observer/body_velocity': {
            'twist.linear.x': result.speed,
            'twist.linear.y': zeros,
            'twist.linear.z': zeros,
            'twist.angular.x': zeros,
            'twist.angular.y': zeros,
            'twist.angular.z': zeros,
        },
        '/vd/estimates/tire_forces': {'fx': result.fx, 'fz': result.fz},
        '/vd/estimates/friction': {
            'mu': result.mu,
            'slip': result.slip,
            'valid': result.mu_valid,
        },
        '/vd/estimates/resistances': {'rolling': result.rolling, 'aero': result.aero},
        '/vd/estimates/slope': {'angle': result.slope, 'valid': result.slope_valid},
    }


def replay_bag(
    in_bag: str | os.PathLike[str],
    out_bag: str | os.PathLike[str],
    *,
    vehicle: EstimatorVehicle | None = None,
    observer_config: ObserverConfig | None = None,
    estimator_config: EstimatorConfig | None = None,
    progress: bool = True,
    cascade: Callable[..., CascadeResult] = run_cascade,
    cascade_kwargs: Mapping[str, Any] | None = None,
) -> ReplayReport:
    """Replay a bag's sensor topics through the cascade and write inputs, truth and estimates.

    Args:
        in_bag: input bag folder or .mcap file.
        out_bag: output bag folder (must not exist).
        vehicle: estimator vehicle; default the Clio file (:func:`default_vehicle_file`).
        observer_config: observer settings; default ObserverConfig().
        estimator_config: estimator settings; default EstimatorConfig().
        progress: show a tqdm progress bar on stderr.
        cascade: the array cascade (injectable for tests); signature of ``run_cascade``.
        cascade_kwargs: further keyword arguments of the cascade (settings added to
            ``run_cascade`` later, so the replay can match the live nodes' parameters).

    Raises:
        ReplayInputError: a sensor topic is missing or has the wrong type.
        BagError: reading or writing failed (see .errors).
    """
    started = time.perf_counter()
    target = Path(out_bag)
    if target.exists() and (not target.is_dir() or any(target.iterdir())):
        # Fail before minutes of work, not when the output is finally written.
        raise BagExistsError(f'{target}: already exists (choose a new bag name)')
    reader = BagReader(in_bag)
    topics = reader.topics
    for name, msgtype in SENSOR_TOPICS.items():
        info = topics.get(name)
        if info is None or info.message_count == 0:
            raise ReplayInputError(f'{in_bag}: no messages on sensor topic {name}')
        if info.msgtype != msgtype:
            raise ReplayInputError(f'{in_bag}: {name} has type {info.msgtype}, need {msgtype}')
    truth = [t for t in topics if t.startswith(TRUTH_PREFIX)]
    total_in = sum(topics[t].message_count for t in [*SENSOR_TOPICS, *truth])
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
        for topic, arr in reader.topic_arrays([*SENSOR_TOPICS, *truth]).items():
            arrays[topic] = arr
            bar.update(len(arr.datas))
        angles = decode_batch(
            SENSOR_TOPICS['/vd/sensors/wheel_angles'], arrays['/vd/sensors/wheel_angles'].datas
        )
        speed = decode_batch(
            SENSOR_TOPICS['/vd/sensors/body_velocity'], arrays['/vd/sensors/body_velocity'].datas
        )
        torque = decode_batch(
            SENSOR_TOPICS['/vd/sensors/wheel_torques'], arrays['/vd/sensors/wheel_torques'].datas
        )
        common, (ia, iv, it) = _align([angles.stamp_ns, speed.stamp_ns, torque.stamp_ns])
        sensor_count = len(angles.stamp_ns) + len(speed.stamp_ns) + len(torque.stamp_ns)
        bar.set_postfix_str(f'cascade on {len(common)} samples')
        cascade_start = time.perf_counter()
        result = cascade(
            common.astype(np.float64) * 1e-9,
            angles.values['angle'][ia],
            speed.values['twist.linear.x'][iv],
            torque.values['torque'][it],
            vehicle or load_estimator_vehicle(default_vehicle_file()),
            observer_config,
            estimator_config,
            **dict(cascade_kwargs or {}),
        )
        cascade_time = time.perf_counter() - cascade_start
        frames = angles.frame_id[ia]
        frame_id = frames[0].decode() if len(frames) else ''
        log_ns = arrays['/vd/sensors/wheel_angles'].log_time_ns[ia]
        outputs: list[tuple[str, str, np.ndarray, list[bytes]]] = []
        for topic in [*SENSOR_TOPICS, *truth]:
            arr = arrays[topic]
            outputs.append((topic, arr.msgtype, arr.log_time_ns, arr.datas))
        for topic, values in _estimates(result, angles.values['angle'][ia]).items():
            datas = encode_batch(ESTIMATE_TOPICS[topic], common, frame_id, values)
            outputs.append((topic, ESTIMATE_TOPICS[topic], log_ns, datas))
        written = _write_merged(out_bag, reader, outputs, bar, total_in)
    wall = time.perf_counter() - started
    sensor_log = np.concatenate([arrays[t].log_time_ns for t in SENSOR_TOPICS])
    return ReplayReport(
        samples=len(common),
        sensor_messages=sensor_count,
        messages_written=written,
        bag_duration_s=float(sensor_log.max() - sensor_log.min()) * 1e-9,
        wall_time_s=wall,
        cascade_time_s=cascade_time,
        unmatched=sensor_count - 3 * len(common),
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
