"""The calibration's window means, converter fit, mapping reference and file writer."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from vd_observer_node.inputs.errors import MappingError
from vd_observer_node.inputs.mapping import mapping_from_dict
from vd_observer_node.tools.calibrate.converter import fit_capacity_factor
from vd_observer_node.tools.calibrate.drive import _Windows
from vd_observer_node.tools.calibrate.errors import CalibrationError, NotDeterminedError
from vd_observer_node.tools.calibrate.vehicle_file import write_vehicle_file


def test_window_means_and_rates_are_the_closed_forms() -> None:
    rng = np.random.default_rng(3)
    stamps = np.sort(rng.uniform(0.0, 20.0, 4000))  # irregular, as CAN frames come
    centres = np.linspace(2.0, 18.0, 50)
    w = _Windows(centres, 0.5)
    # the mean of a linear signal over a centred window is its value at the centre; the
    # trapezoid integrates it exactly, and the integral (a parabola) interpolated linearly at
    # the window's ends is off by at most gap^2 / 8 * slope at each end
    gap = float(np.diff(stamps).max())
    bound = 2.0 * gap**2 / 8.0 * 2.0 / 0.5
    mean = w.mean(stamps, 3.0 + 2.0 * stamps)
    np.testing.assert_allclose(mean, 3.0 + 2.0 * centres, rtol=0.0, atol=bound)
    # the mean rate of a parabola is its central difference: the derivative at the centre
    rate = w.rate(stamps, stamps**2)
    np.testing.assert_allclose(rate, 2.0 * centres, rtol=0.0, atol=2.0 * gap**2 / 4.0 / 0.5)
    flags = stamps > 10.0
    counts = w.count(stamps, flags)
    assert (counts[centres < 9.7] == 0).all() and (counts[centres > 10.3] > 0).all()
    gappy = np.where(np.abs(stamps - 5.0) < 0.01, np.nan, 1.0)
    held = w.mean(stamps, gappy)
    assert np.isnan(held[np.abs(centres - 5.0) < 0.25]).all()
    assert np.isfinite(held[np.abs(centres - 5.0) > 0.3]).all()


def test_the_capacity_factor_is_recovered_where_the_drive_covers_the_speed_ratio() -> None:
    rng = np.random.default_rng(5)
    grid = (0.0, 0.4, 0.6, 0.8, 0.9)
    table = (150.0, 155.0, 165.0, 185.0, 230.0)
    n = 5000
    ratio = rng.uniform(0.5, 0.85, n)  # the drive never stalls nor couples
    pump = rng.uniform(100.0, 400.0, n)  # rad/s
    k = np.interp(ratio, grid, table)
    torque = (pump * 30.0 / math.pi / k) ** 2 * (1.0 + rng.normal(0.0, 0.02, n))
    fits = fit_capacity_factor(grid, pump, ratio * pump, torque)
    assert fits[0] is None and fits[1] is None and fits[4] is None
    for point in (2, 3):
        fit = fits[point]
        assert fit is not None
        # the bin's +-0.05 spans a slope of K: within 1.5 % of the table at the grid point
        assert fit.value == pytest.approx(table[point], rel=0.015)
    with pytest.raises(NotDeterminedError):
        fit_capacity_factor(grid, pump, ratio * pump, np.full(n, 10.0))


def test_the_mapping_reads_a_reference_and_refuses_unknown_keys() -> None:
    mapping = mapping_from_dict(
        {
            'reference': {
                'speed': {'topic': '/gnss/odom', 'type': 'nav_msgs/msg/Odometry'},
                'grade': {
                    'topic': '/grade',
                    'type': 'std_msgs/msg/Float64MultiArray',
                    'indices': [0],
                    'unit': 'deg',
                },
            }
        }
    )
    assert mapping.reference is not None and mapping.reference.speed is not None
    assert mapping.reference.speed.topic == '/gnss/odom'
    assert mapping.reference.grade is not None
    assert mapping.reference.grade.factor == pytest.approx(math.pi / 180.0)
    with pytest.raises(MappingError, match=r'reference\.altitude: unknown key'):
        mapping_from_dict({'reference': {'altitude': {}}})
    with pytest.raises(MappingError, match='not supported'):
        mapping_from_dict(
            {'reference': {'grade': {'topic': '/g', 'type': 'nav_msgs/msg/Odometry'}}}
        )


def test_a_file_the_estimators_would_refuse_is_not_written(tmp_path: Path) -> None:
    out = tmp_path / 'car.yaml'
    with pytest.raises(CalibrationError, match='would not load'):
        write_vehicle_file(out, 'chassis:\n  mass: -3\n')
    assert not out.exists() and not list(tmp_path.iterdir())


def test_an_altitude_grade_is_the_hill_s_angle_and_holds_through_a_stop() -> None:
    from vd_observer_node.tools.calibrate.drive import altitude_grade

    # 3 deg up for 300 m, then level; a stop of 20 s on the hill (the distance stands still)
    speed_t = np.linspace(0.0, 80.0, 8001)
    speed = np.where((speed_t > 10.0) & (speed_t < 30.0), 0.0, 10.0)
    distance = np.concatenate(
        [[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(speed_t))]
    )
    alpha = math.radians(3.0)
    height = np.minimum(distance, 300.0) * math.sin(alpha)
    fix_t = speed_t[::10]  # 10 Hz fixes
    t = np.linspace(0.0, 80.0, 1601)
    grade = altitude_grade(t, fix_t, height[::10], speed_t, speed)
    on_hill = np.interp(t, speed_t, distance)
    up = (on_hill > 25.0) & (on_hill < 275.0)
    level = on_hill > 325.0
    np.testing.assert_allclose(grade[up], alpha, atol=1e-9)
    np.testing.assert_allclose(grade[level & np.isfinite(grade)], 0.0, atol=1e-9)
    assert np.isnan(grade[on_hill < 19.0]).all()  # the window leaves the first fix


def test_the_converter_s_capacity_and_torque_ratio_from_a_modelled_automatic() -> None:
    """An automatic car built from the converter's own equations (the oracle): pump torque
    ``(rpm / K(SR))^2``, turbine torque ``TR(SR)`` times it, through gear 4 (logged as 3: a
    bus offset of 1), the final drive and the efficiency to the wheels, and the motion that
    torque makes on a known grade. The base file (the RAV4's) has other K and TR tables."""
    from vd_common.vehicle.estimation import load_estimation_vehicle
    from vd_common.vehicle.params import default_vehicle_file
    from vd_observer_node.tools.calibrate.calibration import calibrate
    from vd_observer_node.tools.calibrate.drive import CalibrationDrive

    rav4 = Path(default_vehicle_file()).parent / 'toyota_rav4_2017_estimation.yaml'
    base = load_estimation_vehicle(rav4)
    line = base.driveline
    assert line is not None and line.converter is not None
    grid = np.asarray(line.converter.speed_ratio)
    true_k = np.asarray(line.converter.capacity_factor) * 1.1
    true_tr = np.where(
        grid < 0.87, 1.0 + (np.asarray(line.converter.torque_ratio) - 1.0) * 0.8, 1.0
    )
    rng = np.random.default_rng(8)
    n = 6000
    speed_ratio = rng.uniform(0.45, 0.85, n)
    pump = rng.uniform(150.0, 300.0, n)  # rad/s
    pump_torque = (pump * 30.0 / math.pi / np.interp(speed_ratio, grid, true_k)) ** 2
    turbine_torque = np.interp(speed_ratio, grid, true_tr) * pump_torque
    overall = line.ratios[3] * line.final_drive
    wheel_torque = turbine_torque * overall * line.efficiency[3]
    radius = base.wheel.effective_radius
    mass, g = base.chassis.mass, base.environment.gravity
    grade = rng.uniform(-0.05, 0.05, n)
    speed = pump * speed_ratio / overall * radius
    rolling = base.rolling_resistance.c0 * (1.0 + base.rolling_resistance.c1 * speed / 160.0)
    drag = 0.5 * base.aero.air_density * base.aero.drag_coefficient * base.aero.frontal_area
    accel = (
        wheel_torque / radius - mass * g * (np.sin(grade) + rolling * np.cos(grade))
        - drag * speed**2
    ) / mass  # fmt: skip
    omega = np.repeat((speed / radius)[:, None], 4, axis=1)
    drive = CalibrationDrive(
        source='model',
        t=np.arange(n) * 0.05,
        wheel_radps=omega,
        wheel_accel_radps2=np.zeros((n, 4)),  # the wheels' inertia left out of the model
        circumferential=False,
        speed_mps=speed,
        accel_mps2=accel,
        grade_rad=grade,
        wheel_torque_nm=None,
        engine_torque_nm=pump_torque,
        engine_radps=pump,
        engine_accel_radps2=np.zeros(n),
        turbine_radps=pump * speed_ratio,
        gear=np.full(n, 3, dtype=np.int64),
        mapped_gear_offset=1,
        braking=np.zeros(n, dtype=bool),
        brake_bar=None,
        has_brake_input=False,
        engine_path=True,
    )
    result = calibrate(drive, base)
    k = result.fits['torque_converter.capacity_factor']
    tr = result.fits['torque_converter.torque_ratio']
    assert isinstance(k.value, tuple) and isinstance(tr.value, tuple)
    covered = (grid >= 0.5) & (grid <= 0.8)  # the drive's 0.45-0.85, +-0.05 per point
    # the +-0.05 bin spans a slope of each table: within 1 % at the covered points
    np.testing.assert_allclose(np.asarray(k.value)[covered], true_k[covered], rtol=0.01)
    np.testing.assert_allclose(np.asarray(tr.value)[covered], true_tr[covered], rtol=0.01)
    # where the drive does not reach, the base's values stay
    assert k.value[0] == line.converter.capacity_factor[0]
    assert tr.value[0] == line.converter.torque_ratio[0]
