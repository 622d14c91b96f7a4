"""Units in an input mapping are read regardless of case (``unit: RPM`` is rpm)."""

from __future__ import annotations

import math

import pytest
from vd_observer_node.inputs.errors import MappingError
from vd_observer_node.inputs.mapping import UNITS, mapping_from_dict

FLOAT64 = 'std_msgs/msg/Float64MultiArray'
WHEELS = {'topic': '/w', 'type': FLOAT64, 'indices': [0, 1, 2, 3]}


@pytest.mark.parametrize(
    ('written', 'factor', 'per_radius'),
    [
        ('RPM', 2.0 * math.pi / 60.0, False),
        ('Rpm', 2.0 * math.pi / 60.0, False),
        ('Rad/S', 1.0, False),
        ('DEG/S', math.pi / 180.0, False),
        ('KM/H', 1.0 / 3.6, True),
        (' km/h ', 1.0 / 3.6, True),
        ('M/S', 1.0, True),
    ],
)
def test_wheel_speed_units_in_any_case(written: str, factor: float, per_radius: bool) -> None:
    spec = mapping_from_dict({'wheel_speeds': {**WHEELS, 'unit': written}}).wheels
    assert spec.factor == pytest.approx(factor, rel=1e-15)
    assert spec.per_radius is per_radius


def test_units_of_every_input_in_any_case() -> None:
    data = {
        'wheel_angles': {'topic': '/a', 'type': FLOAT64, 'unit': 'DEG'},
        'body_speed': {'topic': '/v', 'type': 'nav_msgs/msg/Odometry', 'unit': 'Km/H'},
        'wheel_torques': {'topic': '/t', 'type': FLOAT64, 'unit': 'KN M'},
        'imu': {'topic': '/imu', 'type': 'sensor_msgs/msg/Imu', 'unit': 'G'},
        'brake': {'topic': '/b', 'type': FLOAT64, 'signal': 'pressure', 'unit': 'KPA'},
    }
    mapping = mapping_from_dict(data)
    assert mapping.wheels.factor == pytest.approx(math.pi / 180.0)
    assert mapping.body_speed.factor == pytest.approx(1.0 / 3.6)
    assert mapping.wheel_torques.factor == 1000.0
    assert mapping.imu is not None and mapping.imu.factor == UNITS['imu']['g']
    assert mapping.brake is not None and mapping.brake.factor == UNITS['brake']['kPa']
    # kPa, MPa and Pa stay apart: only case is folded, never a prefix
    data['brake'] = {**data['brake'], 'unit': 'mpa'}
    brake = mapping_from_dict(data).brake
    assert brake is not None and brake.factor == UNITS['brake']['MPa']


def test_the_engine_speed_unit_in_any_case() -> None:
    engine = {
        'topic': '/can/engine',
        'type': FLOAT64,
        'indices': [1, 0, 2],
        'unit': 'kn m',
        'speed_unit': 'RPM',
    }
    spec = mapping_from_dict({'torque_source': 'engine', 'engine_torque': engine}).engine_torque
    assert spec is not None
    assert spec.speed_factor == pytest.approx(math.pi / 30.0) and spec.factor == 1000.0


def test_an_unknown_unit_is_still_refused_listing_the_units() -> None:
    with pytest.raises(MappingError) as info:
        mapping_from_dict({'wheel_speeds': {**WHEELS, 'unit': 'MPH'}}, source='car.yaml')
    assert str(info.value) == (
        "car.yaml: wheel_speeds.unit 'MPH' is unknown (use one of rad/s, rpm, deg/s, m/s, km/h)"
    )
    with pytest.raises(MappingError, match=r'unit 3 is unknown'):
        mapping_from_dict({'wheel_speeds': {**WHEELS, 'unit': 3}})
