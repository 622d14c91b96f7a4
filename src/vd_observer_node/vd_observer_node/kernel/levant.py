"""Compiled Levant differentiator: `LevantDifferentiator` of `estimation`'s reference, in numba.

Mirrors :class:`vd_observer_node.estimation.differentiator.LevantDifferentiator` step for step (the
three discretizations, the three initialisation policies, every fault rule and counter); the tests
run both on the same inputs and require equal outputs (1e-9) and equal fault counts.

The state lives in numpy arrays owned by `CompiledDifferentiator`; `diff_update` advances one
stamp in place and is what the fused kernels (`kernel.chain`) call for the wheel, speed and
fast wheel observers.

Array layouts (n channels):

* ``prm`` float64 (12,): l0, l1, l2, k0, k1, k2, discretization code, init code, max_gap,
  init_baseline, max_jump_back, input_derivative (0: samples of f, 1: of f');
* ``z`` (3, n) estimates of (f, f', f''); ``f_last``, ``pend_t``, ``pend_f`` (n,);
  ``active`` (n,) bool; ``scal`` (2,): stamp of the last accepted sample (nan before the first),
  1.0 when every channel is active;
* ``counts`` int64 (8,): the `faults.OBSERVER_FAULTS` kinds in order, then rejected samples.
"""

from __future__ import annotations

import math
from typing import Final

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vd_observer_node.errors import InputShapeError
from vd_observer_node.estimation.differentiator import (
    DEFAULT_GAINS,
    DISCRETIZATIONS,
    INIT_POLICIES,
    DerivativeEstimate,
    LevantGains,
    checked_settings,
)
from vd_observer_node.estimation.faults import OBSERVER_FAULTS, FaultCounter
from vd_observer_node.kernel._jit import jit

__all__ = [
    'COUNT_REJECTED',
    'CompiledDifferentiator',
    'diff_params',
    'diff_reset',
    'diff_update',
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

_EULER: Final = 0
_EULER_TAYLOR: Final = 1
_IMPLICIT: Final = 2
_INIT_FD: Final = 0
_INIT_FIRST: Final = 1
_INIT_ZERO: Final = 2
_NEWTON_MAX_ITER: Final = 60
_NEWTON_RTOL: Final = 1e-13
# fault counter slots, OBSERVER_FAULTS order
_NON_FINITE_STAMP: Final = 0
_NON_FINITE_VALUE: Final = 1
_DUPLICATE: Final = 2
_OUT_OF_ORDER: Final = 3
_GAP: Final = 4
_JUMP_BACK: Final = 5
_NON_FINITE_OUTPUT: Final = 6
#: Slot of the rejected-sample count in ``counts`` (after the fault kinds).
COUNT_REJECTED: Final = 7
assert OBSERVER_FAULTS == (
    'non_finite_stamp',
    'non_finite_value',
    'duplicate_stamp',
    'out_of_order',
    'gap',
    'time_jump_back',
    'non_finite_output',
)


def diff_params(
    gains: LevantGains,
    discretization: str,
    init: str,
    max_gap: float,
    init_baseline: float,
    max_jump_back: float,
    input_derivative: int = 0,
) -> FloatArray:
    """The ``prm`` array of one differentiator (see the module docstring)."""
    k0, k1, k2 = gains.nonrecursive()
    return np.array(
        [
            gains.l0,
            gains.l1,
            gains.l2,
            k0,
            k1,
            k2,
            float(DISCRETIZATIONS.index(discretization)),
            float(INIT_POLICIES.index(init)),
            max_gap,
            init_baseline,
            max_jump_back,
            float(input_derivative),
        ]
    )


# DISCRETIZATIONS = ('euler', 'euler_taylor', 'implicit'), INIT_POLICIES =
# ('finite_difference', 'first_sample', 'zero'): the codes above are their indexes.
assert DISCRETIZATIONS.index('euler_taylor') == _EULER_TAYLOR
assert DISCRETIZATIONS.index('implicit') == _IMPLICIT
assert INIT_POLICIES.index('first_sample') == _INIT_FIRST
assert INIT_POLICIES.index('zero') == _INIT_ZERO


@jit
def _sign(x: float) -> float:
    if x > 0.0:
        return 1.0
    if x < 0.0:
        return -1.0
    return x  # 0.0 (or nan, as np.sign)


@jit
def diff_reset(
    prm: FloatArray,
    z: FloatArray,
    f_last: FloatArray,
    active: BoolArray,
    pend_t: FloatArray,
    pend_f: FloatArray,
    scal: FloatArray,
) -> None:
    """Forget all history (`LevantDifferentiator.reset`)."""
    zero_init = int(prm[7]) == _INIT_ZERO
    z[:, :] = 0.0
    scal[0] = math.nan
    for i in range(z.shape[1]):
        f_last[i] = math.nan
        active[i] = zero_init
        pend_t[i] = math.nan
        pend_f[i] = math.nan
    scal[1] = 1.0 if zero_init else 0.0


@jit
def _adopt(
    prm: FloatArray,
    t: float,
    sample: FloatArray,
    finite: BoolArray,
    z: FloatArray,
    active: BoolArray,
    pend_t: FloatArray,
    pend_f: FloatArray,
    scal: FloatArray,
) -> None:
    """Initialise the channels that are not active yet from this sample (`_adopt`)."""
    if scal[1] != 0.0:
        return
    first_sample = int(prm[7]) == _INIT_FIRST
    baseline = prm[9]
    row = int(prm[11])  # the row the samples estimate; rows below it start from 0
    for i in range(z.shape[1]):
        if not finite[i] or active[i]:
            continue
        if first_sample:
            z[0, i] = 0.0
            z[1, i] = 0.0
            z[2, i] = 0.0
            z[row, i] = sample[i]
            active[i] = True
            continue
        if math.isnan(pend_t[i]):
            pend_t[i] = t
            pend_f[i] = sample[i]
            z[row, i] = sample[i]
        elif t - pend_t[i] >= baseline:
            z[0, i] = 0.0
            z[1, i] = 0.0
            z[2, i] = 0.0
            z[row, i] = sample[i]
            z[row + 1, i] = (sample[i] - pend_f[i]) / (t - pend_t[i])
            active[i] = True
        else:
            z[row, i] = sample[i]


@jit
def _positive_cubic_root(a: float, b: float, c: FloatArray, y: FloatArray) -> None:
    """`differentiator._positive_cubic_root` into y, with the same vectorised branches."""
    n = c.shape[0]
    any_positive = False
    for i in range(n):
        if c[i] > 0.0:
            any_positive = True
    if not any_positive:
        for i in range(n):
            y[i] = 0.0
        return
    p = b - a * a / 3.0
    if p > 0.0:
        for i in range(n):
            q = 2.0 * (a * a * a) / 27.0 - a * b / 3.0 - c[i]
            root = math.sqrt(0.25 * q * q + (p * p * p) / 27.0)
            yi = max(np.cbrt(-0.5 * q + root) + np.cbrt(-0.5 * q - root) - a / 3.0, 0.0)
            for _ in range(2):
                residual = ((yi + a) * yi + b) * yi - c[i]
                yi = max(yi - residual / ((3.0 * yi + 2.0 * a) * yi + b), 0.0)
            y[i] = yi
        return
    for i in range(n):
        y[i] = min(np.cbrt(c[i]), c[i] / b)
    for _ in range(_NEWTON_MAX_ITER):
        converged = True
        for i in range(n):
            residual = ((y[i] + a) * y[i] + b) * y[i] - c[i]
            slope = (3.0 * y[i] + 2.0 * a) * y[i] + b
            y_next = max(y[i] - residual / slope, 0.0)
            if not abs(y_next - y[i]) <= _NEWTON_RTOL * max(y_next, 1e-300):
                converged = False
            y[i] = y_next
        if converged:
            break


@jit
def _corrected_first_order(
    prm: FloatArray,
    z: FloatArray,
    g: FloatArray,
    tau: float,
    lip: FloatArray,
    out: FloatArray,
) -> None:
    """`differentiator.first_order_implicit_step` / `first_order_euler_step` per channel."""
    a, b = prm[1], prm[2]
    code = int(prm[6])
    for i in range(z.shape[1]):
        if code == _IMPLICIT:
            scale = (tau * tau) * lip[i]
            w = z[1, i] + tau * z[2, i] - g[i]
            s = _sign(w)
            excess = max(abs(w) / scale - b, 0.0)
            y = 2.0 * excess / (a + math.sqrt(a * a + 4.0 * excess))
            sign_value = s if excess > 0.0 else w / (scale * b)
            out[2, i] = z[2, i] - tau * b * lip[i] * sign_value
            out[1, i] = g[i] + s * scale * (y * y)
        else:
            e = z[1, i] - g[i]
            v = z[2, i] - a * math.sqrt(lip[i]) * (_sign(e) * math.sqrt(abs(e)))
            z1 = z[1, i] + tau * v
            if code == _EULER_TAYLOR:
                z1 = z1 + 0.5 * (tau * tau) * z[2, i]
            out[1, i] = z1
            out[2, i] = z[2, i] - tau * (b * lip[i] * _sign(e))
        out[0, i] = z[0, i] + 0.5 * tau * (z[1, i] + out[1, i])


@jit
def _corrected(
    prm: FloatArray,
    z: FloatArray,
    f: FloatArray,
    tau: float,
    lip: FloatArray,
    out: FloatArray,
) -> None:
    """One step of the configured discretization for every channel (`differentiator.step`)."""
    n = z.shape[1]
    code = int(prm[6])
    if int(prm[11]) == 1:
        _corrected_first_order(prm, z, f, tau, lip, out)
        return
    if code == _IMPLICIT:
        k0, k1, k2 = prm[3], prm[4], prm[5]
        excess = np.empty(n)
        y = np.empty(n)
        w = np.empty(n)
        tau2 = tau * tau
        for i in range(n):
            scale = tau2 * tau * lip[i]
            w[i] = z[0, i] + tau * z[1, i] + 0.5 * tau2 * z[2, i] - f[i]
            excess[i] = max(abs(w[i]) / scale - k2, 0.0)
        _positive_cubic_root(k0, k1, excess, y)
        for i in range(n):
            scale = tau2 * tau * lip[i]
            s = _sign(w[i])
            sign_value = s if excess[i] > 0.0 else w[i] / (scale * k2)
            out[2, i] = z[2, i] - tau * k2 * lip[i] * sign_value
            out[1, i] = (
                z[1, i]
                + tau * z[2, i]
                - 1.5 * tau2 * k2 * lip[i] * sign_value
                - s * k1 * tau2 * lip[i] * y[i]
            )
            out[0, i] = f[i] + s * scale * (y[i] * y[i] * y[i])
        return
    l0, l1, l2 = prm[0], prm[1], prm[2]
    for i in range(n):
        e0 = z[0, i] - f[i]
        v0 = z[1, i] - l0 * np.cbrt(lip[i]) * (_sign(e0) * math.pow(abs(e0), 2.0 / 3.0))
        d1 = z[1, i] - v0
        v1 = z[2, i] - l1 * math.sqrt(lip[i]) * (_sign(d1) * math.sqrt(abs(d1)))
        z2_rate = -l2 * lip[i] * _sign(z[2, i] - v1)
        out[0, i] = z[0, i] + tau * v0
        out[1, i] = z[1, i] + tau * v1
        out[2, i] = z[2, i] + tau * z2_rate
        if code == _EULER_TAYLOR:
            out[0, i] += 0.5 * (tau * tau) * z[2, i]


@jit
def _write_output(z: FloatArray, out: FloatArray) -> None:
    for r in range(3):
        for i in range(z.shape[1]):
            out[r, i] = z[r, i]


@jit
def diff_update(
    prm: FloatArray,
    lip: FloatArray,
    z: FloatArray,
    f_last: FloatArray,
    active: BoolArray,
    pend_t: FloatArray,
    pend_f: FloatArray,
    scal: FloatArray,
    counts: NDArray[np.int64],
    t: float,
    sample: FloatArray,
    out: FloatArray,
    valid: BoolArray,
) -> None:
    """Feed sample (n,) at stamp t; write (f, f', f'') for t to out (3, n) and valid (n,).

    Mirrors `LevantDifferentiator.update` (rejections leave the state unchanged and clear
    `valid`; jumps back and gaps reset; a non-finite channel coasts open loop; an overflow
    resets and counts 'non_finite_output').
    """
    n = z.shape[1]
    t_last = scal[0]
    if not math.isfinite(t):
        counts[_NON_FINITE_STAMP] += 1
        counts[COUNT_REJECTED] += 1
        _write_output(z, out)
        valid[:] = False
        return
    if not math.isnan(t_last):
        if t <= t_last:
            if t_last - t <= prm[10]:
                counts[_DUPLICATE if t == t_last else _OUT_OF_ORDER] += 1
                counts[COUNT_REJECTED] += 1
                _write_output(z, out)
                valid[:] = False
                return
            counts[_JUMP_BACK] += 1
            diff_reset(prm, z, f_last, active, pend_t, pend_f, scal)
        elif t - t_last > prm[8]:
            counts[_GAP] += 1
            diff_reset(prm, z, f_last, active, pend_t, pend_f, scal)
    finite = np.empty(n, dtype=np.bool_)
    all_finite = True
    for i in range(n):
        finite[i] = math.isfinite(sample[i])
        all_finite = all_finite and finite[i]
    if not all_finite:
        counts[_NON_FINITE_VALUE] += 1
    if math.isnan(scal[0]):
        if int(prm[7]) != _INIT_ZERO:
            _adopt(prm, t, sample, finite, z, active, pend_t, pend_f, scal)
            scal[1] = 1.0 if active.all() else 0.0
    else:
        tau = t - scal[0]
        implicit = int(prm[6]) == _IMPLICIT
        row = int(prm[11])
        use = np.empty(n, dtype=np.bool_)
        f_used = np.empty(n)
        all_use = True
        for i in range(n):
            use[i] = finite[i] if implicit else math.isfinite(f_last[i])
            source = sample[i] if implicit else f_last[i]
            f_used[i] = source if use[i] else z[row, i]
            all_use = all_use and use[i]
        corrected = np.empty((3, n))
        _corrected(prm, z, f_used, tau, lip, corrected)
        if scal[1] != 0.0 and all_use:
            z[:, :] = corrected
        else:
            for i in range(n):
                if not active[i]:
                    continue
                if use[i]:
                    z[0, i] = corrected[0, i]
                    z[1, i] = corrected[1, i]
                    z[2, i] = corrected[2, i]
                else:
                    z0, z1, z2 = z[0, i], z[1, i], z[2, i]
                    z[0, i] = z0 + tau * z1 + 0.5 * (tau * tau) * z2
                    z[1, i] = z1 + tau * z2
                    z[2, i] = z2
            _adopt(prm, t, sample, finite, z, active, pend_t, pend_f, scal)
            scal[1] = 1.0 if active.all() else 0.0
    overflow = False
    for r in range(3):
        for i in range(n):
            if not math.isfinite(z[r, i]):
                overflow = True
    if overflow:
        counts[_NON_FINITE_OUTPUT] += 1
        diff_reset(prm, z, f_last, active, pend_t, pend_f, scal)
        _write_output(z, out)
        valid[:] = False
        return
    scal[0] = t
    for i in range(n):
        f_last[i] = sample[i] if finite[i] else math.nan
        valid[i] = finite[i] and active[i]
    _write_output(z, out)


@jit
def diff_block(
    prm: FloatArray,
    lip: FloatArray,
    z: FloatArray,
    f_last: FloatArray,
    active: BoolArray,
    pend_t: FloatArray,
    pend_f: FloatArray,
    scal: FloatArray,
    counts: NDArray[np.int64],
    t: FloatArray,
    samples: FloatArray,
    out: FloatArray,
    valid: BoolArray,
) -> None:
    """`diff_update` over N stamps: t (N,), samples (N, n) -> out (N, 3, n), valid (N, n)."""
    for k in range(t.shape[0]):
        diff_update(
            prm, lip, z, f_last, active, pend_t, pend_f, scal, counts, t[k], samples[k],
            out[k], valid[k],
        )  # fmt: skip


class CompiledDifferentiator:
    """Drop-in for `LevantDifferentiator` running `diff_update` (same arguments, same API)."""

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
        """Create the differentiator; arguments as `LevantDifferentiator`.

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
        self._n = n_channels
        self._row = int(input_derivative)
        self._discretization = discretization
        self.lip = lip
        self.prm = diff_params(
            gains, discretization, init, float(max_gap), init_baseline, jump, input_derivative
        )
        self.z = np.zeros((3, n_channels))
        self.f_last = np.full(n_channels, np.nan)
        self.active = np.zeros(n_channels, dtype=np.bool_)
        self.pend_t = np.full(n_channels, np.nan)
        self.pend_f = np.full(n_channels, np.nan)
        self.scal = np.zeros(2)
        self.counts = np.zeros(len(OBSERVER_FAULTS) + 1, dtype=np.int64)
        self._faults = FaultCounter(OBSERVER_FAULTS)
        self._synced = np.zeros_like(self.counts)
        self._out = np.zeros((3, n_channels))
        self._valid = np.zeros(n_channels, dtype=np.bool_)
        self.reset()
        self._warm_up()

    def _warm_up(self) -> None:
        """Compile `diff_update` (or load it from numba's cache) before the first sample."""
        diff_update(
            self.prm, self.lip, self.z.copy(), self.f_last.copy(), self.active.copy(),
            self.pend_t.copy(), self.pend_f.copy(), self.scal.copy(), self.counts.copy(), 0.0,
            np.zeros(self._n), self._out, self._valid,
        )  # fmt: skip

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
        return self.z.copy()

    @property
    def time(self) -> float | None:
        """Stamp [s] of the last accepted sample, None before the first."""
        t = float(self.scal[0])
        return None if math.isnan(t) else t

    @property
    def rejected_count(self) -> int:
        """Samples rejected for a non-finite, repeated or slightly older stamp."""
        return int(self.counts[COUNT_REJECTED])

    def reset(self) -> None:
        """Forget all history (fault counts stay)."""
        diff_reset(self.prm, self.z, self.f_last, self.active, self.pend_t, self.pend_f, self.scal)

    @property
    def faults(self) -> FaultCounter:
        """Input faults per kind, as the reference counts them (synced from the kernel)."""
        self.sync_faults()
        return self._faults

    def sync_faults(self) -> None:
        """Copy the kernel's fault counts into `faults` (call before `faults.report()`)."""
        delta = self.counts - self._synced
        for slot in np.flatnonzero(delta[: len(OBSERVER_FAULTS)]).tolist():
            self._faults.count(OBSERVER_FAULTS[slot], int(delta[slot]))
        self._synced = self.counts.copy()

    def update(self, t: float, f: ArrayLike) -> DerivativeEstimate:
        """Feed the sample f taken at stamp t; the estimates for t (`LevantDifferentiator`).

        Raises:
            InputShapeError: f does not broadcast to shape (n,).
        """
        try:
            sample = np.broadcast_to(np.asarray(f, dtype=np.float64), (self._n,))
        except ValueError as exc:
            raise InputShapeError(f'expected {self._n} samples, got shape {np.shape(f)}') from exc
        out, valid = self._out, self._valid
        diff_update(
            self.prm, self.lip, self.z, self.f_last, self.active, self.pend_t, self.pend_f,
            self.scal, self.counts, float(t), np.ascontiguousarray(sample), out, valid,
        )  # fmt: skip
        return DerivativeEstimate(out[0].copy(), out[1].copy(), out[2].copy(), valid.copy())
