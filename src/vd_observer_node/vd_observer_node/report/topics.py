"""Topic names and message types the report reads (the vd topic contract)."""

from __future__ import annotations

__all__ = [
    'ESTIMATE_TOPICS',
    'GEAR_TOPIC',
    'SENSOR_TOPICS',
    'TRUTH_TOPICS',
    'WHEEL_NAMES',
]

#: Wheel order of every per-wheel array.
WHEEL_NAMES = ('FL', 'FR', 'RL', 'RR')

SENSOR_TOPICS = {
    '/vd/sensors/wheel_angles': 'vd_msgs/msg/WheelAngles',
    '/vd/sensors/body_velocity': 'geometry_msgs/msg/TwistStamped',
    '/vd/sensors/wheel_torques': 'vd_msgs/msg/WheelTorques',
}
#: Gear changes (``gear`` field) mark the shift windows excluded from the metrics.
GEAR_TOPIC = '/vd/sensors/wheel_torques'

ESTIMATE_TOPICS = {
    '/vd/observer/wheel_states': 'vd_msgs/msg/WheelStates',
    '/vd/observer/body_accel': 'geometry_msgs/msg/AccelStamped',
    '/vd/observer/body_velocity': 'geometry_msgs/msg/TwistStamped',
    '/vd/estimates/tire_forces': 'vd_msgs/msg/TireForces',
    '/vd/estimates/friction': 'vd_msgs/msg/Friction',
    '/vd/estimates/resistances': 'vd_msgs/msg/Resistances',
    '/vd/estimates/slope': 'vd_msgs/msg/Slope',
}

TRUTH_TOPICS = {
    '/vd/truth/wheel_states': 'vd_msgs/msg/WheelStates',
    '/vd/truth/body_accel': 'geometry_msgs/msg/AccelStamped',
    '/vd/truth/body_velocity': 'geometry_msgs/msg/TwistStamped',
    '/vd/truth/tire_forces': 'vd_msgs/msg/TireForces',
    '/vd/truth/friction': 'vd_msgs/msg/Friction',
    '/vd/truth/resistances': 'vd_msgs/msg/Resistances',
    '/vd/truth/slope': 'vd_msgs/msg/Slope',
}
