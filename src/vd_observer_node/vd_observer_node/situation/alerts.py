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

Step functions on named records (`ALERT_PARAMS`, `ALERT_STATE`; compiled with
`vd_observer_node.kernel._jit.jit`): `alert_metrics`, `classify_level`, `step_channel`, all
channels at once in `alerts_update`; and a stateful wrapper (`AlertMonitor`) that the node
calls per estimate.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Any, Final

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vd_observer_node.errors import ConfigurationError, InputShapeError
from vd_observer_node.kernel._jit import jit, new_record

__all__ = [
    'ALERT_INPUT',
    'ALERT_KINDS',
    'ALERT_PARAMS',
    'ALERT_STATE',
    'LEVEL_CRITICAL',
    'LEVEL_OK',
    'LEVEL_WARNING',
    'THRESHOLD_COLUMNS',
    'Alert',
    'AlertConfig',
    'AlertConfigError',
    'AlertMonitor',
    'LevelThresholds',
    'alert_metrics',
    'alert_params',
    'alert_records',
    'alerts_reset',
    'alerts_update',
    'classify_level',
    'slip_velocity',
    'step_channel',
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: Alert kinds; the index is the message code (uint8 kind).
ALERT_KINDS: Final = ('traction', 'lock', 'low_friction')
LEVEL_OK: Final = 0
LEVEL_WARNING: Final = 1
LEVEL_CRITICAL: Final = 2


class AlertConfigError(ConfigurationError):
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


#: Columns of `ALERT_PARAMS.thresholds` (one row per kind, ALERT_KINDS order).
THRESHOLD_COLUMNS: Final = ('warning_on', 'warning_off', 'critical_on', 'critical_off')

#: Settings of the detectors: the gates and hold times of `AlertConfig`, and ``thresholds``
#: (3, 4): per kind (rows, ALERT_KINDS order) the `THRESHOLD_COLUMNS`.
ALERT_PARAMS: Final = np.dtype(
    [
        ('min_slip_velocity', 'f8'),
        ('min_wheel_torque', 'f8'),
        ('raise_hold', 'f8'),
        ('release_hold', 'f8'),
        ('thresholds', 'f8', (3, 4)),
    ],
    align=True,
)
#: State of the detectors; the per-channel fields are shape (3, 4): (kind, wheel).
#:
#: t: [s] stamp of the last update (nan before the first); level: reported level; onset: [s]
#: onset stamp of the reported alert (nan while OK); pending_level: level waiting for its hold
#: time (== level if none); pending_since: [s] first stamp of the pending level (nan if none);
#: run_start: [s] first stamp of the current uninterrupted run of non-OK targets (nan while
#: the target is OK), the onset once the alert is confirmed; detected: [s] stamp at which the
#: reported alert became active (nan while OK).
ALERT_STATE: Final = np.dtype(
    [
        ('t', 'f8'),
        ('level', 'i8', (3, 4)),
        ('onset', 'f8', (3, 4)),
        ('pending_level', 'i8', (3, 4)),
        ('pending_since', 'f8', (3, 4)),
        ('run_start', 'f8', (3, 4)),
        ('detected', 'f8', (3, 4)),
    ],
    align=True,
)
#: One stamp's inputs of the alerts, per wheel (order FL, FR, RL, RR): slip [-] (positive
#: driving), slip_velocity [m/s] omega R - v, torque [N m] drive minus brake, mu [-] utilised
#: friction and mu_valid (0 or 1), mu_max [-] the available friction of the wheel's axle and
#: slip_peak [-] the slip magnitude at mu_max.
ALERT_INPUT: Final = np.dtype(
    [
        ('slip', 'f8', (4,)),
        ('slip_velocity', 'f8', (4,)),
        ('torque', 'f8', (4,)),
        ('mu', 'f8', (4,)),
        ('mu_valid', 'u1', (4,)),  # bool; numba cannot nest an array of b1 in a record
        ('mu_max', 'f8', (4,)),
        ('slip_peak', 'f8', (4,)),
    ],
    align=True,
)


def alert_params(config: AlertConfig) -> Any:
    """The settings as an `ALERT_PARAMS` record (the step functions read it)."""
    rec = new_record(ALERT_PARAMS)
    for name in ('min_slip_velocity', 'min_wheel_torque', 'raise_hold', 'release_hold'):
        setattr(rec, name, getattr(config, name))
    for k, kind in enumerate(ALERT_KINDS):
        th = getattr(config, kind)
        rec.thresholds[k] = [getattr(th, column) for column in THRESHOLD_COLUMNS]
    return rec


@jit
def _sign(x: float) -> float:
    """np.sign of a float (0 stays 0, nan stays nan)."""
    if x > 0.0:
        return 1.0
    if x < 0.0:
        return -1.0
    return x


@jit
def slip_velocity(omega: FloatArray, speed: float, radius: float) -> FloatArray:
    """Slip velocity omega R - v of each wheel.

    Args:
        omega: shape (4,), [rad/s].
        speed: body speed v [m/s].
        radius: effective rolling radius R [m].

    Returns:
        shape (4,), [m/s], positive when the wheel spins faster than the road.
    """
    out = np.empty(omega.shape[0])
    for i in range(omega.shape[0]):
        out[i] = omega[i] * radius - speed
    return out


@jit
def classify_level(value: float, level: int, th: FloatArray) -> int:
    """Level of a metric with a hysteresis band.

    Args:
        value: metric (non-finite counts as OK).
        level: level reported so far (LEVEL_OK, LEVEL_WARNING or LEVEL_CRITICAL).
        th: shape (4,), the thresholds in `THRESHOLD_COLUMNS` order (a row of
            `ALERT_PARAMS.thresholds`).

    Returns:
        The target level: entering a level needs ``*_on``, leaving it needs ``< *_off``.
    """
    if not math.isfinite(value):
        return LEVEL_OK
    if value >= th[2] or (level == LEVEL_CRITICAL and value >= th[3]):
        return LEVEL_CRITICAL
    if value >= th[0] or (level >= LEVEL_WARNING and value >= th[1]):
        return LEVEL_WARNING
    return LEVEL_OK


@jit
def alert_metrics(p: Any, inp: Any, out: FloatArray) -> None:
    """Metric of every (kind, wheel) channel (the module docstring defines them).

    Args:
        p: `ALERT_PARAMS` record (gates min_slip_velocity, min_wheel_torque).
        inp: `ALERT_INPUT` record.
        out: shape (3, 4), written: rows traction, lock, low_friction; 0 where a gate is
            closed, nan for non-finite inputs (treated as OK by `classify_level`).
    """
    gate, min_torque = p.min_slip_velocity, p.min_wheel_torque
    slip, sv, torque, mu = inp.slip, inp.slip_velocity, inp.torque, inp.mu
    mu_valid, mu_max, slip_peak = inp.mu_valid, inp.mu_max, inp.slip_peak
    for w in range(4):
        s, v, tq, m, ok = slip[w], sv[w], torque[w], mu[w], mu_valid[w]
        driving = ((not ok) or m >= 0.0) and tq > min_torque
        braking = ((not ok) or m <= 0.0) and tq < -min_torque
        out[0, w] = s if v > gate and driving else 0.0
        out[1, w] = -s if v < -gate and braking else 0.0
        # mu_max <= 0 or nan never divides: the utilisation stays 0 there
        out[2, w] = abs(m) / mu_max[w] if ok and mu_max[w] > 0.0 else 0.0
        # past its peak slip a tyre uses all the friction there is, though its mu has dropped
        if ok and abs(v) > gate and abs(s) >= slip_peak[w] and _sign(s) == _sign(m):
            out[2, w] = max(out[2, w], 1.0)
        if not (math.isfinite(s) and math.isfinite(v) and math.isfinite(tq)):
            out[0, w] = math.nan
            out[1, w] = math.nan
        if not (math.isfinite(m) and math.isfinite(mu_max[w])):
            out[2, w] = math.nan


@jit
def step_channel(
    s: Any, k: int, w: int, t: float, target: int, raise_hold: float, release_hold: float
) -> bool:
    """Debounce channel (k, w) of `s` in time, in place.

    A higher target must persist ``raise_hold`` [s], a lower one ``release_hold`` [s], to be
    reported. The onset of an alert is the first stamp of the uninterrupted run of non-OK
    targets that raised it from OK; escalation keeps it.

    Args:
        s: `ALERT_STATE` record.
        k, w: kind (ALERT_KINDS index) and wheel.
        t: stamp [s].
        target: level wanted by the metric at t (from `classify_level`).
        raise_hold: [s].
        release_hold: [s].

    Returns:
        Whether the reported level changed.
    """
    level = s.level[k, w]
    run_start = s.run_start[k, w]
    if target == LEVEL_OK:
        run_start = math.nan
    elif math.isnan(run_start):
        run_start = t
    s.run_start[k, w] = run_start
    if target == level:
        s.pending_level[k, w] = target
        s.pending_since[k, w] = math.nan
        return False
    since = s.pending_since[k, w]
    if target != s.pending_level[k, w] or math.isnan(since):
        since = t
    s.pending_level[k, w] = target
    hold = raise_hold if target > level else release_hold
    if t - since < hold:
        s.pending_since[k, w] = since
        return False
    if target == LEVEL_OK:
        s.onset[k, w] = math.nan
        s.detected[k, w] = math.nan
    elif level == LEVEL_OK:
        s.onset[k, w] = run_start
        s.detected[k, w] = t
    s.level[k, w] = target
    s.pending_since[k, w] = math.nan
    return True


@jit
def alerts_reset(s: Any) -> None:
    """All channels of `s` back to OK, no stamp seen."""
    s.t = math.nan
    s.level[:, :] = LEVEL_OK
    s.onset[:, :] = math.nan
    s.pending_level[:, :] = LEVEL_OK
    s.pending_since[:, :] = math.nan
    s.run_start[:, :] = math.nan
    s.detected[:, :] = math.nan


@jit
def alerts_update(p: Any, s: Any, t: float, inp: Any) -> bool:
    """Advance all channels to stamp t: `alert_metrics`, `classify_level`, `step_channel`.

    Args:
        p: `ALERT_PARAMS` record.
        s: `ALERT_STATE` record, advanced in place; a non-finite or non-increasing stamp
            leaves it unchanged.
        t: stamp [s].
        inp: `ALERT_INPUT` record.

    Returns:
        Whether a reported level changed.
    """
    if not math.isfinite(t) or (math.isfinite(s.t) and t <= s.t):
        return False
    s.t = t
    metrics = np.empty((3, 4))
    alert_metrics(p, inp, metrics)
    changed = False
    for k in range(3):
        for w in range(4):
            level = s.level[k, w]
            target = classify_level(metrics[k, w], level, p.thresholds[k])
            if (
                target == LEVEL_OK
                and level == LEVEL_OK
                and s.pending_level[k, w] == LEVEL_OK
                and math.isnan(s.run_start[k, w])
            ):
                continue  # the common quiet case: step_channel would leave it unchanged
            if step_channel(s, k, w, t, target, p.raise_hold, p.release_hold):
                changed = True
    return changed


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


def _wheels(name: str, value: ArrayLike, dtype: type = np.float64) -> NDArray[Any]:
    array: NDArray[Any] = np.ascontiguousarray(value, dtype=dtype)
    if array.shape != (4,):
        raise InputShapeError(f'{name} must have shape (4,), got {array.shape}')
    return array


def alert_records(s: Any) -> tuple[Alert, ...]:
    """The 12 `Alert` records of an `ALERT_STATE` (kinds in ALERT_KINDS order, wheels 0..3
    within each kind)."""
    v = dict(zip(s.dtype.names, s.item(), strict=True))  # one read: record access is slow
    level, onset, detected = v['level'].tolist(), v['onset'].tolist(), v['detected'].tolist()
    return tuple(
        Alert(
            kind=ALERT_KINDS[k],
            wheel=w,
            level=int(level[k][w]),
            active=level[k][w] > LEVEL_OK,
            onset=float(onset[k][w]),
            detected=float(detected[k][w]),
        )
        for k in range(len(ALERT_KINDS))
        for w in range(4)
    )


class AlertMonitor:
    """Stateful wrapper over `alerts_update`: the node calls `update` per estimate.

    Attributes:
        params: `ALERT_PARAMS` record of `config`.
        state: `ALERT_STATE` record.
        last: the 12 records of the last update.
    """

    def __init__(self, config: AlertConfig | None = None) -> None:
        """Create the monitor.

        Args:
            config: settings; defaults if None.
        """
        self.config = config or AlertConfig()
        self.params = alert_params(self.config)
        self.state = new_record(ALERT_STATE)
        #: the inputs of the stamp `update` is given (a buffer, overwritten each call)
        self.input = new_record(ALERT_INPUT)
        self.reset()

    def reset(self) -> None:
        """All channels back to OK."""
        alerts_reset(self.state)
        self.last: tuple[Alert, ...] = alert_records(self.state)

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
            12 records, kinds in ALERT_KINDS order, wheels 0..3 within each kind; the same
            tuple as before while no reported level changes.

        Raises:
            InputShapeError: an input is not shape (4,).
        """
        inp = self.input
        inp.slip[:] = _wheels('slip', slip)
        inp.slip_velocity[:] = _wheels('slip_velocity', slip_vel)
        inp.torque[:] = _wheels('wheel_torque', wheel_torque)
        inp.mu[:] = _wheels('mu', mu)
        inp.mu_valid[:] = _wheels('mu_valid', mu_valid, np.bool_)
        inp.mu_max[:] = _wheels('mu_max', mu_max)
        inp.slip_peak[:] = _wheels('slip_peak', slip_peak)
        changed = alerts_update(self.params, self.state, float(t), inp)
        if changed:
            self.last = alert_records(self.state)
        return self.last

    def active(self) -> tuple[Alert, ...]:
        """The active records of the last update."""
        return tuple(a for a in self.last if a.active)
