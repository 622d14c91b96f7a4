"""Settings that follow the inputs' sample rate (issue 26, item 5).

The slope is a force balance low-passed with ``slope_filter_tau``; the speed's noise enters
it through the derivative of the low-passed speed (``slope_accel_source`` 'speed'). White
noise sampled at a rate f, low-passed with a time constant tau and differentiated, has a
variance of order 1 / (f tau^3); the low-pass's lag adds an error of order tau wherever the
slope changes. Noise alone would call for ``tau ~ f^(-1/3)``, the sum of both for
``tau ~ f^(-1/5)``; measured optima lie between (below), so below 1 kHz, where the default
0.1 s was tuned,

    slope_filter_tau = 0.1 s * (1000 Hz / f)^(1/4)        (0.1 s at and above 1 kHz)

with f the rate of the slower of the wheel and body-speed inputs (the balance uses both).
Measured with paper_table1 written as a car logs it (standard types, speed noise 0.05 m/s;
scripts/example_standard_bag.py), slope RMS [deg] against the tau in use:

| f (wheels / odometry) | drive | 0.1 s | 0.2 s | 0.271 s | 0.3 s | this law |
|---|---|---|---|---|---|---|
| 50 Hz (100 / 50 Hz) | 150 s | 0.588 | 0.234 | 0.223 | 0.238 | 0.211 s |
| 50 Hz (100 / 50 Hz) | 30 s, 3 seeds | | 0.266-0.289 | 0.307-0.336 | 0.347-0.377 | 0.211 s |
| 100 Hz (200 / 100 Hz) | 150 s | 0.418 | 0.180 | | 0.219 | 0.178 s |
| 250 Hz (500 / 250 Hz) | 150 s | 0.276 | 0.143 | | 0.209 | 0.141 s |

A setting follows the rate only where the user left it unset (None in the configuration, no
node parameter, no key in a ``--config`` file); an explicit value is always used as given.
The rate is the one the inputs deliver (`sample_rate_hz`): a 1 kHz stream that loses 30 % of
its messages at random is a 700 Hz stream to the low-pass, whose tau then grows as the law
says (measured under loss, docs/input_mapping.md). Live and offline alike, the rate is
measured on the first `FOLLOW_AFTER` wheel stamps
estimated (and the body speed's header stamps up to the last of them) and the settings follow
it from the next stamp on; the stamps before use the reference rate's values. So a replay of a
live recording gives the live estimates, and a stream shorter than that keeps the reference
values.
"""

from __future__ import annotations

import math
from typing import Final

import numpy as np
from numpy.typing import ArrayLike

__all__ = [
    'FOLLOW_AFTER',
    'PAUSE_INTERVALS',
    'REFERENCE_RATE_HZ',
    'REFERENCE_SLOPE_FILTER_TAU',
    'SPEED_STAMPS_KEPT',
    'RateMeter',
    'follow_rate_hz',
    'nominal_rate_hz',
    'sample_rate_hz',
    'slope_filter_tau_for_rate',
]

#: [Hz] the rate the defaults were tuned at (vd's own 1 kHz sensor topics)
REFERENCE_RATE_HZ: Final = 1000.0
#: [s] ``slope_filter_tau`` at and above the reference rate
REFERENCE_SLOPE_FILTER_TAU: Final = 0.1
#: an interval longer than this many times the median one is a pause, not the rate
#: (`sample_rate_hz`; 30 % random loss gives one that long once in 50 000 intervals)
PAUSE_INTERVALS: Final = 10.0


def slope_filter_tau_for_rate(rate_hz: float) -> float:
    """The slope low-pass time constant for inputs at `rate_hz` (module docstring).

    Args:
        rate_hz: [Hz] rate of the slower of the wheel and body-speed inputs; not finite or
            <= 0 (unknown): the reference rate's value.

    Returns:
        [s] 0.1 at and above 1 kHz, 0.1 * (1000 / rate_hz)^(1/4) below.
    """
    if not (math.isfinite(rate_hz) and rate_hz > 0.0):
        return REFERENCE_SLOPE_FILTER_TAU
    return float(REFERENCE_SLOPE_FILTER_TAU * max(1.0, REFERENCE_RATE_HZ / rate_hz) ** 0.25)


def sample_rate_hz(stamps_ns: ArrayLike) -> float:
    """[Hz] the rate a stream delivers: its distinct stamps per second.

    The intervals between its distinct stamps (sorted, so a reordered stamp does not matter
    and a repeated one is no interval), each longer than `PAUSE_INTERVALS` times their median
    left out (a pause is not a lower rate), counted over their sum. So a stream that loses
    messages at random counts at the rate it delivers them, which is what a low-pass averages
    (30 % lost at 1 kHz: 700 Hz). The median interval, used before issue 38, counted that
    stream at its sender's 1 kHz, since most delivered neighbours are still 1 ms apart.

    Args:
        stamps_ns: shape (N,), [ns], the stream's stamps in arrival order.

    Returns:
        [Hz], nan with fewer than two distinct stamps.
    """
    steps = np.diff(np.unique(np.asarray(stamps_ns, dtype=np.int64)))
    if not steps.size:
        return math.nan
    kept = steps[steps <= PAUSE_INTERVALS * np.median(steps)]
    return 1e9 * kept.size / float(kept.sum())


#: wheel stamps after which the settings left unset follow the measured rate, live and
#: offline alike (the stamps before are estimated with the reference rate's values), so a
#: replay of a live recording gives the live estimates
FOLLOW_AFTER: Final = 200
#: body-speed stamps kept for `follow_rate_hz` (a speed up to 4x faster than the wheels)
SPEED_STAMPS_KEPT: Final = 4 * FOLLOW_AFTER


def nominal_rate_hz(rate_hz: float) -> float:
    """[Hz] `rate_hz` to three significant digits: two measurements of one stream (live and
    in its recording) give the same settings despite a few microseconds of jitter."""
    if not (math.isfinite(rate_hz) and rate_hz > 0.0):
        return math.nan
    return float(f'{rate_hz:.3g}')


def follow_rate_hz(wheel_stamps_ns: ArrayLike, speed_stamps_ns: ArrayLike | None = None) -> float:
    """[Hz] the rate the settings follow: that of the slower of the wheel and body-speed inputs.

    Args:
        wheel_stamps_ns: shape (N,), [ns], the first `FOLLOW_AFTER` wheel stamps estimated.
        speed_stamps_ns: shape (M,), [ns], the body speed's stamps received by then (those
            after the last wheel stamp are left out); None where the speed has no stamps of
            its own (stamped on receipt, or the observer's at the wheel stamps).

    Returns:
        `nominal_rate_hz` of the smaller rate; nan if the wheels' is unknown.
    """
    wheels = np.asarray(wheel_stamps_ns, dtype=np.int64)
    rates = [sample_rate_hz(wheels)]
    if speed_stamps_ns is not None and wheels.size:
        speed = np.asarray(speed_stamps_ns, dtype=np.int64)
        rates.append(sample_rate_hz(speed[speed <= wheels[-1]]))
    if not math.isfinite(rates[0]):
        return math.nan
    return nominal_rate_hz(min(r for r in rates if math.isfinite(r)))


class RateMeter:
    """The first `size` stamps of a stream, for `follow_rate_hz`.

    Attributes:
        size: stamps kept.
    """

    def __init__(self, size: int = FOLLOW_AFTER) -> None:
        """Keep the first `size` (>= 2) stamps."""
        self.size = max(2, int(size))
        self._stamps: list[int] = []

    def add(self, stamp_ns: int) -> bool:
        """Note one stamp [ns] (ignored once full); True when this one filled the meter."""
        if len(self._stamps) >= self.size:
            return False
        self._stamps.append(stamp_ns)
        return len(self._stamps) == self.size

    def add_many(self, stamps_ns: ArrayLike) -> None:
        """Note a block's stamps [ns] (in order) up to `size`."""
        room = self.size - len(self._stamps)
        if room > 0:
            self._stamps.extend(np.asarray(stamps_ns, dtype=np.int64)[:room].tolist())

    @property
    def count(self) -> int:
        """Stamps kept so far."""
        return len(self._stamps)

    @property
    def stamps(self) -> list[int]:
        """[ns] the stamps kept, in arrival order."""
        return list(self._stamps)
