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
