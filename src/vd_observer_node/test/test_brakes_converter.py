"""Brakes and the torque converter (issue 26), against closed forms and scipy.

* `drivetrain.engine_torques` with a torque converter: the turbine torque is the torque ratio
  of the characteristic at the logged speed ratio times the pump torque; without an engine
  speed, the speed ratio is the root scipy's brentq finds of the capacity-factor equation;
  the path holds where the logged turbine speed is i times the driven wheels;
* `brakes.brake_torques`: drive minus gain x pressure, opposing each wheel's rotation; a
  switch on, or a pressure not known, does not hold;
* the estimator never holds an old torque: a NaN torque gives Fx 0 and nothing valid;
* the mapping's ``brake`` and ``gear_offset`` keys, and their refusals.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq
from vd_common.vehicle.estimation import EstimationConverter, parse_estimation_vehicle
from vd_observer_node.errors import ConfigurationError
from vd_observer_node.estimation.brakes import Brakes, brake_gains, brake_torques, new_brake_state
from vd_observer_node.estimation.cascade import (
    CascadeSeries,
    CascadeSettings,
    CascadeState,
    run_cascade,
)
from vd_observer_node.estimation.drivetrain import Drivetrain, engine_torques
from vd_observer_node.estimation.estimator import Estimator, EstimatorConfig
from vd_observer_node.estimation.vehicle import EstimatorVehicle
from vd_observer_node.inputs.errors import MappingError
from vd_observer_node.inputs.mapping import mapping_from_dict

SPEED = (0.0, 0.4, 0.8, 0.9)
TORQUE = (2.0, 1.5, 1.1, 1.0)
CAPACITY = (150.0, 160.0, 190.0, 260.0)  # [rpm / sqrt(N m)]


def _automatic(**kw: object) -> Drivetrain:
    args: dict[str, object] = {
        'ratios': (3.3, 1.9, 1.42, 1.0),
        'final_drive': 4.0,
        'reverse_ratio': 4.1,
        'gear_efficiency': (0.9, 0.91, 0.92, 0.93),
        'converter': EstimationConverter(SPEED, TORQUE, CAPACITY),
        **kw,
    }
    return Drivetrain(**args)  # type: ignore[arg-type]


def test_converter_multiplies_the_pump_torque_by_the_torque_ratio_at_the_speed_ratio() -> None:
    line = _automatic()
    omega = np.full(4, 30.0)
    out = np.empty(4)
    i = 1.42 * 4.0
    for sr in (0.2, 0.5, 0.85, 0.95, 1.1):
        turbine = i * 30.0
        held = engine_torques(
            line.params()[0], 150.0, 3.0, turbine / sr, turbine, omega, np.zeros(4), out
        )
        assert held
        expected = i * np.interp(sr, SPEED, TORQUE) * 150.0 * 0.92
        if sr >= SPEED[-1]:
            expected = i * 150.0 * 0.92  # coupling and overrun: 1
        np.testing.assert_allclose(out, [expected / 2, expected / 2, 0.0, 0.0], rtol=1e-12)


def test_without_engine_speed_the_capacity_factor_gives_the_speed_ratio() -> None:
    line = _automatic()
    i = 1.9 * 4.0
    omega = np.full(4, 12.0)
    turbine_rpm = i * 12.0 * 30.0 / math.pi
    out = np.empty(4)
    for torque in (40.0, 120.0, 200.0):

        def balance(sr: float, torque: float = torque) -> float:
            return turbine_rpm / sr - np.interp(sr, SPEED, CAPACITY) * math.sqrt(torque)

        sr = brentq(balance, 1e-3, SPEED[-1])
        engine_torques(line.params()[0], torque, 2.0, math.nan, math.nan, omega,
                       np.zeros(4), out)  # fmt: skip
        expected = i * np.interp(sr, SPEED, TORQUE) * torque * 0.91
        assert out.sum() == pytest.approx(expected, rel=1e-6)


def test_the_converter_path_holds_where_the_turbine_turns_with_the_wheels() -> None:
    line = _automatic(driven_axle='all', front_share=0.6)
    omega = np.full(4, 20.0)
    i = 1.0 * 4.0
    out = np.empty(4)
    p = line.params()[0]
    assert engine_torques(p, 100.0, 4.0, 100.0, i * 20.0 + 1.0, omega, np.zeros(4), out)
    # all four driven, 60 % on the front axle
    np.testing.assert_allclose(out[:2] / out.sum(), [0.3, 0.3])
    # a shift under way: the turbine is between the gears' speeds
    assert not engine_torques(p, 100.0, 4.0, 100.0, i * 20.0 * 1.2, omega, np.zeros(4), out)
    # no gear the box has: nan, not held
    assert not engine_torques(p, 100.0, 7.0, 100.0, 80.0, omega, np.zeros(4), out)
    assert np.isnan(out).all()


def test_the_vehicle_file_gives_the_automatic_gearbox_and_brakes() -> None:
    data = {
        'chassis': {'mass': 1600.0, 'wheelbase': 2.6, 'cg_to_front_axle': 1.1, 'cg_height': 0.6},
        'wheel': {'inertia_front': 1.5, 'inertia_rear': 1.4, 'effective_radius': 0.34},
        'aero': {'drag_coefficient': 0.33, 'frontal_area': 2.6, 'air_density': 1.2},
        'rolling_resistance': {'c0': 0.01, 'c1': 3.6},
        'environment': {'gravity': 9.81},
        'gearbox': {'ratios': [3.3, 1.9], 'final_drive': 4.0, 'efficiency': [0.9, 0.95]},
        'engine': {'inertia': 0.17},
        'driveline': {'layout': 'AWD', 'front_share': 0.7},
        'torque_converter': {
            'speed_ratio': list(SPEED),
            'torque_ratio': list(TORQUE),
            'capacity_factor': list(CAPACITY),
        },
        'brakes': {'gain_front': 30.0, 'gain_rear': 12.0},
    }
    params = parse_estimation_vehicle(data)
    line = Drivetrain.from_params(params)
    assert line.driven_axle == 'all' and line.front_share == 0.7
    assert line.gear_efficiency == (0.9, 0.95) and line.converter is not None
    brake_params = Brakes.from_params('pressure', params).params()[0]
    assert brake_params.kind == 2 and brake_params.gain.tolist() == [30.0, 30.0, 12.0, 12.0]
    assert not brake_params.learn
    data['torque_converter']['torque_ratio'] = [2.0, 1.0]  # type: ignore[index]
    with pytest.raises(Exception, match=r'torque_converter\.torque_ratio must have one value'):
        parse_estimation_vehicle(data)
    del data['brakes']
    # no gain in the file: learnt online
    no_gain = parse_estimation_vehicle({**data, 'torque_converter': None})
    assert Brakes.from_params('pressure', no_gain).learn
    with pytest.raises(ConfigurationError, match='brake signal must be switch or pressure'):
        Brakes.from_params('pedal', no_gain)


def test_brake_pressure_opposes_each_wheel_and_a_switch_makes_the_torque_unknown() -> None:
    bprm = Brakes('pressure', 40.0, 15.0).params()[0]
    gains = np.empty(4)
    brake_gains(bprm, new_brake_state()[0], gains)
    assert gains.tolist() == [40.0, 40.0, 15.0, 15.0]
    used = np.array([300.0, 300.0, 0.0, 0.0])
    omega = np.array([20.0, 20.0, -20.0, 20.0])
    assert brake_torques(bprm, gains, np.array([10.0, 10.0, 4.0, 4.0]), omega, used)
    np.testing.assert_allclose(used, [300.0 - 400.0, 300.0 - 400.0, 60.0, -60.0])
    used = np.zeros(4)
    assert brake_torques(bprm, gains, np.array([0.0, math.nan, 0.0, 0.0]), omega, used)
    assert np.isnan(used[1]) and np.isfinite(used[[0, 2, 3]]).all()
    # a braked wheel at a standstill: a reaction, not held
    assert not brake_torques(bprm, gains, np.full(4, 5.0), np.zeros(4), np.zeros(4))
    # a gain still to be learnt: no brake torque known while the pressure is on
    learn = Brakes('pressure', learn=True).params()[0]
    brake_gains(learn, new_brake_state()[0], gains)
    assert np.isnan(gains).all()
    assert brake_torques(learn, gains, np.zeros(4), omega, np.zeros(4))
    assert not brake_torques(learn, gains, np.full(4, 3.0), omega, np.zeros(4))
    switch = Brakes('switch').params()[0]
    assert brake_torques(switch, gains, np.array([0.0, 0.0, 0.0, 0.0]), omega, used)
    assert not brake_torques(switch, gains, np.array([1.0, 1.0, 1.0, 1.0]), omega, used)
    assert not brake_torques(switch, gains, np.full(4, math.nan), omega, used)


def _braking_drive(gain: float, grade: float, vehicle: EstimatorVehicle) -> dict[str, np.ndarray]:
    """100 Hz of a car cruising at 20 m/s on a constant grade with the drive torque that
    holds its speed, braking with 20 bar on every wheel (``gain`` N m/bar) and no drive
    from 10 to 12 s and from 22 to 24 s, cruising again between: integrated at 1 kHz with
    the wheels rolling without slip (the balance the estimator inverts, written out)."""
    m, r, g = vehicle.mass, vehicle.effective_radius, vehicle.gravity
    j = 2.0 * (vehicle.inertia_front + vehicle.inertia_rear)
    dt = 1e-3
    v, angle = 20.0, 0.0
    rows: list[list[float]] = []
    for k in range(int(30.0 / dt)):
        t = k * dt
        braking = 10.0 <= t < 12.0 or 22.0 <= t < 24.0
        rolling = (
            vehicle.rolling_c0 * (1.0 + vehicle.rolling_c1 * v / 160.0) * m * g * math.cos(grade)
        )
        resist = rolling + vehicle.drag_factor * v * v + m * g * math.sin(grade)
        pressure = 20.0 if braking else 0.0
        # cruise: the torque that holds the speed; back to 20 m/s smoothly after a braking
        drive = 0.0 if braking else (resist + m * 0.5 * (20.0 - v)) * r / 4.0
        wheel_torque = drive - gain * pressure
        a = (4.0 * wheel_torque / r - resist) / (m + j / (r * r))
        if k % 10 == 0:
            rows.append([t, angle, v, drive, pressure])
        v += a * dt
        angle += v / r * dt
    x = np.array(rows)
    return {
        't': x[:, 0], 'angle': np.repeat(x[:, 1:2], 4, axis=1), 'speed': x[:, 2],
        'torque': np.repeat(x[:, 3:4], 4, axis=1), 'brake': np.repeat(x[:, 4:5], 4, axis=1),
    }  # fmt: skip


def test_the_brake_gain_is_learnt_from_the_decelerations() -> None:
    """No gain in the vehicle file: the first braking teaches it (the slope before it held
    through it; the brake torque unknown until it has converged, after 1 s of braking), the
    second is then estimated with it: its slope valid and right."""
    vehicle = EstimatorVehicle(1600.0, 2.6, 1.1, 0.6, 1.5, 1.4, 0.34, 0.33, 2.6, 1.2,
                               0.01, 3.6, 9.81)  # fmt: skip
    grade = math.radians(2.0)
    drive = _braking_drive(30.0, grade, vehicle)
    state = CascadeState()
    result = run_cascade(
        CascadeSeries(
            drive['t'], drive['angle'], drive['speed'], drive['torque'], brake=drive['brake']
        ),
        CascadeSettings(vehicle, brakes=Brakes('pressure', learn=True)),
        state=state,
    )
    assert state.parts is not None
    learnt = state.parts.brake_parts.state[0]
    gain, braking_time = learnt.gain, learnt.excited_time
    assert learnt.converged and braking_time >= 1.0
    assert gain == pytest.approx(30.0, rel=0.03)
    t = drive['t']
    first = (t >= 10.0) & (t < 12.0)
    second = (t >= 22.5) & (t < 24.0)
    # not learnt yet (less than min_braking_time of braking): unknown, invalid
    assert not result.slope_valid[first][:100].any()
    assert result.slope_valid[second].all()
    np.testing.assert_allclose(result.slope[second], grade, atol=math.radians(0.3))


def test_a_nan_torque_is_never_held() -> None:
    vehicle = EstimatorVehicle(1600.0, 2.6, 1.1, 0.6, 1.5, 1.4, 0.34, 0.33, 2.6, 1.2,
                               0.01, 3.6, 9.81)  # fmt: skip
    est = Estimator(vehicle, EstimatorConfig(slope_filter_tau=0.0))
    omega = np.full(4, 50.0)
    for k in range(20):
        e = est.update(0.01 * k, omega, np.zeros(4), 17.0, 0.0, np.full(4, 200.0))
    assert e.fx[0] == pytest.approx(200.0 / 0.34) and e.slope_valid
    e = est.update(0.2, omega, np.zeros(4), 17.0, 0.0, np.array([200.0, math.nan, 200.0, 200.0]))
    assert np.all(e.fx == 0.0) and not e.mu_valid.any() and not e.slope_valid


def test_the_mapping_reads_brake_and_gear_offset() -> None:
    base = {
        'torque_source': 'engine',
        'engine_torque': {
            'topic': '/can/pt', 'type': 'std_msgs/msg/Float64MultiArray',
            'indices': [0, 1, 2, 3], 'speed_unit': 'rpm', 'gear_offset': 1,
        },
        'brake': {'topic': '/can/brake', 'type': 'std_msgs/msg/Float64MultiArray',
                  'signal': 'pressure', 'indices': [2, 3], 'unit': 'MPa'},
    }  # fmt: skip
    m = mapping_from_dict(base, 'car.yaml')
    assert m.engine.gear_offset == 1 and m.engine.indices == (0, 1, 2, 3)
    assert m.brake is not None and m.brake.signal == 'pressure' and m.brake.factor == 10.0
    assert [s.name for s in m.used_specs] == ['wheel_angles', 'body_speed', 'engine_torque',
                                             'brake']  # fmt: skip
    for change, message in (
        ({'signal': 'pedal'}, "brake.signal 'pedal' is unknown"),
        ({'signal': 'switch', 'indices': [0, 1]}, 'brake.indices must list 1'),
        ({'signal': 'switch', 'indices': [0], 'scale': 2.0}, 'unit and scale are for a'),
        ({'indices': [0, 1, 2]}, 'brake.indices must list 1 or 2 or 4'),
    ):
        brake = {k: v for k, v in base['brake'].items() if k != 'unit'}
        data = {**base, 'brake': {**brake, **change}}
        with pytest.raises(MappingError, match=message):
            mapping_from_dict(data, 'car.yaml')
    data = {**base, 'engine_torque': {**base['engine_torque'], 'gear_offset': 0.5}}
    with pytest.raises(MappingError, match='gear_offset must be an integer'):
        mapping_from_dict(data, 'car.yaml')
