"""Levant's second-order robust exact differentiator, sampled at irregular time steps.

Continuous-time recursive form (Levant 2003; the paper's eq. 2 in standard form), for a
signal f whose third derivative is bounded by L (|f'''| <= L):

    v0  = z1 - l0 * L^(1/3) * |z0 - f|^(2/3) * sign(z0 - f),   z0' = v0
    v1  = z2 - l1 * L^(1/2) * |z1 - v0|^(1/2) * sign(z1 - v0), z1' = v1
    z2' = -l2 * L * sign(z2 - v1)

z0, z1, z2 estimate f, f', f''. The gains here are named in the paper's order (l0 on the
first equation). The default set (l0, l1, l2) = (2.0, 1.5, 1.1) is Levant's published
sequence {1.1, 1.5, 2, 3, 5, 8} for n = 2 (Levant, Int. J. Control 76(9/10), 2003, where
it is indexed the other way round: lambda_2 = 2 on the first equation, lambda_0 = 1.1 on
the last). Substituting the recursion gives the equivalent non-recursive form

    z0' = -k0 * L^(1/3) * |e|^(2/3) sign(e) + z1
    z1' = -k1 * L^(2/3) * |e|^(1/3) sign(e) + z2,      e = z0 - f
    z2' = -k2 * L * sign(e)

with k0 = l0, k1 = l1 * sqrt(l0) (= 2.12), k2 = l2: the set (2, 2.12, 1.1) tabulated by
Levant and Livne for n = 2.

Two discretizations, both driven by the actual time step tau = t_{k+1} - t_k:

* ``'euler'``: explicit (forward) Euler of the recursive form, z_{k+1} = z_k + tau * F(z_k,
  f_k). The sample f_{k+1} only enters at the following step, so the output at t_{k+1} is
  one sample late in its use of data (an error of order tau * |f'''|, within the
  differentiator's own accuracy bound mu * L * tau). In the absence of noise the discrete
  sign term makes z2 chatter with an amplitude of about k2 * L * tau.
* ``'implicit'``: implicit (backward) Euler of the non-recursive form, solved exactly with
  the set-valued sign, after Mojallizadeh, Brogliato and Acary, "Time-discretizations of
  differentiators: design of implicit algorithms and comparative analysis", Int. J. Robust
  Nonlinear Control 31(16), 2021 (and Brogliato, Polyakov, Efimov, IEEE TAC 65(8), 2020 for
  the super-twisting case). The step reduces to a scalar monotone equation in the new
  error e = z0_{k+1} - f_{k+1}: either e = 0 exactly (the sign takes a value inside
  [-1, 1]) or a cubic in |e|^(1/3) with a unique positive root. It uses f_{k+1}, so its
  output is the estimate FOR t_{k+1}, and it has no discretization chattering: for a
  signal with constant f'' the error becomes exactly zero in finite time.

`euler_step` and `implicit_step` are pure functions on a state of shape (3, n) (n
channels, e.g. the four wheels); `LevantDifferentiator` wraps them with time keeping,
initialisation and rejection of invalid samples.

**Samples of the first derivative** (``input_derivative=1``, e.g. wheel speeds from ABS
sensors instead of wheel angles): rows 1 and 2 of the same state run Levant's FIRST-order
differentiator (the super-twisting differentiator) on the samples g = f', with the last two
gains of the same sequence, (l1, l2) = (1.5, 1.1), and L bounding |g''| = |f'''| as before:

    z1' = -l1 * L^(1/2) * |e|^(1/2) * sign(e) + z2,   z2' = -l2 * L * sign(e),   e = z1 - g

and row 0 integrates z1 with the trapezoid rule (from 0 at the initialisation: an estimate of
f up to its unknown initial value). The outputs keep their meaning (f, f', f''), so every
consumer of the wheel observer works unchanged with either input. The implicit step
(`first_order_implicit_step`, after Brogliato, Polyakov, Efimov 2020) reduces to a quadratic
in |e|^(1/2); inside its band it is the backward difference of g, exact for a linear g.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vd_observer_node.errors import ConfigurationError, InputShapeError
from vd_observer_node.estimation.faults import OBSERVER_FAULTS, FaultCounter

__all__ = [
    'DEFAULT_GAINS',
    'DISCRETIZATIONS',
    'INIT_POLICIES',
    'INPUT_DERIVATIVES',
    'DerivativeEstimate',
    'LevantDifferentiator',
    'LevantGains',
    'checked_settings',
    'euler_step',
    'euler_taylor_step',
    'first_order_euler_step',
    'first_order_implicit_step',
    'implicit_step',
    'step',
]

FloatArray = NDArray[np.float64]

#: Allowed discretization names.
DISCRETIZATIONS: Final = ('euler', 'euler_taylor', 'implicit')
#: Allowed initialisation policies, see `LevantDifferentiator`.
INIT_POLICIES: Final = ('finite_difference', 'first_sample', 'zero')
#: Which derivative of f the samples are: 0 = f itself, 1 = f' (see the module docstring).
INPUT_DERIVATIVES: Final = (0, 1)

_NEWTON_MAX_ITER: Final = 60
_NEWTON_RTOL: Final = 1e-13


@dataclass(frozen=True)
class LevantGains:
    """Gains of the recursive form, in the paper's order (l0 on the first equation).

    Attributes:
        l0: gain of the |z0 - f|^(2/3) term [-].
        l1: gain of the |z1 - v0|^(1/2) term [-].
        l2: gain of the sign term driving z2 [-], must exceed 1.
    """

    l0: float = 2.0
    l1: float = 1.5
    l2: float = 1.1

    def __post_init__(self) -> None:
        for name in ('l0', 'l1', 'l2'):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0.0):
                raise ConfigurationError(f'Levant gain {name} must be finite and > 0: {value!r}')
        if self.l2 <= 1.0:
            # The last gain must dominate the unknown f''' (|f'''| <= L) to converge at all.
            raise ConfigurationError(f'Levant gain l2 must be > 1, got {self.l2}')

    def nonrecursive(self) -> tuple[float, float, float]:
        """Gains (k0, k1, k2) of the equivalent non-recursive form [-]."""
        return self.l0, self.l1 * math.sqrt(self.l0), self.l2


#: Levant's published gains for the second-order differentiator.
DEFAULT_GAINS: Final = LevantGains()


def _cbrt(x: ArrayLike) -> FloatArray:
    """Cube root by the C library's ``cbrt``, element by element.

    Not ``np.cbrt``: numpy's vectorised cbrt and pow use SIMD approximations on some CPUs
    (SVML on AVX-512) that differ from libm in the last bit, and the implicit step turns one
    bit of the angle into ~ulp/tau^2 of f'' (1e-7 rad/s^2 at 1 kHz for a 200 rad angle): the
    reference would depend on the CPU it runs on. libm's is also what the compiled kernel
    (`vd_observer_node.kernel.levant`) calls, so the two agree to the last bits.
    """
    a = np.asarray(x, dtype=np.float64)
    return np.array([math.cbrt(v) for v in a.ravel().tolist()]).reshape(a.shape)


def _signed_power(x: FloatArray, exponent: float) -> FloatArray:
    """sign(x) |x|^exponent with the C library's pow (see `_cbrt`) or, for 1/2, sqrt."""
    if exponent == 0.5:
        root: FloatArray = np.sign(x) * np.sqrt(np.abs(x))
        return root
    powers = [math.pow(abs(v), exponent) for v in np.ravel(x).tolist()]
    out: FloatArray = np.sign(x) * np.array(powers).reshape(np.shape(x))
    return out


def euler_step(
    z: FloatArray,
    f: ArrayLike,
    tau: float,
    lipschitz: ArrayLike,
    gains: LevantGains = DEFAULT_GAINS,
) -> FloatArray:
    """One explicit-Euler step of the recursive differentiator.

    Args:
        z: shape (3, n), state (f, f', f'') estimates at t_k, in signal units / s^i.
        f: shape (n,) or scalar, sample at the START of the step, t_k.
        tau: step t_{k+1} - t_k [s], > 0.
        lipschitz: shape (n,) or scalar, L, bound on |f'''| [signal unit / s^3], > 0.
        gains: recursive-form gains.

    Returns:
        shape (3, n), state at t_{k+1}.
    """
    lip = np.asarray(lipschitz, dtype=np.float64)
    e0 = z[0] - np.asarray(f, dtype=np.float64)
    v0 = z[1] - gains.l0 * _cbrt(lip) * _signed_power(e0, 2.0 / 3.0)
    v1 = z[2] - gains.l1 * np.sqrt(lip) * _signed_power(z[1] - v0, 0.5)
    z2_rate = -gains.l2 * lip * np.sign(z[2] - v1)
    return np.stack((z[0] + tau * v0, z[1] + tau * v1, z[2] + tau * z2_rate))


def _positive_cubic_root(a: float, b: float, c: FloatArray) -> FloatArray:
    """Unique root y >= 0 of y^3 + a*y^2 + b*y = c for c >= 0, a, b > 0 (vectorized).

    With p = b - a^2/3 > 0 (true for the default gains) the cubic is increasing on the whole
    real line, so Cardano's formula gives its only real root; two Newton steps then remove
    the cancellation of y = x - a/3 for small c. Otherwise Newton from the upper bound
    min(cbrt(c), c / b) converges monotonically (the polynomial is convex for y >= 0).
    """
    if not np.any(c > 0.0):
        # Inside the band (the common, converged case) the root is 0.
        return np.zeros_like(c)
    p = b - a * a / 3.0
    if p > 0.0:
        q = 2.0 * (a * a * a) / 27.0 - a * b / 3.0 - c
        root = np.sqrt(0.25 * q * q + (p * p * p) / 27.0)
        y = np.maximum(_cbrt(-0.5 * q + root) + _cbrt(-0.5 * q - root) - a / 3.0, 0.0)
        for _ in range(2):
            residual = ((y + a) * y + b) * y - c
            y = np.maximum(y - residual / ((3.0 * y + 2.0 * a) * y + b), 0.0)
        return y
    y = np.minimum(_cbrt(c), c / b)
    for _ in range(_NEWTON_MAX_ITER):
        residual = ((y + a) * y + b) * y - c
        slope = (3.0 * y + 2.0 * a) * y + b
        y_next = np.maximum(y - residual / slope, 0.0)
        converged = np.all(np.abs(y_next - y) <= _NEWTON_RTOL * np.maximum(y_next, 1e-300))
        y = y_next
        if converged:
            break
    return y


def implicit_step(
    z: FloatArray,
    f_next: ArrayLike,
    tau: float,
    lipschitz: ArrayLike,
    gains: LevantGains = DEFAULT_GAINS,
) -> FloatArray:
    """One implicit step of the non-recursive differentiator, solved exactly.

    The state is propagated with the exact transition Phi(tau) of the chain of integrators
    (the Taylor terms of Livne & Levant 2014) and the output injections are evaluated at the
    NEW error e = z0_{k+1} - f_{k+1}, with the set-valued sign (implicit discretization of
    Mojallizadeh, Brogliato, Acary 2021; Brogliato, Polyakov, Efimov 2020):

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
        z: shape (3, n), state at t_k.
        f_next: shape (n,) or scalar, sample at the END of the step, t_{k+1}.
        tau: step [s], > 0.
        lipschitz: shape (n,) or scalar, L [signal unit / s^3], > 0.
        gains: recursive-form gains (converted to the non-recursive form).

    Returns:
        shape (3, n), state at t_{k+1} (the estimate for stamp t_{k+1}).
    """
    k0, k1, k2 = gains.nonrecursive()
    lip = np.asarray(lipschitz, dtype=np.float64)
    target = np.asarray(f_next, dtype=np.float64)
    # integer powers as products: the same bits in numpy, Python floats and the kernel
    tau2 = tau * tau
    scale = tau2 * tau * lip
    w = z[0] + tau * z[1] + 0.5 * tau2 * z[2] - target
    s = np.sign(w)
    excess = np.maximum(np.abs(w) / scale - k2, 0.0)
    y = _positive_cubic_root(k0, k1, excess)
    # Inside the band the multivalued sign takes the value that zeroes the error exactly.
    sign_value = np.where(excess > 0.0, s, w / (scale * k2))
    out = np.empty((3, *np.shape(w)))
    out[2] = z[2] - tau * k2 * lip * sign_value
    out[1] = z[1] + tau * z[2] - 1.5 * tau2 * k2 * lip * sign_value - s * k1 * tau2 * lip * y
    out[0] = target + s * scale * (y * y * y)
    return out


def euler_taylor_step(
    z: FloatArray,
    f: ArrayLike,
    tau: float,
    lipschitz: ArrayLike,
    gains: LevantGains = DEFAULT_GAINS,
) -> FloatArray:
    """Explicit step with the Taylor term of Livne & Levant (Automatica 50(8), 2014).

    Same as `euler_step` but z0 also integrates tau^2/2 * z2, which restores the accuracy
    asymptotics |z_i - f^(i)| = O(L * tau^(3 - i)) of the sampled differentiator (plain
    explicit Euler only reaches O(tau) for z1).

    Args:
        z: shape (3, n), state at t_k.
        f: shape (n,) or scalar, sample at the START of the step, t_k.
        tau: step [s], > 0.
        lipschitz: shape (n,) or scalar, L [signal unit / s^3], > 0.
        gains: recursive-form gains.

    Returns:
        shape (3, n), state at t_{k+1}.
    """
    z_next = euler_step(z, f, tau, lipschitz, gains)
    z_next[0] += 0.5 * (tau * tau) * z[2]
    return z_next


def first_order_euler_step(
    z: FloatArray,
    g: ArrayLike,
    tau: float,
    lipschitz: ArrayLike,
    gains: LevantGains = DEFAULT_GAINS,
    *,
    taylor: bool = False,
) -> FloatArray:
    """One explicit step of the first-order differentiator on samples g of f'.

    Args:
        z: shape (3, n), state (f, f', f'') at t_k; rows 1, 2 are the differentiator's.
        g: shape (n,) or scalar, sample of f' at the START of the step, t_k.
        tau: step [s], > 0.
        lipschitz: shape (n,) or scalar, L, bound on |g''| = |f'''| [unit / s^3], > 0.
        gains: the last two (l1, l2) are the first-order gains.
        taylor: add the Taylor term tau^2/2 * z2 to z1 (Livne & Levant 2014).

    Returns:
        shape (3, n), state at t_{k+1} (row 0: trapezoid integral of row 1).
    """
    lip = np.asarray(lipschitz, dtype=np.float64)
    e = z[1] - np.asarray(g, dtype=np.float64)
    v = z[2] - gains.l1 * np.sqrt(lip) * _signed_power(e, 0.5)
    z1 = z[1] + tau * v
    if taylor:
        z1 = z1 + 0.5 * (tau * tau) * z[2]
    z2 = z[2] - tau * (gains.l2 * lip * np.sign(e))
    return np.stack((z[0] + 0.5 * tau * (z[1] + z1), z1, z2))


def first_order_implicit_step(
    z: FloatArray,
    g_next: ArrayLike,
    tau: float,
    lipschitz: ArrayLike,
    gains: LevantGains = DEFAULT_GAINS,
) -> FloatArray:
    """One implicit step of the first-order differentiator on samples g of f', solved exactly.

    With a = l1, b = l2, the new error e = z1_{k+1} - g_{k+1} and s in Sign(e):

        z2+ = z2 - tau*b*L*s,   z1+ = z1 + tau*z2+ - tau*a*L^(1/2)*|e|^(1/2) sign(e)

    Writing w = z1 + tau*z2 - g_{k+1} and |e| = tau^2*L*y^2 this is e + tau^2*L*(a*y + b*s)
    = w: if |w| <= b*tau^2*L then e = 0 and s = w/(b*tau^2*L) (z2+ is then the backward
    difference of g when z1 = g_k), else y > 0 solves y^2 + a*y = |w|/(tau^2*L) - b.

    Args:
        z: shape (3, n), state at t_k; rows 1, 2 are the differentiator's.
        g_next: shape (n,) or scalar, sample of f' at the END of the step, t_{k+1}.
        tau: step [s], > 0.
        lipschitz: shape (n,) or scalar, L [unit / s^3], > 0.
        gains: the last two (l1, l2) are the first-order gains.

    Returns:
        shape (3, n), state at t_{k+1} (row 0: trapezoid integral of row 1).
    """
    a, b = gains.l1, gains.l2
    lip = np.asarray(lipschitz, dtype=np.float64)
    target = np.asarray(g_next, dtype=np.float64)
    scale = (tau * tau) * lip
    w = z[1] + tau * z[2] - target
    s = np.sign(w)
    excess = np.maximum(np.abs(w) / scale - b, 0.0)
    # the root of y^2 + a*y = excess in the form without cancellation for small excess
    y = 2.0 * excess / (a + np.sqrt(a * a + 4.0 * excess))
    sign_value = np.where(excess > 0.0, s, w / (scale * b))
    out = np.empty((3, *np.shape(w)))
    out[2] = z[2] - tau * b * lip * sign_value
    out[1] = target + s * scale * (y * y)
    out[0] = z[0] + 0.5 * tau * (z[1] + out[1])
    return out


def step(
    discretization: str,
    z: FloatArray,
    f_start: ArrayLike,
    f_end: ArrayLike,
    tau: float,
    lipschitz: ArrayLike,
    gains: LevantGains = DEFAULT_GAINS,
    input_derivative: int = 0,
) -> FloatArray:
    """Dispatch one step by discretization name (explicit uses f_start, implicit f_end).

    ``input_derivative`` 1: the samples are of f' (the first-order steps).

    Raises:
        ConfigurationError: unknown discretization name.
    """
    if input_derivative == 1 and discretization in DISCRETIZATIONS:
        if discretization == 'implicit':
            return first_order_implicit_step(z, f_end, tau, lipschitz, gains)
        taylor = discretization == 'euler_taylor'
        return first_order_euler_step(z, f_start, tau, lipschitz, gains, taylor=taylor)
    if discretization == 'euler':
        return euler_step(z, f_start, tau, lipschitz, gains)
    if discretization == 'euler_taylor':
        return euler_taylor_step(z, f_start, tau, lipschitz, gains)
    if discretization == 'implicit':
        return implicit_step(z, f_end, tau, lipschitz, gains)
    raise ConfigurationError(f'unknown discretization {discretization!r}; use {DISCRETIZATIONS}')


def _open_loop(z: FloatArray, tau: float) -> FloatArray:
    """Taylor prediction used for channels whose sample is missing or non-finite."""
    return np.stack(
        (z[0] + tau * z[1] + 0.5 * (tau * tau) * z[2], z[1] + tau * z[2], z[2]),
    )


class DerivativeEstimate(NamedTuple):
    """Output of `LevantDifferentiator.update` for one stamp.

    Attributes:
        value: shape (n,), estimate of f.
        first: shape (n,), estimate of f' [unit/s].
        second: shape (n,), estimate of f'' [unit/s^2].
        valid: shape (n,), bool, False while a channel is not initialised or its current
            sample was rejected (then the outputs are an open-loop prediction).
    """

    value: FloatArray
    first: FloatArray
    second: FloatArray
    valid: NDArray[np.bool_]


def checked_settings(
    lipschitz: ArrayLike,
    n_channels: int,
    discretization: str,
    init: str,
    max_gap: float,
    init_baseline: float,
    max_jump_back: float | None,
    input_derivative: int = 0,
) -> tuple[FloatArray, float]:
    """Check a differentiator's settings (see `LevantDifferentiator`).

    Returns:
        (L per channel, shape (n,); the jump back [s] that resets, `max_gap` if None).

    Raises:
        ConfigurationError: invalid L, name or gap.
    """
    if discretization not in DISCRETIZATIONS:
        raise ConfigurationError(
            f'unknown discretization {discretization!r}; use one of {DISCRETIZATIONS}'
        )
    if init not in INIT_POLICIES:
        raise ConfigurationError(f'unknown init policy {init!r}; use one of {INIT_POLICIES}')
    if n_channels < 1:
        raise ConfigurationError(f'n_channels must be >= 1, got {n_channels}')
    if input_derivative not in INPUT_DERIVATIVES:
        raise ConfigurationError(
            f'input_derivative must be one of {INPUT_DERIVATIVES}, got {input_derivative!r}'
        )
    lip = np.broadcast_to(np.asarray(lipschitz, dtype=np.float64), (n_channels,)).copy()
    if not np.all(np.isfinite(lip) & (lip > 0.0)):
        raise ConfigurationError(f'Lipschitz bounds L must be finite and > 0: {lip}')
    if not (math.isfinite(init_baseline) and init_baseline >= 0.0):
        raise ConfigurationError(f'init_baseline must be finite and >= 0: {init_baseline}')
    if not max_gap > 0.0:
        raise ConfigurationError(f'max_gap must be > 0, got {max_gap}')
    jump = float(max_gap) if max_jump_back is None else float(max_jump_back)
    if not jump > 0.0:
        raise ConfigurationError(f'max_jump_back must be > 0, got {max_jump_back}')
    return lip, jump


class LevantDifferentiator:
    """Stateful n-channel Levant differentiator on irregular time stamps.

    Second order on samples of f, or first order on samples of f' (``input_derivative=1``,
    see the module docstring); the outputs are (f, f', f'') estimates either way.

    Invalid input never poisons the state (every case counted in `faults`, see
    `vd_observer_node.estimation.faults`):

    * a non-finite stamp, a duplicate stamp or a stamp slightly older than the last one is
      rejected (state unchanged, also counted in `rejected_count`);
    * a stamp older than the last one by more than `max_jump_back` (a looped bag, a restarted
      source) resets the state and starts again from that sample ('time_jump_back');
    * a gap longer than `max_gap` re-initialises every channel from the new sample ('gap');
    * a non-finite sample of one channel makes that channel coast open loop for the step (its
      `valid` flag is False; 'non_finite_value');
    * a step whose state overflows (absurdly large finite input) resets the state
      ('non_finite_output'), so the outputs stay finite always.

    Initialisation policies (per channel, on its first finite samples):
        'first_sample': z = (f0, 0, 0) at the first sample.
        'finite_difference': waits for a sample at least `init_baseline` after the first
            and starts from z = (f1, (f1 - f0) / (t1 - t0), 0), which removes most of the
            convergence transient when the signal starts with a large slope (a car already
            moving); a baseline of a few tens of ms keeps noise from producing a huge
            initial slope.
        'zero': z = (0, 0, 0) before the first sample, then normal steps (shows finite-time
            convergence from a wrong state; mostly for tests).
    """

    def __init__(
        self,
        lipschitz: ArrayLike,
        *,
        n_channels: int,
        gains: LevantGains = DEFAULT_GAINS,
        discretization: str = 'implicit',
        init: str = 'finite_difference',
        max_gap: float = math.inf,
        init_baseline: float = 0.0,
        max_jump_back: float | None = None,
        input_derivative: int = 0,
    ) -> None:
        """Create the differentiator.

        Args:
            lipschitz: shape (n,) or scalar, L, bound on |f'''| [unit/s^3], > 0.
            n_channels: number n of independent signals differentiated together.
            gains: recursive-form gains.
            discretization: one of `DISCRETIZATIONS`.
            init: one of `INIT_POLICIES`.
            max_gap: time gap [s] beyond which the state is re-initialised.
            init_baseline: minimum time [s] between the two samples of the
                'finite_difference' initialisation.
            max_jump_back: a stamp older than the last accepted one by more than this [s]
                resets the state instead of being rejected; None = `max_gap`.
            input_derivative: one of `INPUT_DERIVATIVES`: 0 when the samples are f, 1 when
                they are f' (L then bounds the second derivative of the samples).

        Raises:
            ConfigurationError: invalid L, name or gap.
        """
        lip, jump = checked_settings(
            lipschitz,
            n_channels,
            discretization,
            init,
            max_gap,
            init_baseline,
            max_jump_back,
            input_derivative,
        )
        self._row = int(input_derivative)
        self._init_baseline = float(init_baseline)
        self._lipschitz = lip
        self._n = n_channels
        self._gains = gains
        self._discretization = discretization
        self._init = init
        self._max_gap = float(max_gap)
        self._max_jump_back = jump
        self.rejected_count = 0
        self.faults = FaultCounter(OBSERVER_FAULTS)
        self.reset()

    @property
    def discretization(self) -> str:
        """Discretization name."""
        return self._discretization

    @property
    def input_derivative(self) -> int:
        """Which derivative of f the samples are (0: f, 1: f')."""
        return self._row

    @property
    def state(self) -> FloatArray:
        """shape (3, n), copy of (f, f', f'') estimates at `time`."""
        return self._z.copy()

    @property
    def time(self) -> float | None:
        """Stamp [s] of the last accepted sample, None before the first."""
        return self._t

    def reset(self) -> None:
        """Forget all history (back to the state before the first sample)."""
        self._z = np.zeros((3, self._n))
        self._t: float | None = None
        # Sample at the current stamp per channel (NaN where missing); the explicit step needs
        # it as the start-of-step sample.
        self._f_last = np.full(self._n, np.nan)
        self._active = np.full(self._n, self._init == 'zero')
        # First finite sample (stamp, value) of channels waiting for a finite difference.
        self._pending_t = np.full(self._n, np.nan)
        self._pending_f = np.full(self._n, np.nan)
        self._all_active = bool(np.all(self._active))

    def update(self, t: float, f: ArrayLike) -> DerivativeEstimate:
        """Feed the sample f taken at stamp t and return the estimates for stamp t.

        Args:
            t: sample stamp [s]; must increase strictly.
            f: shape (n,) or scalar, the sample.

        Returns:
            The estimates for stamp t (unchanged previous ones if t was rejected).

        Raises:
            InputShapeError: f does not broadcast to shape (n,).
        """
        try:
            sample = np.broadcast_to(np.asarray(f, dtype=np.float64), (self._n,))
        except ValueError as exc:
            raise InputShapeError(f'expected {self._n} samples, got shape {np.shape(f)}') from exc
        if not math.isfinite(t):
            return self._reject('non_finite_stamp')
        if self._t is not None:
            if t <= self._t:
                if self._t - t <= self._max_jump_back:
                    return self._reject('duplicate_stamp' if t == self._t else 'out_of_order')
                self.faults.count('time_jump_back')
                self.reset()
            elif t - self._t > self._max_gap:
                self.faults.count('gap')
                self.reset()
        finite = np.isfinite(sample)
        if not finite.all():
            self.faults.count('non_finite_value')
        if self._t is None:
            self._start(t, sample, finite)
        else:
            self._advance(t, sample, finite)
        if not np.isfinite(self._z).all():
            # Overflow from absurd (finite) input: start again rather than emit inf/NaN.
            self.faults.count('non_finite_output')
            self.reset()
            return self._output(np.zeros(self._n, dtype=bool))
        self._t = t
        self._f_last = np.where(finite, sample, np.nan)
        return self._output(finite & self._active)

    def _reject(self, kind: str) -> DerivativeEstimate:
        self.faults.count(kind)
        self.rejected_count += 1
        return self._output(np.zeros(self._n, dtype=bool))

    def _start(self, t: float, sample: FloatArray, finite: NDArray[np.bool_]) -> None:
        if self._init == 'zero':
            return
        self._adopt(t, sample, finite)
        self._all_active = bool(np.all(self._active))

    def _adopt(self, t: float, sample: FloatArray, finite: NDArray[np.bool_]) -> None:
        """Initialise channels that are not active yet from this sample."""
        if self._all_active:
            return
        new = finite & ~self._active
        row = self._row  # the row the samples estimate; rows below it start from 0
        if self._init == 'first_sample':
            self._z[:, new] = 0.0
            self._z[row, new] = sample[new]
            self._active |= new
            return
        pending = np.isfinite(self._pending_t)
        first = new & ~pending
        with np.errstate(invalid='ignore'):
            second = new & pending & (t - self._pending_t >= self._init_baseline)
        waiting = new & pending & ~second
        self._z[row, waiting] = sample[waiting]
        if np.any(second):
            dt = t - self._pending_t[second]
            self._z[:, second] = 0.0
            self._z[row, second] = sample[second]
            self._z[row + 1, second] = (sample[second] - self._pending_f[second]) / dt
            self._active |= second
        self._pending_t[first] = t
        self._pending_f[first] = sample[first]
        self._z[row, first] = sample[first]

    def _advance(self, t: float, sample: FloatArray, finite: NDArray[np.bool_]) -> None:
        assert self._t is not None
        tau = t - self._t
        z = self._z
        if self._discretization == 'implicit':
            use = finite
            f_used = np.where(finite, sample, z[self._row])
        else:
            # Explicit schemes correct with the sample at the start of the step.
            use = np.isfinite(self._f_last)
            f_used = np.where(use, self._f_last, z[self._row])
        corrected = step(
            self._discretization,
            z,
            f_used,
            f_used,
            tau,
            self._lipschitz,
            self._gains,
            self._row,
        )
        if self._all_active and bool(np.all(use)):
            self._z = corrected
            return
        predicted = _open_loop(z, tau)
        stepped = np.where(use & self._active, corrected, predicted)
        self._z = np.where(self._active, stepped, z)
        self._adopt(t, sample, finite)
        self._all_active = bool(np.all(self._active))

    def _output(self, valid: NDArray[np.bool_]) -> DerivativeEstimate:
        return DerivativeEstimate(
            self._z[0].copy(), self._z[1].copy(), self._z[2].copy(), valid.copy()
        )
