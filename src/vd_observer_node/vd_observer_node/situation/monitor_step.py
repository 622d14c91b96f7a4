"""The situation monitor's stamp, compiled: restart check, fast observer, friction, alerts.

`situation_block` is the one loop that runs the monitor, over N >= 1 stamps: the offline
replay and the evaluation call it on blocks of a record (`monitor.run_situation`), the
alerts and pipeline nodes on one stamp at a time (`monitor.SituationMonitor.update`). One
stamp after the fast observer is `monitor_step` (it calls `friction_fit.friction_update`
and `alerts.alerts_update`); with ``VD_JIT=0`` the same source runs as plain Python.
"""

from __future__ import annotations

import math
from typing import Any, Final, NamedTuple

import numpy as np
from numpy.typing import NDArray

from vd_observer_node.estimation.levant_step import LevantParts, levant_reset, levant_update
from vd_observer_node.kernel._jit import jit, jit_inlined
from vd_observer_node.situation.alerts import ALERT_KINDS, alerts_reset, alerts_update
from vd_observer_node.situation.friction_fit import (
    FrictionFit,
    fit_reset,
    friction_update,
    vehicle_road_class,
)

__all__ = [
    'LEVELS_CHANGED',
    'MONITOR_PARAMS',
    'MONITOR_STATE',
    'POTENTIAL_MOVED',
    'AlertParts',
    'MonitorParts',
    'SituationBlock',
    'SituationInputs',
    'monitor_restarts',
    'monitor_step',
    'situation_block',
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: Settings of `monitor_step` besides those of its parts: radius [m] the effective rolling
#: radius; slip_floor_speed, max_observer_disagreement [m/s] as `SituationConfig`; max_gap
#: [s] the observers' (a stamp older than the last by more than this restarts the monitor).
MONITOR_PARAMS: Final = np.dtype(
    [
        ('radius', 'f8'),
        ('slip_floor_speed', 'f8'),
        ('max_observer_disagreement', 'f8'),
        ('max_gap', 'f8'),
    ],
    align=True,
)
#: State of `monitor_step` besides its parts': t [s] the stamp of the last call (nan before).
MONITOR_STATE: Final = np.dtype([('t', 'f8')], align=True)
#: `monitor_step` flags: the friction potential took the stamp (new solution)...
POTENTIAL_MOVED: Final = 1
#: ...a reported alert level changed.
LEVELS_CHANGED: Final = 2


@jit
def monitor_restarts(p: Any, s: Any, t: float) -> bool:
    """Whether stamp t must restart the monitor: older than the last call's stamp by more than
    ``max_gap`` (a looped bag or a restarted source), as the observers restart."""
    return not math.isnan(s.t) and t < s.t - p.max_gap


class AlertParts(NamedTuple):
    """The alerts' records, each as the 1-element array it lives in: `alerts.ALERT_PARAMS`,
    `alerts.ALERT_STATE` and the stamp's `alerts.ALERT_INPUT` (a buffer)."""

    params: NDArray[Any]
    state: NDArray[Any]
    input: NDArray[Any]


class MonitorParts(NamedTuple):
    """Everything `situation_block` advances, by part (records as the 1-element arrays they
    live in: numba types arrays on its fast path). NamedTuples, not one nested record: the
    parts hold arrays whose length is a setting (road scales, the tyre's peak table) or
    arrays of per-channel records, which a numpy record cannot nest.

    Attributes:
        params: `MONITOR_PARAMS`.
        state: `MONITOR_STATE`.
        fast: the fast wheel observer.
        friction: the friction fit (`friction_fit.FrictionFit`).
        alerts: the alerts.
    """

    params: NDArray[Any]
    state: NDArray[Any]
    fast: LevantParts
    friction: FrictionFit
    alerts: AlertParts


class SituationInputs(NamedTuple):
    """The monitor's inputs over N stamps (contiguous arrays).

    Attributes:
        angles: shape (N, 4), [rad] wheel angles (or speeds [rad/s]).
        speeds: shape (N,), [m/s] measured body speed.
        torques: shape (N, 4), [N m] drive minus brake torque.
        omega: shape (N, 4), [rad/s] the cascade observer's wheel speed.
        mu: shape (N, 4), [-] utilised friction (estimator).
        mu_valid: shape (N, 4), bool.
        fz: shape (N, 4), [N] wheel loads (estimator).
    """

    angles: FloatArray
    speeds: FloatArray
    torques: FloatArray
    omega: FloatArray
    mu: FloatArray
    mu_valid: BoolArray
    fz: FloatArray


class SituationBlock(NamedTuple):
    """The monitor's outputs over N stamps, written by `situation_block`.

    Attributes:
        t: shape (N,), [s].
        level: shape (N, 3, 4), alert level per kind (ALERT_KINDS order) and wheel.
        onset: shape (N, 3, 4), [s] onset stamp (nan while inactive).
        detected: shape (N, 3, 4), [s] detection stamp (nan while inactive).
        mu_max: shape (N, 2), [-] per axle.
        slip_peak: shape (N, 2), [-] per axle.
        confidence: shape (N, 2), [0..1] per axle.
        road_class: shape (N, 2), ROAD_* code per axle.
        vehicle_road_class: shape (N,), ROAD_* code.
        slip: shape (N, 4), [-] the fast slip the traction and lock alerts saw.
    """

    t: FloatArray
    level: NDArray[np.int64]
    onset: FloatArray
    detected: FloatArray
    mu_max: FloatArray
    slip_peak: FloatArray
    confidence: FloatArray
    road_class: NDArray[np.int64]
    vehicle_road_class: NDArray[np.int64]
    slip: FloatArray

    @classmethod
    def empty(cls, n: int) -> SituationBlock:
        """Buffers for N stamps."""
        kinds = len(ALERT_KINDS)
        return cls(
            np.zeros(n), np.zeros((n, kinds, 4), dtype=np.int64),
            np.full((n, kinds, 4), math.nan), np.full((n, kinds, 4), math.nan),
            np.zeros((n, 2)), np.zeros((n, 2)), np.zeros((n, 2)),
            np.zeros((n, 2), dtype=np.int64), np.zeros(n, dtype=np.int64), np.zeros((n, 4)),
        )  # fmt: skip


@jit_inlined
def monitor_step(
    parts: MonitorParts, t: float, inputs: SituationInputs, k: int, fast_omega: FloatArray,
    fast_valid: BoolArray,
) -> int:  # fmt: skip
    """One stamp of the monitor after its fast observer: friction potential, then alerts.

    Args:
        parts: the monitor's records, advanced in place; ``parts.alerts.input`` is written
            with the stamp's alert inputs (its ``slip`` is the fast slip the traction and
            lock alerts see).
        t: stamp [s].
        inputs: the inputs; row `k` is the stamp's.
        k: the stamp's row.
        fast_omega: shape (4,), [rad/s] the fast observer's wheel speed at t.
        fast_valid: shape (4,), its validity.

    Returns:
        `POTENTIAL_MOVED` | `LEVELS_CHANGED` flags.
    """
    p, s = parts.params[0], parts.state[0]
    alert = parts.alerts.input[0]
    speed, omega, mu, mu_valid = (
        inputs.speeds[k],
        inputs.omega[k],
        inputs.mu[k],
        inputs.mu_valid[k],
    )
    radius, gate = p.radius, p.max_observer_disagreement
    sv_fast = alert.slip_velocity
    slip = alert.slip
    sv_cascade = np.empty(4)
    steady = np.empty(4, dtype=np.bool_)
    for i in range(4):
        sv_fast[i] = fast_omega[i] * radius - speed if fast_valid[i] else 0.0
        # vd_common.vehicle.tire.slip_ratio: the denominator floored at slip_floor_speed
        slip[i] = sv_fast[i] / max(max(abs(sv_fast[i] + speed), abs(speed)), p.slip_floor_speed)
        sv_cascade[i] = omega[i] * radius - speed
        # While the two observers disagree the cascade's omega (and its omega-dot, hence mu)
        # lags a fast wheel transient: such (slip, mu) pairs lie off the tyre's curve.
        agree = abs(sv_fast[i] - sv_cascade[i]) <= gate if gate > 0.0 else True
        steady[i] = agree and mu_valid[i]
    flags = 0
    if friction_update(parts.friction, t, sv_cascade, speed, mu, steady, inputs.fz[k]):
        flags |= POTENTIAL_MOVED
    pot = parts.friction.potential[0]
    alert.torque[:] = inputs.torques[k]
    alert.mu[:] = mu
    alert.mu_valid[:] = mu_valid
    for i in range(4):
        alert.mu_max[i] = pot.mu_max[i // 2]
        alert.slip_peak[i] = pot.slip_peak[i // 2]
    if alerts_update(parts.alerts.params[0], parts.alerts.state[0], t, alert):
        flags |= LEVELS_CHANGED
    s.t = t
    return flags


@jit
def situation_block(
    parts: MonitorParts, t: FloatArray, inputs: SituationInputs, out: SituationBlock
) -> int:
    """The monitor over N stamps; returns the `monitor_step` flags of all of them (or-ed; a
    restart sets both).

    Args:
        parts: the monitor's records, advanced in place.
        t: shape (N,), [s].
        inputs: the N stamps' inputs.
        out: written, row k after stamp k.
    """
    fast_part, mp, ms = parts.fast, parts.params[0], parts.state[0]
    fp, fs = fast_part.params[0], fast_part.state[0]
    pot, al = parts.friction.potential[0], parts.alerts.state[0]
    fast = np.empty((3, 4))
    fast_valid = np.empty(4, dtype=np.bool_)
    flags = 0
    for k in range(t.shape[0]):
        if monitor_restarts(mp, ms, t[k]):
            # a looped bag or a restarted source: start again, as the observers do
            levant_reset(fp, fs, fast_part.channels)
            fit_reset(parts.friction)
            alerts_reset(al)
            ms.t = math.nan
            flags |= POTENTIAL_MOVED | LEVELS_CHANGED  # the results start again too
        levant_update(
            fp, fast_part.lipschitz, fs, fast_part.channels, t[k], inputs.angles[k], fast,
            fast_valid,
        )  # fmt: skip
        flags |= monitor_step(parts, t[k], inputs, k, fast[1], fast_valid)
        out.t[k] = t[k]
        out.level[k] = al.level
        out.onset[k] = al.onset
        out.detected[k] = al.detected
        out.mu_max[k] = pot.mu_max
        out.slip_peak[k] = pot.slip_peak
        out.confidence[k] = pot.confidence
        out.road_class[k] = pot.road_class
        out.vehicle_road_class[k] = vehicle_road_class(pot.road_class, pot.confidence)
        out.slip[k] = parts.alerts.input[0].slip
    return flags
