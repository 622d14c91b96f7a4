"""The online mass and grade estimator's per-stamp step (compiled), over named records.

The math of `mass_grade` (see its module docstring for the model, the filters and the
excitation gates): `mass_update` is one stamp of `mass_grade.MassGradeEstimator.update`,
`mass_rescale` its `rescale_force`; `rls_update` is the recursive least squares both this
estimator and `rolling_radius` run. `mass_grade.MassGradeEstimator` and the estimator's step
(`estimator_step`) call these, on a `MASS_PARAMS` record (built by `mass_grade.mass_params`),
a `MASS_STATE` record and its `MASS_OUT` record (the last estimate).

Squares are products (``x * x``), never ``x ** 2``: numba's power and CPython's pow() may
differ in the last bit, and the results must not depend on whether the step is compiled.
"""

from __future__ import annotations

import math
from typing import Final

import numpy as np
from numpy.typing import NDArray

from vd_observer_node.estimation.faults import STAMP_FAULTS, stamp_step
from vd_observer_node.estimation.formulas import rolling_coefficient_at
from vd_observer_node.kernel._jit import jit

__all__ = [
    'MASS_GRADE_FAULTS',
    'MASS_OUT',
    'MASS_PARAMS',
    'MASS_STATE',
    'forgetting_factor',
    'mass_held',
    'mass_rescale',
    'mass_reset',
    'mass_update',
    'rls_update',
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: Fault kinds the mass estimator counts (all handled: the output stays finite).
MASS_GRADE_FAULTS: Final = (*STAMP_FAULTS, 'mass_clamped')
_NON_FINITE_STAMP, _NON_FINITE_VALUE = 0, 1
_CLAMPED: Final = len(STAMP_FAULTS)

#: The settings in the units the step uses (`mass_grade.mass_params`): the nominal vehicle
#: [kg, m/s^2, kg/m, -, -], the `MassGradeConfig` fields, 1/m bounds [1/kg], the slope bound
#: as a sine and the warm-up time [s].
MASS_PARAMS: Final = np.dtype(
    [
        ('mass', 'f8'),
        ('gravity', 'f8'),
        ('drag', 'f8'),
        ('rolling_c0', 'f8'),
        ('rolling_c1', 'f8'),
        ('mass_tau', 'f8'),
        ('grade_tau', 'f8'),
        ('filter_tau', 'f8'),
        ('noise_density', 'f8'),
        ('std_ratio', 'f8'),
        ('min_speed', 'f8'),
        ('slope_min_speed', 'f8'),
        ('min_accel', 'f8'),
        ('min_force_ratio', 'f8'),
        ('min_change_ratio', 'f8'),
        ('max_force_rate', 'f8'),
        ('theta_min', 'f8'),
        ('theta_max', 'f8'),
        ('converged_std_ratio', 'f8'),
        ('min_excited_time', 'f8'),
        ('use_std_ratio', 'f8'),
        ('max_sine', 'f8'),
        ('max_gap', 'f8'),
        ('warmup', 'f8'),
    ],
    align=True,
)
#: One estimate (`mass_grade.MassGradeEstimate`'s fields).
MASS_OUT: Final = np.dtype(
    [
        ('mass', 'f8'),
        ('mass_std', 'f8'),
        ('converged', 'b1'),
        ('mass_used', 'f8'),
        ('excited', 'b1'),
        ('slope', 'f8'),
        ('slope_valid', 'b1'),
        ('excited_time', 'f8'),
    ],
    align=True,
)
#: The estimator's memory: last stamp (nan: none), the two low-pass stages of F and of v
#: (``lp_on``: started), the grade_tau low-passes of F_lp and y (nan: none), the published
#: slope [rad], excited time and time since the (re)start [s], whether the estimate has
#: converged and whether it is used (``in_use``), 1/m and its variance, the relative variance
#: of the force's scale (``scale_var``, [-]: set by the caller, the estimator's from the
#: radius its Fx used; 0 alone), the last estimate (``has_last``) and the fault counts
#: (`MASS_GRADE_FAULTS` order).
MASS_STATE: Final = np.dtype(
    [
        ('t', 'f8'),
        ('lp_on', 'b1'),
        ('f1', 'f8'),
        ('f2', 'f8'),
        ('v1', 'f8'),
        ('v2', 'f8'),
        ('f_slow', 'f8'),
        ('y_slow', 'f8'),
        ('slope', 'f8'),
        ('excited_time', 'f8'),
        ('running', 'f8'),
        ('converged', 'b1'),
        ('in_use', 'b1'),
        ('theta', 'f8', (1,)),
        ('cov', 'f8', (1, 1)),
        ('scale_var', 'f8'),
        ('has_last', 'b1'),
        ('out', MASS_OUT),
        ('counts', 'i8', (len(MASS_GRADE_FAULTS),)),
    ],
    align=True,
)


@jit
def forgetting_factor(dt: float, tau: float) -> float:
    """Forgetting factor of one step ``dt`` for a memory of ``tau`` seconds.

    Args:
        dt: step, [s], >= 0.
        tau: memory time constant, [s]; ``inf`` (or 0 steps) means no forgetting.

    Returns:
        ``exp(-dt / tau)`` in (0, 1], [-].
    """
    if math.isinf(tau) or dt <= 0.0:
        return 1.0
    return math.exp(-dt / tau)


@jit
def rls_update(
    theta: FloatArray,
    cov: FloatArray,
    phi: FloatArray,
    y: float,
    forgetting: FloatArray,
    noise_var: float,
    update: BoolArray,
) -> None:
    """One recursive-least-squares step (`mass_grade.rls_step`) on ``theta`` (n,) and ``cov``
    (n, n), in place (both are read whole before either is written: pass copies to keep the
    step's inputs).

    Time update ``P <- D P D``, ``D = diag(forgetting)^(-1/2)``; the measurement ``y = phi .
    theta + e``, ``var(e) = noise_var``, corrects only the parameters selected by ``update``
    (a Schmidt update, whose innovation variance still counts the others' uncertainty); the
    covariance update is the Joseph form, so P stays symmetric positive definite.
    """
    n = theta.shape[0]
    d = np.empty(n)
    for i in range(n):
        d[i] = 1.0 / math.sqrt(forgetting[i])
    p = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            p[i, j] = cov[i, j] * (d[i] * d[j])
    th = theta.copy()
    if not update.any():
        theta[:] = th
        cov[:, :] = p
        return
    p_phi = np.zeros(n)
    for i in range(n):
        for j in range(n):
            p_phi[i] += p[i, j] * phi[j]
    phi_p_phi = 0.0
    phi_theta = 0.0
    for i in range(n):
        phi_p_phi += phi[i] * p_phi[i]
        phi_theta += phi[i] * th[i]
    denominator = phi_p_phi + noise_var
    innovation = y - phi_theta
    k = np.zeros(n)
    for i in range(n):
        if update[i]:
            k[i] = p_phi[i] / denominator
    # (I - k phi^T) P (I - k phi^T)^T + noise_var k k^T, then symmetrised
    a = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            a[i, j] = (1.0 if i == j else 0.0) - k[i] * phi[j]
    ap = np.zeros((n, n))
    for i in range(n):
        for j in range(n):
            for m in range(n):
                ap[i, j] += a[i, m] * p[m, j]
    p_new = np.zeros((n, n))
    for i in range(n):
        for j in range(n):
            for m in range(n):
                p_new[i, j] += ap[i, m] * a[j, m]
            p_new[i, j] += noise_var * (k[i] * k[j])
    for i in range(n):
        for j in range(n):
            cov[i, j] = 0.5 * (p_new[i, j] + p_new[j, i])
        theta[i] = th[i] + k[i] * innovation


@jit
def _rls1_bounded(
    s: np.record, phi: float, y: float, lam: float, noise_var: float, lo: float, hi: float
) -> bool:
    """`rls_update` of the one parameter ``s.theta`` (variance ``s.cov``), then clamped to
    [lo, hi]; a non-finite result is dropped. Returns whether the clamp acted."""
    phis = np.full(1, phi)
    lams = np.full(1, lam)
    theta = s.theta.copy()
    cov = s.cov.copy()
    rls_update(theta, cov, phis, y, lams, noise_var, np.ones(1, np.bool_))
    clamped = False
    if math.isfinite(theta[0]) and math.isfinite(cov[0, 0]):
        if not lo <= theta[0] <= hi:
            clamped = True
            theta[0] = min(max(theta[0], lo), hi)
        s.theta[0] = theta[0]
        s.cov[0, 0] = cov[0, 0]
    return clamped


@jit
def mass_reset(p: np.record, s: np.record) -> None:
    """Forget everything: nominal 1/m and prior variance, filters empty (counts stay)."""
    s.t = math.nan
    s.lp_on = False
    s.f_slow = math.nan
    s.y_slow = math.nan
    s.slope = 0.0
    s.excited_time = 0.0
    s.running = 0.0
    s.converged = False
    s.in_use = False
    s.theta[0] = 1.0 / p.mass
    sigma = p.std_ratio / p.mass  # d(1/m) = dm / m^2
    s.cov[0, 0] = sigma * sigma
    s.scale_var = 0.0
    s.has_last = False


@jit
def _mass_std(s: np.record) -> float:
    """[kg] the mass's standard deviation: the regression's (delta method, d(1/m) = dm/m^2)
    and the force scale's (``s.scale_var``, relative), independent. The regression learns
    m/F's scale: a force 3 % off (the radius not known yet) is a mass 3 % off, whatever
    the excitation, so convergence needs the force's scale known as well."""
    theta = s.theta[0]
    regression = max(s.cov[0, 0], 0.0) / (theta * theta * theta * theta)
    return math.sqrt(regression + s.scale_var / (theta * theta))


@jit
def _mass_out(p: np.record, s: np.record, excited: bool, valid: bool) -> None:
    """The estimate of the state into ``s.out``."""
    theta = s.theta[0]
    mass = 1.0 / theta
    o = s.out
    o.mass = mass
    o.mass_std = _mass_std(s)
    o.converged = s.converged
    o.mass_used = mass if s.in_use else p.mass
    o.excited = excited
    o.slope = s.slope
    o.slope_valid = valid
    o.excited_time = s.excited_time


@jit
def mass_held(p: np.record, s: np.record) -> None:
    """``s.out`` as `MassGradeEstimator.current`: the last estimate, or the fresh one."""
    if not s.has_last:
        _mass_out(p, s, False, False)


@jit
def mass_update(p: np.record, s: np.record, t: float, sum_fx: float, speed: float) -> bool:
    """One stamp (`mass_grade.MassGradeEstimator.update`) into ``s.out``.

    Args:
        p: `MASS_PARAMS` record.
        s: `MASS_STATE` record; its fault counts are incremented.
        t: stamp [s].
        sum_fx: sum of the four tyre longitudinal forces [N].
        speed: body speed [m/s].

    Returns:
        Whether the stamp was accepted (else ``s.out`` is the held estimate).
    """
    if not (math.isfinite(sum_fx) and math.isfinite(speed)):
        s.counts[_NON_FINITE_VALUE if math.isfinite(t) else _NON_FINITE_STAMP] += 1
        mass_held(p, s)
        return False
    kind, dt = stamp_step(s.t, t, p.max_gap)
    if kind >= 0:
        s.counts[kind] += 1
    if math.isnan(dt):
        mass_held(p, s)
        return False
    if kind >= 0:  # a gap or a jump back: start again from this sample
        mass_reset(p, s)
    s.t = t
    g = p.gravity
    weight = p.mass * g
    direction = 1.0 if speed >= 0.0 else -1.0
    force = sum_fx - direction * p.drag * speed * speed
    # F and v through the same two first-order stages (the estimator's slope filter);
    # dv/dt is the backward difference of the filtered speed.
    if dt == 0.0 or not s.lp_on:
        s.lp_on = True
        f1, f2, v1, v2 = force, force, speed, speed
        accel = 0.0
        force_rate = 0.0
    else:
        w = 1.0 if p.filter_tau <= 0.0 else -math.expm1(-dt / p.filter_tau)
        f1 = s.f1 + w * (force - s.f1)
        f2 = s.f2 + w * (f1 - s.f2)
        v1 = s.v1 + w * (speed - s.v1)
        v2 = s.v2 + w * (v1 - s.v2)
        accel = (v2 - s.v2) / dt
        force_rate = (f2 - s.f2) / dt
    s.f1, s.f2, s.v1, s.v2 = f1, f2, v1, v2
    f_lp, v_lp = f2, v2
    c_r = rolling_coefficient_at(p.rolling_c0, p.rolling_c1, v_lp)
    y = accel + direction * g * c_r * math.cos(s.slope)
    # The high-pass removes a grade that is constant over grade_tau (same on both sides).
    if dt == 0.0 or math.isnan(s.f_slow):
        f_slow, y_slow = f_lp, y
    else:
        w_slow = -math.expm1(-dt / p.grade_tau)
        f_slow = s.f_slow + w_slow * (f_lp - s.f_slow)
        y_slow = s.y_slow + w_slow * (y - s.y_slow)
    s.f_slow, s.y_slow = f_slow, y_slow
    f_hp = f_lp - f_slow
    y_hp = y - y_slow
    s.running += dt
    excited = (
        dt > 0.0
        and s.running >= p.warmup
        and abs(speed) >= p.min_speed
        and (abs(accel) >= p.min_accel or abs(f_lp) >= p.min_force_ratio * weight)
        and abs(f_hp) >= p.min_change_ratio * weight
        and abs(force_rate) <= p.max_force_rate * weight
    )
    if excited:
        lam = forgetting_factor(dt, p.mass_tau)
        noise_var = p.noise_density * p.noise_density / dt
        if _rls1_bounded(s, f_hp, y_hp, lam, noise_var, p.theta_min, p.theta_max):
            s.counts[_CLAMPED] += 1
        s.excited_time += dt
        theta = s.theta[0]
        std = _mass_std(s)
        if s.excited_time >= p.min_excited_time and std * theta <= p.converged_std_ratio:
            s.converged = True
        if s.converged or std * theta <= p.use_std_ratio:
            s.in_use = True
    valid = False
    if abs(speed) >= p.slope_min_speed:
        m_used = 1.0 / s.theta[0] if s.in_use else p.mass
        sine = (f_lp / m_used - y) / g
        bound = p.max_sine
        s.slope = math.asin(min(max(sine, -bound), bound))
        valid = abs(sine) <= bound
    _mass_out(p, s, excited, valid)
    s.has_last = True
    return True


@jit
def mass_rescale(p: np.record, s: np.record, ratio: float) -> bool:
    """The force fed from now on is ``ratio`` times what it was (`MassGradeEstimator.
    rescale_force`): 1/m and the filters' force states follow. Returns whether the rescaled
    1/m had to be clamped (nothing changes before the first excited stamp)."""
    if s.excited_time <= 0.0:
        return False
    theta = s.theta[0] / ratio
    clamped = not p.theta_min <= theta <= p.theta_max
    s.theta[0] = min(max(theta, p.theta_min), p.theta_max)
    s.cov[0, 0] = s.cov[0, 0] / (ratio * ratio)
    if s.lp_on:
        s.f1 *= ratio
        s.f2 *= ratio
    if not math.isnan(s.f_slow):
        s.f_slow *= ratio
    return clamped
