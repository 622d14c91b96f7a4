"""The replay's output messages from a cascade result: the estimate topics as the live
observer and estimator nodes publish them, and the alerts and friction potential as the alerts
node does (as topic -> field -> array, for the batch encoder)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import fields, replace
from typing import Any

import numpy as np
from vd_common.topics import (
    ESTIMATES_ALERTS,
    ESTIMATES_FRICTION,
    ESTIMATES_FRICTION_POTENTIAL,
    ESTIMATES_MASS,
    ESTIMATES_RESISTANCES,
    ESTIMATES_ROLLING_RADIUS,
    ESTIMATES_SLOPE,
    ESTIMATES_TIRE_FORCES,
    OBSERVER_BODY_ACCEL,
    OBSERVER_BODY_VELOCITY,
    OBSERVER_WHEEL_STATES,
)

from vd_observer_node.estimation.cascade import CascadeResult
from vd_observer_node.estimation.estimator import (
    MASS_MESSAGE_FIELDS,
    RADIUS_MESSAGE_FIELDS,
    EstimatorConfig,
)
from vd_observer_node.estimation.imu_grade import SOURCE_FORCE
from vd_observer_node.situation.monitor import SituationMonitor, SituationSeries, run_situation

__all__ = ['estimate_topics', 'joined_results', 'situation_topics']

_SITUATION_BLOCK = 20_000  # samples per progress-bar update of the situation phase


def estimate_topics(
    result: CascadeResult, angles: np.ndarray, config: EstimatorConfig | None = None
) -> dict[str, dict[str, np.ndarray]]:
    """The estimate topics of a cascade result, as the live nodes publish them: the online
    mass and radius only where `config` adapts them (the nodes publish no constants), the
    mass also where the result has the IMU's regression."""
    n = result.t.shape[0]
    zeros = np.zeros(n)
    source = np.full(n, result.torque_source, dtype=np.uint8)
    topics: dict[str, dict[str, np.ndarray]] = {
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
            'sources': _slope_sources(result),
        },
    }
    # the online mass where adapted; with an IMU the regression's (`imu_grade`, in the fields)
    if (config is not None and config.mass_adaptation) or result.imu_mass.shape[0] > 0:
        topics[ESTIMATES_MASS] = {
            field: getattr(result, attr) for field, attr in MASS_MESSAGE_FIELDS
        }
    if config is not None and config.radius_adaptation:
        topics[ESTIMATES_ROLLING_RADIUS] = {
            field: getattr(result, attr) for field, attr in RADIUS_MESSAGE_FIELDS
        }
    return topics


def _slope_sources(result: CascadeResult) -> np.ndarray:
    """The Slope messages' ``sources`` bits (`imu_grade.SOURCE_FORCE`, `SOURCE_IMU`); a
    result without them (an injected cascade): the force balance where the slope is valid."""
    if result.slope_sources.shape == result.slope_valid.shape:
        return result.slope_sources
    return np.where(result.slope_valid, SOURCE_FORCE, 0).astype(np.uint8)


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


def joined_results(first: CascadeResult, second: CascadeResult) -> CascadeResult:
    """Two consecutive blocks' results as one (per-stamp arrays joined; the totals, e.g.
    the fault counts, are the second's)."""
    n, m = first.t.shape[0], second.t.shape[0]
    joined: dict[str, Any] = {}
    for f in fields(first):
        a, b = getattr(first, f.name), getattr(second, f.name)
        if isinstance(a, np.ndarray) and a.shape[:1] == (n,) and b.shape[:1] == (m,):
            joined[f.name] = np.concatenate([a, b])
    return replace(second, **joined)


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
        runner: `run_situation` (injectable for tests).
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
