"""Powertrain laws: engine map and idle governor, launch clutch, shift logic, brakes.

Each law works on Python floats (fast path used inside the integrator) and on numpy arrays
(vectorised path used to evaluate outputs on thousands of samples at once).

Conventions: engine speed ``w_e`` and gearbox input speed ``w_gb`` in [rad/s]; torques in
[N m]. The overall ratio ``i = i_gear * i_final`` relates gearbox input speed to the speed of
the differential carrier, ``w_gb = i * w_carrier``; ``i = 0`` is neutral.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum

import numpy as np
from numpy.typing import NDArray
from vd_common.vehicle.params import (
    ClutchParams,
    EngineParams,
    GearboxParams,
)

__all__ = [
    'ClutchMode',
    'DrivelineState',
    'ShiftDecision',
    'brake_torque',
    'clutch_engagement',
    'clutch_torque',
    'combustion_torque',
    'decide_shift',
    'engine_drag_torque',
    'full_load_torque',
    'upshift_speed',
]

FloatArray = NDArray[np.float64]
Scalar = float | FloatArray

# Engine speed [rad/s] over which the drag torque changes sign: keeps the friction law
# smooth at a (never reached in practice) engine standstill.
_ENGINE_DRAG_SIGN_SPEED = 5.0
# Fraction of the rev limit over which the fuel cut-off ramps the combustion torque to 0.
_LIMITER_BAND = 0.04


class ClutchMode(IntEnum):
    """Discrete clutch state, switched by the driver logic at sample instants."""

    OPEN = 0  # pedal down: during a gear shift
    LAUNCH = 1  # engagement scheduled on engine speed (idle still, launch, stop)
    LOCKED = 2  # fully engaged (friction law still allows slip above capacity)


def full_load_torque(w_e: Scalar, ep: EngineParams) -> Scalar:
    """Full-load (throttle 1) net torque from the published curve, linear interpolation.

    Args:
        w_e: engine speed, [rad/s].
        ep: engine parameters.

    Returns:
        Torque, [N m]; held constant below the first and above the last breakpoint.
    """
    if isinstance(w_e, float):
        return _interp_scalar(w_e, ep.full_load_speed, ep.full_load_torque)
    out: FloatArray = np.interp(w_e, ep.full_load_speed, ep.full_load_torque)
    return out


def _interp_scalar(x: float, xs: tuple[float, ...], ys: tuple[float, ...]) -> float:
    if x <= xs[0]:
        return ys[0]
    if x >= xs[-1]:
        return ys[-1]
    lo, hi = 0, len(xs) - 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if xs[mid] <= x:
            lo = mid
        else:
            hi = mid
    return ys[lo] + (ys[hi] - ys[lo]) * (x - xs[lo]) / (xs[hi] - xs[lo])


def engine_drag_torque(w_e: Scalar, ep: EngineParams) -> Scalar:
    """Closed-throttle friction and pumping torque (a dissipative R law).

    Args:
        w_e: engine speed, [rad/s].
        ep: engine parameters.

    Returns:
        Drag torque opposing rotation, [N m] (positive for positive speed).
    """
    if isinstance(w_e, float):
        return (ep.drag_torque_c0 + ep.drag_torque_c1 * abs(w_e)) * math.tanh(
            w_e / _ENGINE_DRAG_SIGN_SPEED
        )
    w = np.asarray(w_e, dtype=float)
    out: FloatArray = (ep.drag_torque_c0 + ep.drag_torque_c1 * np.abs(w)) * np.tanh(
        w / _ENGINE_DRAG_SIGN_SPEED
    )
    return out


def combustion_torque(
    throttle: Scalar, w_e: Scalar, ep: EngineParams, governor_speed: Scalar = 0.0
) -> Scalar:
    """Indicated (combustion) torque: the modulated effort source of the engine.

    ``throttle * (T_full(w) + T_drag(w))`` so that the net torque at full load is the
    published curve, plus a proportional governor that adds torque below its target speed
    (the idle speed, or a higher rev-matching target while the driver shifts down), times a
    fuel cut-off ramp at the rev limit.

    Args:
        throttle: accelerator position, [0..1].
        w_e: engine speed, [rad/s].
        ep: engine parameters.
        governor_speed: rev-matching target, [rad/s]; the idle speed if higher.

    Returns:
        Torque, [N m] (>= 0).
    """
    band = _LIMITER_BAND * ep.max_speed
    if isinstance(throttle, float) and isinstance(w_e, float):
        t_full = _interp_scalar(w_e, ep.full_load_speed, ep.full_load_torque)
        drag = (ep.drag_torque_c0 + ep.drag_torque_c1 * abs(w_e)) * math.tanh(
            w_e / _ENGINE_DRAG_SIGN_SPEED
        )
        demand = throttle * (t_full + drag)
        target = max(ep.idle_speed, governor_speed)
        idle = min(max(ep.idle_gain * (target - w_e), 0.0), t_full + drag)
        cut = min(max((ep.max_speed - w_e) / band, 0.0), 1.0)
        return max(demand, idle) * cut
    thr = np.asarray(throttle, dtype=float)
    w = np.asarray(w_e, dtype=float)
    t_full_a = np.interp(w, ep.full_load_speed, ep.full_load_torque)
    drag_a = (ep.drag_torque_c0 + ep.drag_torque_c1 * np.abs(w)) * np.tanh(
        w / _ENGINE_DRAG_SIGN_SPEED
    )
    target_a = np.maximum(ep.idle_speed, np.asarray(governor_speed, dtype=float))
    idle_a = np.clip(ep.idle_gain * (target_a - w), 0.0, t_full_a + drag_a)
    cut_a = np.clip((ep.max_speed - w) / band, 0.0, 1.0)
    out: FloatArray = np.maximum(thr * (t_full_a + drag_a), idle_a) * cut_a
    return out


def _smoothstep(x: float) -> float:
    x = min(max(x, 0.0), 1.0)
    return x * x * (3.0 - 2.0 * x)


def clutch_engagement(mode: Scalar, w_e: Scalar, cp: ClutchParams, ramp: Scalar = 1.0) -> Scalar:
    """Clutch engagement in [0, 1].

    OPEN -> 0, LOCKED -> ``ramp`` (1 once the post-shift engagement ramp is over),
    LAUNCH -> smoothstep of the engine speed between ``engage_start_speed`` and
    ``engage_full_speed`` (a centrifugal-clutch-like launch).

    Args:
        mode: :class:`ClutchMode` value(s) as float.
        w_e: engine speed, [rad/s].
        cp: clutch parameters.
        ramp: engagement ramp after a shift, [0..1].

    Returns:
        Engagement, [-].
    """
    span = cp.engage_full_speed - cp.engage_start_speed
    if isinstance(mode, float) and isinstance(w_e, float):
        if mode >= ClutchMode.LOCKED:
            return float(ramp)
        if mode >= ClutchMode.LAUNCH:
            return _smoothstep((w_e - cp.engage_start_speed) / span)
        return 0.0
    m = np.asarray(mode, dtype=float)
    x = np.clip((np.asarray(w_e, dtype=float) - cp.engage_start_speed) / span, 0.0, 1.0)
    launch = x * x * (3.0 - 2.0 * x)
    out: FloatArray = np.where(
        m >= ClutchMode.LOCKED,
        np.asarray(ramp, dtype=float),
        np.where(m >= ClutchMode.LAUNCH, launch, 0.0),
    )
    return out


def clutch_torque(
    slip: Scalar, mode: Scalar, w_e: Scalar, cp: ClutchParams, ramp: Scalar = 1.0
) -> Scalar:
    """Friction torque of the clutch (a modulated R law on the slip speed).

    Args:
        slip: gearbox input speed minus engine speed, [rad/s].
        mode: :class:`ClutchMode` value(s) as float.
        w_e: engine speed, [rad/s] (schedules the launch engagement).
        cp: clutch parameters.
        ramp: engagement ramp after a shift, [0..1].

    Returns:
        Torque, [N m], same sign as ``slip`` (dissipative).
    """
    if isinstance(slip, float) and isinstance(mode, float) and isinstance(w_e, float):
        c = clutch_engagement(mode, w_e, cp, ramp)
        return c * cp.capacity * math.tanh(slip / cp.slip_speed)
    c_a = clutch_engagement(np.asarray(mode, dtype=float), np.asarray(w_e, dtype=float), cp, ramp)
    out: FloatArray = c_a * cp.capacity * np.tanh(np.asarray(slip, dtype=float) / cp.slip_speed)
    return out


def brake_torque(omega: Scalar, pedal: Scalar, max_torque: float, lock_speed: float) -> Scalar:
    """Brake friction torque on one wheel (a modulated R law on the wheel speed).

    Args:
        omega: wheel speed, [rad/s].
        pedal: brake pedal, [0..1].
        max_torque: torque at pedal 1, [N m].
        lock_speed: tanh regularisation speed, [rad/s].

    Returns:
        Torque opposing the rotation, [N m]; holds a stopped wheel like a stiff damper.
    """
    if isinstance(omega, float) and isinstance(pedal, float):
        return pedal * max_torque * math.tanh(omega / lock_speed)
    out: FloatArray = (
        np.asarray(pedal, dtype=float) * max_torque * np.tanh(np.asarray(omega) / lock_speed)
    )
    return out


def upshift_speed(throttle: float, gp: GearboxParams) -> float:
    """Gearbox input speed that triggers an upshift, linear in throttle, [rad/s]."""
    thr = min(max(throttle, 0.0), 1.0)
    return gp.upshift_speed_closed + thr * (gp.upshift_speed_open - gp.upshift_speed_closed)


@dataclass(frozen=True)
class DrivelineState:
    """Discrete state of the driver/transmission logic.

    Attributes:
        gear: engaged gear 1..n (the target gear during a shift).
        clutch: clutch mode.
        shift_end: time [s] when the current shift ends, or None when not shifting.
        hold_brake: whether the standstill hold brake is applied.
        ramp_start: time [s] the clutch started closing after a shift (engagement ramps
            from 0 to 1 over ``clutch.engage_time``); far in the past otherwise.
        rev_match: engine speed target [rad/s] of the governor during a downshift (the
            driver blips the throttle), 0 otherwise.
    """

    gear: int
    clutch: ClutchMode
    shift_end: float | None = None
    hold_brake: bool = False
    ramp_start: float = -1e9
    rev_match: float = 0.0


@dataclass(frozen=True)
class ShiftDecision:
    """A change of the discrete state decided at one sample."""

    state: DrivelineState
    description: str


def decide_shift(
    t: float,
    state: DrivelineState,
    w_e: float,
    w_gb_per_gear: FloatArray,
    throttle: float,
    speed: float,
    hold_brake_enabled: bool,
    gp: GearboxParams,
    cp: ClutchParams,
) -> ShiftDecision | None:
    """Driver/transmission logic, evaluated at sample instants.

    Rules (first match wins):

    1. a shift in progress ends at ``shift_end``: clutch LOCKED on the new gear, its
       engagement ramping from 0 to 1 over ``clutch.engage_time``;
    2. LOCKED and ``w_e < engage_start_speed``: open into LAUNCH (the car is stopping);
    3. LAUNCH and ``w_e >= engage_full_speed`` and throttle > 0: LOCK;
    4. (not when the clutch is held OPEN, i.e. coasting in neutral) up/down-shift with
       hysteresis on the gearbox input speed of the current gear (a downshift also sets
       the rev-matching target to the new gear's input speed):
       up when above :func:`upshift_speed` (throttle dependent), down when below
       ``downshift_speed``; a shift opens the clutch and cuts the throttle for
       ``shift_time`` (instant when ``shift_time`` is 0 or the clutch is not LOCKED);
    5. hold brake on when throttle is 0 and ``|speed|`` < 0.1 m/s, off as soon as the
       throttle is pressed.

    Args:
        t: sample time, [s].
        state: current discrete state.
        w_e: engine speed, [rad/s].
        w_gb_per_gear: gearbox input speed for each gear 1..n, shape (n,), [rad/s].
        throttle: driver throttle, [0..1].
        speed: vehicle speed, [m/s].
        hold_brake_enabled: scenario switch for rule 5.
        gp: gearbox parameters.
        cp: clutch parameters.

    Returns:
        The new state and a description, or None when nothing changes.
    """
    if state.shift_end is not None:
        if t >= state.shift_end - 1e-12:
            new = DrivelineState(state.gear, ClutchMode.LOCKED, None, state.hold_brake, t)
            return ShiftDecision(new, f'shift to gear {state.gear} completed')
        return None
    n = len(gp.ratios)
    if state.clutch == ClutchMode.LOCKED and w_e < cp.engage_start_speed:
        new = DrivelineState(state.gear, ClutchMode.LAUNCH, None, state.hold_brake)
        return ShiftDecision(new, 'clutch opened (engine below engagement speed)')
    if state.clutch == ClutchMode.LAUNCH and w_e >= cp.engage_full_speed and throttle > 0.0:
        new = DrivelineState(state.gear, ClutchMode.LOCKED, None, state.hold_brake)
        return ShiftDecision(new, 'clutch locked after launch')
    w_gb = float(w_gb_per_gear[state.gear - 1])
    target = state.gear
    if state.clutch == ClutchMode.OPEN:
        pass  # held in neutral (coast-down): the driver does not shift
    elif state.gear < n and w_gb > upshift_speed(throttle, gp):
        target = state.gear + 1
    elif state.gear > 1 and w_gb < gp.downshift_speed:
        target = state.gear - 1
    if target != state.gear:
        kind = 'up' if target > state.gear else 'down'
        if state.clutch == ClutchMode.LOCKED and gp.shift_time > 0.0:
            match = float(w_gb_per_gear[target - 1]) if target < state.gear else 0.0
            new = DrivelineState(
                target, ClutchMode.OPEN, t + gp.shift_time, state.hold_brake, rev_match=match
            )
        else:
            new = DrivelineState(target, state.clutch, None, state.hold_brake, state.ramp_start)
        return ShiftDecision(new, f'{kind}shift {state.gear}->{target}')
    if hold_brake_enabled:
        if not state.hold_brake and throttle <= 0.0 and abs(speed) < 0.1:
            new = DrivelineState(state.gear, state.clutch, None, True, state.ramp_start)
            return ShiftDecision(new, 'hold brake applied at standstill')
        if state.hold_brake and throttle > 0.0:
            new = DrivelineState(state.gear, state.clutch, None, False, state.ramp_start)
            return ShiftDecision(new, 'hold brake released')
    return None
