"""The IMU's mounting learnt online, where the mapping does not state it.

A mapping without ``imu.mount_rpy_deg`` gives the IMU's own three axes (`decode`: the
sensor's specific force and angular rate, no mounting applied). `MountingLearner` averages
them, and the wheels' speed, over windows of ``WINDOW_S`` by stamp, and fits the mounting
(`mounting.fit_mounting`, the fit ``vd calibrate`` makes of a recorded drive) every
``FIT_EVERY`` windows until the drive determines it. From then on the IMU is read through
it (`project`); before, the fusion gets no IMU sample (nan: the force-balance slope goes on
alone), rather than a sensor read in a guessed orientation (an upside-down one read as
aligned gave 3 deg of grade error on the RAV4).

The car's acceleration of window ``j`` is the central difference of the windows' mean speeds,
``(v[j+1] - v[j-1]) / (2 W)`` (a wheel angle's mean speed over a window is its difference
over the window's span), and the specific force it is set against is weighted alike,
``(f[j-1] + 2 f[j] + f[j+1]) / 4``.

Live and offline alike: each stream (the wheel stamps the chain estimates, the IMU's samples
in arrival order) is cut into windows by stamp; a sample stamped before its stream's open
window is left out, in both. Which windows are complete, and so every fit, depends only on
the stamps, not on how the two streams interleave. A mounting fitted when window ``j + 1``
is complete (both streams have a sample in window ``j + 2``) reads the IMU samples stamped
from window ``j + 2`` on (``LearntMounting.from_s``): a live node reads a sample when a wheel
stamp not before it is estimated and the IMU has one not before that stamp (`imu_hold`), by
which time both streams are in window ``j + 2`` and the fit is made, as in a replay.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Final, overload

import numpy as np
import numpy.typing as npt

from vd_observer_node.inputs.errors import MountingNotDeterminedError
from vd_observer_node.inputs.mapping import InputMapping, InputSpec
from vd_observer_node.inputs.mounting import MountingFit, fit_mounting
from vd_observer_node.inputs.rotation import Rows

__all__ = [
    'FIT_EVERY',
    'MAX_WINDOWS',
    'MIN_WINDOWS',
    'WINDOW_S',
    'LearntMounting',
    'MountingLearner',
    'learnt_line',
    'new_learner',
    'project',
    'project_held',
    'project_sample',
    'unstated_mounting_note',
]

FloatArray = npt.NDArray[np.float64]

#: [s] the windows' length: as ``vd calibrate``'s averaging window (long against the wheel
#: speed's quantisation and the IMU's vibration, short against a braking)
WINDOW_S: Final = 0.5
_WINDOW_NS: Final = round(WINDOW_S * 1e9)
#: windows between two fits while none determines the mounting (5 s)
FIT_EVERY: Final = 10
#: the least windows a fit is tried on (20 s: the jackknife's 10 stretches of 2 s each)
MIN_WINDOWS: Final = 40
#: the most windows a fit rests on (the last 20 min): a drive that never shows the mounting
#: (a long steady cruise) keeps neither its memory nor the fits' cost growing
MAX_WINDOWS: Final = 2400


@overload
def project(rows: Rows, force: Sequence[float], rate: Sequence[float]) -> tuple[float, float]: ...
@overload
def project(rows: Rows, force: FloatArray, rate: FloatArray) -> tuple[FloatArray, FloatArray]: ...
def project(rows: Rows, force: Any, rate: Any) -> tuple[Any, Any]:
    """The body's forward specific force and pitch rate from the sensor's vectors.

    The same operations, in the same order, on floats (a live sample) and on arrays (a
    replay's block), so that both give the same bits.

    Args:
        rows: the mounting's rotation body <- sensor by rows (`MountingFit.rows`).
        force: (x, y, z) [m/s^2] of the sensor's specific force: floats, or shape (3, N).
        rate: (x, y, z) [rad/s] of its angular rate (nan: none).

    Returns:
        [m/s^2] the forward specific force and [rad/s] the pitch rate (nose down positive).
    """
    ax, ay, az = rows[0]
    rx, ry, rz = rows[1]
    return (
        ax * force[0] + ay * force[1] + az * force[2],
        rx * rate[0] + ry * rate[1] + rz * rate[2],
    )


@dataclass(frozen=True)
class LearntMounting:
    """A mounting the drive has determined.

    Attributes:
        fit: the fit (angles, their spread, rows).
        from_s: [s] the IMU samples stamped at or after this are read through it.
        windows: the windows the fit saw (``WINDOW_S`` each).
    """

    fit: MountingFit
    from_s: float
    windows: int


class _Windows:
    """One stream cut into windows by stamp: each closed window's summary, by index."""

    def __init__(self) -> None:
        self.index = -1  # the open window's (-1: none yet)
        self.first = -1  # the first window's
        self.stamps: list[int] = []
        self.rows: list[Sequence[float]] = []
        self.closed: dict[int, FloatArray] = {}
        self.early = 0  # samples stamped before the open window, left out

    def add(self, stamp_ns: int, row: Sequence[float]) -> int | None:
        """A sample; the index of the window it closes (None: none)."""
        index = stamp_ns // _WINDOW_NS
        if index < self.index:
            self.early += 1
            return None
        closing = None
        if index > self.index:
            closing = self.index if self.index >= 0 else None
            self.first = index if self.index < 0 else self.first
            self.index = index
        self.stamps.append(stamp_ns)
        self.rows.append(row)
        return closing

    def take(self) -> tuple[npt.NDArray[np.int64], FloatArray]:
        """The closing window's samples (all but the newest, which opened the next)."""
        stamps = np.array(self.stamps[:-1], dtype=np.int64)
        rows = np.array(self.rows[:-1], dtype=np.float64)
        del self.stamps[:-1], self.rows[:-1]
        return stamps, rows


class MountingLearner:
    """The mounting learnt from the wheel stamps and the IMU's samples (module docstring).

    Attributes:
        radius: [m] the wheels' effective rolling radius (their decoded values are angles
            [rad] or speeds [rad/s]).
        angles: the wheel values are angles (else speeds).
        learnt: the mounting, once the drive determines it (None: not yet).
        reason: why the last fit did not determine it ('' before the first fit).
    """

    def __init__(self, radius: float, angles: bool) -> None:
        self.radius = radius
        self.angles = angles
        self.learnt: LearntMounting | None = None
        self.reason = ''
        self._wheels = _Windows()
        self._imu = _Windows()
        self._complete = -1  # windows up to this one are closed on both streams (-1: none)
        self._force: list[FloatArray] = []  # each complete window's mean specific force
        self._speed: list[float] = []  # [m/s] its mean speed
        self._taken = 0  # complete windows taken in (the fits are every FIT_EVERY of them)

    def wheels(self, stamp_ns: int, values: Sequence[float]) -> None:
        """A wheel stamp [ns] the chain estimates, with its wheels' values (shape (4,), [rad]
        or [rad/s])."""
        if self.learnt is None:
            closing = self._wheels.add(stamp_ns, values)
            if closing is not None:
                stamps, rows = self._wheels.take()
                self._wheels.closed[closing] = self._mean_speed(stamps, rows)
                self._advance()

    def imu(self, stamp_ns: int, vectors: Sequence[float]) -> None:
        """An IMU sample [ns]: its specific force (x, y, z) [m/s^2] and angular rate (x, y, z)
        [rad/s] in the sensor's frame (the rate is not used)."""
        if self.learnt is None:
            closing = self._imu.add(stamp_ns, vectors[:3])
            if closing is not None:
                _, rows = self._imu.take()
                self._imu.closed[closing] = rows.mean(axis=0)
                self._advance()

    def wheels_many(self, stamps_ns: npt.NDArray[np.int64], values: FloatArray) -> None:
        """`wheels` for each row, in order (a replay's block)."""
        for stamp, row in zip(stamps_ns.tolist(), values.tolist(), strict=True):
            if self.learnt is not None:
                return
            self.wheels(stamp, row)

    def imu_many(self, stamps_ns: npt.NDArray[np.int64], values: FloatArray) -> None:
        """`imu` for each row of shape (N, 6), in order (a replay's block)."""
        for stamp, row in zip(stamps_ns.tolist(), values.tolist(), strict=True):
            if self.learnt is not None:
                return
            self.imu(stamp, row)

    def _mean_speed(self, stamps: npt.NDArray[np.int64], rows: FloatArray) -> FloatArray:
        """[m/s] a wheel window's mean speed (nan: a wheel unknown, or one angle sample)."""
        mean = rows.mean(axis=1)
        if not self.angles:
            return np.array([self.radius * float(mean.mean())])
        span = (int(stamps[-1]) - int(stamps[0])) * 1e-9
        if span <= 0.0:
            return np.array([math.nan])
        return np.array([self.radius * float(mean[-1] - mean[0]) / span])

    def _advance(self) -> None:
        """Take in the windows now closed on both streams; fit every ``FIT_EVERY``."""
        if self._complete < 0:  # from the first window both streams have samples in
            if self._wheels.first < 0 or self._imu.first < 0:
                return
            self._complete = max(self._wheels.first, self._imu.first) - 1
        complete = min(self._wheels.index, self._imu.index) - 1
        nan3 = np.full(3, math.nan)
        while self._complete < complete:
            self._complete += 1
            j = self._complete
            self._force.append(self._imu.closed.pop(j, nan3))
            self._speed.append(float(self._wheels.closed.pop(j, nan3[:1])[0]))
            if len(self._speed) > MAX_WINDOWS + 2:
                del self._force[0], self._speed[0]
            self._taken += 1
            windows = self._taken - 2  # the rows with both neighbours
            if windows >= MIN_WINDOWS and windows % FIT_EVERY == 0:
                self._fit(j)
                if self.learnt is not None:
                    return

    def _fit(self, newest: int) -> None:
        f = np.array(self._force)
        v = np.array(self._speed)
        accel = (v[2:] - v[:-2]) / (2.0 * WINDOW_S)
        force = 0.25 * (f[:-2] + 2.0 * f[1:-1] + f[2:])
        try:
            fit = fit_mounting(force, accel)
        except MountingNotDeterminedError as error:
            self.reason = str(error)
            return
        # the fit rests on windows up to `newest`, complete once both streams are in the
        # window after it: the samples from that one on are read through it
        self.learnt = LearntMounting(fit, (newest + 1) * WINDOW_S, accel.size)
        self._force.clear()
        self._speed.clear()


def unstated_mounting_note(spec: InputSpec | None) -> str:
    """What to say of the mapping's ``imu`` where it learns its mounting ('' otherwise):
    `vd replay` prints it under its ``imu:`` line, ``pipeline_node`` logs it at start."""
    if spec is None or not spec.learns_mounting:
        return ''
    return (
        'the mapping states no imu.mount_rpy_deg: the mounting is learnt from the drive and '
        'the IMU fused from then on; to fuse it from the first stamp, state the angles '
        'learnt, or those vd calibrate learns from a whole recorded drive (docs/calibrate.md)'
    )


def learnt_line(learnt: LearntMounting | None, reason: str, first_s: float | None = None) -> str:
    """One line on the mounting learnt online (`vd replay`, ``pipeline_node``'s log).

    Args:
        reason: why it is not learnt (`MountingLearner.reason`).
        first_s: [s] the drive's first stamp (the time it is fused from is said after it;
            None: as a stamp).
    """
    if learnt is None:
        return f'mounting not learnt: {reason or "too short a drive"}'
    fit = learnt.fit
    rpy = ', '.join(f'{a:.1f}' for a in fit.rpy_deg)
    std = ', '.join(f'{a:.1f}' for a in fit.std_deg)
    return (
        f'mounting learnt: [{rpy}] ± [{std}] deg (roll, pitch, yaw) from {learnt.windows} '
        'windows; '
        + (
            f'the IMU is fused from stamp {learnt.from_s:.1f} s'
            if first_s is None
            else f'the IMU is fused from {learnt.from_s - first_s:.1f} s into the drive'
        )
    )


def new_learner(mapping: InputMapping, radius: float) -> MountingLearner | None:
    """The learner of the mapping's IMU mounting (None: no IMU, or its mounting is stated).

    Args:
        radius: [m] the effective rolling radius the wheels' values are read with.
    """
    if mapping.imu is None or not mapping.imu.learns_mounting:
        return None
    return MountingLearner(radius, angles=mapping.wheels.name == 'wheel_angles')


def project_sample(
    learnt: LearntMounting | None, sample: Sequence[float] | None
) -> tuple[float, ...] | None:
    """A live held IMU sample (stamp [s], then `imu`'s six values) as the fusion reads it:
    stamp, forward specific force, pitch rate; None before the mounting applies."""
    if learnt is None or sample is None or not sample[0] >= learnt.from_s:
        return None
    force, rate = project(learnt.fit.rows, sample[1:4], sample[4:7])
    return (sample[0], force, rate)


def project_held(learnt: LearntMounting | None, held: FloatArray) -> FloatArray:
    """`project_sample` for a replay's held samples.

    Args:
        held: shape (N, 7), the stamp [s] (nan: none) and the six values of each stamp's
            sample.

    Returns:
        shape (N, 3): stamp, forward specific force, pitch rate; nan rows where
        `project_sample` gives None.
    """
    out = np.full((held.shape[0], 3), np.nan)
    if learnt is None:
        return out
    use = held[:, 0] >= learnt.from_s
    cols = held[use]
    force, rate = project(learnt.fit.rows, cols[:, 1:4].T, cols[:, 4:7].T)
    out[use, 0] = cols[:, 0]
    out[use, 1] = force
    out[use, 2] = rate
    return out
