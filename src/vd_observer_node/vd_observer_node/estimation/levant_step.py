"""Levant's robust exact differentiator, one sample at a time: its only implementation.

Continuous-time recursive form (Levant 2003; the paper's eq. 2 in standard form), for a
signal f whose third derivative is bounded by L (|f'''| <= L):

    v0  = z1 - l0 * L^(1/3) * |z0 - f|^(2/3) * sign(z0 - f),   z0' = v0
    v1  = z2 - l1 * L^(1/2) * |z1 - v0|^(1/2) * sign(z1 - v0), z1' = v1
    z2' = -l2 * L * sign(z2 - v1)

z0, z1, z2 estimate f, f', f''. The gains are named in the paper's order (l0 on the first
equation; `differentiator.LevantGains`). Substituting the recursion gives the equivalent
non-recursive form

    z0' = -k0 * L^(1/3) * |e|^(2/3) sign(e) + z1
    z1' = -k1 * L^(2/3) * |e|^(1/3) sign(e) + z2,      e = z0 - f
    z2' = -k2 * L * sign(e)

with k0 = l0, k1 = l1 * sqrt(l0), k2 = l2.

Discretizations, all driven by the actual time step tau = t_{k+1} - t_k:

* ``'euler'`` (`euler_step`): explicit (forward) Euler of the recursive form, z_{k+1} = z_k +
  tau * F(z_k, f_k). The sample f_{k+1} only enters at the following step (an error of order
  tau * |f'''|, within the differentiator's own accuracy bound mu * L * tau). Without noise
  the discrete sign term makes z2 chatter with an amplitude of about k2 * L * tau.
* ``'euler_taylor'``: the same with the Taylor term tau^2/2 * z2 in z0 (Livne & Levant,
  Automatica 50(8), 2014), which restores the accuracy |z_i - f^(i)| = O(L * tau^(3 - i)).
* ``'implicit'`` (`implicit_step`): implicit (backward) Euler of the non-recursive form, solved
  exactly with the set-valued sign, after Mojallizadeh, Brogliato and Acary, Int. J. Robust
  Nonlinear Control 31(16), 2021 (and Brogliato, Polyakov, Efimov, IEEE TAC 65(8), 2020). The
  step reduces to a scalar monotone equation in the new error e = z0_{k+1} - f_{k+1}: either
  e = 0 exactly or a cubic in |e|^(1/3) with a unique positive root. It uses f_{k+1}, so its
  output is the estimate FOR t_{k+1}, without discretization chattering.

**Samples of the first derivative** (``input_derivative`` 1, e.g. ABS wheel speeds): rows 1
and 2 run Levant's first-order (super-twisting) differentiator on g = f' with the gains
(l1, l2), L bounding |g''| = |f'''|:

    z1' = -l1 * L^(1/2) * |e|^(1/2) * sign(e) + z2,   z2' = -l2 * L * sign(e),   e = z1 - g

and row 0 integrates z1 with the trapezoid rule (from 0 at the initialisation). Its implicit
step (`first_order_implicit_step`) reduces to a quadratic in |e|^(1/2); inside its band it is
the backward difference of g, exact for a linear g.

The step functions are compiled with numba (`vd_observer_node.kernel._jit.jit`) and run as
plain Python with ``VD_JIT=0``. They work on numpy records with named fields:

* parameters: one record of `PARAMS_DTYPE` (`differentiator.levant_params` builds it), plus
  the bounds L per channel as a float array (n,);
* state: one record of `STATE_DTYPE` (stamp, fault counters) and a record array (n,) of
  `CHANNEL_DTYPE` (per channel: the estimates z = (f, f', f''), the last sample, the
  initialisation's bookkeeping, the resolution learnt).

**L following the resolution** (``PARAMS_DTYPE.follow_resolution``, the wheel angles' default):
each channel notes the smallest non-zero change between consecutive samples (an encoder's
step; for exact angles, a tiny one at the first slow roll) and steps with
`followed_lipschitz` of it instead of its given L, which is then the floor. The same samples
in the same order give the same L live and offline, at the same stamp.

`levant_update` is one stamp of `differentiator.LevantDifferentiator` (every fault rule and
counter); the per-channel steps `euler_step`, `implicit_step`, `first_order_euler_step`,
`first_order_implicit_step` (dispatched by `levant_step`) are its pure math, on z of shape
(3,), returning the new (z0, z1, z2).
"""

from __future__ import annotations

import math
from typing import Any, Final, NamedTuple

import numpy as np
from numpy.typing import NDArray

from vd_observer_node.estimation.faults import OBSERVER_FAULTS
from vd_observer_node.kernel._jit import jit

__all__ = [
    'CHANNEL_DTYPE',
    'DISCRETIZATIONS',
    'FOLLOW_MAX_RATIO',
    'INIT_POLICIES',
    'INPUT_DERIVATIVES',
    'PARAMS_DTYPE',
    'RESOLUTION_REFERENCE',
    'STATE_DTYPE',
    'LevantParts',
    'euler_step',
    'first_order_euler_step',
    'first_order_implicit_step',
    'followed_lipschitz',
    'implicit_step',
    'levant_held',
    'levant_reset',
    'levant_step',
    'levant_update',
    'levant_update_arrays',
    'new_channels',
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: Allowed discretization names; a record holds the index (``PARAMS_DTYPE.discretization``).
DISCRETIZATIONS: Final = ('euler', 'euler_taylor', 'implicit')
#: Allowed initialisation policies (see `differentiator.LevantDifferentiator`), as indexes.
INIT_POLICIES: Final = ('finite_difference', 'first_sample', 'zero')
#: Which derivative of f the samples are: 0 = f itself, 1 = f' (see the module docstring).
INPUT_DERIVATIVES: Final = (0, 1)

# the codes the compiled functions compare with (numba bakes module constants in)
_EULER_TAYLOR: Final = DISCRETIZATIONS.index('euler_taylor')
_IMPLICIT: Final = DISCRETIZATIONS.index('implicit')
_INIT_FIRST: Final = INIT_POLICIES.index('first_sample')
_INIT_ZERO: Final = INIT_POLICIES.index('zero')
_NEWTON_MAX_ITER: Final = 60
_NEWTON_RTOL: Final = 1e-13

#: Settings of one differentiator: the gains (recursive l0..l2, non-recursive k0..k2 [-]),
#: the discretization and init policy (indexes into `DISCRETIZATIONS`, `INIT_POLICIES`), the
#: gap [s] that re-initialises, the finite-difference baseline [s], the jump back [s] that
#: resets, and which derivative of f the samples are.
PARAMS_DTYPE: Final = np.dtype(
    [
        ('l0', 'f8'), ('l1', 'f8'), ('l2', 'f8'), ('k0', 'f8'), ('k1', 'f8'), ('k2', 'f8'),
        ('discretization', 'i8'), ('init', 'i8'), ('max_gap', 'f8'), ('init_baseline', 'f8'),
        ('max_jump_back', 'f8'), ('input_derivative', 'i8'), ('follow_resolution', 'b1'),
    ],
    align=True,
)  # fmt: skip
#: What one differentiator remembers besides its channels: the stamp of the last accepted
#: sample [s] (nan before the first), whether every channel is initialised, and the count of
#: every `faults.OBSERVER_FAULTS` kind (fields named as the kinds) and of rejected samples.
STATE_DTYPE: Final = np.dtype(
    [('t', 'f8'), ('all_active', 'b1')]
    + [(kind, 'i8') for kind in OBSERVER_FAULTS]
    + [('rejected', 'i8')],
    align=True,
)
#: One channel's memory: the estimates z = (f, f', f''), the sample at the current stamp
#: (nan where missing; the explicit steps correct with it), initialised or not, the first
#: sample (stamp [s], value) of a 'finite_difference' initialisation (nan: none yet), and,
#: where L follows the resolution, the smallest non-zero change between consecutive samples
#: seen so far [unit] (0: none yet) and the L it gives [unit / s^3] (0: the floor).
CHANNEL_DTYPE: Final = np.dtype(
    [
        ('z', 'f8', (3,)), ('f_last', 'f8'), ('active', 'b1'), ('pend_t', 'f8'), ('pend_f', 'f8'),
        ('resolution', 'f8'), ('lipschitz', 'f8'),
    ],
    align=True,
)  # fmt: skip
#: [rad] the resolution the wheel angles' L floor (`ObserverConfig.wheel_lipschitz`, 300) was
#: chosen for: a 96 counts/rev encoder; finer samples raise L (`followed_lipschitz`)
RESOLUTION_REFERENCE: Final = 2.0 * math.pi / 96.0
#: the most a fine resolution raises L above its floor
FOLLOW_MAX_RATIO: Final = 10.0
# a resolution within this of the reference keeps the floor bit for bit (a 96-count encoder's
# steps differ from 2 pi / 96 in the last bits)
_FOLLOW_SLACK: Final = 1e-6


def new_channels(n: int) -> np.recarray[tuple[int], np.dtype[np.record]]:
    """A zeroed record array (n,) of `CHANNEL_DTYPE` (``channels[i].z`` is a view)."""
    return np.zeros(n, CHANNEL_DTYPE).view(np.recarray)


class LevantParts(NamedTuple):
    """One differentiator's records and arrays, as the compiled loops take them
    (`differentiator.LevantDifferentiator.parts`): params and state as the 1-element arrays
    they live in (numba types arrays on its fast path), the Lipschitz constants per channel,
    and the per-channel records as a plain structured array (a recarray's attributes are
    Python lookups).

    Attributes:
        params: shape (1,), `PARAMS_DTYPE`.
        lipschitz: shape (n,), [input units / s^(order)] per channel.
        state: shape (1,), `STATE_DTYPE`.
        channels: shape (n,), `CHANNEL_DTYPE`.
    """

    params: NDArray[Any]
    lipschitz: FloatArray
    state: NDArray[Any]
    channels: Any  # a plain structured array; `levant_update` types it as a recarray


@jit
def _sign(x: float) -> float:
    """np.sign of a float: 1, -1, or x itself for 0.0 and nan."""
    if x > 0.0:
        return 1.0
    if x < 0.0:
        return -1.0
    return x


@jit
def _positive_cubic_root(a: float, b: float, c: float) -> float:
    """Unique root y >= 0 of y^3 + a*y^2 + b*y = c for c >= 0, a, b > 0.

    With p = b - a^2/3 > 0 (true for the default gains) the cubic is increasing on the whole
    real line, so Cardano's formula gives its only real root; two Newton steps then remove
    the cancellation of y = x - a/3 for small c. Otherwise Newton from the upper bound
    min(cbrt(c), c / b) converges monotonically (the polynomial is convex for y >= 0).
    C library cbrt and pow throughout: numpy's vectorised ones differ in the last bit on
    some CPUs, which the implicit step would amplify by 1/tau^2 in f''.
    """
    if not c > 0.0:
        return 0.0  # inside the band: the common, converged case
    p = b - a * a / 3.0
    if p > 0.0:
        q = 2.0 * (a * a * a) / 27.0 - a * b / 3.0 - c
        root = math.sqrt(0.25 * q * q + (p * p * p) / 27.0)
        y = max(np.cbrt(-0.5 * q + root) + np.cbrt(-0.5 * q - root) - a / 3.0, 0.0)
        for _ in range(2):
            residual = ((y + a) * y + b) * y - c
            y = max(y - residual / ((3.0 * y + 2.0 * a) * y + b), 0.0)
        return float(y)
    y = min(np.cbrt(c), c / b)
    for _ in range(_NEWTON_MAX_ITER):
        residual = ((y + a) * y + b) * y - c
        y_next = max(y - residual / ((3.0 * y + 2.0 * a) * y + b), 0.0)
        converged = abs(y_next - y) <= _NEWTON_RTOL * max(y_next, 1e-300)
        y = y_next
        if converged:
            break
    return float(y)


@jit
def euler_step(
    p: np.record, z: FloatArray, f: float, tau: float, lip: float, taylor: bool
) -> tuple[float, float, float]:
    """One explicit-Euler step of the recursive differentiator.

    Args:
        p: `PARAMS_DTYPE` record (the gains l0, l1, l2).
        z: shape (3,), (f, f', f'') estimates at t_k [unit / s^i].
        f: sample at the START of the step, t_k.
        tau: step t_{k+1} - t_k [s], > 0.
        lip: L, bound on |f'''| [unit / s^3], > 0.
        taylor: add the Taylor term tau^2/2 * z2 to z0 ('euler_taylor').

    Returns:
        (z0, z1, z2) at t_{k+1}.
    """
    e0 = z[0] - f
    v0 = z[1] - p.l0 * np.cbrt(lip) * (_sign(e0) * math.pow(abs(e0), 2.0 / 3.0))
    d1 = z[1] - v0
    v1 = z[2] - p.l1 * math.sqrt(lip) * (_sign(d1) * math.sqrt(abs(d1)))
    z0 = z[0] + tau * v0
    if taylor:
        z0 += 0.5 * (tau * tau) * z[2]
    return z0, z[1] + tau * v1, z[2] + tau * (-p.l2 * lip * _sign(z[2] - v1))


@jit
def implicit_step(
    p: np.record, z: FloatArray, f_next: float, tau: float, lip: float
) -> tuple[float, float, float]:
    """One implicit step of the non-recursive differentiator, solved exactly.

    The state is propagated with the exact transition Phi(tau) of the chain of integrators
    (the Taylor terms of Livne & Levant 2014) and the output injections are evaluated at the
    NEW error e = z0_{k+1} - f_{k+1}, with the set-valued sign (Mojallizadeh, Brogliato,
    Acary 2021; Brogliato, Polyakov, Efimov 2020):

        z2+ = z2 - tau*k2*L*s,                                              s in Sign(e)
        z1+ = z1 + tau*z2 - 1.5*tau^2*k2*L*s - tau*k1*L^(2/3)*|e|^(1/3) sign(e)
        z0+ = f_{k+1} + e

    with the scalar equation for e, writing w = z0 + tau*z1 + tau^2/2*z2 - f_{k+1} (error
    of the open-loop Taylor prediction) and |e| = tau^3*L*y^3:

        e + tau^3*L*(k0*y^2 + k1*y + k2*s) = w.

    If |w| <= k2*tau^3*L then e = 0 and s = w/(k2*tau^3*L) in [-1, 1]; else y > 0 is the
    unique positive root of a cubic. The weights (tau^3, 1.5*tau^2, tau) with which the sign
    term enters (z0, z1, z2) are this module's choice: they make the linear dynamics inside
    the band dead-beat (both remaining error eigenvalues 0), so a signal with constant f''
    is reproduced exactly two steps after the error enters the band, with no chattering.
    (Injecting Phi(tau) times the continuous-time vector, (tau^3/2, tau^2, tau), leaves an
    undamped period-2 oscillation in the band instead.)

    Args:
        p: `PARAMS_DTYPE` record (the gains k0, k1, k2).
        z: shape (3,), state at t_k.
        f_next: sample at the END of the step, t_{k+1}.
        tau: step [s], > 0.
        lip: L [unit / s^3], > 0.

    Returns:
        (z0, z1, z2) at t_{k+1}: the estimate for stamp t_{k+1}.
    """
    k0, k1, k2 = p.k0, p.k1, p.k2
    tau2 = tau * tau  # integer powers as products: the same bits compiled and in Python
    scale = tau2 * tau * lip
    w = z[0] + tau * z[1] + 0.5 * tau2 * z[2] - f_next
    s = _sign(w)
    excess = max(abs(w) / scale - k2, 0.0)
    y = _positive_cubic_root(k0, k1, excess)
    # inside the band the multivalued sign takes the value that zeroes the error exactly
    sign_value = s if excess > 0.0 else w / (scale * k2)
    z2 = z[2] - tau * k2 * lip * sign_value
    z1 = z[1] + tau * z[2] - 1.5 * tau2 * k2 * lip * sign_value - s * k1 * tau2 * lip * y
    return f_next + s * scale * (y * y * y), z1, z2


@jit
def first_order_euler_step(
    p: np.record, z: FloatArray, g: float, tau: float, lip: float, taylor: bool
) -> tuple[float, float, float]:
    """One explicit step of the first-order differentiator on samples g of f'.

    Args:
        p: `PARAMS_DTYPE` record (l1, l2 are the first-order gains).
        z: shape (3,), state (f, f', f'') at t_k; z1, z2 are the differentiator's.
        g: sample of f' at the START of the step, t_k.
        tau: step [s], > 0.
        lip: L, bound on |g''| = |f'''| [unit / s^3], > 0.
        taylor: add the Taylor term tau^2/2 * z2 to z1 (Livne & Levant 2014).

    Returns:
        (z0, z1, z2) at t_{k+1} (z0: trapezoid integral of z1).
    """
    e = z[1] - g
    v = z[2] - p.l1 * math.sqrt(lip) * (_sign(e) * math.sqrt(abs(e)))
    z1 = z[1] + tau * v
    if taylor:
        z1 = z1 + 0.5 * (tau * tau) * z[2]
    z2 = z[2] - tau * (p.l2 * lip * _sign(e))
    return z[0] + 0.5 * tau * (z[1] + z1), z1, z2


@jit
def first_order_implicit_step(
    p: np.record, z: FloatArray, g_next: float, tau: float, lip: float
) -> tuple[float, float, float]:
    """One implicit step of the first-order differentiator on samples g of f', solved exactly.

    With a = l1, b = l2, the new error e = z1_{k+1} - g_{k+1} and s in Sign(e):

        z2+ = z2 - tau*b*L*s,   z1+ = z1 + tau*z2+ - tau*a*L^(1/2)*|e|^(1/2) sign(e)

    Writing w = z1 + tau*z2 - g_{k+1} and |e| = tau^2*L*y^2 this is e + tau^2*L*(a*y + b*s)
    = w: if |w| <= b*tau^2*L then e = 0 and s = w/(b*tau^2*L) (z2+ is then the backward
    difference of g when z1 = g_k), else y > 0 solves y^2 + a*y = |w|/(tau^2*L) - b.

    Args:
        p: `PARAMS_DTYPE` record (l1, l2 are the first-order gains).
        z: shape (3,), state at t_k; z1, z2 are the differentiator's.
        g_next: sample of f' at the END of the step, t_{k+1}.
        tau: step [s], > 0.
        lip: L [unit / s^3], > 0.

    Returns:
        (z0, z1, z2) at t_{k+1} (z0: trapezoid integral of z1).
    """
    a, b = p.l1, p.l2
    scale = (tau * tau) * lip
    w = z[1] + tau * z[2] - g_next
    s = _sign(w)
    excess = max(abs(w) / scale - b, 0.0)
    # the root of y^2 + a*y = excess in the form without cancellation for small excess
    y = 2.0 * excess / (a + math.sqrt(a * a + 4.0 * excess))
    sign_value = s if excess > 0.0 else w / (scale * b)
    z1 = g_next + s * scale * (y * y)
    return z[0] + 0.5 * tau * (z[1] + z1), z1, z[2] - tau * b * lip * sign_value


@jit
def levant_step(
    p: np.record, z: FloatArray, f: float, tau: float, lip: float
) -> tuple[float, float, float]:
    """One step of the discretization and input derivative `p` names.

    ``f`` is the sample the scheme corrects with: at the start of the step (t_k) for the
    explicit schemes, at its end (t_{k+1}) for the implicit one. Arguments as `euler_step`.
    """
    code = p.discretization
    if p.input_derivative == 1:
        if code == _IMPLICIT:
            return first_order_implicit_step(p, z, f, tau, lip)
        return first_order_euler_step(p, z, f, tau, lip, code == _EULER_TAYLOR)
    if code == _IMPLICIT:
        return implicit_step(p, z, f, tau, lip)
    return euler_step(p, z, f, tau, lip, code == _EULER_TAYLOR)


@jit
def followed_lipschitz(floor: float, resolution: float) -> float:
    """L for samples of this resolution: the floor times sqrt(reference / resolution), at
    most `FOLLOW_MAX_RATIO` times the floor, never below it.

    With measurement noise of amplitude eps, the differentiator's error in f' grows as
    L^(1/3) eps^(2/3) (Levant 2003), while too small an L leaves it behind wherever |f'''|
    exceeds L (a torque step, a gear shift); the sum is smallest for L ~ eps^(-1/2). The
    quantisation step of an encoder is that eps; `RESOLUTION_REFERENCE` and the floor are the
    96-count encoder and the L tuned for it. Measured on paper_table1 at 1 kHz (docs/
    estimation.md, "The wheel L follows the resolution"): the omega-optimal L is 300, about
    1000 and about 3000 for 96, 1024 and 8192 counts/rev, as this law gives; ideal angles
    take the cap.

    Args:
        floor: L without a finer resolution [unit / s^3], > 0.
        resolution: smallest non-zero change between consecutive samples [unit]; <= 0 or
            nan: unknown (the floor).

    Returns:
        [unit / s^3].
    """
    if not resolution > 0.0:
        return floor
    ratio = math.sqrt(RESOLUTION_REFERENCE / resolution)
    if ratio <= 1.0 + _FOLLOW_SLACK:
        return floor
    return floor * min(ratio, FOLLOW_MAX_RATIO)


@jit
def _follow_resolution(lip: FloatArray, channels: np.recarray, sample: FloatArray) -> None:
    """Note each channel's change since its last sample; a smaller non-zero one than seen
    so far sets the channel's resolution and the L it follows (`followed_lipschitz`)."""
    for i in range(channels.shape[0]):
        c = channels[i]
        step = abs(sample[i] - c.f_last)  # nan where either sample is missing
        if step > 0.0 and (c.resolution == 0.0 or step < c.resolution):
            c.resolution = step
            c.lipschitz = followed_lipschitz(lip[i], step)


@jit
def levant_reset(p: np.record, s: np.record, channels: np.recarray) -> None:
    """Forget all history (the fault counters stay, and so does the resolution each channel
    learnt: a property of the sensor, not of the drive).

    Args:
        p: `PARAMS_DTYPE` record.
        s: `STATE_DTYPE` record, reset in place.
        channels: (n,) `CHANNEL_DTYPE` records, reset in place.
    """
    zero_init = p.init == _INIT_ZERO
    s.t = math.nan
    s.all_active = zero_init
    for i in range(channels.shape[0]):
        c = channels[i]
        c.z[:] = 0.0
        c.f_last = math.nan
        c.active = zero_init
        c.pend_t = math.nan
        c.pend_f = math.nan


@jit
def _adopt(
    p: np.record, channels: np.recarray, t: float, sample: FloatArray, finite: BoolArray
) -> None:
    """Initialise the channels that are not active yet from this sample."""
    row = p.input_derivative  # the row the samples estimate; rows below it start from 0
    for i in range(channels.shape[0]):
        c = channels[i]
        if not finite[i] or c.active:
            continue
        if p.init == _INIT_FIRST:
            c.z[:] = 0.0
            c.z[row] = sample[i]
            c.active = True
        elif math.isnan(c.pend_t):
            c.pend_t = t
            c.pend_f = sample[i]
            c.z[row] = sample[i]
        elif t - c.pend_t >= p.init_baseline:
            c.z[:] = 0.0
            c.z[row] = sample[i]
            c.z[row + 1] = (sample[i] - c.pend_f) / (t - c.pend_t)
            c.active = True
        else:
            c.z[row] = sample[i]


@jit
def _all_active(channels: np.recarray) -> bool:
    for i in range(channels.shape[0]):  # noqa: SIM110  # a loop numba compiles
        if not channels[i].active:
            return False
    return True


@jit
def _write_output(channels: np.recarray, out: FloatArray) -> None:
    for i in range(channels.shape[0]):
        z = channels[i].z
        out[0, i] = z[0]
        out[1, i] = z[1]
        out[2, i] = z[2]


@jit
def _rejected(channels: np.recarray, out: FloatArray, valid: BoolArray) -> None:
    _write_output(channels, out)
    valid[:] = False


@jit
def levant_held(channels: np.recarray, out: FloatArray, valid: BoolArray) -> None:
    """The estimates of the last stamp fed, again, where a stamp brings no new sample.

    Args:
        channels: (n,) `CHANNEL_DTYPE` records (unchanged).
        out: shape (3, n), written: (f, f', f'') at the last stamp fed.
        valid: shape (n,), written: what `levant_update` said at the last stamp it took (a
            channel initialised whose sample was finite).
    """
    _write_output(channels, out)
    for i in range(channels.shape[0]):
        c = channels[i]
        valid[i] = c.active and math.isfinite(c.f_last)


@jit
def levant_update(
    p: np.record,
    lip: FloatArray,
    s: np.record,
    channels: np.recarray,
    t: float,
    sample: FloatArray,
    out: FloatArray,
    valid: BoolArray,
) -> None:
    """Feed the samples at stamp t; write the estimates for t and their validity.

    Invalid input never poisons the state (each case counted in its field of `s`):

    * a non-finite stamp, a duplicate stamp or one older than the last by at most
      ``p.max_jump_back`` is rejected (state unchanged; also counted in ``s.rejected``);
    * a stamp older by more (a looped bag) resets and starts again from this sample
      ('time_jump_back'); a gap longer than ``p.max_gap`` re-initialises ('gap');
    * a non-finite sample of one channel makes that channel coast open loop for the step
      ('non_finite_value', its ``valid`` False);
    * a step whose state overflows resets the state ('non_finite_output').

    Args:
        p: `PARAMS_DTYPE` record.
        lip: shape (n,), L per channel [unit / s^3].
        s: `STATE_DTYPE` record, advanced in place.
        channels: (n,) `CHANNEL_DTYPE` records, advanced in place.
        t: stamp [s].
        sample: shape (n,), the samples (f, or f' with ``p.input_derivative`` 1).
        out: shape (3, n), written: the estimates (f, f', f'') for t.
        valid: shape (n,), written: False where a channel is not initialised or its sample
            was rejected (its outputs are then an open-loop prediction).
    """
    n = channels.shape[0]
    if not math.isfinite(t):
        s.non_finite_stamp += 1
        s.rejected += 1
        _rejected(channels, out, valid)
        return
    if not math.isnan(s.t):
        if t <= s.t:
            if s.t - t <= p.max_jump_back:
                if t == s.t:
                    s.duplicate_stamp += 1
                else:
                    s.out_of_order += 1
                s.rejected += 1
                _rejected(channels, out, valid)
                return
            s.time_jump_back += 1
            levant_reset(p, s, channels)
        elif t - s.t > p.max_gap:
            s.gap += 1
            levant_reset(p, s, channels)
    finite = np.empty(n, dtype=np.bool_)
    all_finite = True
    for i in range(n):
        finite[i] = math.isfinite(sample[i])
        all_finite = all_finite and finite[i]
    if not all_finite:
        s.non_finite_value += 1
    if math.isnan(s.t):
        if p.init != _INIT_ZERO:
            _adopt(p, channels, t, sample, finite)
            s.all_active = _all_active(channels)
    else:
        tau = t - s.t
        implicit = p.discretization == _IMPLICIT
        follow = p.follow_resolution
        if follow:
            _follow_resolution(lip, channels, sample)
        for i in range(n):
            c = channels[i]
            if not c.active:
                continue
            z = c.z
            # the explicit schemes correct with the sample at the start of the step
            f = sample[i] if implicit else c.f_last
            if math.isfinite(f):
                lip_i = c.lipschitz if follow and c.lipschitz > 0.0 else lip[i]
                z0, z1, z2 = levant_step(p, z, f, tau, lip_i)
            else:  # no sample: the open-loop Taylor prediction
                z0 = z[0] + tau * z[1] + 0.5 * (tau * tau) * z[2]
                z1 = z[1] + tau * z[2]
                z2 = z[2]
            z[0] = z0
            z[1] = z1
            z[2] = z2
        if not s.all_active:
            _adopt(p, channels, t, sample, finite)
            s.all_active = _all_active(channels)
    for i in range(n):
        z = channels[i].z
        if not (math.isfinite(z[0]) and math.isfinite(z[1]) and math.isfinite(z[2])):
            # overflow from absurd (finite) input: start again rather than emit inf or nan
            s.non_finite_output += 1
            levant_reset(p, s, channels)
            _rejected(channels, out, valid)
            return
    s.t = t
    for i in range(n):
        c = channels[i]
        c.f_last = sample[i] if finite[i] else math.nan
        valid[i] = finite[i] and c.active
    _write_output(channels, out)


@jit
def levant_update_arrays(
    p_a: np.ndarray,
    lip: FloatArray,
    s_a: np.ndarray,
    channels: np.recarray,
    t: float,
    sample: FloatArray,
    out: FloatArray,
    valid: BoolArray,
) -> None:
    """`levant_update` with its two records as the 1-element arrays they live in
    (`kernel._jit.record_array`): what the wrapper calls once a sample, as numba types arrays
    on its fast path and records not."""
    levant_update(p_a[0], lip, s_a[0], channels, t, sample, out, valid)
