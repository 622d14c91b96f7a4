"""Constitutive laws of the vehicle bond graph, specialised for speed.

Each factory returns one callable that the generated right-hand side calls with Python
floats (the integrator's hot loop; a closure with every parameter in a local and ``math``
functions, no ``isinstance`` chains) and the output evaluation calls with numpy arrays (then
the vectorised reference implementations of :mod:`.tire`, :mod:`.powertrain` and
:mod:`.resistances` are used). ``test_vehicle_laws.py`` checks both paths agree.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from vd_common.vehicle.params import (
    AeroParams,
    ClutchParams,
    EngineParams,
    RollingResistanceParams,
    TireParams,
)
from vd_common.vehicle.tire import tire_force_from_slip_velocity

from vd_sim_node.vehicle.powertrain import (
    brake_torque,
    clutch_torque,
    combustion_torque,
    engine_drag_torque,
)
from vd_sim_node.vehicle.resistances import aero_drag, rolling_resistance

__all__ = [
    'make_aero_law',
    'make_brake_law',
    'make_clutch_law',
    'make_clutch_ramp',
    'make_combustion_law',
    'make_engine_drag_law',
    'make_gravity_law',
    'make_rolling_law',
    'make_tire_law',
]

Law = Callable[..., Any]
_F = float


def make_tire_law(tp: TireParams) -> Law:
    """``law(v_slip_ground, v_ground, v_body, fz, mu) -> Fx`` [N], the modulated tyre R.

    The R's own flow is ``omega R - v_ground``; the slip is taken relative to the body
    speed (``omega R - v``, the wheel hub moves with the body), as in the shared definition.
    """
    fz0 = tp.nominal_load
    c = tp.pCx1
    dx1, dx2 = tp.pDx1, tp.pDx2
    ex1, ex2, ex3, ex4 = tp.pEx1, tp.pEx2, tp.pEx3, tp.pEx4
    kx1, kx2, kx3 = tp.pKx1, tp.pKx2, tp.pKx3
    hx1, hx2, vx1, vx2 = tp.pHx1, tp.pHx2, tp.pVx1, tp.pVx2
    v_min = tp.low_speed_velocity
    sin, atan, exp = math.sin, math.atan, math.exp

    def law(vsg: Any, vgr: Any, vg: Any, fz: Any, mu: Any) -> Any:
        if vsg.__class__ is _F and fz.__class__ is _F:
            if fz <= 0.0:
                return 0.0
            wr = vsg + vgr
            vs = wr - vg
            den = wr if wr > 0.0 else -wr
            avg = vg if vg > 0.0 else -vg
            if avg > den:
                den = avg
            if v_min > den:
                den = v_min
            dfz = (fz - fz0) / fz0
            kx = vs / den + hx1 + hx2 * dfz
            dx = mu * (dx1 + dx2 * dfz) * fz
            sv = fz * (vx1 + vx2 * dfz)
            if dx <= 0.0:
                return sv
            ex = (ex1 + ex2 * dfz + ex3 * dfz * dfz) * (
                1.0 - ex4 * (1.0 if kx > 0.0 else (-1.0 if kx < 0.0 else 0.0))
            )
            if ex > 1.0:
                ex = 1.0
            bk = fz * (kx1 + kx2 * dfz) * exp(kx3 * dfz) / (c * dx) * kx
            return dx * sin(c * atan(bk - ex * (bk - atan(bk)))) + sv
        return tire_force_from_slip_velocity(vsg + vgr - vg, vg, fz, mu, tp)

    return law


def make_brake_law(max_torque: float, lock_speed: float) -> Law:
    """``law(omega, pedal) -> torque`` [N m], the modulated brake R of one wheel."""
    tanh = math.tanh
    inv = 1.0 / lock_speed

    def law(omega: Any, pedal: Any) -> Any:
        if omega.__class__ is _F:
            if pedal == 0.0:
                return 0.0
            return pedal * max_torque * tanh(omega * inv)
        return brake_torque(omega, pedal, max_torque, lock_speed)

    return law


def make_rolling_law(rp: RollingResistanceParams, wheels: float) -> Law:
    """``law(v_ground, v_body, fz_wheel) -> force`` [N] for ``wheels`` wheels of equal load.

    The force depends on the body speed (paper eq. 7); it acts at the ground point.
    """
    k0 = rp.c0 * wheels
    k1 = rp.c1 / 160.0
    inv = 1.0 / rp.regularisation_speed
    tanh = math.tanh

    def law(vgr: Any, v: Any, fz: Any) -> Any:
        if v.__class__ is _F:
            av = v if v > 0.0 else -v
            return k0 * (1.0 + k1 * av) * fz * tanh(v * inv)
        return rolling_resistance(v, wheels * fz, rp)

    return law


def make_aero_law(ap: AeroParams) -> Law:
    """``law(v) -> drag`` [N], the aero R."""
    k = 0.5 * ap.air_density * ap.drag_coefficient * ap.frontal_area

    def law(v: Any) -> Any:
        if v.__class__ is _F:
            return k * v * (v if v > 0.0 else -v)
        return aero_drag(v, ap)

    return law


def make_gravity_law(weight: float, component: str) -> Law:
    """``law(t, slope) -> effort`` [N]: ``-weight sin(slope)`` or ``-weight cos(slope)``."""
    import numpy as np

    fast = math.sin if component == 'sin' else math.cos
    slow = np.sin if component == 'sin' else np.cos

    def law(t: Any, slope: Any) -> Any:
        if slope.__class__ is _F:
            return -weight * fast(slope)
        return -weight * slow(slope)

    return law


def make_clutch_law(cp: ClutchParams) -> Law:
    """``law(slip, mode, w_engine, ramp) -> torque`` [N m], the clutch R (see powertrain)."""
    cap = cp.capacity
    inv_slip = 1.0 / cp.slip_speed
    start = cp.engage_start_speed
    inv_span = 1.0 / (cp.engage_full_speed - cp.engage_start_speed)
    tanh = math.tanh

    def law(slip: Any, mode: Any, we: Any, ramp: Any) -> Any:
        if slip.__class__ is _F:
            if mode >= 2.0:
                return ramp * cap * tanh(slip * inv_slip)
            if mode >= 1.0:
                x = (we - start) * inv_span
                if x <= 0.0:
                    return 0.0
                if x > 1.0:
                    x = 1.0
                return x * x * (3.0 - 2.0 * x) * cap * tanh(slip * inv_slip)
            return 0.0
        return clutch_torque(slip, mode, we, cp, ramp)

    return law


def make_clutch_ramp(cp: ClutchParams) -> Law:
    """``block(t, ramp_start) -> [0..1]``: clutch engagement ramp after a shift."""
    import numpy as np

    inv = 1.0 / cp.engage_time if cp.engage_time > 0.0 else math.inf

    def block(t: Any, start: Any) -> Any:
        if t.__class__ is _F:
            x = (t - start) * inv
            return 1.0 if x >= 1.0 else (x if x > 0.0 else 0.0)
        with np.errstate(invalid='ignore'):
            return np.clip((np.asarray(t) - start) * inv, 0.0, 1.0)

    return block


def make_combustion_law(ep: EngineParams) -> Law:
    """``law(t, throttle, w_engine, governor_speed) -> torque`` [N m], the engine's MSe."""
    xs = ep.full_load_speed
    ys = ep.full_load_torque
    slopes = [(ys[i + 1] - ys[i]) / (xs[i + 1] - xs[i]) for i in range(len(xs) - 1)]
    n = len(xs)
    c0, c1 = ep.drag_torque_c0, ep.drag_torque_c1
    idle, gain = ep.idle_speed, ep.idle_gain
    w_max = ep.max_speed
    inv_band = 1.0 / (0.04 * ep.max_speed)
    inv_sign = 1.0 / 5.0
    tanh = math.tanh

    def law(t: Any, thr: Any, we: Any, gov_speed: Any) -> Any:
        if we.__class__ is _F:
            if we <= xs[0]:
                tf = ys[0]
            elif we >= xs[-1]:
                tf = ys[-1]
            else:
                i = 1
                while i < n and xs[i] < we:
                    i += 1
                tf = ys[i - 1] + slopes[i - 1] * (we - xs[i - 1])
            tot = tf + (c0 + c1 * (we if we > 0.0 else -we)) * tanh(we * inv_sign)
            demand = thr * tot
            gov = gain * ((idle if idle > gov_speed else gov_speed) - we)
            if gov > tot:
                gov = tot
            if gov > demand:
                demand = gov
            cut = (w_max - we) * inv_band
            if cut >= 1.0:
                return demand
            return demand * cut if cut > 0.0 else 0.0
        return combustion_torque(thr, we, ep, gov_speed)

    return law


def make_engine_drag_law(ep: EngineParams) -> Law:
    """``law(w_engine) -> torque`` [N m], the engine friction R."""
    c0, c1 = ep.drag_torque_c0, ep.drag_torque_c1
    tanh = math.tanh

    def law(we: Any) -> Any:
        if we.__class__ is _F:
            return (c0 + c1 * (we if we > 0.0 else -we)) * tanh(we * 0.2)
        return engine_drag_torque(we, ep)

    return law
