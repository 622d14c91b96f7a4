"""Low-pass filter of estimates on irregular time steps.

`lowpass_update` and `lowpass_derivative` are the compiled step (what the estimator runs per
stamp); `LowPass` keeps one filter's state and calls them. The state of a filter of ``order``
stages over ``d`` channels: ``stages`` (order, d), ``prev`` (d,) the last output before the
latest step, and a `LOWPASS_META` record.
"""

from __future__ import annotations

import math
from typing import Final

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vd_observer_node.errors import ConfigurationError
from vd_observer_node.kernel._jit import jit, new_record

__all__ = [
    'LOWPASS_META',
    'LowPass',
    'lowpass_derivative',
    'lowpass_reset',
    'lowpass_update',
]

FloatArray = NDArray[np.float64]

#: A filter's bookkeeping: its stages hold a signal, ``prev`` holds the output before the
#: latest step, and that step's length [s].
LOWPASS_META: Final = np.dtype(
    [('started', 'b1'), ('has_prev', 'b1'), ('last_dt', 'f8')], align=True
)


@jit
def lowpass_reset(meta: np.record) -> None:
    """Forget the state: the next input initialises every stage."""
    meta.started = False
    meta.has_prev = False
    meta.last_dt = 0.0


@jit
def lowpass_update(
    tau: float,
    stages: FloatArray,
    prev: FloatArray,
    meta: np.record,
    dt: float,
    x: FloatArray,
    out: FloatArray,
) -> None:
    """Advance by ``dt`` [s] with the (finite) input ``x`` (d,) and write the output to ``out``.

    Each stage y <- y + (1 - exp(-dt / tau)) * (x - y); tau = 0 passes ``x`` through. The
    first input after a reset initialises every stage (a steady start).
    """
    if tau == 0.0:
        out[:] = x
        return
    if not meta.started:
        for j in range(stages.shape[0]):
            stages[j, :] = x
        meta.started = True
        out[:] = x
        return
    alpha = -math.expm1(-max(dt, 0.0) / tau)
    prev[:] = stages[-1]
    meta.has_prev = True
    meta.last_dt = dt
    for i in range(x.shape[0]):
        signal = x[i]
        for j in range(stages.shape[0]):
            stages[j, i] += alpha * (signal - stages[j, i])
            signal = stages[j, i]
        out[i] = signal


@jit
def lowpass_derivative(
    stages: FloatArray, prev: FloatArray, meta: np.record, out: FloatArray
) -> None:
    """Rate of change of the output over the last step, (y_k - y_(k-1)) / dt, into ``out``
    (d,); zeros before the second update (or with tau = 0: never updated)."""
    if not (meta.started and meta.has_prev and meta.last_dt > 0.0):
        out[:] = 0.0
        return
    for i in range(out.shape[0]):
        out[i] = (stages[-1, i] - prev[i]) / meta.last_dt


class LowPass:
    """Cascade of `order` identical first-order lags, exact for piecewise-constant input.

    Each stage y <- y + (1 - exp(-dt / tau)) * (x - y). With order 2 the filter is critically
    damped (no overshoot on steps) with a group delay of order * tau at low frequency.
    tau = 0 passes the input through unchanged.
    """

    def __init__(self, tau: float, order: int = 2) -> None:
        """Create the filter.

        Args:
            tau: time constant of each stage [s], >= 0.
            order: number of stages, >= 1.

        Raises:
            ConfigurationError: negative or non-finite tau, order < 1.
        """
        if not (math.isfinite(tau) and tau >= 0.0):
            raise ConfigurationError(f'filter time constant must be finite and >= 0: {tau}')
        if order < 1:
            raise ConfigurationError(f'filter order must be >= 1: {order}')
        self._tau = float(tau)
        self._order = order
        self._meta = new_record(LOWPASS_META)
        # sized by the first input (any shape, filtered element-wise)
        self._shape: tuple[int, ...] = ()
        self._stages = np.zeros((order, 1))
        self._prev = np.zeros(1)

    @property
    def delay(self) -> float:
        """Low-frequency group delay order * tau [s]."""
        return self._order * self._tau

    def reset(self) -> None:
        """Forget the state; the next input initialises every stage."""
        lowpass_reset(self._meta)

    def derivative(self) -> FloatArray:
        """Rate of change of the output over the last step [unit/s]: (y_k - y_(k-1)) / dt.

        This is the same low-pass applied to the backward difference of the input (the
        difference commutes with the linear filter), so the filtered derivative of a noisy
        signal is obtained without differentiating the raw signal; exact on a ramp in steady
        state, with half a sample of delay. Zero before the second update or with tau = 0.
        """
        if not self._meta.started:
            return np.zeros(())
        out = np.empty(self._prev.shape[0])
        lowpass_derivative(self._stages, self._prev, self._meta, out)
        return out.reshape(self._shape)

    def update(self, dt: float, x: ArrayLike) -> FloatArray:
        """Advance by dt [s] with the (finite) input x and return the output (same shape)."""
        value = np.array(x, dtype=np.float64)
        if self._tau == 0.0:
            return value
        flat = np.ascontiguousarray(value.reshape(-1))
        if not self._meta.started and value.shape != self._shape:
            self._shape = value.shape
            self._stages = np.zeros((self._order, flat.shape[0]))
            self._prev = np.zeros(flat.shape[0])
        out = np.empty(flat.shape[0])
        lowpass_update(self._tau, self._stages, self._prev, self._meta, float(dt), flat, out)
        return out.reshape(value.shape)
