"""The IMU sample (any held input's) each stamp of the live chain takes, independent of
delivery order.

A replay holds, at each wheel stamp, the newest IMU sample not later than it. A live node
receives the IMU and the wheel sensors on separate subscriptions, and which of the IMU sample
of a stamp and the stamp's last wheel message is taken first depends on the executor: taking
the newest IMU sample *received* made the fused slope differ from run to run (0.04-0.1 deg on
the lockstep demo). `ImuHold` holds a completed stamp back until the IMU has delivered a
sample at or after it, so that every stamp takes what the replay takes, unless the IMU is
behind the newest wheel stamp by more than ``max_age`` (an IMU not heard from yet is awaited
that long from the first stamp), when the stamps go on without it.
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from typing import Generic, TypeVar

__all__ = ['ImuHold', 'ImuSample']

#: a held input's sample: its stamp [s], then its values (the IMU's: forward specific force
#: [m/s^2], pitch rate [rad/s] (nan: none))
ImuSample = tuple[float, ...]
T = TypeVar('T')


class ImuHold(Generic[T]):
    """Stamps held until their IMU sample is known; each released with it.

    Attributes:
        max_age: [s] an IMU this far behind the newest stamp is not waited for.
        late: IMU samples that came out of stamp order (each is put where the replay's sort
            puts it, for the stamps still to come; a stamp released before it came took the
            older sample).
    """

    def __init__(self, max_age: float, held: int = 4096) -> None:
        """Args:
        max_age: [s] as the fusion's (`ImuGradeConfig.max_age`).
        held: IMU samples kept (the stamps held back need the ones after the oldest of
            them: 4 s at 1 kHz).
        """
        self.max_age = max_age
        self._samples: deque[ImuSample] = deque(maxlen=held)
        self._stamps: deque[tuple[int, T]] = deque()
        self._first = math.nan  # [s] the first stamp: an IMU not heard from yet is awaited since
        self.late = 0

    @property
    def waiting(self) -> int:
        """Stamps held back now."""
        return len(self._stamps)

    @property
    def oldest(self) -> int | None:
        """[ns] the oldest stamp held back (None: none)."""
        return self._stamps[0][0] if self._stamps else None

    def sample(self, sample: ImuSample) -> list[tuple[int, T, ImuSample | None]]:
        """An IMU sample arrived; the stamps it releases, in order (see `stamp`)."""
        if self._samples and sample[0] < self._samples[-1][0]:
            self.late += 1
            ordered = list(self._samples)
            bisect.insort(ordered, sample, key=lambda s: s[0])  # after equal stamps, as sorted
            self._samples = deque(ordered, maxlen=self._samples.maxlen)
        else:
            self._samples.append(sample)
        return self._release()

    def stamp(self, stamp_ns: int, item: T) -> list[tuple[int, T, ImuSample | None]]:
        """A completed stamp [ns] and what it carries; the stamps released now, in order,
        each with the newest IMU sample not later than it (None: none)."""
        self._stamps.append((stamp_ns, item))
        if math.isnan(self._first):
            self._first = stamp_ns * 1e-9
        return self._release()

    def flush(self) -> list[tuple[int, T, ImuSample | None]]:
        """Every stamp held back, released with what has arrived (the IMU will not come)."""
        return self._release(everything=True)

    def _release(self, everything: bool = False) -> list[tuple[int, T, ImuSample | None]]:
        out: list[tuple[int, T, ImuSample | None]] = []
        if not self._stamps:
            return out
        newest_imu = self._samples[-1][0] if self._samples else -math.inf
        # the IMU is behind since its newest sample (or, before its first, since the first
        # stamp): by more than max_age, it is not waited for
        since = self._samples[-1][0] if self._samples else self._first
        gone = everything or since < self._stamps[-1][0] * 1e-9 - self.max_age
        while self._stamps:
            stamp_ns, item = self._stamps[0]
            t = stamp_ns * 1e-9
            if not (gone or newest_imu >= t):
                break
            self._stamps.popleft()
            out.append((stamp_ns, item, self._held(t)))
        return out

    def _held(self, t: float) -> ImuSample | None:
        for sample in reversed(self._samples):
            if sample[0] <= t:
                return sample
        return None
