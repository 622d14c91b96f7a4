"""Compiled situation monitor: fast wheel observer, friction potential and alerts, in numba.

Mirrors :class:`vd_observer_node.situation.monitor.SituationMonitor` with its parts
(:class:`~vd_observer_node.situation.friction_potential.FrictionPotentialEstimator`: the similarity
fit on the Magic Formula at every road scale, its confidence and road classes;
:class:`~vd_observer_node.situation.alerts.AlertMonitor`: metrics, hysteresis and debounce) step
for step; the tests run both on the same inputs and require equal outputs (1e-9; levels and road
classes exactly).

The Magic Formula of one sample is evaluated at all road scales with its per-sample terms
(load change, curvature, stiffness) computed once, which is where most of the reference's time
went.

Array layouts: ``prm_f`` (`N_FRICTION_PARAMS`,), ``tp`` (15,) tyre coefficients, ``table``
(5, L) the tyre's unit peaks (load, mu_drive, slip_drive, mu_brake, slip_brake), ``scales``
(M,); friction state ``cost`` (2, M), ``count``, ``load``, ``direction``, ``last_sample`` (2,),
``fscal`` (1,) stamp of the fit, ``classes`` (2,) int64, ``pot`` (`POT_SIZE`,) the last
friction potential packed (``P_*`` offsets); alert state ``ch`` (3, 4, 5) per (kind, wheel):
level, onset, pending level, pending since, run start; ``detected`` (3, 4); ``ascal`` (1,)
stamp of the last alert update; monitor ``mscal`` (1,) stamp of the last call.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any, Final

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vd_observer_node.errors import InputShapeError
from vd_observer_node.estimation.differentiator import LevantDifferentiator
from vd_observer_node.estimation.faults import OBSERVER_FAULTS
from vd_observer_node.estimation.levant_step import levant_reset, levant_update
from vd_observer_node.estimation.observer import WHEEL_INPUTS, ObserverConfig
from vd_observer_node.kernel._jit import jit
from vd_observer_node.situation.alerts import ALERT_KINDS, Alert, AlertConfig
from vd_observer_node.situation.friction_potential import (
    ROAD_UNKNOWN,
    FrictionPotential,
    FrictionPotentialConfig,
    TyreCurves,
)
from vd_observer_node.situation.monitor import Situation, SituationConfig

__all__ = [
    'POT_SIZE',
    'P_CONFIDENCE',
    'P_MU_MAX',
    'P_ROAD',
    'P_SCALE',
    'P_SLIP_PEAK',
    'P_T',
    'CompiledSituationMonitor',
    'SituationArrays',
    'monitor_reset',
    'monitor_update',
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
IntArray = NDArray[np.int64]

P_T: Final = 0
P_MU_MAX: Final = 1
P_SLIP_PEAK: Final = 3
P_CONFIDENCE: Final = 5
P_ROAD: Final = 7
P_SCALE: Final = 9
POT_SIZE: Final = 11

(_FORGET, _LOAD_TIME, _PRIOR, _SHRINK, _MIN_SLIP, _MAX_SLIP, _MIN_SLIP_SPEED, _SV_NOISE,
 _MIN_SIGMAS, _MU_NOISE, _MARGIN, _EVIDENCE_SAMPLES, _HOLD, _EV_LOW, _EV_HIGH, _B0, _B1, _B2,
 _CLASS_MARGIN, _CLASS_MIN_CONF) = range(20)  # fmt: skip
N_FRICTION_PARAMS: Final = 20
_SLOPE_STEP: Final = 1e-4  # friction_potential._SLOPE_STEP
_ROAD_ICE: Final = 1
_ROAD_DRY: Final = 4
# prm_a: min_slip_velocity, min_wheel_torque, raise_hold, release_hold
# prm_s: radius, slip_floor_speed, max_observer_disagreement, max_gap (observer)
_LEVEL, _ONSET, _PENDING, _SINCE, _RUN = range(5)


def _friction_params(config: FrictionPotentialConfig) -> FloatArray:
    c = config
    return np.array(
        [
            c.forgetting_time, c.load_time, c.prior_road_scale, float(c.shrink_to_prior),
            c.min_slip, c.max_slip, c.min_slip_speed, c.slip_velocity_noise, c.min_slip_sigmas,
            c.mu_noise_std, c.confidence_margin, c.evidence_samples, c.evidence_hold_time,
            c.evidence_low, c.evidence_high, *c.class_bounds, c.class_margin,
            c.class_min_confidence,
        ],
        dtype=np.float64,
    )  # fmt: skip


def _tyre_params(curves: TyreCurves) -> tuple[FloatArray, FloatArray]:
    tp = curves.tire
    coefficients = np.array(
        [
            tp.nominal_load, tp.pCx1, tp.pDx1, tp.pDx2, tp.pEx1, tp.pEx2, tp.pEx3, tp.pEx4,
            tp.pKx1, tp.pKx2, tp.pKx3, tp.pHx1, tp.pHx2, tp.pVx1, tp.pVx2,
        ],
        dtype=np.float64,
    )  # fmt: skip
    tb = curves.table
    table = np.stack([tb.load, tb.mu_drive, tb.slip_drive, tb.mu_brake, tb.slip_brake])
    return coefficients, np.ascontiguousarray(table, dtype=np.float64)


@jit
def _sign(x: float) -> float:
    if x > 0.0:
        return 1.0
    if x < 0.0:
        return -1.0
    return x


@jit
def _mu_at_scales(
    tp: FloatArray, slip: float, load: float, scales: FloatArray, out: FloatArray
) -> None:
    """mu(slip; r) = Fx(slip, load, r) / load at every road scale r (`TyreCurves.mu`)."""
    fz0, c = tp[0], tp[1]
    z = max(load, 0.0)
    dfz = (z - fz0) / fz0
    kx = slip + (tp[11] + tp[12] * dfz)
    ex = min((tp[4] + tp[5] * dfz + tp[6] * dfz * dfz) * (1.0 - tp[7] * _sign(kx)), 1.0)
    kk = z * (tp[8] + tp[9] * dfz) * math.exp(tp[10] * dfz)
    d_base = tp[2] + tp[3] * dfz
    shift = z * (tp[13] + tp[14] * dfz)
    for j in range(scales.shape[0]):
        dx = scales[j] * d_base * z
        safe = dx if dx > 0.0 else 1.0
        bk = kk / (c * safe) * kx
        fx = dx * math.sin(c * math.atan(bk - ex * (bk - math.atan(bk))))
        out[j] = ((fx if dx > 0.0 else 0.0) + shift) / load


@jit
def _classify_road(mu_max: float, confidence: float, previous: int, prm_f: FloatArray) -> int:
    """`friction_potential.classify_road`."""
    if not math.isfinite(mu_max) or confidence < prm_f[_CLASS_MIN_CONF]:
        return 0
    b0, b1, b2 = prm_f[_B0], prm_f[_B1], prm_f[_B2]
    raw = _ROAD_ICE + (1 if b0 <= mu_max else 0) + (1 if b1 <= mu_max else 0)
    raw += 1 if b2 <= mu_max else 0
    if _ROAD_ICE <= previous <= _ROAD_DRY and raw != previous:
        bounds = (b0, b1, b2)
        lo = -math.inf if previous == _ROAD_ICE else bounds[previous - _ROAD_ICE - 1]
        hi = math.inf if previous == _ROAD_DRY else bounds[previous - _ROAD_ICE]
        margin = prm_f[_CLASS_MARGIN]
        if lo - margin <= mu_max < hi + margin:
            return previous
    return raw


@jit
def _fit_solution(
    prm_f: FloatArray,
    scales: FloatArray,
    table: FloatArray,
    cost: FloatArray,
    count: FloatArray,
    load: FloatArray,
    direction: FloatArray,
    t: float,
    last_sample: FloatArray,
    classes: IntArray,
    pot: FloatArray,
) -> None:
    """`fit_solution` (with `_confidence`) into ``pot``; the new classes into ``classes``."""
    m = scales.shape[0]
    pot[P_T] = t
    for a in range(2):
        best = 0
        for j in range(1, m):
            if cost[a, j] < cost[a, best]:
                best = j
        tl = table[0]
        z = min(max(load[a], tl[0]), tl[-1])
        if direction[a] >= 0.0:
            unit_mu = np.interp(z, tl, table[1])
            unit_slip = np.interp(z, tl, table[2])
        else:
            unit_mu = np.interp(z, tl, table[3])
            unit_slip = np.interp(z, tl, table[4])
        fitted = scales[best] if count[a] > 0.0 else prm_f[_PRIOR]
        best_peak = scales[best] * unit_mu
        rival = math.inf
        for j in range(m):
            if abs(scales[j] * unit_mu - best_peak) > prm_f[_MARGIN] and cost[a, j] < rival:
                rival = cost[a, j]
        informed = count[a] > 0.0 and math.isfinite(rival)
        advantage = rival - cost[a, best] if informed else 0.0
        evidence = advantage / max(count[a], 1.0) * prm_f[_EVIDENCE_SAMPLES]
        span = prm_f[_EV_HIGH] - prm_f[_EV_LOW]
        conf = (evidence - prm_f[_EV_LOW]) / span
        conf = min(max(conf, 0.0), 1.0) if not math.isnan(conf) else conf
        if prm_f[_HOLD] > 0.0:
            age = t - last_sample[a] if math.isfinite(last_sample[a]) else 0.0
            conf *= math.exp(-max(age, 0.0) / prm_f[_HOLD])
        weight = min(max(conf / max(prm_f[_CLASS_MIN_CONF], 1e-9), 0.0), 1.0)
        if prm_f[_SHRINK] != 0.0:
            scale = weight * fitted + (1.0 - weight) * prm_f[_PRIOR]
        else:
            scale = fitted
        mu_max = scale * unit_mu
        pot[P_MU_MAX + a] = mu_max
        pot[P_SLIP_PEAK + a] = scale * unit_slip
        pot[P_CONFIDENCE + a] = conf
        pot[P_SCALE + a] = fitted
        road = _classify_road(mu_max, conf, classes[a], prm_f)
        pot[P_ROAD + a] = road
    classes[0] = int(pot[P_ROAD])
    classes[1] = int(pot[P_ROAD + 1])


@jit
def _friction_reset(
    prm_f: FloatArray,
    scales: FloatArray,
    table: FloatArray,
    static_load: FloatArray,
    cost: FloatArray,
    count: FloatArray,
    load: FloatArray,
    direction: FloatArray,
    fscal: FloatArray,
    last_sample: FloatArray,
    classes: IntArray,
    pot: FloatArray,
) -> None:
    """`FrictionPotentialEstimator.reset`."""
    cost[:, :] = 0.0
    count[:] = 0.0
    load[:] = static_load
    direction[:] = 1.0
    fscal[0] = math.nan
    last_sample[:] = math.nan
    classes[:] = 0
    _fit_solution(
        prm_f, scales, table, cost, count, load, direction, math.nan, last_sample, classes, pot
    )


@jit
def _friction_update(
    prm_f: FloatArray,
    tp: FloatArray,
    scales: FloatArray,
    table: FloatArray,
    cost: FloatArray,
    count: FloatArray,
    load: FloatArray,
    direction: FloatArray,
    fscal: FloatArray,
    last_sample: FloatArray,
    classes: IntArray,
    pot: FloatArray,
    t: float,
    sv: FloatArray,
    speed: float,
    mu: FloatArray,
    mu_valid: BoolArray,
    fz: FloatArray,
) -> None:
    """`FrictionPotentialEstimator.update` (fit_step, then fit_solution if it moved)."""
    st = fscal[0]
    if not math.isfinite(t) or (math.isfinite(st) and t <= st):
        return
    if math.isfinite(speed):
        m = scales.shape[0]
        slips = np.empty(4)
        sigmas = np.empty(4)
        use = np.zeros(4, dtype=np.bool_)
        n_use = 0
        for i in range(4):
            den = max(abs(sv[i] + speed), abs(speed))
            slip = sv[i] / den if den > 0.0 else math.nan
            sigma = prm_f[_SV_NOISE] / den if den > 0.0 else math.inf
            threshold = prm_f[_MIN_SIGMAS] * sigma
            if math.isnan(threshold):
                continue
            ok = (
                mu_valid[i]
                and math.isfinite(slip)
                and math.isfinite(mu[i])
                and math.isfinite(fz[i])
                and fz[i] > 0.0
                and den >= prm_f[_MIN_SLIP_SPEED]
                and abs(slip) >= max(prm_f[_MIN_SLIP], threshold)
                and _sign(slip) == _sign(mu[i])
            )
            if ok:
                use[i] = True
                n_use += 1
                slips[i] = min(max(slip, -prm_f[_MAX_SLIP]), prm_f[_MAX_SLIP])
                sigmas[i] = sigma
        if n_use > 0:
            dt = 0.0 if not math.isfinite(st) else t - st
            lam = math.exp(-dt / prm_f[_FORGET])
            blend = 1.0 - math.exp(-dt / prm_f[_LOAD_TIME]) if dt > 0.0 else 1.0
            mid = np.empty(m)
            up = np.empty(m)
            down = np.empty(m)
            h = _SLOPE_STEP
            for a in range(2):
                rows = 0
                acc = np.zeros(m)
                z_sum = 0.0
                s_sum = 0.0
                for i in (2 * a, 2 * a + 1):
                    if not use[i]:
                        continue
                    s, z = slips[i], fz[i]
                    _mu_at_scales(tp, s, z, scales, mid)
                    _mu_at_scales(tp, s + h, z, scales, up)
                    _mu_at_scales(tp, s - h, z, scales, down)
                    noise2 = prm_f[_MU_NOISE] ** 2
                    for j in range(m):
                        slope = (up[j] - down[j]) / (2.0 * h)
                        variance = noise2 + (slope * sigmas[i]) ** 2
                        acc[j] += (mu[i] - mid[j]) ** 2 / variance
                    rows += 1
                    z_sum += z
                    s_sum += _sign(s)
                if rows == 0:
                    continue
                for j in range(m):
                    cost[a, j] = lam * cost[a, j] + acc[j]
                count[a] = lam * count[a] + float(rows)
                load[a] += blend * (z_sum / rows - load[a])
                direction[a] += blend * (s_sum / rows - direction[a])
                last_sample[a] = t
    fscal[0] = t
    _fit_solution(prm_f, scales, table, cost, count, load, direction, t, last_sample, classes, pot)


@jit
def _classify_level(value: float, level: int, th: FloatArray) -> int:
    """`alerts.classify_level`; th = (warning_on, warning_off, critical_on, critical_off)."""
    if not math.isfinite(value):
        return 0
    if value >= th[2] or (level == 2 and value >= th[3]):
        return 2
    if value >= th[0] or (level >= 1 and value >= th[1]):
        return 1
    return 0


@jit
def _alerts_reset(ch: FloatArray, detected: FloatArray, ascal: FloatArray) -> None:
    for k in range(3):
        for w in range(4):
            ch[k, w, _LEVEL] = 0.0
            ch[k, w, _ONSET] = math.nan
            ch[k, w, _PENDING] = 0.0
            ch[k, w, _SINCE] = math.nan
            ch[k, w, _RUN] = math.nan
            detected[k, w] = math.nan
    ascal[0] = math.nan


@jit
def _alerts_update(
    prm_a: FloatArray,
    thresholds: FloatArray,
    ch: FloatArray,
    detected: FloatArray,
    ascal: FloatArray,
    t: float,
    slip: FloatArray,
    sv: FloatArray,
    torque: FloatArray,
    mu: FloatArray,
    mu_valid: BoolArray,
    mu_max: FloatArray,
    slip_peak: FloatArray,
) -> None:
    """`AlertMonitor.update` (metrics by `alert_metrics`, then `step_channel` per channel)."""
    if not math.isfinite(t) or (math.isfinite(ascal[0]) and t <= ascal[0]):
        return
    ascal[0] = t
    gate, min_torque = prm_a[0], prm_a[1]
    metrics = np.zeros((3, 4))
    for w in range(4):
        s, v, tq, m, ok = slip[w], sv[w], torque[w], mu[w], mu_valid[w]
        driving = ((not ok) or m >= 0.0) and tq > min_torque
        braking = ((not ok) or m <= 0.0) and tq < -min_torque
        if v > gate and driving:
            metrics[0, w] = s
        if v < -gate and braking:
            metrics[1, w] = -s
        if ok and mu_max[w] > 0.0:
            metrics[2, w] = abs(m) / mu_max[w]
        past_peak = ok and abs(v) > gate and abs(s) >= slip_peak[w] and _sign(s) == _sign(m)
        if past_peak:
            metrics[2, w] = max(metrics[2, w], 1.0)
        if not (math.isfinite(s) and math.isfinite(v) and math.isfinite(tq)):
            metrics[0, w] = math.nan
            metrics[1, w] = math.nan
        if not (math.isfinite(m) and math.isfinite(mu_max[w])):
            metrics[2, w] = math.nan
    raise_hold, release_hold = prm_a[2], prm_a[3]
    for k in range(3):
        for w in range(4):
            level = int(ch[k, w, _LEVEL])
            target = _classify_level(metrics[k, w], level, thresholds[k])
            if (
                target == 0
                and level == 0
                and ch[k, w, _PENDING] == 0.0
                and math.isnan(ch[k, w, _RUN])
            ):
                continue
            run_start = ch[k, w, _RUN]
            if target == 0:
                run_start = math.nan
            elif math.isnan(run_start):
                run_start = t
            if target == level:
                ch[k, w, _PENDING] = target
                ch[k, w, _SINCE] = math.nan
                ch[k, w, _RUN] = run_start
                continue
            since = ch[k, w, _SINCE]
            if target != ch[k, w, _PENDING] or math.isnan(since):
                since = t
            hold = raise_hold if target > level else release_hold
            if t - since >= hold:
                if target == 0:
                    onset = math.nan
                elif level == 0:
                    onset = run_start
                else:
                    onset = ch[k, w, _ONSET]
                ch[k, w, _LEVEL] = target
                ch[k, w, _ONSET] = onset
                ch[k, w, _PENDING] = target
                ch[k, w, _SINCE] = math.nan
                ch[k, w, _RUN] = run_start
                if level == 0:
                    detected[k, w] = t
                elif target == 0:
                    detected[k, w] = math.nan
            else:
                ch[k, w, _PENDING] = target
                ch[k, w, _SINCE] = since
                ch[k, w, _RUN] = run_start


class SituationArrays:
    """Every parameter and state array of the monitor kernel (see the module docstring)."""

    def __init__(
        self,
        curves: TyreCurves,
        static_load: ArrayLike,
        radius: float,
        observer: ObserverConfig,
        alerts: AlertConfig,
        friction: FrictionPotentialConfig,
        situation: SituationConfig,
    ) -> None:
        """Parameters from the settings; the state is set by `monitor_reset`."""
        self.static_load = np.ascontiguousarray(static_load, dtype=np.float64)
        if self.static_load.shape != (2,):
            raise InputShapeError(
                f'static_load must have shape (2,), got {self.static_load.shape}'
            )
        fast_config = replace(observer, wheel_lipschitz=situation.alert_wheel_lipschitz)
        self.fast = LevantDifferentiator(
            fast_config.wheel_lipschitz,
            n_channels=4,
            gains=fast_config.gains,
            discretization=fast_config.discretization,
            init=fast_config.init,
            max_gap=fast_config.max_gap,
            init_baseline=fast_config.init_baseline,
            input_derivative=WHEEL_INPUTS.index(fast_config.wheel_input),
        )
        self.prm_f = _friction_params(friction)
        self.tp, self.table = _tyre_params(curves)
        self.scales = np.asarray(friction.road_scales, dtype=np.float64)
        self.prm_a = np.array(
            [alerts.min_slip_velocity, alerts.min_wheel_torque, alerts.raise_hold,
             alerts.release_hold]
        )  # fmt: skip
        self.thresholds = np.array(
            [
                [th.warning_on, th.warning_off, th.critical_on, th.critical_off]
                for th in (alerts.traction, alerts.lock, alerts.low_friction)
            ]
        )
        self.prm_s = np.array(
            [radius, situation.slip_floor_speed, situation.max_observer_disagreement,
             observer.max_gap]
        )  # fmt: skip
        m = self.scales.shape[0]
        self.cost = np.zeros((2, m))
        self.count = np.zeros(2)
        self.load = np.zeros(2)
        self.direction = np.zeros(2)
        self.fscal = np.zeros(1)
        self.last_sample = np.zeros(2)
        self.classes = np.zeros(2, dtype=np.int64)
        self.pot = np.zeros(POT_SIZE)
        self.ch = np.zeros((3, 4, 5))
        self.detected = np.zeros((3, 4))
        self.ascal = np.zeros(1)
        self.mscal = np.full(1, math.nan)


@jit
def monitor_reset(
    fprm: np.record,
    flip: FloatArray,
    fst_: np.record,
    fch: np.recarray,
    prm_f: FloatArray,
    scales: FloatArray,
    table: FloatArray,
    static_load: FloatArray,
    cost: FloatArray,
    count: FloatArray,
    load: FloatArray,
    direction: FloatArray,
    fscal: FloatArray,
    last_sample: FloatArray,
    classes: IntArray,
    pot: FloatArray,
    ch: FloatArray,
    detected: FloatArray,
    ascal: FloatArray,
) -> None:
    """`SituationMonitor.reset`: fast observer, friction fit and alerts back to the start."""
    levant_reset(fprm, fst_, fch)
    _friction_reset(
        prm_f, scales, table, static_load, cost, count, load, direction, fscal, last_sample,
        classes, pot,
    )  # fmt: skip
    _alerts_reset(ch, detected, ascal)


@jit
def monitor_update(
    fprm: np.record,
    flip: FloatArray,
    fst_: np.record,
    fch: np.recarray,
    prm_f: FloatArray,
    tp: FloatArray,
    scales: FloatArray,
    table: FloatArray,
    static_load: FloatArray,
    cost: FloatArray,
    count: FloatArray,
    load: FloatArray,
    direction: FloatArray,
    fscal: FloatArray,
    last_sample: FloatArray,
    classes: IntArray,
    pot: FloatArray,
    prm_a: FloatArray,
    thresholds: FloatArray,
    ch: FloatArray,
    detected: FloatArray,
    ascal: FloatArray,
    prm_s: FloatArray,
    mscal: FloatArray,
    t: float,
    wheel_angle: FloatArray,
    speed: float,
    torque: FloatArray,
    omega: FloatArray,
    mu: FloatArray,
    mu_valid: BoolArray,
    fz: FloatArray,
    slip_out: FloatArray,
) -> None:
    """`SituationMonitor.update` for stamp t; results stay in pot, ch, detected, slip_out."""
    if not math.isnan(mscal[0]) and t < mscal[0] - prm_s[3]:
        monitor_reset(
            fprm, flip, fst_, fch, prm_f, scales, table, static_load, cost, count, load,
            direction, fscal, last_sample, classes, pot, ch, detected, ascal,
        )  # fmt: skip
    fast = np.empty((3, 4))
    fast_valid = np.empty(4, dtype=np.bool_)
    levant_update(fprm, flip, fst_, fch, t, wheel_angle, fast, fast_valid)
    radius, floor, gate = prm_s[0], prm_s[1], prm_s[2]
    v = speed
    sv_fast = np.empty(4)
    sv_cascade = np.empty(4)
    steady = np.empty(4, dtype=np.bool_)
    for i in range(4):
        sv_fast[i] = fast[1, i] * radius - v if fast_valid[i] else 0.0
        den = max(max(abs(sv_fast[i] + v), abs(v)), floor)
        slip_out[i] = sv_fast[i] / den
        sv_cascade[i] = omega[i] * radius - v
        steady[i] = abs(sv_fast[i] - sv_cascade[i]) <= gate if gate > 0.0 else True
        steady[i] = steady[i] and mu_valid[i]
    _friction_update(
        prm_f, tp, scales, table, cost, count, load, direction, fscal, last_sample, classes,
        pot, t, sv_cascade, v, mu, steady, fz,
    )  # fmt: skip
    wheel_mu_max = np.empty(4)
    wheel_slip_peak = np.empty(4)
    for i in range(4):
        axle = i // 2
        wheel_mu_max[i] = pot[P_MU_MAX + axle]
        wheel_slip_peak[i] = pot[P_SLIP_PEAK + axle]
    _alerts_update(
        prm_a, thresholds, ch, detected, ascal, t, slip_out, sv_fast, torque, mu, mu_valid,
        wheel_mu_max, wheel_slip_peak,
    )  # fmt: skip
    mscal[0] = t


def monitor_args(a: SituationArrays) -> tuple[object, ...]:
    """The state/parameter arguments of `monitor_update` (everything before ``t``)."""
    return (
        *a.fast.kernel_args, a.prm_f, a.tp, a.scales, a.table, a.static_load, a.cost, a.count,
        a.load, a.direction, a.fscal, a.last_sample, a.classes, a.pot, a.prm_a, a.thresholds,
        a.ch, a.detected, a.ascal, a.prm_s, a.mscal,
    )  # fmt: skip


def reset_arrays(a: SituationArrays) -> None:
    """`monitor_reset` on the arrays of `a` (and the monitor's last stamp forgotten)."""
    f = a.fast
    monitor_reset(
        f.params, f.lipschitz, f.record, f.channels, a.prm_f, a.scales, a.table, a.static_load,
        a.cost, a.count, a.load, a.direction, a.fscal, a.last_sample, a.classes, a.pot, a.ch,
        a.detected, a.ascal,
    )  # fmt: skip
    a.mscal[0] = math.nan


def potential_from_arrays(pot: FloatArray) -> FrictionPotential:
    """The `FrictionPotential` of a packed potential (copies)."""
    return FrictionPotential(
        t=float(pot[P_T]),
        mu_max=pot[P_MU_MAX : P_MU_MAX + 2].copy(),
        slip_peak=pot[P_SLIP_PEAK : P_SLIP_PEAK + 2].copy(),
        confidence=pot[P_CONFIDENCE : P_CONFIDENCE + 2].copy(),
        road_class=pot[P_ROAD : P_ROAD + 2].astype(np.int64),
        road_scale=pot[P_SCALE : P_SCALE + 2].copy(),
    )


def alerts_from_arrays(ch: FloatArray, detected: FloatArray) -> tuple[Alert, ...]:
    """The 12 `Alert` records (kinds in ALERT_KINDS order, wheels 0..3 within each)."""
    return tuple(
        Alert(
            kind=ALERT_KINDS[k],
            wheel=w,
            level=int(ch[k, w, _LEVEL]),
            active=bool(ch[k, w, _LEVEL] > 0.0),
            onset=float(ch[k, w, _ONSET]),
            detected=float(detected[k, w]),
        )
        for k in range(3)
        for w in range(4)
    )


class CompiledSituationMonitor:
    """Drop-in for `situation.SituationMonitor` running `monitor_update` (same API)."""

    def __init__(
        self,
        curves: TyreCurves,
        static_load: ArrayLike,
        radius: float,
        *,
        observer: ObserverConfig | None = None,
        alerts: AlertConfig | None = None,
        friction: FrictionPotentialConfig | None = None,
        situation: SituationConfig | None = None,
    ) -> None:
        """Create the monitor (arguments as `SituationMonitor`)."""
        self.config = situation or SituationConfig()
        base = observer or ObserverConfig()
        self.observer_config = replace(base, wheel_lipschitz=self.config.alert_wheel_lipschitz)
        self.arrays = SituationArrays(
            curves,
            static_load,
            radius,
            base,
            alerts or AlertConfig(),
            friction or FrictionPotentialConfig(),
            self.config,
        )
        #: the leading (state and parameter) arguments of `monitor_update`
        self.args = monitor_args(self.arrays)
        self.slip = np.zeros(4)
        # compile (or load from numba's cache) now, not at the first sample; then start afresh
        zeros = np.zeros(4)
        self.update_arrays(0.0, zeros, 1.0, zeros, zeros, zeros, np.zeros(4, np.bool_), zeros)
        fast = self.arrays.fast.record
        for kind in (*OBSERVER_FAULTS, 'rejected'):
            fast[kind] = 0
        self.reset()

    def reset(self) -> None:
        """Back to the initial state (after a time jump or a new bag)."""
        reset_arrays(self.arrays)

    def update_arrays(
        self,
        t: float,
        wheel_angle: FloatArray,
        speed: float,
        wheel_torque: FloatArray,
        omega: FloatArray,
        mu: FloatArray,
        mu_valid: BoolArray,
        load: FloatArray,
    ) -> None:
        """`update` without building result objects: read `arrays` (pot, ch, detected), `slip`.

        Arrays must be contiguous float64 (bool for mu_valid) of shape (4,).
        """
        kernel: Any = monitor_update  # its leading arguments come as one tuple
        kernel(
            *self.args, float(t), wheel_angle, float(speed), wheel_torque, omega, mu, mu_valid,
            load, self.slip,
        )  # fmt: skip

    def update(
        self,
        t: float,
        wheel_angle: ArrayLike,
        speed: float,
        wheel_torque: ArrayLike,
        omega: ArrayLike,
        mu: ArrayLike,
        mu_valid: ArrayLike,
        load: ArrayLike,
    ) -> Situation:
        """Advance to stamp t (`SituationMonitor.update`).

        Raises:
            InputShapeError: an array input has the wrong shape.
        """
        self.update_arrays(
            t,
            _floats('wheel_angle', wheel_angle),
            speed,
            _floats('wheel_torque', wheel_torque),
            _floats('omega', omega),
            _floats('mu', mu),
            _bools('mu_valid', mu_valid),
            _floats('load', load),
        )
        a = self.arrays
        return Situation(
            float(t),
            potential_from_arrays(a.pot),
            alerts_from_arrays(a.ch, a.detected),
            self.slip.copy(),
        )

    def active(self) -> tuple[Alert, ...]:
        """The active alert records of the last update."""
        return tuple(
            x for x in alerts_from_arrays(self.arrays.ch, self.arrays.detected) if x.active
        )


def _floats(name: str, value: ArrayLike) -> FloatArray:
    array = np.ascontiguousarray(value, dtype=np.float64)
    if array.shape != (4,):
        raise InputShapeError(f'{name} must have shape (4,), got {array.shape}')
    return array


def _bools(name: str, value: ArrayLike) -> BoolArray:
    array = np.ascontiguousarray(value, dtype=np.bool_)
    if array.shape != (4,):
        raise InputShapeError(f'{name} must have shape (4,), got {array.shape}')
    return array


_ = ROAD_UNKNOWN  # the road codes of friction_potential: 0 unknown, 1 ice ... 4 dry
