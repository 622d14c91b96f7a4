"""Offset of the engine-torque signal, learnt while the gearbox is in neutral (issue 16).

The engine path (`drivetrain.py`) takes the engine torque a car reports on CAN as exact. It
comes from the engine control unit's map, and an offset ``b`` of a few N m there reaches the
wheels multiplied by the overall ratio (14 in first gear): +-10 N m at the crankshaft bias the
slope by ~2 deg RMS on ``mass_drive``. While the gearbox is in neutral (gear 0: the simulator
reports 0 while the clutch is open in a shift), nothing but the engine's own inertia takes
the net torque, ``J_e * d(omega_e)/dt = T_signal - b``, so over one neutral episode from t0
to t1::

    b = (integral of T_signal dt  -  J_e * (omega_e(t1) - omega_e(t0))) / (t1 - t0)

The engine speed is not differentiated (its noise enters at the two ends only), and neither
the slope nor the mass enters: the offset is learnt apart from what the estimator estimates.
The integral is the trapezoid rule over the episode's samples. Episodes shorter than
``min_episode_time`` are skipped (the clutch may not be fully open); the others are averaged
weighted by their duration. The estimate is used (subtracted from the signal before
`drivetrain.engine_wheel_torques`) once ``min_episodes`` episodes and ``min_time`` seconds of
neutral give a mean whose standard deviation is at most ``converged_std``; before that the
signal is taken as it is. The mean is clamped to +-``max_offset``. A gap or a stamp older than
``max_gap`` restarts the learning, as it restarts the observers.

`torque_offset_step` is the step (compiled with numba, plain Python with ``VD_JIT=0``) on
numpy records with named fields: the settings (`offset_params`), the state
(`new_offset_state`) and the estimate it writes (`new_offset_estimate`);
`TorqueOffsetEstimator` owns the records and calls it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any, Final, NamedTuple

import numpy as np
from numpy.typing import NDArray

from vd_observer_node.errors import ConfigurationError
from vd_observer_node.kernel._jit import jit, new_record

__all__ = [
    'OFFSET_ESTIMATE_DTYPE',
    'OFFSET_MESSAGE_FIELDS',
    'OFFSET_PARAMS_DTYPE',
    'OFFSET_STATE_DTYPE',
    'TorqueOffset',
    'TorqueOffsetConfig',
    'TorqueOffsetEstimator',
    'new_offset_estimate',
    'new_offset_state',
    'offset_estimate',
    'offset_from_record',
    'offset_params',
    'publish_mask',
    'torque_offset_step',
]

#: The estimate as published (vd_msgs/TorqueOffsetEstimate): each field after the header, in
#: CDR order, and the attribute of `TorqueOffset` it carries (`cascade.CascadeResult`'s is
#: ``torque_offset_<attribute>``, ``torque_offset`` for ``offset``).
OFFSET_MESSAGE_FIELDS: Final = (
    ('offset', 'offset'),
    ('offset_std', 'std'),
    ('offset_used', 'used'),
    ('converged', 'converged'),
    ('clamped', 'clamped'),
    ('episodes', 'episodes'),
)


@dataclass(frozen=True)
class TorqueOffsetConfig:
    """Settings of the engine-torque offset estimator.

    Attributes:
        min_episode_time: [s] a neutral episode shorter than this is not used.
        min_episodes: neutral episodes needed before the estimate is used.
        min_time: [s] total neutral time needed before the estimate is used.
        converged_std: [N m] the estimate is used once its standard deviation (of the mean
            over episodes) is at most this.
        max_offset: [N m] the estimate is clamped to +-this (counted as the
            ``torque_offset_clamped`` fault).
        max_gap: [s] a gap longer than this, or a stamp older by more than this, restarts the
            learning.
    """

    min_episode_time: float = 0.1
    min_episodes: int = 3
    min_time: float = 0.5
    converged_std: float = 1.0
    max_offset: float = 30.0
    max_gap: float = 0.5

    def __post_init__(self) -> None:
        for name in ('min_episode_time', 'min_time', 'converged_std', 'max_offset', 'max_gap'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ConfigurationError(f'torque_offset.{name} must be > 0, got {value}')
        if isinstance(self.min_episodes, bool) or int(self.min_episodes) != self.min_episodes:
            raise ConfigurationError(
                f'torque_offset.min_episodes must be an integer, got {self.min_episodes!r}'
            )
        if self.min_episodes < 2:
            # one episode has no spread: its standard deviation would say nothing
            raise ConfigurationError(
                f'torque_offset.min_episodes must be >= 2, got {self.min_episodes}'
            )

    @classmethod
    def from_mapping(cls, data: dict[str, Any]) -> TorqueOffsetConfig:
        """Build from a flat mapping (e.g. ROS parameters).

        Raises:
            ConfigurationError: unknown key or invalid value.
        """
        unknown = set(data) - {f.name for f in fields(cls)}
        if unknown:
            raise ConfigurationError(f'unknown torque-offset settings: {sorted(unknown)}')
        return cls(**data)


#: The settings of `TorqueOffsetConfig` as the step reads them (same names and units).
OFFSET_PARAMS_DTYPE: Final = np.dtype(
    [('min_episode_time', 'f8'), ('min_episodes', 'i8'), ('min_time', 'f8'),
     ('converged_std', 'f8'), ('max_offset', 'f8'), ('max_gap', 'f8')],
    align=True,
)  # fmt: skip
#: The estimator's memory (`new_offset_state` gives the start):
#:
#: * last_t: [s] last stamp taken (nan before any);
#: * t0: [s] start of the current neutral episode (nan: not in one); w0: [rad/s] engine
#:   speed at t0;
#: * t1: [s] latest stamp of the episode; w1: [rad/s] engine speed and torque1: [N m]
#:   engine-torque signal at t1;
#: * integral: [N m s] trapezoid integral of the signal from t0 to t1;
#: * sum_w: [s] total duration of the episodes used; sum_wb: [N m s] sum of duration *
#:   episode offset; sum_wbb: [N^2 m^2 s] sum of duration * episode offset^2; sum_ww: [s^2]
#:   sum of duration^2 (for the effective number of episodes);
#: * episodes: number of episodes used; clamped: stamps at which the estimate was clamped
#:   (a fault total, kept through restarts).
OFFSET_STATE_DTYPE: Final = np.dtype(
    [('last_t', 'f8'), ('t0', 'f8'), ('w0', 'f8'), ('t1', 'f8'), ('w1', 'f8'),
     ('torque1', 'f8'), ('integral', 'f8'), ('sum_w', 'f8'), ('sum_wb', 'f8'),
     ('sum_wbb', 'f8'), ('sum_ww', 'f8'), ('episodes', 'i8'), ('clamped', 'i8')],
    align=True,
)  # fmt: skip


class TorqueOffset(NamedTuple):
    """The estimate after a stamp.

    Attributes:
        offset: [N m] estimated offset of the engine-torque signal (0 before any episode).
        std: [N m] its standard deviation (``max_offset`` while fewer than two episodes).
        converged: the estimate is trusted and used.
        used: [N m] what the engine path subtracts from the signal (``offset`` once
            converged, else 0).
        episodes: neutral episodes used so far.
        clamped: the mean of the episodes is beyond +-``max_offset`` (``offset`` is the bound).
    """

    offset: float
    std: float
    converged: bool
    used: float
    episodes: int
    clamped: bool = False


#: `TorqueOffset` as the step writes it (same fields, ``std`` as ``offset_std``: a record's
#: ``std`` is numpy's method).
OFFSET_ESTIMATE_DTYPE: Final = np.dtype(
    [('offset', 'f8'), ('offset_std', 'f8'), ('converged', 'b1'), ('used', 'f8'),
     ('episodes', 'i8'), ('clamped', 'b1')],
    align=True,
)  # fmt: skip


def offset_params(config: TorqueOffsetConfig) -> np.record:
    """The `OFFSET_PARAMS_DTYPE` record of `config`."""
    p = new_record(OFFSET_PARAMS_DTYPE)
    for name in OFFSET_PARAMS_DTYPE.names or ():
        p[name] = getattr(config, name)
    return p


def new_offset_state() -> np.record:
    """An `OFFSET_STATE_DTYPE` record with nothing learnt (no stamp, no episode)."""
    s = new_record(OFFSET_STATE_DTYPE)
    s.last_t = math.nan
    s.t0 = math.nan
    return s


def new_offset_estimate() -> np.record:
    """A zeroed `OFFSET_ESTIMATE_DTYPE` record for `torque_offset_step` to write into."""
    return new_record(OFFSET_ESTIMATE_DTYPE)


def offset_from_record(out: np.record) -> TorqueOffset:
    """The `TorqueOffset` an `OFFSET_ESTIMATE_DTYPE` record holds."""
    return TorqueOffset(
        float(out.offset),
        float(out.offset_std),
        bool(out.converged),
        float(out.used),
        int(out.episodes),
        bool(out.clamped),
    )


@jit
def offset_estimate(p: np.record, s: np.record, out: np.record) -> None:
    """The estimate state `s` holds, into `out` (offset clamped to +-``max_offset``).

    Args:
        p: `OFFSET_PARAMS_DTYPE` record.
        s: `OFFSET_STATE_DTYPE` record.
        out: `OFFSET_ESTIMATE_DTYPE` record, written.
    """
    if s.episodes < 1:
        out.offset = 0.0
        out.offset_std = p.max_offset
        out.converged = False
        out.used = 0.0
        out.episodes = 0
        out.clamped = False
        return
    mean = s.sum_wb / s.sum_w
    std = p.max_offset
    if s.episodes >= 2:
        variance = max(s.sum_wbb / s.sum_w - mean * mean, 0.0)
        n_eff = s.sum_w * s.sum_w / s.sum_ww
        std = math.sqrt(variance / max(n_eff - 1.0, 1e-9))
    offset = min(max(mean, -p.max_offset), p.max_offset)
    converged = s.episodes >= p.min_episodes and s.sum_w >= p.min_time and std <= p.converged_std
    out.offset = offset
    out.offset_std = std
    out.converged = converged
    out.used = offset if converged else 0.0
    out.episodes = s.episodes
    out.clamped = offset != mean


@jit
def _stamp_dt(last: float, t: float, max_gap: float) -> float:
    """`faults.classify_stamp` for a finite stamp ``t`` after ``last`` (nan: none): the step
    dt [s] (0.0 at the start), nan to hold (repeated or slightly older), -1.0 to restart."""
    if math.isnan(last):
        return 0.0
    dt = t - last
    if dt == 0.0 or (dt < 0.0 and -dt <= max_gap):
        return math.nan
    if dt < 0.0 or dt > max_gap:
        return -1.0
    return dt


@jit
def torque_offset_step(
    p: np.record,
    inertia: float,
    s: np.record,
    t: float,
    engine_torque: float,
    gear: float,
    engine_speed: float,
    out: np.record,
) -> None:
    """One stamp of the offset estimator: advances `s` in place, writes the estimate to `out`.

    Args:
        p: `OFFSET_PARAMS_DTYPE` record (`offset_params`).
        inertia: J_e [kg m^2], the engine's (crankshaft, flywheel, clutch disc).
        s: `OFFSET_STATE_DTYPE` record, the state after the previous stamp
            (`new_offset_state` at the start).
        t: stamp [s]; a non-finite, repeated or slightly older one is ignored (state held).
        engine_torque: engine-torque signal [N m].
        gear: engaged gear (`drivetrain.gear_number`, as a float): 0 is neutral.
        engine_speed: [rad/s] crankshaft speed (nan if not measured: nothing is learnt).
        out: `OFFSET_ESTIMATE_DTYPE` record, written: the estimate after the stamp.
    """
    dt = _stamp_dt(s.last_t, t, p.max_gap) if math.isfinite(t) else math.nan
    if math.isnan(dt):
        offset_estimate(p, s, out)
        return
    if dt < 0.0:
        # a time jump: start again, as the observers do (the fault total stays)
        s.t0 = math.nan
        s.w0 = s.t1 = s.w1 = s.torque1 = s.integral = 0.0
        s.sum_w = s.sum_wb = s.sum_wbb = s.sum_ww = 0.0
        s.episodes = 0
    s.last_t = t
    neutral = gear == 0.0 and math.isfinite(engine_torque) and math.isfinite(engine_speed)
    if not math.isnan(s.t0):
        if neutral:
            s.integral = s.integral + 0.5 * (s.torque1 + engine_torque) * (t - s.t1)
            s.t1 = t
            s.w1 = engine_speed
            s.torque1 = engine_torque
        else:  # the episode ends: used if long enough
            duration = s.t1 - s.t0
            s.t0 = math.nan
            if duration >= p.min_episode_time:
                b = (s.integral - inertia * (s.w1 - s.w0)) / duration
                s.sum_w = s.sum_w + duration
                s.sum_wb = s.sum_wb + duration * b
                s.sum_wbb = s.sum_wbb + duration * b * b
                s.sum_ww = s.sum_ww + duration * duration
                s.episodes = s.episodes + 1
    elif neutral:
        s.t0 = t
        s.w0 = engine_speed
        s.t1 = t
        s.w1 = engine_speed
        s.torque1 = engine_torque
        s.integral = 0.0
    offset_estimate(p, s, out)
    if out.clamped:
        s.clamped = s.clamped + 1


def publish_mask(
    episodes: NDArray[np.int64],
    converged: NDArray[np.bool_],
    previous: tuple[int, bool] | None,
) -> NDArray[np.bool_]:
    """The stamps at which the estimate is published: where it changes.

    The estimate changes only when a neutral episode ends, convergence changes or the learning
    restarts, so the nodes and the replay publish it there (and at the first stamp) instead of
    at every stamp.

    Args:
        episodes: shape (N,), episodes used after each stamp.
        converged: shape (N,), converged after each stamp.
        previous: (episodes, converged) of the last stamp before these (None: these are the
            first).

    Returns:
        shape (N,), bool.
    """
    n = episodes.shape[0]
    if n == 0:
        return np.zeros(0, dtype=bool)
    before_e = np.empty(n, dtype=np.int64)
    before_c = np.empty(n, dtype=bool)
    before_e[1:], before_c[1:] = episodes[:-1], converged[:-1]
    if previous is None:
        before_e[0], before_c[0] = -1, False  # the first stamp is always published
    else:
        before_e[0], before_c[0] = previous
    out: NDArray[np.bool_] = (episodes != before_e) | (converged != before_c)
    return out


class TorqueOffsetEstimator:
    """`torque_offset_step` with its records kept.

    Attributes:
        config: settings.
        inertia: J_e [kg m^2].
        params: `OFFSET_PARAMS_DTYPE` record of `config`.
        state: `OFFSET_STATE_DTYPE` record, the state after the last stamp.
        estimate: the estimate after the last stamp.
    """

    def __init__(self, config: TorqueOffsetConfig, inertia: float) -> None:
        """Start with nothing learnt."""
        self.config = config
        self.inertia = float(inertia)
        self.params = offset_params(config)
        self.state = new_offset_state()
        self._out = new_offset_estimate()
        offset_estimate(self.params, self.state, self._out)
        self.estimate = offset_from_record(self._out)

    def update(
        self, t: float, engine_torque: float, gear: int, engine_speed: float
    ) -> TorqueOffset:
        """The estimate after stamp t [s] (`torque_offset_step`)."""
        torque_offset_step(
            self.params, self.inertia, self.state, float(t), float(engine_torque), float(gear),
            float(engine_speed), self._out,
        )  # fmt: skip
        self.estimate = offset_from_record(self._out)
        return self.estimate
