"""Low-pass filter of estimates on irregular time steps.

`lowpass_update` and `lowpass_derivative` are the compiled step (what the estimator runs per
stamp); `LowPass` keeps one filter's state and calls them. The state of a filter of ``order``
stages over ``d`` channels: ``stages`` (order, d), ``prev`` (2, d) (row 0: the output before
the latest (sub-)step; row 1: the latest input) and a `LOWPASS_META` record.

A step is exact for an input held at its new value over the step, which is what a sampled
signal looks like at the sampling rate. Over a gap (lost messages: a step longer than
``BRIDGE_FROM`` time constants, `lowpass_gap`) that is wrong: a ramp held at its end value
for 200 ms is a step, whose derivative the slope's m*dv/dt would see as a spike. The state
is carried across such a gap (only the caller's ``max_gap`` restarts a filter): all of the
step but its last sample period is bridged (`lowpass_bridge`), run as the lost samples with
the input interpolated linearly from the previous sample to the new one (or along a
polynomial the caller knows better: the estimator's speed), then the new sample is taken
over one sample period as any other (docs/faults.md, loss).
"""

from __future__ import annotations

import math
from typing import Final

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vd_observer_node.errors import ConfigurationError
from vd_observer_node.kernel._jit import jit, new_record

__all__ = [
    'BRIDGE_FROM',
    'BRIDGE_MAX_STEPS',
    'LOWPASS_META',
    'LowPass',
    'lowpass_bridge',
    'lowpass_derivative',
    'lowpass_gap',
    'lowpass_input',
    'lowpass_on_ramp',
    'lowpass_reset',
    'lowpass_update',
    'mode_step',
]

FloatArray = NDArray[np.float64]

#: A step longer than this [time constants] is a gap: bridged in sub-steps (module docstring).
BRIDGE_FROM: Final = 0.2
#: At most this many sub-steps (a longer gap takes longer ones: 0.5 s, vd's ``max_gap``, is
#: 500 steps at 1 kHz).
BRIDGE_MAX_STEPS: Final = 1000

#: A filter's bookkeeping: its stages hold a signal, ``prev`` holds the output before the
#: latest (sub-)step, and that step's length [s].
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
def lowpass_gap(tau: float, meta: np.record, dt: float) -> float:
    """The part of a step of ``dt`` [s] that is a gap to bridge [s], else 0.

    A step longer than ``BRIDGE_FROM * tau`` after at least two inputs is a gap: all of it but
    its last sample period (the step before it, ``meta.last_dt``), over which the new input
    is then taken as usual.
    """
    if not (tau > 0.0 and meta.has_prev and dt > BRIDGE_FROM * tau):
        return 0.0
    period: float = meta.last_dt
    if not 0.0 < period < dt:
        return 0.0
    return dt - period


@jit
def lowpass_bridge(
    tau: float,
    stages: FloatArray,
    prev: FloatArray,
    span: float,
    period: float,
    x0: FloatArray,
    rate: FloatArray,
    curve: FloatArray,
) -> None:
    """Advance over a gap of ``span`` [s] with the input x0 + rate * s + curve * s^2 (d,).

    The gap is run as the samples it lost: in equal sub-steps as near ``period`` as divide
    it (at most ``BRIDGE_MAX_STEPS``), each holding its end value as a sample does, so a
    ramp leaves the filter where the lost samples would have. ``prev[1]`` becomes the input
    at the end. The output and its derivative are those of the step that follows (the
    sample after the gap, `lowpass_update` over ``period``).

    Args:
        tau: time constant of each stage [s], > 0.
        stages: (order, d), advanced in place.
        prev: (2, d), its row 1 written.
        span: [s], > 0.
        period: the sample period [s] of the filter's input before the gap, > 0.
        x0, rate, curve: (d,), the input's polynomial in the time s [s] since the gap began.
    """
    n_sub = min(max(round(span / period), 1), BRIDGE_MAX_STEPS)
    h = span / n_sub
    alpha = -math.expm1(-h / tau)
    for i in range(stages.shape[1]):
        for k in range(n_sub):
            s = (k + 1) * h
            signal = x0[i] + (rate[i] + curve[i] * s) * s
            for j in range(stages.shape[0]):
                stages[j, i] += alpha * (signal - stages[j, i])
                signal = stages[j, i]
        prev[1, i] = x0[i] + (rate[i] + curve[i] * span) * span


@jit
def lowpass_on_ramp(tau: float, stages: FloatArray, i: int, value: float, rate: float) -> None:
    """Put channel ``i``'s stages where a ramp through ``value`` now at ``rate`` [unit/s]
    has left them: stage j lags (j + 1) tau behind it (a steady start of a moving signal)."""
    for j in range(stages.shape[0]):
        stages[j, i] = value - (j + 1) * tau * rate


@jit
def lowpass_input(
    tau: float, stages: FloatArray, prev: FloatArray, meta: np.record, i: int
) -> tuple[float, float]:
    """The filter's estimate of channel ``i``'s input now and of its rate [unit, unit/s]: a
    ramp through ``order`` stages lags by ``order * tau``, so the input is the output plus
    that lag times the output's rate (the rate 0 before two inputs)."""
    rate = 0.0
    if meta.started and meta.has_prev and meta.last_dt > 0.0:
        rate = (stages[-1, i] - prev[0, i]) / meta.last_dt
    return stages[-1, i] + stages.shape[0] * tau * rate, rate


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
    first input after a reset initialises every stage (a steady start). A gap
    (`lowpass_gap`) is bridged with the input interpolated linearly from the last one
    (``prev[1]``) to ``x`` (`lowpass_bridge`), then ``x`` taken over the sample period.

    Args:
        tau: time constant of each stage [s], >= 0.
        stages: (order, d), advanced in place.
        prev: (2, d), written: the output before the last step, and ``x``.
        meta: `LOWPASS_META` record, advanced in place.
        dt: step [s] (negative counts as 0).
        x: (d,), the input at the end of the step.
        out: (d,), written: the output.
    """
    if tau == 0.0:
        out[:] = x
        return
    if not meta.started:
        for j in range(stages.shape[0]):
            stages[j, :] = x
        prev[1, :] = x
        meta.started = True
        out[:] = x
        return
    step = max(dt, 0.0)
    span = lowpass_gap(tau, meta, step)
    if span > 0.0:
        x0 = prev[1].copy()
        rate = (x - x0) / step  # the line through the two samples
        lowpass_bridge(tau, stages, prev, span, meta.last_dt, x0, rate, np.zeros_like(x))
        step = step - span
    alpha = -math.expm1(-step / tau)
    prev[0, :] = stages[-1]
    for i in range(x.shape[0]):
        signal = x[i]
        for j in range(stages.shape[0]):
            stages[j, i] += alpha * (signal - stages[j, i])
            signal = stages[j, i]
        out[i] = signal
    prev[1, :] = x
    meta.has_prev = True
    meta.last_dt = step


@jit
def lowpass_derivative(
    stages: FloatArray, prev: FloatArray, meta: np.record, out: FloatArray
) -> None:
    """Rate of change of the output over the last (sub-)step, (y_k - y_(k-1)) / dt, into
    ``out`` (d,); zeros before the second update (or with tau = 0: never updated)."""
    if not (meta.started and meta.has_prev and meta.last_dt > 0.0):
        out[:] = 0.0
        return
    for i in range(out.shape[0]):
        out[i] = (stages[-1, i] - prev[0, i]) / meta.last_dt


class LowPass:
    """Cascade of `order` identical first-order lags, exact for piecewise-constant input
    (a gap bridged as `lowpass_update` says).

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
        self._prev = np.zeros((2, 1))

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
        out = np.empty(self._prev.shape[1])
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
            self._prev = np.zeros((2, flat.shape[0]))
        out = np.empty(flat.shape[0])
        lowpass_update(self._tau, self._stages, self._prev, self._meta, float(dt), flat, out)
        return out.reshape(value.shape)


@jit
def mode_step(
    omega: float, zeta: float, dt: float, target: float, x: float, rate: float
) -> tuple[float, float]:
    """One step of a damped second-order mode ``x'' = omega^2 (target - x) - 2 zeta omega x'``
    (semi-implicit Euler: stable, and near the mode's own response at ``omega dt <= 0.5``).

    Args:
        omega: undamped angular frequency [rad/s] (> 0).
        zeta: damping ratio [-].
        dt: step [s].
        target: where the mode settles (the input, held over the step).
        x, rate: the state and its rate [per s] before the step.

    Returns:
        (x, rate) after the step.
    """
    accel = omega * omega * (target - x) - 2.0 * zeta * omega * rate
    rate = rate + dt * accel
    return x + dt * rate, rate
