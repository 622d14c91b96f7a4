"""Pure accuracy metrics: numpy arrays in, small frozen dataclasses out.

Conventions: ``t`` is time [s], shape (N,), non-decreasing. Errors are ``estimate - truth``.
Statistics over an empty selection are ``nan`` with ``samples == 0`` (a report shows "n/a"
rather than failing when, say, a drive never excites the tyres enough for mu).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    'ErrorStats',
    'ValueStats',
    'change_times',
    'error_stats',
    'evaluation_mask',
    'merge_times',
    'relative_error_stats',
    'selected_errors',
    'step_times',
    'value_stats',
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class ErrorStats:
    """Error statistics of an estimate against the truth over the selected samples.

    Attributes:
        rms: root mean square of the error, unit of the quantity.
        max_abs: largest absolute error, unit of the quantity.
        mean: mean error (bias, estimate minus truth), unit of the quantity.
        samples: number of samples (elements) the statistics are taken over.
    """

    rms: float
    max_abs: float
    mean: float
    samples: int


_EMPTY = ErrorStats(float('nan'), float('nan'), float('nan'), 0)


@dataclass(frozen=True)
class ValueStats:
    """Statistics of an estimate's own values, where there is nothing to compare it with.

    Attributes:
        samples: elements (rows, or rows x wheels) of the estimate.
        valid: elements that are finite and whose ``valid`` flag is set (where it has one).
        valid_pct: [%] ``valid`` of ``samples`` (nan without samples).
        minimum: smallest valid value, unit of the quantity (nan without a valid value).
        mean: mean of the valid values.
        maximum: largest valid value.
    """

    samples: int
    valid: int
    valid_pct: float
    minimum: float
    mean: float
    maximum: float


def value_stats(values: ArrayLike, valid: ArrayLike | None = None) -> ValueStats:
    """Count, valid share, min, mean and max of an estimate's valid values.

    Args:
        values: any shape, e.g. (N,) or (N, 4).
        valid: bool, broadcastable to that shape (the estimator's own flags); None: every
            finite value is valid. Non-finite values never are.
    """
    data = np.asarray(values, dtype=np.float64)
    ok = np.isfinite(data)
    if valid is not None:
        ok &= np.broadcast_to(np.asarray(valid, dtype=bool), data.shape)
    count = int(ok.sum())
    nan = float('nan')
    pct = 100.0 * count / data.size if data.size else nan
    if count == 0:
        return ValueStats(int(data.size), 0, pct, nan, nan, nan)
    kept = data[ok]
    return ValueStats(
        int(data.size), count, pct, float(kept.min()), float(kept.mean()), float(kept.max())
    )


def error_stats(
    estimate: ArrayLike, truth: ArrayLike, mask: ArrayLike | None = None
) -> ErrorStats:
    """RMS, max and mean of ``estimate - truth`` over the elements where ``mask`` is true.

    Args:
        estimate: any shape, e.g. (N,) or (N, 4).
        truth: same shape as ``estimate``.
        mask: bool, broadcastable to that shape ((N,) masks rows of an (N, 4) array);
            None selects everything. Non-finite errors are always left out.
    """
    error = np.asarray(estimate, dtype=np.float64) - np.asarray(truth, dtype=np.float64)
    return _stats(error, mask)


def relative_error_stats(
    estimate: ArrayLike,
    truth: ArrayLike,
    scale: ArrayLike,
    mask: ArrayLike | None = None,
) -> ErrorStats:
    """Statistics of ``(estimate - truth) / scale`` (e.g. scale = |truth| or a static load).

    Args:
        estimate: any shape.
        truth: same shape.
        scale: broadcastable to that shape, same unit; must be nonzero where selected.
        mask: as in :func:`error_stats`.

    Returns:
        Dimensionless statistics (multiply by 100 for percent).
    """
    error = np.asarray(estimate, dtype=np.float64) - np.asarray(truth, dtype=np.float64)
    with np.errstate(divide='ignore', invalid='ignore'):
        ratio = error / np.asarray(scale, dtype=np.float64)
    return _stats(ratio, mask)


def selected_errors(error: FloatArray, mask: ArrayLike | None) -> FloatArray:
    """The finite elements of ``error`` where ``mask`` holds, flattened (shape (K,)).

    Args:
        error: any shape, e.g. (N,) or (N, 4).
        mask: bool, broadcastable to that shape ((N,) masks rows of an (N, 4) array), or
            None (everything finite).
    """
    select = np.isfinite(error)
    if mask is not None:
        m = np.asarray(mask, dtype=bool)
        if m.ndim < error.ndim:  # a per-row mask for a per-wheel array
            m = m.reshape(m.shape + (1,) * (error.ndim - m.ndim))
        select &= np.broadcast_to(m, error.shape)
    values: FloatArray = error[select]
    return values


def _stats(error: FloatArray, mask: ArrayLike | None) -> ErrorStats:
    values = selected_errors(error, mask)
    if values.size == 0:
        return _EMPTY
    return ErrorStats(
        rms=float(np.sqrt(np.mean(np.square(values)))),
        max_abs=float(np.max(np.abs(values))),
        mean=float(np.mean(values)),
        samples=int(values.size),
    )


def step_times(
    t: ArrayLike, signal: ArrayLike, min_jump: float, merge_s: float = 0.5
) -> FloatArray:
    """Times of steps in a piecewise-constant signal (e.g. the true road slope).

    A step is a sample-to-sample change larger than ``min_jump``; changes closer together
    than ``merge_s`` count as one step (a step spread over a few samples).

    Args:
        t: shape (N,), [s].
        signal: shape (N,), any unit.
        min_jump: smallest change counted as a step, unit of ``signal``.
        merge_s: [s], changes within this time of the previous one belong to its step.

    Returns:
        shape (K,), [s], the time of the first sample after each step.
    """
    times = np.asarray(t, dtype=np.float64)
    values = np.asarray(signal, dtype=np.float64)
    jumps = np.flatnonzero(np.abs(np.diff(values)) > min_jump) + 1
    return merge_times(times[jumps], merge_s)


def change_times(t: ArrayLike, values: ArrayLike, merge_s: float = 0.0) -> FloatArray:
    """Times where a discrete signal (e.g. the engaged gear) changes value.

    Args:
        t: shape (N,), [s].
        values: shape (N,), integers or other exactly comparable values.
        merge_s: [s], changes within this time of the previous one are merged (0: none).

    Returns:
        shape (K,), [s], the time of the first sample with the new value.
    """
    times = np.asarray(t, dtype=np.float64)
    v = np.asarray(values)
    changes = np.flatnonzero(v[1:] != v[:-1]) + 1
    return merge_times(times[changes], merge_s)


def merge_times(times: FloatArray, merge_s: float) -> FloatArray:
    """Event times without those within ``merge_s`` of the previous one (0: keep all).

    Args:
        times: shape (K,), [s] increasing.
        merge_s: [s].
    """
    if times.size == 0 or merge_s <= 0.0:
        return times
    keep = np.ones(times.size, dtype=bool)
    keep[1:] = np.diff(times) > merge_s
    return times[keep]


def evaluation_mask(
    t: ArrayLike,
    *,
    start: float,
    events: Sequence[float] | ArrayLike = (),
    half_width: float = 0.5,
) -> BoolArray:
    """Samples that count in the metrics: from ``start`` on, away from transient events.

    Args:
        t: shape (N,), [s].
        start: [s], first time evaluated (e.g. the first stamp + 1 s of start-up).
        events: [s], times of slope steps and gear shifts.
        half_width: [s], samples with |t - event| <= half_width are excluded.

    Returns:
        shape (N,), bool.
    """
    times = np.asarray(t, dtype=np.float64)
    mask = times >= start
    for event in np.asarray(events, dtype=np.float64).ravel().tolist():
        mask &= np.abs(times - event) > half_width
    return mask
