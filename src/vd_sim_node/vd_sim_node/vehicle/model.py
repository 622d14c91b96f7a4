"""The Clio model assembled as a bond graph (``vd_sim_node.bondgraph``).

Structure (flows: velocities; efforts: forces/torques; see ``docs/vehicle_model.md``)::

    engine 1 (w_e): I engine, MSe combustion torque(throttle, w_e), R drag(w_e)
       ^ clutch0 (0-junction, clutch torque): R clutch(slip = w_gb - w_e, mode, w_e)
       ^ MTF gearbox+final drive, ratio input i (w_gb = i * w_carrier)
       ^ TF differential 1/2 (w_carrier = (w_FL + w_FR) / 2)
       ^ diff0 (0-junction: equal torque on both front wheels = open differential)
       ^ wheel 1 (w_i) x4: I wheel, R brake(w_i, pedal), C angle (zero stiffness: q = angle),
                          TF R_eff -> contact0_i (0-junction, tyre force Fx_i):
                                          R tyre(v_slip = w_i R - v_g, v_g, Fz_i, mu)
                                          -> ground 1 (v_g): R rolling front/rear axle
    ground 1 (v_g) -> gp0 (0-junction): v_g = v - h * pitch_rate
        <- x 1 (v): I total mass m, MSe -m g sin(alpha), R aero
        <- TF(-h) <- pitch 1 (pitch rate, nose-down positive): I pitch inertia
    pitch 1 -> TF(-a_s) -> susp0 front, TF(+b_s) -> susp0 rear
    heave 1 (z_s dot): I sprung mass, MSe -m_s g cos(alpha) -> susp0 front / rear
    susp0 axle (0-junction, suspension tension): -> spring 1 (C, R) and -> unsprung 1
    unsprung 1 axle: I (2 corner masses), MSe -m_u g cos(alpha), -> tyre 1 (C, R to ground)

Vertical dynamics are per axle (left = right, no roll), each wheel carries half of its
axle's tyre force. The ground forces act at ground level under the CG through the
power-conserving gp0 junction, so the pitch equation sees ``-h (sum Fx - sum F_r)`` exactly
as the shared convention demands, and ``m v' = sum Fx - sum F_r - F_aero - m g sin(alpha)``.
The tyre and rolling-resistance laws are modulated by the body speed v (the wheel hubs move
with the body), so the tyre sees exactly the shared slip definition; the small difference
``h * pitch_rate`` between v and the ground-point flow only moves power between the pitch
motion and those R elements (the total power balance stays exact).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from vd_common.vehicle.params import VehicleParams

from vd_sim_node.bondgraph import BondGraph, CompiledModel, compile_model
from vd_sim_node.vehicle.laws import (
    make_aero_law,
    make_brake_law,
    make_clutch_law,
    make_clutch_ramp,
    make_combustion_law,
    make_engine_drag_law,
    make_gravity_law,
    make_rolling_law,
    make_tire_law,
)

__all__ = ['INPUTS', 'WHEELS', 'Geometry', 'VehicleModel', 'build_vehicle_graph']

FloatArray = NDArray[np.float64]
WHEELS = ('FL', 'FR', 'RL', 'RR')
#: Model inputs in order: driver throttle actually applied [0..1], brake pedal [0..1], road
#: slope [rad], road friction scale [-], overall ratio gear*final [-], clutch mode (float),
#: start time of the clutch engagement ramp after a shift [s], governor (rev-matching)
#: target speed [rad/s] (0: idle).
INPUTS = (
    'throttle',
    'brake',
    'slope',
    'road_mu',
    'ratio',
    'clutch_mode',
    'clutch_ramp_start',
    'governor_speed',
)


@dataclass(frozen=True)
class Geometry:
    """Derived mass distribution.

    Attributes:
        m: total mass, [kg].
        m_s: sprung mass, [kg].
        m_uf: front axle unsprung mass (both corners), [kg].
        m_ur: rear axle unsprung mass (both corners), [kg].
        a_s: sprung CG to front axle, [m].
        b_s: sprung CG to rear axle, [m].
        a: whole-vehicle CG to front axle, [m].
        b: whole-vehicle CG to rear axle, [m].
        h: whole-vehicle CG height, [m].
    """

    m: float
    m_s: float
    m_uf: float
    m_ur: float
    a_s: float
    b_s: float
    a: float
    b: float
    h: float

    @classmethod
    def of(cls, vp: VehicleParams) -> Geometry:
        """Derive the geometry from the parameters (whole-vehicle CG as published)."""
        c = vp.chassis
        m_uf = 2.0 * c.unsprung_mass_front
        m_ur = 2.0 * c.unsprung_mass_rear
        m_s = c.mass - m_uf - m_ur
        # The unsprung masses sit on the axles, so the sprung CG follows from the whole one.
        a_s = c.sprung_cg_to_front_axle
        return cls(
            m=c.mass,
            m_s=m_s,
            m_uf=m_uf,
            m_ur=m_ur,
            a_s=a_s,
            b_s=c.wheelbase - a_s,
            a=c.cg_to_front_axle,
            b=c.wheelbase - c.cg_to_front_axle,
            h=c.cg_height,
        )


def _zero_law(q: Any) -> Any:
    return 0.0 * q


def build_vehicle_graph(vp: VehicleParams) -> BondGraph:
    """Assemble the whole vehicle as a bond graph.

    Args:
        vp: vehicle parameters.

    Returns:
        The (not yet compiled) bond graph; inputs are :data:`INPUTS`.
    """
    geo = Geometry.of(vp)
    g = vp.environment.gravity
    w = vp.wheel
    bg = BondGraph('clio_rl_1_1')
    bg.add_input('throttle', 0.0)
    bg.add_input('brake', 0.0)
    bg.add_input('slope', 0.0)
    bg.add_input('road_mu', 1.0)
    bg.add_input('ratio', vp.gearbox.ratios[0] * vp.gearbox.final_drive)
    bg.add_input('clutch_mode', 1.0)
    bg.add_input('clutch_ramp_start', -1e9)
    bg.add_input('governor_speed', 0.0)

    # --- longitudinal body motion, ground point and pitch -----------------------------
    m = geo.m
    bg.add_one('x')
    bg.add_i('mass_x', m)
    bg.add_se('grade', make_gravity_law(m * g, 'sin'), signals=('slope',))
    bg.add_r('aero', law=make_aero_law(vp.aero))
    bg.connect('grade', 'x')
    bg.connect('x', 'mass_x', name='body')
    bg.add_flow_sensor('v_body', 'body')
    bg.connect('x', 'aero')

    bg.add_one('pitch')
    bg.add_i('pitch_inertia', vp.chassis.pitch_inertia)
    bg.connect('pitch', 'pitch_inertia')

    bg.add_zero('gp')
    bg.add_tf('tf_h', -geo.h)
    bg.connect('x', 'gp')
    bg.connect('pitch', 'tf_h')
    bg.connect('tf_h', 'gp')
    bg.add_one('ground')
    bg.connect('gp', 'ground', name='ground_point')
    bg.add_flow_sensor('v_ground', 'ground_point')

    # --- vertical: heave, suspension, unsprung, tyre per axle ---------------------------
    m_s = geo.m_s
    bg.add_one('heave')
    bg.add_i('mass_sprung', m_s)
    bg.add_se('weight_sprung', make_gravity_law(m_s * g, 'cos'), signals=('slope',))
    bg.connect('weight_sprung', 'heave')
    bg.connect('heave', 'mass_sprung')
    s = vp.suspension
    axles = (
        ('front', -geo.a_s, geo.m_uf, s.stiffness_front, s.damping_front),
        ('rear', geo.b_s, geo.m_ur, s.stiffness_rear, s.damping_rear),
    )
    for axle, arm, m_u, k_s, c_s in axles:
        bg.add_zero(f'susp_{axle}')
        bg.add_tf(f'tf_pitch_{axle}', arm)
        bg.connect('heave', f'susp_{axle}')
        bg.connect('pitch', f'tf_pitch_{axle}')
        bg.connect(f'tf_pitch_{axle}', f'susp_{axle}')
        bg.add_one(f'spring_{axle}')
        bg.add_c(f'spring_c_{axle}', 1.0 / (2.0 * k_s))
        bg.add_r(f'spring_r_{axle}', 2.0 * c_s)
        bg.connect(f'susp_{axle}', f'spring_{axle}')
        bg.connect(f'spring_{axle}', f'spring_c_{axle}')
        bg.connect(f'spring_{axle}', f'spring_r_{axle}')
        bg.add_one(f'unsprung_{axle}')
        bg.add_i(f'mass_unsprung_{axle}', m_u)
        bg.add_se(
            f'weight_unsprung_{axle}',
            make_gravity_law(m_u * g, 'cos'),
            signals=('slope',),
        )
        bg.connect(f'susp_{axle}', f'unsprung_{axle}')
        bg.connect(f'weight_unsprung_{axle}', f'unsprung_{axle}')
        bg.connect(f'unsprung_{axle}', f'mass_unsprung_{axle}')
        bg.add_one(f'tyre_{axle}')
        bg.add_c(f'tyre_c_{axle}', 1.0 / (2.0 * w.tyre_vertical_stiffness))
        bg.add_r(f'tyre_r_{axle}', 2.0 * w.tyre_vertical_damping)
        bg.connect(f'unsprung_{axle}', f'tyre_{axle}', name=f'tyre_force_{axle}')
        bg.connect(f'tyre_{axle}', f'tyre_c_{axle}')
        bg.connect(f'tyre_{axle}', f'tyre_r_{axle}')
        bg.add_effort_sensor(f'tyre_tension_{axle}', f'tyre_force_{axle}')
        # Tyre load per wheel: half the axle's compression (the bond carries tension).
        bg.add_block(f'fz_wheel_{axle}', lambda t, e: -0.5 * e, signals=(f'tyre_tension_{axle}',))
        bg.add_r(
            f'rolling_{axle}',
            law=make_rolling_law(vp.rolling_resistance, 2.0),
            signals=('v_body', f'fz_wheel_{axle}'),
        )
        bg.connect('ground', f'rolling_{axle}')

    # --- wheels, tyres, brakes -------------------------------------------------------
    tire_law = make_tire_law(vp.tire)
    r_eff = w.effective_radius
    bk = vp.brakes
    for name in WHEELS:
        front = name.startswith('F')
        axle = 'front' if front else 'rear'
        bg.add_one(f'wheel_{name}')
        bg.add_i(f'spin_{name}', w.inertia_front if front else w.inertia_rear)
        bg.connect(f'wheel_{name}', f'spin_{name}')
        bg.add_c(f'angle_{name}', law=_zero_law, energy=_zero_law)
        bg.connect(f'wheel_{name}', f'angle_{name}')
        t_max = bk.max_torque_front if front else bk.max_torque_rear
        bg.add_r(
            f'brake_{name}',
            law=make_brake_law(t_max, bk.lock_speed),
            signals=('brake',),
        )
        bg.connect(f'wheel_{name}', f'brake_{name}')
        bg.add_tf(f'radius_{name}', r_eff)
        bg.connect(f'wheel_{name}', f'radius_{name}')
        bg.add_zero(f'contact_{name}')
        bg.connect(f'radius_{name}', f'contact_{name}')
        bg.add_r(
            f'tyre_{name}',
            law=tire_law,
            signals=('v_ground', 'v_body', f'fz_wheel_{axle}', 'road_mu'),
        )
        bg.connect(f'contact_{name}', f'tyre_{name}')
        bg.connect(f'contact_{name}', 'ground')

    # --- driveline: open differential, gearbox, clutch, engine ---------------------------
    bg.add_zero('diff')
    bg.connect('wheel_FL', 'diff', name='drive_FL')
    bg.connect('wheel_FR', 'diff', name='drive_FR')
    bg.add_tf('tf_diff', 0.5)
    bg.connect('diff', 'tf_diff')
    bg.add_tf('gearbox', lambda t, i: i, signals=('ratio',))
    bg.connect('tf_diff', 'gearbox', name='carrier')
    bg.add_zero('clutch')
    bg.connect('gearbox', 'clutch', name='gearbox_input')
    bg.add_one('engine')
    bg.add_i('engine_inertia', vp.engine.inertia)
    bg.connect('clutch', 'engine')
    bg.connect('engine', 'engine_inertia', name='crank')
    bg.add_flow_sensor('w_engine', 'crank')
    bg.add_block('clutch_ramp', make_clutch_ramp(vp.clutch), signals=('clutch_ramp_start',))
    bg.add_r(
        'clutch_friction',
        law=make_clutch_law(vp.clutch),
        signals=('clutch_mode', 'w_engine', 'clutch_ramp'),
    )
    bg.connect('clutch', 'clutch_friction')
    bg.add_se(
        'combustion',
        make_combustion_law(vp.engine),
        signals=('throttle', 'w_engine', 'governor_speed'),
    )
    bg.connect('combustion', 'engine')
    bg.add_r('engine_drag', law=make_engine_drag_law(vp.engine))
    bg.connect('engine', 'engine_drag')
    return bg


class VehicleModel:
    """The compiled Clio model plus the index bookkeeping the simulator needs.

    Attributes:
        params: the vehicle parameters.
        geometry: derived mass distribution.
        compiled: the compiled bond-graph model.
        n_states: number of states.
    """

    def __init__(self, params: VehicleParams) -> None:
        """Build and compile the bond graph of ``params``."""
        self.params = params
        self.geometry = Geometry.of(params)
        self.graph = build_vehicle_graph(params)
        self.compiled: CompiledModel = compile_model(self.graph)
        self.n_states = self.compiled.n_states
        si = self.compiled.state_index
        self.idx_p_x = si['mass_x.p']
        self.idx_p_spin = np.array([si[f'spin_{n}.p'] for n in WHEELS])
        self.idx_angle = np.array([si[f'angle_{n}.q'] for n in WHEELS])
        self.idx_p_engine = si['engine_inertia.p']
        self.inertia = np.array(
            [params.wheel.inertia_front] * 2 + [params.wheel.inertia_rear] * 2, dtype=float
        )
        oi = self.compiled.output_index
        self.out = {
            'v_ground': oi['v_ground'],
            'fz_front': oi['fz_wheel_front'],
            'fz_rear': oi['fz_wheel_rear'],
            'aero': oi['x->aero.e'],
            'rolling_front': oi['ground->rolling_front.e'],
            'rolling_rear': oi['ground->rolling_rear.e'],
            'clutch_torque': oi['clutch->clutch_friction.e'],
            'combustion': oi['combustion->engine.e'],
            'engine_drag': oi['engine->engine_drag.e'],
            'w_gearbox_input': oi['gearbox_input.f'],
        }
        self.out_fx = np.array([oi[f'contact_{n}->tyre_{n}.e'] for n in WHEELS])
        self.out_brake = np.array([oi[f'wheel_{n}->brake_{n}.e'] for n in WHEELS])
        self.out_drive = np.array([oi['drive_FL.e'], oi['drive_FR.e']])
        # The effort on the bond into an I element is its momentum derivative: omega_dot and
        # the body acceleration come out of the same evaluation as every other output.
        self.out_spin_rate = np.array([oi[f'wheel_{n}->spin_{n}.e'] for n in WHEELS])
        self.out_momentum_rate_x = oi['body.e']
        self.rhs: Callable[..., FloatArray] = self.compiled.rhs

    def input_vector(
        self,
        throttle: float,
        brake: float,
        slope: float,
        road_mu: float,
        ratio: float,
        clutch_mode: float,
        clutch_ramp_start: float = -1e9,
        governor_speed: float = 0.0,
    ) -> FloatArray:
        """Input vector in :data:`INPUTS` order, shape (8,)."""
        return np.array(
            [
                throttle,
                brake,
                slope,
                road_mu,
                ratio,
                clutch_mode,
                clutch_ramp_start,
                governor_speed,
            ],
            dtype=float,
        )

    def static_state(self, slope: float, engine_speed: float) -> FloatArray:
        """State at rest in static equilibrium on a road of ``slope``.

        Args:
            slope: road slope, [rad].
            engine_speed: engine speed, [rad/s].

        Returns:
            x0, shape (n_states,): spring deflections at equilibrium, momenta zero except the
            engine's, wheel angles zero.
        """
        geo = self.geometry
        vp = self.params
        g = vp.environment.gravity * np.cos(slope)
        susp_front = geo.m_s * g * geo.b_s / vp.chassis.wheelbase
        susp_rear = geo.m_s * g * geo.a_s / vp.chassis.wheelbase
        tyre_front = susp_front + geo.m_uf * g
        tyre_rear = susp_rear + geo.m_ur * g
        kt2 = 2.0 * vp.wheel.tyre_vertical_stiffness
        s = vp.suspension
        return self.compiled.initial_state(
            {
                # Compression is a negative extension; the bonds carry tension.
                'spring_c_front': -susp_front / (2.0 * s.stiffness_front),
                'spring_c_rear': -susp_rear / (2.0 * s.stiffness_rear),
                'tyre_c_front': -tyre_front / kt2,
                'tyre_c_rear': -tyre_rear / kt2,
                'engine_inertia': vp.engine.inertia * engine_speed,
            }
        )
