"""The topic contract of the vd stack: every topic name and its message type.

One table, used by the nodes that publish, subscribe or record these topics, so a name is
written once. Types are ROS 2 type names ('pkg/msg/Type'). See the README's topic contract.
"""

from __future__ import annotations

from typing import Final

__all__ = ['ALERTS', 'CONTRACT', 'ESTIMATES', 'OBSERVER', 'SENSORS', 'TRUTH']

SENSORS: Final = {
    '/vd/sensors/wheel_angles': 'vd_msgs/msg/WheelAngles',
    '/vd/sensors/body_velocity': 'geometry_msgs/msg/TwistStamped',
    '/vd/sensors/wheel_torques': 'vd_msgs/msg/WheelTorques',
}
OBSERVER: Final = {
    '/vd/observer/wheel_states': 'vd_msgs/msg/WheelStates',
    '/vd/observer/body_accel': 'geometry_msgs/msg/AccelStamped',
    '/vd/observer/body_velocity': 'geometry_msgs/msg/TwistStamped',
}
ESTIMATES: Final = {
    '/vd/estimates/tire_forces': 'vd_msgs/msg/TireForces',
    '/vd/estimates/friction': 'vd_msgs/msg/Friction',
    '/vd/estimates/resistances': 'vd_msgs/msg/Resistances',
    '/vd/estimates/slope': 'vd_msgs/msg/Slope',
}
ALERTS: Final = {
    '/vd/estimates/alerts': 'vd_msgs/msg/Alerts',
    '/vd/estimates/friction_potential': 'vd_msgs/msg/FrictionPotential',
}
TRUTH: Final = {
    '/vd/truth/wheel_states': 'vd_msgs/msg/WheelStates',
    '/vd/truth/body_accel': 'geometry_msgs/msg/AccelStamped',
    '/vd/truth/body_velocity': 'geometry_msgs/msg/TwistStamped',
    '/vd/truth/tire_forces': 'vd_msgs/msg/TireForces',
    '/vd/truth/friction': 'vd_msgs/msg/Friction',
    '/vd/truth/resistances': 'vd_msgs/msg/Resistances',
    '/vd/truth/slope': 'vd_msgs/msg/Slope',
    '/vd/truth/friction_potential': 'vd_msgs/msg/FrictionPotential',
}
CONTRACT: Final = {**SENSORS, **OBSERVER, **ESTIMATES, **ALERTS, **TRUTH}
