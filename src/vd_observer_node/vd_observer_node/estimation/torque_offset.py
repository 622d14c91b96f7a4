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

`torque_offset_step` is the pure step; `TorqueOffsetEstimator` keeps its state. The compiled
twin is `vd_observer_node.kernel.torque_offset`, tested equal.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any, Final, NamedTuple

import numpy as np
from numpy.typing import NDArray

from vd_observer_node.errors import ConfigurationError
from vd_observer_node.estimation.faults import RESTART_FAULTS, classify_stamp

__all__ = [
    'OFFSET_MESSAGE_FIELDS',
    'TorqueOffset',
    'TorqueOffsetConfig',
    'TorqueOffsetEstimator',
    'TorqueOffsetState',
    'offset_estimate',
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


class TorqueOffsetState(NamedTuple):
    """The estimator's memory (the compiled twin keeps the same slots in this order).

    Attributes:
        last_t: [s] last stamp taken (nan before any).
        t0: [s] start of the current neutral episode (nan: not in one).
        w0: [rad/s] engine speed at t0.
        t1: [s] latest stamp of the episode.
        w1: [rad/s] engine speed at t1.
        torque1: [N m] engine-torque signal at t1.
        integral: [N m s] trapezoid integral of the signal from t0 to t1.
        sum_w: [s] total duration of the episodes used.
        sum_wb: [N m s] sum of duration * episode offset.
        sum_wbb: [N^2 m^2 s] sum of duration * episode offset^2.
        sum_ww: [s^2] sum of duration^2 (for the effective number of episodes).
        episodes: number of episodes used.
        clamped: number of stamps at which the estimate was clamped.
    """

    last_t: float = math.nan
    t0: float = math.nan
    w0: float = 0.0
    t1: float = 0.0
    w1: float = 0.0
    torque1: float = 0.0
    integral: float = 0.0
    sum_w: float = 0.0
    sum_wb: float = 0.0
    sum_wbb: float = 0.0
    sum_ww: float = 0.0
    episodes: float = 0.0
    clamped: float = 0.0


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


def offset_estimate(config: TorqueOffsetConfig, state: TorqueOffsetState) -> TorqueOffset:
    """The estimate a state holds (offset clamped to +-``max_offset``)."""
    if state.episodes < 1.0:
        return TorqueOffset(0.0, config.max_offset, False, 0.0, 0, False)
    mean = state.sum_wb / state.sum_w
    std = config.max_offset
    if state.episodes >= 2.0:
        variance = max(state.sum_wbb / state.sum_w - mean * mean, 0.0)
        n_eff = state.sum_w * state.sum_w / state.sum_ww
        std = math.sqrt(variance / max(n_eff - 1.0, 1e-9))
    offset = min(max(mean, -config.max_offset), config.max_offset)
    converged = (
        state.episodes >= config.min_episodes
        and state.sum_w >= config.min_time
        and std <= config.converged_std
    )
    return TorqueOffset(
        offset, std, converged, offset if converged else 0.0, int(state.episodes), offset != mean
    )


def _closed(
    config: TorqueOffsetConfig, inertia: float, state: TorqueOffsetState
) -> TorqueOffsetState:
    """The state with its neutral episode ended (used if long enough)."""
    duration = state.t1 - state.t0
    ended = state._replace(t0=math.nan)
    if duration < config.min_episode_time:
        return ended
    b = (state.integral - inertia * (state.w1 - state.w0)) / duration
    return ended._replace(
        sum_w=state.sum_w + duration,
        sum_wb=state.sum_wb + duration * b,
        sum_wbb=state.sum_wbb + duration * b * b,
        sum_ww=state.sum_ww + duration * duration,
        episodes=state.episodes + 1.0,
    )


def torque_offset_step(
    config: TorqueOffsetConfig,
    inertia: float,
    state: TorqueOffsetState,
    t: float,
    engine_torque: float,
    gear: int,
    engine_speed: float,
) -> tuple[TorqueOffset, TorqueOffsetState]:
    """One stamp of the offset estimator (pure).

    Args:
        config: settings.
        inertia: J_e [kg m^2], the engine's (crankshaft, flywheel, clutch disc).
        state: the state after the previous stamp (`TorqueOffsetState()` at the start).
        t: stamp [s]; a non-finite one is ignored.
        engine_torque: engine-torque signal [N m].
        gear: engaged gear (`drivetrain.gear_number`): 0 is neutral.
        engine_speed: [rad/s] crankshaft speed (nan if not measured: nothing is learnt).

    Returns:
        (the estimate after the stamp, the next state).
    """
    last = None if math.isnan(state.last_t) else state.last_t
    kind, dt = classify_stamp(last, t, config.max_gap)
    if dt is None:
        return offset_estimate(config, state), state  # non-finite, repeated, slightly older
    if kind in RESTART_FAULTS:
        # a time jump: start again, as the observers do (the fault total stays)
        state = TorqueOffsetState(clamped=state.clamped)
    state = state._replace(last_t=t)
    neutral = gear == 0 and math.isfinite(engine_torque) and math.isfinite(engine_speed)
    if not math.isnan(state.t0):
        if neutral:
            state = state._replace(
                integral=state.integral + 0.5 * (state.torque1 + engine_torque) * (t - state.t1),
                t1=t,
                w1=engine_speed,
                torque1=engine_torque,
            )
        else:
            state = _closed(config, inertia, state)
    elif neutral:
        state = state._replace(
            t0=t, w0=engine_speed, t1=t, w1=engine_speed, torque1=engine_torque, integral=0.0
        )
    estimate = offset_estimate(config, state)
    if estimate.clamped:
        state = state._replace(clamped=state.clamped + 1.0)
    return estimate, state


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
    """`torque_offset_step` with its state kept.

    Attributes:
        config: settings.
        inertia: J_e [kg m^2].
        state: the state after the last stamp.
        estimate: the estimate after the last stamp.
    """

    def __init__(self, config: TorqueOffsetConfig, inertia: float) -> None:
        """Start with nothing learnt."""
        self.config = config
        self.inertia = inertia
        self.state = TorqueOffsetState()
        self.estimate = offset_estimate(config, self.state)

    def update(
        self, t: float, engine_torque: float, gear: int, engine_speed: float
    ) -> TorqueOffset:
        """The estimate after stamp t [s] (`torque_offset_step`)."""
        self.estimate, self.state = torque_offset_step(
            self.config, self.inertia, self.state, t, engine_torque, gear, engine_speed
        )
        return self.estimate
