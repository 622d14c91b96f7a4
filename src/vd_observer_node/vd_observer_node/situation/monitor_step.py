"""The situation monitor's stamp, compiled: restart check, fast observer, friction, alerts.

`situation_block` is the one loop that runs the monitor, over N >= 1 stamps: the offline
replay and the evaluation call it on blocks of a record (`monitor.run_situation`), the
alerts and pipeline nodes on one stamp at a time (`monitor.SituationMonitor.update`). One
stamp after the fast observer is `monitor_step` (it calls `friction_fit.friction_update`
and `alerts.alerts_update`); with ``VD_JIT=0`` the same source runs as plain Python.
"""

from __future__ import annotations

import math
from typing import Any, Final

import numpy as np
from numpy.typing import NDArray

from vd_observer_node.estimation.levant_step import levant_reset, levant_update
from vd_observer_node.kernel._jit import jit
from vd_observer_node.situation.alerts import alerts_reset, alerts_update
from vd_observer_node.situation.friction_fit import (
    fit_reset,
    friction_update,
    vehicle_road_class,
)

__all__ = [
    'LEVELS_CHANGED',
    'MONITOR_PARAMS',
    'MONITOR_STATE',
    'POTENTIAL_MOVED',
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


@jit
def monitor_step(
    p: Any,
    s: Any,
    fp: Any,
    tyre: Any,
    scales: FloatArray,
    table: FloatArray,
    fs: Any,
    cost: FloatArray,
    pot: Any,
    ap: Any,
    al: Any,
    t: float,
    fast_omega: FloatArray,
    fast_valid: BoolArray,
    speed: float,
    torque: FloatArray,
    omega: FloatArray,
    mu: FloatArray,
    mu_valid: BoolArray,
    fz: FloatArray,
    slip: FloatArray,
) -> int:
    """One stamp of the monitor after its fast observer: friction potential, then alerts.

    Args:
        p: `MONITOR_PARAMS` record.
        s: `MONITOR_STATE` record.
        fp, tyre, scales, table, fs, cost, pot: the friction fit's settings and state
            (`friction_fit.friction_update`).
        ap, al: the alerts' settings and state (`alerts.alerts_update`).
        t: stamp [s].
        fast_omega: shape (4,), [rad/s] the fast observer's wheel speed at t.
        fast_valid: shape (4,), its validity.
        speed: [m/s] measured body speed.
        torque: shape (4,), [N m] drive minus brake torque.
        omega: shape (4,), [rad/s] the cascade observer's wheel speed.
        mu: shape (4,), [-] utilised friction (estimator).
        mu_valid: shape (4,), bool.
        fz: shape (4,), [N] wheel loads (estimator).
        slip: shape (4,), written: [-] the fast slip the traction and lock alerts see.

    Returns:
        `POTENTIAL_MOVED` | `LEVELS_CHANGED` flags.
    """
    radius, gate = p.radius, p.max_observer_disagreement
    sv_fast = np.empty(4)
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
    if friction_update(
        fp, tyre, scales, table, fs, cost, pot, t, sv_cascade, speed, mu, steady, fz
    ):
        flags |= POTENTIAL_MOVED
    wheel_mu_max = np.empty(4)
    wheel_slip_peak = np.empty(4)
    for i in range(4):
        wheel_mu_max[i] = pot.mu_max[i // 2]
        wheel_slip_peak[i] = pot.slip_peak[i // 2]
    if alerts_update(
        ap, al, t, slip, sv_fast, torque, mu, mu_valid, wheel_mu_max, wheel_slip_peak
    ):
        flags |= LEVELS_CHANGED
    s.t = t
    return flags


@jit
def situation_block(
    fp_a: Any, flip: FloatArray, fs_a: Any, fch: np.recarray, mp_a: Any, ms_a: Any,
    fp_b: Any, tyre_a: Any, scales: FloatArray, table: FloatArray, static_load: FloatArray,
    fs_b: Any, cost: FloatArray, pot_a: Any, ap_a: Any, al_a: Any, t: FloatArray,
    angles: FloatArray,
    speeds: FloatArray, torques: FloatArray, omega: FloatArray, mu: FloatArray,
    mu_valid: BoolArray, fz: FloatArray, level: NDArray[np.int64], onset: FloatArray,
    det: FloatArray, mu_max: FloatArray, slip_peak: FloatArray, confidence: FloatArray,
    road: NDArray[np.int64], vehicle_road: NDArray[np.int64], slip: FloatArray,
) -> int:  # fmt: skip
    """The monitor over N stamps; returns the `monitor_step` flags of all of them (or-ed; a
    restart sets both).

    Args (each record as the 1-element array it lives in, `kernel._jit.record_array`):
        fp_a, flip, fs_a, fch: the fast differentiator (`LevantDifferentiator.kernel_args`).
        mp_a, ms_a: `MONITOR_PARAMS`, `MONITOR_STATE` records.
        fp_b, tyre_a, scales, table, static_load, fs_b, cost, pot_a: the friction fit's
            settings and state (`friction_fit.friction_update`, `fit_reset`).
        ap_a, al_a: the alerts' settings and state.
        t: shape (N,), [s]; angles (N, 4) wheel angles (or speeds); speeds (N,) measured
            body speed [m/s]; torques (N, 4) [N m]; omega (N, 4) the cascade's wheel speed
            [rad/s]; mu (N, 4); mu_valid (N, 4); fz (N, 4) [N].
        level, onset, det: shape (N, 3, 4), written: each alert's level, onset and detection
            stamps [s] after the stamp.
        mu_max, slip_peak, confidence: shape (N, 2), written: the friction potential.
        road: shape (N, 2), written: road class per axle; vehicle_road (N,) the vehicle's.
        slip: shape (4,), written: the fast slip of the last stamp.
    """
    # the records come as the 1-element arrays they live in (`kernel._jit.record_array`)
    fp_, fs_, mp, ms, fp, tyre = fp_a[0], fs_a[0], mp_a[0], ms_a[0], fp_b[0], tyre_a[0]
    fs, pot, ap, al = fs_b[0], pot_a[0], ap_a[0], al_a[0]
    fast = np.empty((3, 4))
    fast_valid = np.empty(4, dtype=np.bool_)
    flags = 0
    for k in range(t.shape[0]):
        if monitor_restarts(mp, ms, t[k]):
            # a looped bag or a restarted source: start again, as the observers do
            levant_reset(fp_, fs_, fch)
            fit_reset(fp, scales, table, static_load, fs, cost, pot)
            alerts_reset(al)
            ms.t = math.nan
            flags |= POTENTIAL_MOVED | LEVELS_CHANGED  # the results start again too
        levant_update(fp_, flip, fs_, fch, t[k], angles[k], fast, fast_valid)
        flags |= monitor_step(
            mp, ms, fp, tyre, scales, table, fs, cost, pot, ap, al, t[k], fast[1], fast_valid,
            speeds[k], torques[k], omega[k], mu[k], mu_valid[k], fz[k], slip,
        )  # fmt: skip
        level[k] = al.level
        onset[k] = al.onset
        det[k] = al.detected
        mu_max[k] = pot.mu_max
        slip_peak[k] = pot.slip_peak
        confidence[k] = pot.confidence
        road[k] = pot.road_class
        vehicle_road[k] = vehicle_road_class(pot.road_class, pot.confidence)
    return flags
