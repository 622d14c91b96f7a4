"""The friction-potential fit's per-sample math: step functions on named records (numba).

The model and its reasons are in `vd_observer_node.situation.friction_potential` (the
settings, the result and the stateful `FrictionPotentialEstimator` that owns the records and
calls these functions). Everything here runs compiled (`vd_observer_node.kernel._jit.jit`),
and as plain Python with ``VD_JIT=0``.

Records (`vd_observer_node.situation.records`; fields by name, in numba too):

* `FRICTION_PARAMS`: the scalar settings, fields named as `FrictionPotentialConfig`'s;
* `TYRE`: the Magic Formula coefficients the fit evaluates, named as `TireParams`';
* `FIT_STATE`: the forgotten statistics per axle (A = 2: 0 front, 1 rear);
* `POTENTIAL`: the last friction potential (what `FrictionPotential` reports).

Arrays whose length is a setting stay arrays next to them: ``scales`` (M,) the road scales,
``cost`` (2, M) the forgotten weighted squared residuals per axle and road scale, ``recent``
(2, M) the same forgotten over ``change_time`` (the road-change test), ``table``
(5, L) the tyre's peaks at road scale 1 against the load (rows load, mu_drive, slip_drive,
mu_brake, slip_brake; `vd_common.vehicle.friction.FrictionTable`).

Road class codes: 0 unknown, 1 ice, 2 snow, 3 wet, 4 dry (`vd_common.vehicle.friction`).
"""

from __future__ import annotations

import math
from typing import Any, Final, NamedTuple

import numpy as np
from numpy.typing import NDArray

from vd_observer_node.kernel._jit import jit

__all__ = [
    'FIT_STATE',
    'FRICTION_PARAMS',
    'POTENTIAL',
    'TYRE',
    'FrictionFit',
    'classify_road',
    'fit_reset',
    'fit_solution',
    'fit_step',
    'friction_update',
    'mu_at_scales',
    'unfloored_slip',
    'vehicle_road_class',
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: Scalar settings of the fit (`FrictionPotentialConfig` without ``road_scales``).
FRICTION_PARAMS: Final = np.dtype(
    [
        ('forgetting_time', 'f8'),
        ('load_time', 'f8'),
        ('prior_road_scale', 'f8'),
        ('shrink_to_prior', 'b1'),
        ('min_slip', 'f8'),
        ('max_slip', 'f8'),
        ('min_slip_speed', 'f8'),
        ('slip_velocity_noise', 'f8'),
        ('min_slip_sigmas', 'f8'),
        ('mu_noise_std', 'f8'),
        ('confidence_margin', 'f8'),
        ('evidence_samples', 'f8'),
        ('evidence_hold_time', 'f8'),
        ('evidence_low', 'f8'),
        ('evidence_high', 'f8'),
        ('change_time', 'f8'),
        ('change_evidence', 'f8'),
        ('class_bounds', 'f8', (3,)),
        ('class_margin', 'f8'),
        ('class_min_confidence', 'f8'),
    ],
    align=True,
)
#: Magic Formula coefficients of the longitudinal force (`vd_common.vehicle.params.TireParams`).
TYRE: Final = np.dtype(
    [
        (name, 'f8')
        for name in [
            'nominal_load',
            'pCx1',
            'pDx1',
            'pDx2',
            'pEx1',
            'pEx2',
            'pEx3',
            'pEx4',
            'pKx1',
            'pKx2',
            'pKx3',
            'pHx1',
            'pHx2',
            'pVx1',
            'pVx2',
        ]
    ],
    align=True,
)
#: Forgotten statistics per axle besides ``cost``.
#:
#: count: forgotten number of used samples; load: [N] smoothed wheel load of the used
#: samples; direction: smoothed sign of their force (> 0 driving); t: [s] stamp of the last
#: accepted step (nan before the first); last_sample: [s] stamp of the axle's last usable
#: sample (nan if none); recent_count: the sample count of ``recent``; changes: road changes
#: detected per axle (the statistics restarted from ``recent``).
FIT_STATE: Final = np.dtype(
    [
        ('count', 'f8', (2,)),
        ('recent_count', 'f8', (2,)),
        ('changes', 'i8', (2,)),
        ('load', 'f8', (2,)),
        ('direction', 'f8', (2,)),
        ('t', 'f8'),
        ('last_sample', 'f8', (2,)),
    ],
    align=True,
)
#: The friction potential per axle (fields as `FrictionPotential`); ``road_class`` is also
#: the previous class the next solution's hysteresis starts from.
POTENTIAL: Final = np.dtype(
    [
        ('t', 'f8'),
        ('mu_max', 'f8', (2,)),
        ('slip_peak', 'f8', (2,)),
        ('confidence', 'f8', (2,)),
        ('road_class', 'i8', (2,)),
        ('road_scale', 'f8', (2,)),
    ],
    align=True,
)

#: [-] slip step of the numerical slope d mu / d s.
_SLOPE_STEP: Final = 1e-4
_ROAD_UNKNOWN: Final = 0
_ROAD_ICE: Final = 1
_ROAD_DRY: Final = 4


class FrictionFit(NamedTuple):
    """The fit's records and arrays, as its step functions take them (each record as the
    1-element array it lives in, `kernel._jit.record_array`: numba types arrays on its fast
    path; a NamedTuple because numba cannot nest arrays of a length set by the settings in a
    record).

    Attributes:
        params: shape (1,), `FRICTION_PARAMS`.
        tyre: shape (1,), `TYRE`.
        scales: shape (M,), [-] the road scales.
        table: shape (5, L), the tyre's peaks at road scale 1 against the load.
        static_load: shape (2,), [N] wheel load per axle before any sample.
        state: shape (1,), `FIT_STATE`.
        cost: shape (2, M), the forgotten weighted squared residuals.
        recent: shape (2, M), the same forgotten over ``change_time``.
        potential: shape (1,), `POTENTIAL`: the last solution.
    """

    params: NDArray[Any]
    tyre: NDArray[Any]
    scales: FloatArray
    table: FloatArray
    static_load: FloatArray
    state: NDArray[Any]
    cost: FloatArray
    recent: FloatArray
    potential: NDArray[Any]


@jit
def _sign(x: float) -> float:
    """np.sign of a float (0 stays 0, nan stays nan)."""
    if x > 0.0:
        return 1.0
    if x < 0.0:
        return -1.0
    return x


@jit
def unfloored_slip(slip_velocity: float, speed: float) -> tuple[float, float]:
    """Slip ratio without the floor of `vd_common.vehicle.tire.slip_ratio`, and its denominator.

    The fit gates samples on the denominator itself (``min_slip_speed``) and weights them by
    the slip noise it implies, so it needs the true denominator, not a floored one.

    Args:
        slip_velocity: [m/s] omega R - v.
        speed: body speed v [m/s].

    Returns:
        (slip [-] = (omega R - v) / max(|omega R|, |v|), positive driving, nan where the
        denominator is 0; denominator [m/s]).
    """
    den = max(abs(slip_velocity + speed), abs(speed))
    return (slip_velocity / den if den > 0.0 else math.nan), den


@jit
def mu_at_scales(tyre: Any, slip: float, load: float, scales: FloatArray, out: FloatArray) -> None:
    """mu(s; r) = Fx(s, Fz, r) / Fz at every road scale r (the similarity model).

    `vd_common.vehicle.tire.magic_formula_fx` with its per-sample terms (load change,
    curvature, stiffness) computed once for all scales: most of the fit's time is here.

    Args:
        tyre: `TYRE` record.
        slip: [-] signed slip.
        load: [N] wheel load (> 0).
        scales: shape (M,), [-] road scales.
        out: shape (M,), [-] written.
    """
    fz0, c = tyre.nominal_load, tyre.pCx1
    z = max(load, 0.0)
    dfz = (z - fz0) / fz0
    kx = slip + (tyre.pHx1 + tyre.pHx2 * dfz)
    ex = min(
        (tyre.pEx1 + tyre.pEx2 * dfz + tyre.pEx3 * dfz * dfz) * (1.0 - tyre.pEx4 * _sign(kx)),
        1.0,
    )
    kk = z * (tyre.pKx1 + tyre.pKx2 * dfz) * math.exp(tyre.pKx3 * dfz)
    d_base = tyre.pDx1 + tyre.pDx2 * dfz
    shift = z * (tyre.pVx1 + tyre.pVx2 * dfz)
    for j in range(scales.shape[0]):
        dx = scales[j] * d_base * z
        # Dx -> 0 (no load or no friction) gives Fx -> 0: guard the division, zero the force
        safe = dx if dx > 0.0 else 1.0
        bk = kk / (c * safe) * kx
        fx = dx * math.sin(c * math.atan(bk - ex * (bk - math.atan(bk))))
        out[j] = ((fx if dx > 0.0 else 0.0) + shift) / load


@jit
def classify_road(mu_max: float, confidence: float, previous: int, p: Any) -> int:
    """Road class from mu_max with hysteresis.

    Args:
        mu_max: [-] estimated friction potential.
        confidence: [0..1].
        previous: class of the previous stamp (road class code).
        p: `FRICTION_PARAMS` record (class bounds, margin and minimum confidence).

    Returns:
        0 (unknown) if confidence < class_min_confidence; otherwise the class whose band
        holds mu_max, keeping ``previous`` while mu_max is within class_margin outside its band.
    """
    if not math.isfinite(mu_max) or confidence < p.class_min_confidence:
        return _ROAD_UNKNOWN
    b = p.class_bounds
    raw = _ROAD_ICE
    for i in range(3):
        raw += 1 if b[i] <= mu_max else 0
    if _ROAD_ICE <= previous <= _ROAD_DRY and raw != previous:
        lo = -math.inf if previous == _ROAD_ICE else b[previous - _ROAD_ICE - 1]
        hi = math.inf if previous == _ROAD_DRY else b[previous - _ROAD_ICE]
        if lo - p.class_margin <= mu_max < hi + p.class_margin:
            return previous
    return raw


@jit
def _argmin(row: FloatArray) -> int:
    """Index of the least value (the first of equals)."""
    best = 0
    for j in range(1, row.shape[0]):
        if row[j] < row[best]:
            best = j
    return best


@jit
def _unit_peak(table: FloatArray, load: float, direction: float) -> tuple[float, float]:
    """The tyre's peak mu and slip at road scale 1 at a load [N], driving (direction >= 0) or
    braking, from the peak table (module docstring; the load clipped to the table)."""
    tl = table[0]
    z = min(max(load, tl[0]), tl[-1])
    if direction >= 0.0:
        return np.interp(z, tl, table[1]), np.interp(z, tl, table[2])
    return np.interp(z, tl, table[3]), np.interp(z, tl, table[4])


@jit
def _road_changed(fit: FrictionFit, a: int) -> bool:
    """Whether axle ``a``'s recent samples reject the road of its whole window.

    The profile-likelihood test of the confidence, on the recent statistics: the extra cost
    of the window's best road scale over the recent samples' own best, per recent sample
    times ``evidence_samples`` (or the recent count, if smaller), at least
    ``change_evidence``, and the two peaks more than ``confidence_margin`` apart.
    """
    p, s, recent = fit.params[0], fit.state[0], fit.recent
    count = s.recent_count[a]
    if p.change_evidence <= 0.0 or count <= 0.0:
        return False
    window = _argmin(fit.cost[a])
    own = _argmin(recent[a])
    unit_mu = _unit_peak(fit.table, s.load[a], s.direction[a])[0]
    if abs(fit.scales[window] - fit.scales[own]) * unit_mu <= p.confidence_margin:
        return False
    extra = (recent[a, window] - recent[a, own]) / max(count, 1.0)
    evidence: float = extra * min(count, p.evidence_samples)
    threshold: float = p.change_evidence
    return evidence >= threshold


@jit
def fit_solution(
    p: Any, scales: FloatArray, table: FloatArray, s: Any, cost: FloatArray, pot: Any
) -> None:
    """The friction potential of the statistics, written to ``pot``.

    Per axle: the best road scale (least cost), its peak at the smoothed load and force
    direction, and the confidence: the least extra cost of a scale whose peak is more than
    ``confidence_margin`` from the best one's, per sample times ``evidence_samples`` (or the
    forgotten sample count, if smaller), mapped linearly from ``evidence_low`` (0) to
    ``evidence_high`` (1), decayed with the time since the axle's last usable sample over
    ``evidence_hold_time`` divided by the misfit (the mean weighted squared residual per
    sample at the best scale, when above 1). Below ``class_min_confidence`` the reported
    scale is shrunk towards the prior road (``shrink_to_prior``): unexcited, every scale fits
    the linear part of the curve.

    Args:
        p: `FRICTION_PARAMS` record.
        scales: shape (M,), [-] road scales.
        table: shape (5, L), the tyre's peaks at road scale 1 (module docstring).
        s: `FIT_STATE` record.
        cost: shape (2, M).
        pot: `POTENTIAL` record; its ``road_class`` is read as the previous classes
            (hysteresis), then everything is overwritten for stamp ``s.t``.
    """
    m = scales.shape[0]
    pot.t = s.t
    for a in range(2):
        best = _argmin(cost[a])
        unit_mu, unit_slip = _unit_peak(table, s.load[a], s.direction[a])
        fitted = scales[best] if s.count[a] > 0.0 else p.prior_road_scale
        best_peak = scales[best] * unit_mu
        rival = math.inf
        for j in range(m):
            if abs(scales[j] * unit_mu - best_peak) > p.confidence_margin and cost[a, j] < rival:
                rival = cost[a, j]
        informed = s.count[a] > 0.0 and math.isfinite(rival)
        advantage = rival - cost[a, best] if informed else 0.0
        # about 1 (or less: mu_noise_std is an upper bound) when one curve explains the data
        misfit = cost[a, best] / s.count[a] if s.count[a] > 0.0 else 0.0
        # never more independent samples than the window holds: after a pause one new sample
        # replaces the forgotten data and must not count as evidence_samples of them
        evidence = advantage / max(s.count[a], 1.0) * min(s.count[a], p.evidence_samples)
        conf = (evidence - p.evidence_low) / (p.evidence_high - p.evidence_low)
        conf = min(max(conf, 0.0), 1.0) if not math.isnan(conf) else conf
        if p.evidence_hold_time > 0.0:
            age = s.t - s.last_sample[a] if math.isfinite(s.last_sample[a]) else 0.0
            # the data disagree among themselves (two roads in the window, a force transient):
            # while fresh samples come the forgetting sorts it out; once they stop, nothing
            # will, and the estimate must not be kept for the hold time (braking_low_mu: a
            # confident 0.52 for 3 s on the dry road after the patch, class 'wet' with noise)
            conf *= math.exp(-max(age, 0.0) * max(misfit, 1.0) / p.evidence_hold_time)
        weight = min(max(conf / max(p.class_min_confidence, 1e-9), 0.0), 1.0)
        if p.shrink_to_prior:
            scale = weight * fitted + (1.0 - weight) * p.prior_road_scale
        else:
            scale = fitted
        mu_max = scale * unit_mu
        pot.mu_max[a] = mu_max
        pot.slip_peak[a] = scale * unit_slip
        pot.confidence[a] = conf
        pot.road_scale[a] = fitted
        pot.road_class[a] = classify_road(mu_max, conf, pot.road_class[a], p)


@jit
def fit_reset(fit: FrictionFit) -> None:
    """Forget all data: empty statistics, and in the potential the prior road, confidence 0.

    Args:
        fit: the fit's records and arrays; its state, cost and potential are overwritten
            (``static_load`` is the wheel load per axle before any sample).
    """
    s, pot, cost = fit.state[0], fit.potential[0], fit.cost
    cost[:, :] = 0.0
    fit.recent[:, :] = 0.0
    s.count[:] = 0.0
    s.recent_count[:] = 0.0
    s.changes[:] = 0
    s.load[:] = fit.static_load
    s.direction[:] = 1.0
    s.t = math.nan
    s.last_sample[:] = math.nan
    pot.road_class[:] = _ROAD_UNKNOWN
    fit_solution(fit.params[0], fit.scales, fit.table, s, cost, pot)


@jit
def fit_step(
    fit: FrictionFit,
    t: float,
    sv: FloatArray,
    speed: float,
    mu: FloatArray,
    mu_valid: BoolArray,
    fz: FloatArray,
) -> bool:
    """Add one stamp's wheel samples to the statistics (in place).

    Each used sample adds, per road scale, its squared residual weighted by the variance it
    would have if that scale's curve were right, ``mu_noise_std^2 + (d mu/d s)^2 sigma_s^2``,
    ``sigma_s = slip_velocity_noise / denominator`` (errors in variables); the statistics are
    forgotten with ``forgetting_time`` only at stamps that bring samples.

    Args:
        fit: the fit's records and arrays (its state and cost are advanced).
        t: stamp [s].
        sv: shape (4,), [m/s] omega R - v, order FL, FR, RL, RR.
        speed: [m/s] body speed v.
        mu: shape (4,), [-] utilised friction Fx/Fz.
        mu_valid: shape (4,), bool.
        fz: shape (4,), [N] estimated wheel loads.

    Returns:
        Whether the stamp was taken (finite and later than ``s.t``); a stamp not taken leaves
        the state unchanged. Ignored samples: invalid or non-finite values, a load <= 0, a
        slip denominator below ``min_slip_speed``, |slip| below ``min_slip`` or
        ``min_slip_sigmas`` slip noise, and a mu of the opposite sign of the slip (a tyre
        force has the sign of its slip; the opposite is an estimation transient).
    """
    p, tyre, scales, s, cost = fit.params[0], fit.tyre[0], fit.scales, fit.state[0], fit.cost
    recent = fit.recent
    st = s.t
    if not math.isfinite(t) or (math.isfinite(st) and t <= st):
        return False
    if math.isfinite(speed):
        m = scales.shape[0]
        slips = np.empty(4)
        sigmas = np.empty(4)
        use = np.zeros(4, dtype=np.bool_)
        n_use = 0
        for i in range(4):
            slip, den = unfloored_slip(sv[i], speed)
            sigma = p.slip_velocity_noise / den if den > 0.0 else math.inf
            threshold = p.min_slip_sigmas * sigma
            if math.isnan(threshold):
                continue
            ok = (
                mu_valid[i]
                and math.isfinite(slip)
                and math.isfinite(mu[i])
                and math.isfinite(fz[i])
                and fz[i] > 0.0
                and den >= p.min_slip_speed
                and abs(slip) >= max(p.min_slip, threshold)
                and _sign(slip) == _sign(mu[i])
            )
            if ok:
                use[i] = True
                n_use += 1
                slips[i] = min(max(slip, -p.max_slip), p.max_slip)
                sigmas[i] = sigma
        if n_use > 0:
            dt = 0.0 if not math.isfinite(st) else t - st
            lam = math.exp(-dt / p.forgetting_time)
            lam_recent = math.exp(-dt / p.change_time) if p.change_time > 0.0 else 0.0
            blend = 1.0 - math.exp(-dt / p.load_time) if dt > 0.0 else 1.0
            mid = np.empty(m)
            up = np.empty(m)
            down = np.empty(m)
            h = _SLOPE_STEP
            noise2 = p.mu_noise_std**2
            for a in range(2):
                rows = 0
                acc = np.zeros(m)
                z_sum = 0.0
                s_sum = 0.0
                for i in (2 * a, 2 * a + 1):
                    if not use[i]:
                        continue
                    x, z = slips[i], fz[i]
                    mu_at_scales(tyre, x, z, scales, mid)
                    mu_at_scales(tyre, x + h, z, scales, up)
                    mu_at_scales(tyre, x - h, z, scales, down)
                    for j in range(m):
                        slope = (up[j] - down[j]) / (2.0 * h)
                        variance = noise2 + (slope * sigmas[i]) ** 2
                        acc[j] += (mu[i] - mid[j]) ** 2 / variance
                    rows += 1
                    z_sum += z
                    s_sum += _sign(x)
                if rows == 0:
                    continue
                for j in range(m):
                    cost[a, j] = lam * cost[a, j] + acc[j]
                    recent[a, j] = lam_recent * recent[a, j] + acc[j]
                s.count[a] = lam * s.count[a] + float(rows)
                s.recent_count[a] = lam_recent * s.recent_count[a] + float(rows)
                if _road_changed(fit, a):
                    # another road: what the window holds from before is not this road's
                    cost[a, :] = recent[a, :]
                    s.count[a] = s.recent_count[a]
                    s.changes[a] += 1
                s.load[a] += blend * (z_sum / rows - s.load[a])
                s.direction[a] += blend * (s_sum / rows - s.direction[a])
                s.last_sample[a] = t
    s.t = t
    return True


@jit
def friction_update(
    fit: FrictionFit,
    t: float,
    sv: FloatArray,
    speed: float,
    mu: FloatArray,
    mu_valid: BoolArray,
    fz: FloatArray,
) -> bool:
    """`fit_step`, then `fit_solution` into the potential if the stamp was taken; returns that."""
    if not fit_step(fit, t, sv, speed, mu, mu_valid, fz):
        return False
    fit_solution(fit.params[0], fit.scales, fit.table, fit.state[0], fit.cost, fit.potential[0])
    return True


@jit
def vehicle_road_class(road_class: NDArray[np.int64], confidence: FloatArray) -> int:
    """Class of the most confident axle with a known class (0, unknown, if none).

    Args:
        road_class: shape (2,), class code per axle.
        confidence: shape (2,), [0..1] per axle (finite where the class is known).
    """
    best = -1
    best_conf = -math.inf
    for a in range(2):
        if road_class[a] != _ROAD_UNKNOWN and confidence[a] > best_conf:
            best, best_conf = a, confidence[a]
    return int(road_class[best]) if best >= 0 else _ROAD_UNKNOWN
