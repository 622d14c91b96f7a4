"""Low-pass filter of estimates on irregular time steps."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vd_observer_node.errors import ConfigurationError

__all__ = ['LowPass']


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
        self._stages: list[NDArray[np.float64]] | None = None
        self._previous: NDArray[np.float64] | None = None
        self._last_dt = 0.0

    @property
    def delay(self) -> float:
        """Low-frequency group delay order * tau [s]."""
        return self._order * self._tau

    def reset(self) -> None:
        """Forget the state; the next input initialises every stage."""
        self._stages = None
        self._previous = None
        self._last_dt = 0.0

    def derivative(self) -> NDArray[np.float64]:
        """Rate of change of the output over the last step [unit/s]: (y_k - y_(k-1)) / dt.

        This is the same low-pass applied to the backward difference of the input (the
        difference commutes with the linear filter), so the filtered derivative of a noisy
        signal is obtained without differentiating the raw signal; exact on a ramp in steady
        state, with half a sample of delay. Zero before the second update or with tau = 0.
        """
        if self._previous is None or self._last_dt <= 0.0 or self._stages is None:
            return np.zeros(()) if self._stages is None else np.zeros_like(self._stages[-1])
        return (self._stages[-1] - self._previous) / self._last_dt

    def update(self, dt: float, x: ArrayLike) -> NDArray[np.float64]:
        """Advance by dt [s] with the (finite) input x and return the output (same shape)."""
        value = np.array(x, dtype=np.float64)
        if self._tau == 0.0:
            return value
        if self._stages is None:
            self._stages = [value.copy() for _ in range(self._order)]
            return value
        alpha = -math.expm1(-max(dt, 0.0) / self._tau)
        self._previous = self._stages[-1].copy()
        self._last_dt = dt
        signal = value
        for stage in self._stages:
            stage += alpha * (signal - stage)
            signal = stage
        return signal.copy()
