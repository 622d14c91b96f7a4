"""Bags from arrays, for tests and development: simulator runs and known-answer fixtures.

:func:`write_topic_arrays_bag` writes any header-stamped fixed-layout topics from numpy
arrays (batch-encoded, interleaved in stamp order, log time = header stamp, as a live
recording of a simulation would be). :func:`sim_topics` and :func:`cascade_topics` map a
simulator run (the simulator's ``SimResult``, duck-typed) and a cascade result to the vd
topics. Nothing here imports the simulator: its runs are arguments.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from typing import Any

import numpy as np
from vd_common.topics import (
    ESTIMATES_ALERTS,
    ESTIMATES_FRICTION_POTENTIAL,
    OPTIONAL_SENSORS,
    SENSORS_BODY_VELOCITY,
    SENSORS_IMU,
    SENSORS_WHEEL_ANGLES,
    SENSORS_WHEEL_TORQUES,
    TRUTH_BODY_ACCEL,
    TRUTH_BODY_VELOCITY,
    TRUTH_FRICTION,
    TRUTH_FRICTION_POTENTIAL,
    TRUTH_RESISTANCES,
    TRUTH_SLOPE,
    TRUTH_TIRE_FORCES,
    TRUTH_WHEEL_STATES,
)
from vd_common.vehicle import friction

from vd_observer_node.bag.alerts_cdr import ALERTS_TYPE as _ALERTS_TYPE
from vd_observer_node.bag.alerts_cdr import encode_alerts
from vd_observer_node.bag.cdr_batch import encode_batch
from vd_observer_node.bag.writer import BagWriter
from vd_observer_node.estimation.cascade import CascadeResult
from vd_observer_node.estimation.estimator import EstimatorConfig
from vd_observer_node.inputs.rotation import mount_rotation
from vd_observer_node.tools.replay import estimate_topics
from vd_observer_node.tools.report.topics import (
    ALERT_TOPICS,
    ESTIMATE_TOPICS,
    SENSOR_TOPICS,
    TRUTH_TOPICS,
)

__all__ = [
    'TopicValues',
    'alerts_topics',
    'cascade_topics',
    'encode_alerts',
    'sim_topics',
    'true_potential_values',
    'write_topic_arrays_bag',
]

#: topic -> {dotted field name: array of shape (N,) or (N, K)}; fields not given are zero.
TopicValues = Mapping[str, Mapping[str, np.ndarray]]

_TYPES = {**SENSOR_TOPICS, **OPTIONAL_SENSORS, **ESTIMATE_TOPICS, **ALERT_TOPICS, **TRUTH_TOPICS}


def _full_fields(msgtype: str, n: int, given: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    from vd_observer_node.bag.cdr_batch import flat_fields

    out: dict[str, np.ndarray] = {}
    for field in flat_fields(msgtype):
        if field.name in given:
            out[field.name] = np.asarray(given[field.name])
        else:
            shape = (n, field.count) if field.count > 1 else (n,)
            out[field.name] = np.zeros(shape, dtype=field.dtype)
    return out


def write_topic_arrays_bag(
    path: str | os.PathLike[str],
    stamp_ns: np.ndarray,
    topics: TopicValues,
    *,
    stamps: Mapping[str, np.ndarray] | None = None,
    log_delay_ns: Mapping[str, int] | None = None,
    frame_id: str = 'base_link',
) -> None:
    """Write a bag holding the given topics, one message per stamp.

    Args:
        path: bag folder to create.
        stamp_ns: shape (N,), int64 [ns], header stamp (and log time) of every topic.
        topics: values per topic (vd topic names; types from :mod:`.topics`).
        stamps: per-topic stamps [ns] overriding ``stamp_ns`` (topics of other lengths).
        log_delay_ns: per-topic log time minus header stamp [ns] (default 0), e.g. to mimic
            an estimator that publishes late.
        frame_id: header.frame_id of every message.
    """
    names = list(topics)
    datas: list[bytes] = []
    logs: list[np.ndarray] = []
    which: list[np.ndarray] = []
    for k, name in enumerate(names):
        topic_stamps = np.asarray((stamps or {}).get(name, stamp_ns), dtype=np.int64)
        n = topic_stamps.shape[0]
        if _TYPES[name] == _ALERTS_TYPE:
            datas.extend(encode_alerts(topic_stamps, frame_id, topics[name]))
        else:
            values = _full_fields(_TYPES[name], n, topics[name])
            datas.extend(encode_batch(_TYPES[name], topic_stamps, frame_id, values))
        logs.append(topic_stamps + int((log_delay_ns or {}).get(name, 0)))
        which.append(np.full(n, k, dtype=np.int64))
    log = np.concatenate(logs)
    index = np.concatenate(which)
    order = np.argsort(log, kind='stable')
    with BagWriter(path) as writer:
        for name in names:
            writer.add_topic(name, _TYPES[name])
        writer.write_interleaved(
            names, index[order], [datas[k] for k in order.tolist()], log[order]
        )


def sim_topics(
    sim: Any,
    *,
    truth: bool = True,
    imu: bool = False,
    imu_mount_rpy_deg: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> dict[str, dict[str, np.ndarray]]:
    """Sensor (and truth) topic values of a simulator run, as the simulator node publishes them.

    Args:
        sim: a simulator run's ``SimResult`` (duck-typed: only its arrays).
        truth: include the ``/vd/truth/*`` topics.
        imu: include the IMU (``/vd/sensors/imu``: ``sim.imu``'s specific force in
            ``linear_acceleration`` x and z, ``sim.gyro``'s pitch rate in
            ``angular_velocity.y``, the orientation marked unknown as REP 145 says), as the
            simulator node publishes it for a scenario with an IMU.
        imu_mount_rpy_deg: the IMU's frame in the body (roll, pitch, yaw) [deg]: its
            vectors are written in that frame, as a sensor mounted so would measure them
            (the simulator node publishes the body's axes: (0, 0, 0)).
    """
    topics: dict[str, dict[str, np.ndarray]] = {
        SENSORS_WHEEL_ANGLES: {'angle': sim.wheel_angle},
        SENSORS_BODY_VELOCITY: {'twist.linear.x': sim.body_speed},
        SENSORS_WHEEL_TORQUES: {
            'torque': sim.wheel_torque,
            'engine_torque': sim.engine_torque,
            'engine_speed': sim.engine_speed,
            'gear': np.asarray(sim.gear).astype(np.int8),
        },
    }
    if imu:
        n = len(sim.imu)
        unknown = np.zeros((n, 9))
        unknown[:, 0] = -1.0
        force = np.zeros((n, 3))
        force[:, 0], force[:, 2] = sim.imu[:, 0], sim.imu[:, 1]
        rate = np.zeros((n, 3))
        rate[:, 1] = sim.gyro
        fields: dict[str, np.ndarray] = {
            'orientation.w': np.ones(n),
            'orientation_covariance': unknown,
            'angular_velocity_covariance': np.zeros((n, 9)),
        }
        if any(imu_mount_rpy_deg):
            # the sensor reads R^T v of a body vector v (R body <- sensor)
            rows = np.array(mount_rotation(*np.radians(imu_mount_rpy_deg)))
            force, rate = force @ rows, rate @ rows
            fields['angular_velocity.x'] = rate[:, 0]
            fields['angular_velocity.z'] = rate[:, 2]
            fields['linear_acceleration.y'] = force[:, 1]
        fields['angular_velocity.y'] = rate[:, 1]
        fields['linear_acceleration.x'] = force[:, 0]
        fields['linear_acceleration.z'] = force[:, 2]
        topics[SENSORS_IMU] = fields
    if truth:
        topics.update(
            {
                TRUTH_WHEEL_STATES: {
                    'angle': sim.angle_true,
                    'omega': sim.omega,
                    'omega_dot': sim.omega_dot,
                },
                TRUTH_BODY_ACCEL: {'accel.linear.x': sim.accel_true},
                TRUTH_BODY_VELOCITY: {'twist.linear.x': sim.speed_true},
                TRUTH_TIRE_FORCES: {'fx': sim.fx, 'fz': sim.fz},
                TRUTH_FRICTION: {'mu': sim.mu, 'slip': sim.slip, 'valid': sim.fz > 0.0},
                TRUTH_RESISTANCES: {'rolling': sim.rolling, 'aero': sim.aero},
                TRUTH_SLOPE: {'angle': sim.slope, 'valid': np.ones(sim.t.shape, bool)},
            }
        )
        if hasattr(sim, 'peak_mu'):
            topics[TRUTH_FRICTION_POTENTIAL] = true_potential_values(sim.peak_mu, sim.peak_slip)
    return topics


def true_potential_values(peak_mu: np.ndarray, peak_slip: np.ndarray) -> dict[str, np.ndarray]:
    """``/vd/truth/friction_potential`` fields from the per-wheel true peaks, as the simulator
    node publishes them (axle means, confidence 1, road class of the true μ_max).

    Args:
        peak_mu: shape (N, 4), [-] true MF peak μ per wheel (``SimResult.peak_mu``).
        peak_slip: shape (N, 4), [-] slip at the peak (``SimResult.peak_slip``).
    """
    mu_max = friction.axle_mean(peak_mu)
    return {
        'mu_max': mu_max,
        'slip_peak': friction.axle_mean(peak_slip),
        'confidence': np.ones_like(mu_max),
        'road_class': friction.road_class(mu_max).astype(np.uint8),
        'vehicle_road_class': friction.vehicle_road_class(mu_max).astype(np.uint8),
    }


def alerts_topics(
    t0_ns: int,
    level: np.ndarray,
    onset: np.ndarray | None = None,
    detected: np.ndarray | None = None,
    mu_max: np.ndarray | None = None,
    slip_peak: np.ndarray | None = None,
    confidence: np.ndarray | None = None,
    road_class: np.ndarray | None = None,
) -> dict[str, dict[str, np.ndarray]]:
    """``/vd/estimates/alerts`` (and ``friction_potential``) values from detector arrays.

    Args:
        t0_ns: [ns] stamp of t = 0 for the onset/detected stamps.
        level: shape (N, 3, 4), alert levels.
        onset: shape (N, 3, 4), [s] from t0 (nan while inactive), or None.
        detected: same, or None.
        mu_max, slip_peak, confidence: shape (N, 2), or None (no friction-potential topic
            unless ``mu_max`` is given).
        road_class: shape (N, 2) codes, or None.
    """

    def ns(seconds: np.ndarray | None) -> np.ndarray:
        if seconds is None:
            return np.zeros(level.shape, dtype=np.int64)
        s = np.asarray(seconds, dtype=np.float64)
        return np.where(np.isfinite(s), t0_ns + np.round(np.nan_to_num(s) * 1e9), 0).astype(
            np.int64
        )

    out: dict[str, dict[str, np.ndarray]] = {
        ESTIMATES_ALERTS: {
            'level': np.asarray(level),
            'onset_ns': ns(onset),
            'detected_ns': ns(detected),
        }
    }
    if mu_max is not None:
        m = np.asarray(mu_max, dtype=np.float64)
        classes = np.zeros(m.shape, np.uint8) if road_class is None else np.asarray(road_class)
        out[ESTIMATES_FRICTION_POTENTIAL] = {
            'mu_max': m,
            'slip_peak': np.zeros_like(m) if slip_peak is None else np.asarray(slip_peak),
            'confidence': np.zeros_like(m) if confidence is None else np.asarray(confidence),
            'road_class': classes.astype(np.uint8),
        }
    return out


def cascade_topics(
    result: CascadeResult,
    wheel_angle: np.ndarray,
    estimator_config: EstimatorConfig | None = None,
) -> dict[str, dict[str, np.ndarray]]:
    """Observer and estimate topic values of a ``cascade.CascadeResult``, exactly as
    ``vd replay`` writes them (:func:`vd_observer_node.tools.replay.estimate_topics`): the
    online mass and rolling radius only where ``estimator_config`` adapts them, as the nodes
    publish them.

    Args:
        result: the cascade result.
        wheel_angle: shape (N, 4), [rad], measured angles echoed in ``wheel_states.angle``.
        estimator_config: the settings the cascade ran with (None: the defaults, which adapt
            neither).
    """
    return estimate_topics(result, wheel_angle, estimator_config)
