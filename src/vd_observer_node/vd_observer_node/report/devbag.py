"""Bags from arrays, for tests and development: simulator runs and known-answer fixtures.

:func:`write_topic_arrays_bag` writes any header-stamped fixed-layout topics from numpy
arrays (batch-encoded, interleaved in stamp order, log time = header stamp, as a live
recording of a simulation would be). :func:`sim_topics` and :func:`cascade_topics` map a
simulator run (``vd_sim_node...SimResult``) and a cascade result to the vd topics.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from typing import Any

import numpy as np

from ..bag.cdr_batch import encode_batch
from ..bag.writer import BagWriter
from .topics import ESTIMATE_TOPICS, SENSOR_TOPICS, TRUTH_TOPICS

__all__ = ['TopicValues', 'cascade_topics', 'sim_topics', 'write_topic_arrays_bag']

#: topic -> {dotted field name: array of shape (N,) or (N, K)}; fields not given are zero.
TopicValues = Mapping[str, Mapping[str, np.ndarray]]

_TYPES = {**SENSOR_TOPICS, **ESTIMATE_TOPICS, **TRUTH_TOPICS}


def _full_fields(msgtype: str, n: int, given: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    from ..bag.cdr_batch import flat_fields

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


def sim_topics(sim: Any, *, truth: bool = True) -> dict[str, dict[str, np.ndarray]]:
    """Sensor (and truth) topic values of a simulator run, as the simulator node publishes them.

    Args:
        sim: a ``vd_sim_node.vehicle.simulation.SimResult`` (duck-typed: only its arrays).
        truth: include the ``/vd/truth/*`` topics.
    """
    topics: dict[str, dict[str, np.ndarray]] = {
        '/vd/sensors/wheel_angles': {'angle': sim.wheel_angle},
        '/vd/sensors/body_velocity': {'twist.linear.x': sim.body_speed},
        '/vd/sensors/wheel_torques': {
            'torque': sim.wheel_torque,
            'engine_torque': sim.engine_torque,
            'engine_speed': sim.engine_speed,
            'gear': np.asarray(sim.gear).astype(np.int8),
        },
    }
    if truth:
        topics.update(
            {
                '/vd/truth/wheel_states': {
                    'angle': sim.angle_true,
                    'omega': sim.omega,
                    'omega_dot': sim.omega_dot,
                },
                '/vd/truth/body_accel': {'accel.linear.x': sim.accel_true},
                '/vd/truth/body_velocity': {'twist.linear.x': sim.speed_true},
                '/vd/truth/tire_forces': {'fx': sim.fx, 'fz': sim.fz},
                '/vd/truth/friction': {'mu': sim.mu, 'slip': sim.slip, 'valid': sim.fz > 0.0},
                '/vd/truth/resistances': {'rolling': sim.rolling, 'aero': sim.aero},
                '/vd/truth/slope': {'angle': sim.slope, 'valid': np.ones(sim.t.shape, bool)},
            }
        )
    return topics


def cascade_topics(result: Any, wheel_angle: np.ndarray) -> dict[str, dict[str, np.ndarray]]:
    """Observer and estimate topic values of a ``cascade.CascadeResult`` (as replay writes).

    Args:
        result: the cascade result (duck-typed).
        wheel_angle: shape (N, 4), [rad], measured angles echoed in ``wheel_states.angle``.
    """
    return {
        '/vd/observer/wheel_states': {
            'angle': wheel_angle,
            'omega': result.omega,
            'omega_dot': result.omega_dot,
        },
        '/vd/observer/body_accel': {'accel.linear.x': result.accel},
        '/vd/observer/body_velocity': {'twist.linear.x': result.speed},
        '/vd/estimates/tire_forces': {'fx': result.fx, 'fz': result.fz},
        '/vd/estimates/friction': {'mu': result.mu, 'slip': result.slip, 'valid': result.mu_valid},
        '/vd/estimates/resistances': {'rolling': result.rolling, 'aero': result.aero},
        '/vd/estimates/slope': {'angle': result.slope, 'valid': result.slope_valid},
    }
