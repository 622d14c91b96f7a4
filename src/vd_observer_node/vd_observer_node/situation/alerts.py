"""Early detection of critical wheel situations, with hysteresis (ROS-free).

Three alert kinds per wheel (FL=0, FR=1, RL=2, RR=3):

* ``traction`` (code 0): excessive drive slip, traction control would act. Metric: the slip
  ratio ``s`` while the slip velocity ``omega R - v`` exceeds ``min_slip_velocity``, the wheel
  is driven (torque > ``min_wheel_torque``) and the tyre force is not braking (``mu >= 0`` or
  invalid).
* ``lock`` (code 1): wheel lock tendency under braking, ABS would act. Metric: ``-s`` while
  ``omega R - v < -min_slip_velocity``, the wheel is braked (torque < ``-min_wheel_torque``)
  and the tyre force is not driving (``mu <= 0`` or invalid). The torque and force-sign gates
  reject wheel-speed transients: when a spinning wheel re-grips during a gear shift, a fast
  wheel-speed estimate overshoots below the road speed while no brake acts; an undriven rear
  wheel cannot spin.
* ``low_friction`` (code 2): the utilised friction approaches the available one. Metric: the
  utilisation ``|mu| / mu_max`` of a wheel with a valid ``mu`` (``mu_max`` of its axle from
  `vd_observer_node.situation.friction_potential`), and 1 for a wheel past its peak slip (slip
  beyond ``slip_peak`` with a force of the same sign and the slip-velocity gate open): past the
  peak the tyre uses all the friction there is, even though its mu has dropped below the peak.

Each metric goes through `classify_level` (two thresholds per level, ``*_on`` to enter,
``*_off`` to leave: a hysteresis band) and then `step_channel` (debounce in time: a higher
level must hold ``raise_hold`` seconds to be reported, a lower one ``release_hold`` seconds).
The onset stamp of an alert is the first stamp of the uninterrupted run of samples that raised
it from level 0, so the node can report when the situation began, not when it was confirmed.

Pure step functions (`slip_velocity`, `classify_level`, `step_channel`, `alert_metrics`) and a
stateful wrapper (`AlertMonitor`) that the node calls per estimate.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Any, Final

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vd_observer_node.errors import InputShapeError, ObserverError

__all__ = [
    'ALERT_KINDS',
    'LEVEL_CRITICAL',
    'LEVEL_OK',
    'LEVEL_WARNING',
    'Alert',
    'AlertConfig',
    'AlertConfigError',
    'AlertMonitor',
    'ChannelState',
    'LevelThresholds',
    'alert_metrics',
    'classify_level',
    'slip_velocity',
    'step_channel',
]

FloatArray = NDArray[np.float64]

#: Alert kinds; the index is the message code (uint8 kind).
ALERT_KINDS: Final = ('traction', 'lock', 'low_friction')
LEVEL_OK: Final = 0
LEVEL_WARNING: Final = 1
LEVEL_CRITICAL: Final = 2


class AlertConfigError(ObserverError):
    """An alert threshold or hold time is invalid (names the setting and the rule)."""


@dataclass(frozen=True)
class LevelThresholds:
    """Hysteresis thresholds of one metric (a larger metric is worse).

    Attributes:
        warning_on: metric >= this enters WARNING.
        warning_off: metric < this leaves WARNING (to OK); < warning_on.
        critical_on: metric >= this enters CRITICAL; >= warning_on.
        critical_off: metric < this leaves CRITICAL (to WARNING or OK); < critical_on.
    """

    warning_on: float
    warning_off: float
    critical_on: float
    critical_off: float

    def __post_init__(self) -> None:
        values = (self.warning_on, self.warning_off, self.critical_on, self.critical_off)
        if not all(math.isfinite(v) for v in values):
            raise AlertConfigError(f'thresholds must be finite, got {values}')
        if not self.warning_off < self.warning_on:
            raise AlertConfigError(
                f'warning_off {self.warning_off} must be < warning_on {self.warning_on}'
            )
        if not self.critical_off < self.critical_on:
            raise AlertConfigError(
                f'critical_off {self.critical_off} must be < critical_on {self.critical_on}'
            )
        if not (self.warning_on <= self.critical_on and self.warning_off <= self.critical_off):
            raise AlertConfigError(
                'critical thresholds must not be below the warning ones, got '
                f'warning {self.warning_on}/{self.warning_off}, '
                f'critical {self.critical_on}/{self.critical_off}'
            )


def _slip_thresholds() -> LevelThresholds:
    return LevelThresholds(warning_on=0.12, warning_off=0.08, critical_on=0.25, critical_off=0.18)


def _utilisation_thresholds() -> LevelThresholds:
    return LevelThresholds(warning_on=0.8, warning_off=0.65, critical_on=0.95, critical_off=0.85)


@dataclass(frozen=True)
class AlertConfig:
    """Settings of the alert detectors.

    Attributes:
        traction: thresholds on the drive slip ratio [-].
        lock: thresholds on the brake slip ratio magnitude [-].
        low_friction: thresholds on the utilisation |mu| / mu_max [-].
        min_slip_velocity: |omega R - v| [m/s] below which a slip ratio is not alarming (at
            walking pace the ratio of two small speeds is large for a harmless creep).
        min_wheel_torque: [N m] a wheel counts as driven above this wheel torque and as
            braked below its negative (traction and lock gates).
        raise_hold: a higher level must hold this long [s] before it is reported.
        release_hold: a lower level must hold this long [s] before it is reported.
    """

    traction: LevelThresholds = field(default_factory=_slip_thresholds)
    lock: LevelThresholds = field(default_factory=_slip_thresholds)
    low_friction: LevelThresholds = field(default_factory=_utilisation_thresholds)
    min_slip_velocity: float = 0.3
    min_wheel_torque: float = 20.0
    raise_hold: float = 0.01
    release_hold: float = 0.3

    def __post_init__(self) -> None:
        for name in ('min_slip_velocity', 'min_wheel_torque', 'raise_hold', 'release_hold'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise AlertConfigError(f'{name} must be finite and >= 0, got {value}')

    @classmethod
    def from_mapping(cls, data: dict[str, Any]) -> AlertConfig:
        """Build from a flat mapping (e.g. ROS parameters).

        Threshold keys are ``<kind>.<threshold>``, e.g. ``traction.warning_on``; the others
        are the field names.

        Raises:
            AlertConfigError: unknown key or invalid value.
        """
        nested: dict[str, dict[str, float]] = {k: {} for k in ALERT_KINDS}
        flat: dict[str, Any] = {}
        scalar_names = {f.name for f in fields(cls)} - set(ALERT_KINDS)
        threshold_names = {f.name for f in fields(LevelThresholds)}
        for key, value in data.items():
            kind, _, name = key.partition('.')
            if kind in nested and name in threshold_names:
                nested[kind][name] = float(value)
            elif key in scalar_names:
                flat[key] = value
            else:
                raise AlertConfigError(f'unknown alert setting {key!r}')
        defaults = cls()
        kwargs: dict[str, Any] = dict(flat)
        for kind, values in nested.items():
            if values:
                base = getattr(defaults, kind)
                merged = {f.name: values.get(f.name, getattr(base, f.name)) for f in fields(base)}
                kwargs[kind] = LevelThresholds(**merged)
        return cls(**kwargs)


def slip_velocity(omega: ArrayLike, speed: float, radius: float) -> FloatArray:
    """Slip velocity omega R - v of each wheel.

    Args:
        omega: shape (4,), [rad/s].
        speed: body speed v [m/s].
        radius: effective rolling radius R [m].

    Returns:
        shape (4,), [m/s], positive when the wheel spins faster than the road.
    """
    out: FloatArray = np.asarray(omega, dtype=float) * radius - speed
    return out


def classify_level(value: float, level: int, thresholds: LevelThresholds) -> int:
    """Level of a metric with a hysteresis band (pure).

    Args:
        value: metric (non-finite counts as OK).
        level: level reported so far (LEVEL_OK, LEVEL_WARNING or LEVEL_CRITICAL).
        thresholds: on/off thresholds.

    Returns:
        The target level: entering a level needs ``*_on``, leaving it needs ``< *_off``.
    """
    if not math.isfinite(value):
        return LEVEL_OK
    th = thresholds
    if value >= th.critical_on or (level == LEVEL_CRITICAL and value >= th.critical_off):
        return LEVEL_CRITICAL
    if value >= th.warning_on or (level >= LEVEL_WARNING and value >= th.warning_off):
        return LEVEL_WARNING
    return LEVEL_OK


@dataclass(frozen=True)
class ChannelState:
    """Debounce state of one (kind, wheel) channel.

    Attributes:
        level: reported level.
        onset: [s] onset stamp of the reported alert (nan while OK).
        pending_level: level waiting for its hold time (== level if none).
        pending_since: [s] first stamp of the pending level (nan if none).
        run_start: [s] first stamp of the current uninterrupted run of non-OK targets
            (nan while the target is OK): the onset once the alert is confirmed.
    """

    level: int = LEVEL_OK
    onset: float = math.nan
    pending_level: int = LEVEL_OK
    pending_since: float = math.nan
    run_start: float = math.nan

    @property
    def active(self) -> bool:
        """True while the reported level is WARNING or CRITICAL."""
        return self.level > LEVEL_OK


def step_channel(
    state: ChannelState, t: float, target: int, raise_hold: float, release_hold: float
) -> ChannelState:
    """Debounce one channel in time (pure).

    Args:
        state: state before stamp t.
        t: stamp [s].
        target: level wanted by the metric at t (from `classify_level`).
        raise_hold: [s] a higher target must persist this long to be reported.
        release_hold: [s] a lower target must persist this long to be reported.

    Returns:
        The state after stamp t.
    """
    run_start = state.run_start
    if target == LEVEL_OK:
        run_start = math.nan
    elif math.isnan(run_start):
        run_start = t
    if target == state.level:
        return ChannelState(state.level, state.onset, target, math.nan, run_start)
    if target != state.pending_level or math.isnan(state.pending_since):
        pending_since = t
    else:
        pending_since = state.pending_since
    hold = raise_hold if target > state.level else release_hold
    if t - pending_since >= hold:
        if target == LEVEL_OK:
            onset = math.nan
        elif state.level == LEVEL_OK:
            onset = run_start
        else:
            onset = state.onset
        return ChannelState(target, onset, target, math.nan, run_start)
    return ChannelState(state.level, state.onset, target, pending_since, run_start)


@dataclass(frozen=True)
class Alert:
    """One alert record, as the node publishes it.

    Attributes:
        kind: 'traction', 'lock' or 'low_friction' (message code = ALERT_KINDS.index).
        wheel: 0..3, order FL, FR, RL, RR.
        level: LEVEL_OK, LEVEL_WARNING or LEVEL_CRITICAL.
        active: level > LEVEL_OK.
        onset: [s] stamp at which the situation began (nan while inactive).
        detected: [s] stamp at which the alert became active (nan while inactive);
            detected - onset is the confirmation time.
    """

    kind: str
    wheel: int
    level: int
    active: bool
    onset: float
    detected: float

    @property
    def kind_code(self) -> int:
        """uint8 code of the kind in the message."""
        return ALERT_KINDS.index(self.kind)


def _wheels(name: str, value: ArrayLike, dtype: type = float) -> NDArray[Any]:
    array: NDArray[Any] = np.asarray(value, dtype=dtype)
    if array.shape != (4,):
        raise InputShapeError(f'{name} must have shape (4,), got {array.shape}')
    return array


def alert_metrics(
    slip: ArrayLike,
    slip_vel: ArrayLike,
    wheel_torque: ArrayLike,
    mu: ArrayLike,
    mu_valid: ArrayLike,
    mu_max: ArrayLike,
    slip_peak: ArrayLike,
    config: AlertConfig,
) -> FloatArray:
    """Metric of every (kind, wheel) channel (pure).

    Args:
        slip: shape (4,), [-] slip ratio, positive driving.
        slip_vel: shape (4,), [m/s] omega R - v.
        wheel_torque: shape (4,), [N m] drive minus brake torque.
        mu: shape (4,), [-] utilised friction.
        mu_valid: shape (4,), bool.
        mu_max: shape (4,), [-] available friction of each wheel's axle.
        slip_peak: shape (4,), [-] slip magnitude at mu_max.
        config: gates (min_slip_velocity, min_wheel_torque).

    Returns:
        shape (3, 4): rows traction, lock, low_friction; 0 where a gate is closed, nan for
        non-finite inputs (treated as OK by `classify_level`).

    Raises:
        InputShapeError: an input is not shape (4,).
    """
    s = _wheels('slip', slip)
    sv = _wheels('slip_velocity', slip_vel)
    torque = _wheels('wheel_torque', wheel_torque)
    m = _wheels('mu', mu)
    ok = _wheels('mu_valid', mu_valid, bool)
    mmax = _wheels('mu_max', mu_max)
    speak = _wheels('slip_peak', slip_peak)
    gate = config.min_slip_velocity
    driving = (~ok | (m >= 0.0)) & (torque > config.min_wheel_torque)
    braking = (~ok | (m <= 0.0)) & (torque < -config.min_wheel_torque)
    out: FloatArray = np.zeros((3, 4))
    np.copyto(out[0], s, where=(sv > gate) & driving)
    np.copyto(out[1], -s, where=(sv < -gate) & braking)
    # mu_max <= 0 or nan never divides: the utilisation stays 0 there.
    np.divide(np.abs(m), mmax, out=out[2], where=ok & (mmax > 0.0))
    with np.errstate(invalid='ignore'):
        past_peak = ok & (np.abs(sv) > gate) & (np.abs(s) >= speak) & (np.sign(s) == np.sign(m))
    out[2] = np.where(past_peak, np.maximum(out[2], 1.0), out[2])
    bad = ~(np.isfinite(s) & np.isfinite(sv) & np.isfinite(torque))
    out[:2, bad] = math.nan
    out[2, ~(np.isfinite(m) & np.isfinite(mmax))] = math.nan
    return out


class AlertMonitor:
    """Stateful detectors of all (kind, wheel) channels; the node calls `update` per estimate."""

    def __init__(self, config: AlertConfig | None = None) -> None:
        """Create the monitor.

        Args:
            config: settings; defaults if None.
        """
        self.config = config or AlertConfig()
        self.reset()

    def reset(self) -> None:
        """All channels back to OK."""
        self.channels = [[ChannelState() for _ in range(4)] for _ in ALERT_KINDS]
        self._detected = np.full((len(ALERT_KINDS), 4), math.nan)
        self._t = math.nan
        self._records = [self._record(k, w) for k in range(len(ALERT_KINDS)) for w in range(4)]
        self.last: tuple[Alert, ...] = tuple(self._records)

    def _record(self, k: int, w: int) -> Alert:
        channel = self.channels[k][w]
        return Alert(
            kind=ALERT_KINDS[k],
            wheel=w,
            level=channel.level,
            active=channel.active,
            onset=channel.onset,
            detected=float(self._detected[k, w]),
        )

    def update(
        self,
        t: float,
        slip: ArrayLike,
        slip_vel: ArrayLike,
        wheel_torque: ArrayLike,
        mu: ArrayLike,
        mu_valid: ArrayLike,
        mu_max: ArrayLike,
        slip_peak: ArrayLike,
    ) -> tuple[Alert, ...]:
        """Advance all channels to stamp t.

        Args:
            t: stamp [s]; non-finite or non-increasing: the previous records are returned.
            slip: shape (4,), [-] slip ratio, positive driving.
            slip_vel: shape (4,), [m/s] omega R - v (see `slip_velocity`).
            wheel_torque: shape (4,), [N m] drive minus brake torque.
            mu: shape (4,), [-] utilised friction.
            mu_valid: shape (4,), bool.
            mu_max: shape (4,), [-] available friction per wheel
                (`FrictionPotential.wheel_mu_max()`).
            slip_peak: shape (4,), [-] slip at mu_max per wheel
                (`FrictionPotential.wheel_slip_peak()`).

        Returns:
            12 records, kinds in ALERT_KINDS order, wheels 0..3 within each kind.

        Raises:
            InputShapeError: an input is not shape (4,).
        """
        metrics = alert_metrics(
            slip, slip_vel, wheel_torque, mu, mu_valid, mu_max, slip_peak, self.config
        )
        if not math.isfinite(t) or (math.isfinite(self._t) and t <= self._t):
            return self.last
        self._t = t
        cfg = self.config
        thresholds = (cfg.traction, cfg.lock, cfg.low_friction)
        changed = False
        for k in range(len(ALERT_KINDS)):
            for w in range(4):
                state = self.channels[k][w]
                target = classify_level(float(metrics[k, w]), state.level, thresholds[k])
                if (
                    target == LEVEL_OK
                    and state.level == LEVEL_OK
                    and state.pending_level == LEVEL_OK
                    and math.isnan(state.run_start)
                ):
                    continue  # the common quiet case: step_channel would return it unchanged
                new = step_channel(state, t, target, cfg.raise_hold, cfg.release_hold)
                self.channels[k][w] = new
                if new.level != state.level:
                    if state.level == LEVEL_OK:
                        self._detected[k, w] = t
                    elif new.level == LEVEL_OK:
                        self._detected[k, w] = math.nan
                    changed = True
                    self._records[4 * k + w] = self._record(k, w)
        if changed:
            self.last = tuple(self._records)
        return self.last

    def active(self) -> tuple[Alert, ...]:
        """The active records of the last update."""
        return tuple(a for a in self.last if a.active)
