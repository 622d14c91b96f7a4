"""The TRUE vehicle of a run when it is not the vehicle file: load, tyre radius, torque offset.

A car is rarely the vehicle file: it carries passengers and luggage, its tyres wear or lose
pressure, and a torque signal taken from an engine map has an offset. The estimators keep
the nominal file; the simulator is given a variant built here, so tests and evaluations can
measure what a wrong parameter costs and what an adaptation recovers (issue 16).

* :func:`loaded` adds (or removes) a point mass at a given position: total mass, whole and
  sprung CG position and height, and the sprung pitch inertia (parallel-axis theorem) change
  together, so the bond graph's static loads, load transfer and pitch stay consistent (the
  model derives all of them from :class:`~vd_common.vehicle.params.ChassisParams`).
* :func:`tyre_radius_scale` scales the effective rolling radius R_eff (worn tyre, low
  pressure: about -3 % ... +1 %).
* :func:`vd_sim_node.vehicle.simulation.with_torque_offset` adds an offset to the simulated
  torque SIGNALS of a finished run (engine torque, and the driven wheels' torque through the
  gear ratio), not to the physics: the car drives as before, only the sensor lies.

A scenario's ``true_vehicle`` section (:class:`~vd_sim_node.vehicle.scenario.VehicleVariant`)
makes the :class:`~vd_sim_node.vehicle.simulation.Simulator` do both itself
(:func:`apply_variant`, :func:`driven_wheel_torque_offset`), so the simulator node drives the
true car from the scenario file while the estimators read the vehicle file.

All functions are pure and return new frozen objects.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from numpy.typing import NDArray
from vd_common.errors import ParameterError
from vd_common.vehicle.params import VehicleParams

from vd_sim_node.vehicle.scenario import VehicleVariant

__all__ = [
    'DEFAULT_LOAD_POSITION',
    'apply_variant',
    'driven_wheel_torque_offset',
    'load_position_for_cg_shift',
    'loaded',
    'tyre_radius_scale',
]

#: Default position of an added load behind the front axle, [m]: the centroid of rear-seat
#: passengers and luggage of a small hatchback (rear seat near the rear axle, boot behind
#: it), so a load moves the CG back as a real one does. The Clio's CG is 0.95 m behind the
#: front axle; +400 kg here moves it back by about 0.2 m.
DEFAULT_LOAD_POSITION = 1.6


def load_position_for_cg_shift(
    params: VehicleParams, extra_mass_kg: float, cg_shift_m: float
) -> float:
    """Position of a point load that moves the whole-vehicle CG back by ``cg_shift_m``.

    Args:
        params: the nominal vehicle.
        extra_mass_kg: added mass, [kg], non-zero.
        cg_shift_m: wanted rearward CG shift, [m] (negative: forward).

    Returns:
        Load position behind the front axle, [m].

    Raises:
        ParameterError: ``extra_mass_kg`` is 0 (no load cannot move the CG).
    """
    if extra_mass_kg == 0.0:
        raise ParameterError('a CG shift needs a non-zero extra mass')
    c = params.chassis
    m_new = c.mass + extra_mass_kg
    # (m a + dm x) / (m + dm) = a + shift  =>  x = a + shift (m + dm) / dm
    return c.cg_to_front_axle + cg_shift_m * m_new / extra_mass_kg


def loaded(
    params: VehicleParams,
    extra_mass_kg: float,
    cg_shift_m: float | None = None,
    *,
    load_position_m: float | None = None,
    load_height_m: float | None = None,
) -> VehicleParams:
    """The vehicle with a point mass added to (or, if negative, removed from) the body.

    The load belongs to the sprung mass. The whole-vehicle CG moves to the mass-weighted mean
    of the old CG and the load; the sprung pitch inertia about the NEW sprung CG follows from
    the parallel-axis theorem (the unsprung masses taken at the wheel centre height, the
    unloaded radius, to place the sprung CG vertically).
    Static axle loads, suspension deflections and load transfer then follow in the model from
    the new mass and geometry.

    Args:
        params: the nominal vehicle.
        extra_mass_kg: added mass, [kg]; negative removes mass (a lighter driver, no fuel).
        cg_shift_m: rearward shift of the whole-vehicle CG, [m]; sets the load position
            (exclusive with ``load_position_m``). Default: the load sits at
            ``load_position_m``.
        load_position_m: load position behind the front axle, [m]; default
            :data:`DEFAULT_LOAD_POSITION`.
        load_height_m: load height above ground, [m]; default the CG height (then the CG
            height is unchanged).

    Returns:
        The loaded vehicle; ``name`` says what changed.

    Raises:
        ParameterError: both ``cg_shift_m`` and ``load_position_m`` are given, a value is
            not finite, or the result is not physical (mass not above the unsprung masses,
            CG or sprung CG outside the wheelbase, pitch inertia <= 0).
    """
    c = params.chassis
    if cg_shift_m is not None and load_position_m is not None:
        raise ParameterError('give cg_shift_m or load_position_m, not both')
    for label, value in (
        ('extra_mass_kg', extra_mass_kg),
        ('cg_shift_m', cg_shift_m),
        ('load_position_m', load_position_m),
        ('load_height_m', load_height_m),
    ):
        if value is not None and not math.isfinite(value):
            raise ParameterError(f'{label} must be finite, got {value}')
    if extra_mass_kg == 0.0:
        if cg_shift_m:
            raise ParameterError('a CG shift needs a non-zero extra mass')
        return params
    if cg_shift_m is not None:
        x_load = load_position_for_cg_shift(params, extra_mass_kg, cg_shift_m)
    else:
        x_load = DEFAULT_LOAD_POSITION if load_position_m is None else load_position_m
    z_load = c.cg_height if load_height_m is None else load_height_m

    m_uf = 2.0 * c.unsprung_mass_front
    m_ur = 2.0 * c.unsprung_mass_rear
    m_s = c.mass - m_uf - m_ur
    m_new = c.mass + extra_mass_kg
    m_s_new = m_s + extra_mass_kg
    if m_s_new <= 0.0:
        raise ParameterError(
            f'removing {-extra_mass_kg:g} kg leaves no sprung mass (sprung {m_s:g} kg)'
        )
    a_new = (c.mass * c.cg_to_front_axle + extra_mass_kg * x_load) / m_new
    h_new = (c.mass * c.cg_height + extra_mass_kg * z_load) / m_new
    if not 0.0 < a_new < c.wheelbase:
        raise ParameterError(
            f'the load at {x_load:.3f} m puts the CG at {a_new:.3f} m from the front axle, '
            f'outside the wheelbase {c.wheelbase:g} m'
        )
    if h_new <= 0.0:
        raise ParameterError(f'the load puts the CG height at {h_new:.3f} m, not above ground')
    # Sprung CG (the unsprung masses sit on the axles), before and after.
    a_s = (c.mass * c.cg_to_front_axle - m_ur * c.wheelbase) / m_s
    a_s_new = (m_s * a_s + extra_mass_kg * x_load) / m_s_new
    if not 0.0 < a_s_new < c.wheelbase:
        raise ParameterError(
            f'the load puts the sprung CG at {a_s_new:.3f} m, outside the wheelbase'
        )
    # Sprung CG heights, with the unsprung masses at the wheel centre (unloaded radius):
    # then whole, sprung and load heights add up exactly, before and after.
    z_u = params.wheel.unloaded_radius
    z_s = (c.mass * c.cg_height - (m_uf + m_ur) * z_u) / m_s
    z_s_new = (m_s * z_s + extra_mass_kg * z_load) / m_s_new
    inertia = (
        c.pitch_inertia
        + m_s * ((a_s - a_s_new) ** 2 + (z_s - z_s_new) ** 2)
        + extra_mass_kg * ((x_load - a_s_new) ** 2 + (z_load - z_s_new) ** 2)
    )
    if inertia <= 0.0:
        raise ParameterError(f'removing the load leaves a pitch inertia {inertia:g} <= 0')
    chassis = dataclasses.replace(
        c, mass=m_new, cg_to_front_axle=a_new, cg_height=h_new, pitch_inertia=inertia
    )
    name = f'{params.name} {extra_mass_kg:+g} kg at {x_load:.2f} m'
    return dataclasses.replace(params, chassis=chassis, name=name)


def tyre_radius_scale(params: VehicleParams, scale: float) -> VehicleParams:
    """The vehicle with its effective rolling radius R_eff multiplied by ``scale``.

    Wear and pressure change R_eff by a few per cent; the wheel inertia and the tyre's
    vertical properties are left as they are (their change is second order here). The
    unloaded radius is raised with R_eff only if R_eff would pass it (the parser's rule
    R_eff <= unloaded radius).

    Args:
        params: the nominal vehicle.
        scale: factor, [-], in (0.5, 1.5) (e.g. 0.97 for a worn tyre).

    Returns:
        The vehicle with the new R_eff; ``name`` says what changed.

    Raises:
        ParameterError: ``scale`` is not finite or outside (0.5, 1.5).
    """
    if not (math.isfinite(scale) and 0.5 < scale < 1.5):
        raise ParameterError(f'tyre radius scale must be in (0.5, 1.5), got {scale}')
    w = params.wheel
    r_eff = w.effective_radius * scale
    wheel = dataclasses.replace(
        w, effective_radius=r_eff, unloaded_radius=max(w.unloaded_radius, r_eff)
    )
    name = f'{params.name} R_eff x{scale:g}'
    return dataclasses.replace(params, wheel=wheel, name=name)


def apply_variant(params: VehicleParams, variant: VehicleVariant) -> VehicleParams:
    """The true vehicle of a scenario's ``true_vehicle`` section (its physical part).

    Args:
        params: the vehicle file's parameters.
        variant: the scenario's variant.

    Returns:
        ``params`` itself if the variant changes no physics, else the loaded and/or
        re-tyred vehicle (load first, then the tyre radius).

    Raises:
        ParameterError: the variant gives a non-physical car.
    """
    out = params
    if variant.extra_mass_kg != 0.0:
        out = loaded(
            out,
            variant.extra_mass_kg,
            variant.cg_shift_m,
            load_position_m=variant.load_position_m,
            load_height_m=variant.load_height_m,
        )
    if variant.tyre_radius_scale != 1.0:
        out = tyre_radius_scale(out, variant.tyre_radius_scale)
    return out


def driven_wheel_torque_offset(
    params: VehicleParams, gear: NDArray[np.int64], engine_offset_nm: float
) -> NDArray[np.float64]:
    """Per-sample offset of each driven (front) wheel's torque signal, [N m].

    Args:
        params: the vehicle (gear ratios, final drive).
        gear: engaged gear per sample, shape (M,), 0 during a shift.
        engine_offset_nm: offset of the engine torque, [N m].

    Returns:
        shape (M,): ``engine_offset_nm * ratio(gear) * final_drive / 2`` (open differential),
        0 where ``gear`` is 0.
    """
    gb = params.gearbox
    overall = np.concatenate(([0.0], np.asarray(gb.ratios) * gb.final_drive))
    out: NDArray[np.float64] = 0.5 * engine_offset_nm * overall[np.clip(gear, 0, len(gb.ratios))]
    return out
