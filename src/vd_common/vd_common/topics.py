"""The topic contract of the vd stack: every topic name and its message type.

One table, used by the nodes that publish, subscribe or record these topics and by the tools,
tests and scripts that read them, so a name is written once: here. Code elsewhere uses the
constants below, never a literal ``/vd/...`` string (src/vd_common/test/test_topics.py
fails on one). A constant is named after its topic: the part after ``/vd/`` in upper case,
``/`` written ``_`` (``/vd/truth/slope`` is ``TRUTH_SLOPE``). Types are ROS 2 type names
('pkg/msg/Type'). See the README's topic contract.
"""

from __future__ import annotations

from typing import Final

__all__ = [
    'ALERTS',
    'COMBINED',
    'CONTRACT',
    'ESTIMATES',
    'ESTIMATES_ALERTS',
    'ESTIMATES_COMBINED',
    'ESTIMATES_FRICTION',
    'ESTIMATES_FRICTION_POTENTIAL',
    'ESTIMATES_MASS',
    'ESTIMATES_NAMESPACE',
    'ESTIMATES_RESISTANCES',
    'ESTIMATES_ROLLING_RADIUS',
    'ESTIMATES_SLOPE',
    'ESTIMATES_TIRE_FORCES',
    'ESTIMATES_TORQUE_OFFSET',
    'NAMESPACE',
    'OBSERVER',
    'OBSERVER_BODY_ACCEL',
    'OBSERVER_BODY_VELOCITY',
    'OBSERVER_NAMESPACE',
    'OBSERVER_WHEEL_STATES',
    'ON_CHANGE',
    'OPTIONAL_SENSORS',
    'SENSORS',
    'SENSORS_BODY_VELOCITY',
    'SENSORS_IMU',
    'SENSORS_NAMESPACE',
    'SENSORS_WHEEL_ANGLES',
    'SENSORS_WHEEL_TORQUES',
    'STATUS',
    'STATUS_NAMESPACE',
    'STATUS_RECORDER_PROGRESS',
    'TRUTH',
    'TRUTH_BODY_ACCEL',
    'TRUTH_BODY_VELOCITY',
    'TRUTH_FRICTION',
    'TRUTH_FRICTION_POTENTIAL',
    'TRUTH_NAMESPACE',
    'TRUTH_RESISTANCES',
    'TRUTH_SLOPE',
    'TRUTH_TIRE_FORCES',
    'TRUTH_WHEEL_STATES',
]

#: Every vd topic starts with this (the recorder records all of them).
NAMESPACE: Final = '/vd/'
#: The groups' namespaces (the alerts and the friction potential are estimates too).
SENSORS_NAMESPACE: Final = '/vd/sensors/'
OBSERVER_NAMESPACE: Final = '/vd/observer/'
ESTIMATES_NAMESPACE: Final = '/vd/estimates/'
TRUTH_NAMESPACE: Final = '/vd/truth/'
#: The nodes' own progress, for a simulator in lockstep (not recorded).
STATUS_NAMESPACE: Final = '/vd/status/'

# The simulator's measurements (or a bag's), the inputs of the observer and estimator.
SENSORS_WHEEL_ANGLES: Final = '/vd/sensors/wheel_angles'
SENSORS_BODY_VELOCITY: Final = '/vd/sensors/body_velocity'
SENSORS_WHEEL_TORQUES: Final = '/vd/sensors/wheel_torques'
# Optional: the simulator's IMU (specific force), where its scenario has one.
SENSORS_IMU: Final = '/vd/sensors/imu'
# The observer's outputs.
OBSERVER_WHEEL_STATES: Final = '/vd/observer/wheel_states'
OBSERVER_BODY_ACCEL: Final = '/vd/observer/body_accel'
OBSERVER_BODY_VELOCITY: Final = '/vd/observer/body_velocity'
# The estimator's outputs.
ESTIMATES_TIRE_FORCES: Final = '/vd/estimates/tire_forces'
ESTIMATES_FRICTION: Final = '/vd/estimates/friction'
ESTIMATES_RESISTANCES: Final = '/vd/estimates/resistances'
ESTIMATES_SLOPE: Final = '/vd/estimates/slope'
ESTIMATES_MASS: Final = '/vd/estimates/mass'
ESTIMATES_ROLLING_RADIUS: Final = '/vd/estimates/rolling_radius'
ESTIMATES_TORQUE_OFFSET: Final = '/vd/estimates/torque_offset'
# Every per-stamp estimate in one message (pipeline_node's estimate_topics 'combined' or 'both').
ESTIMATES_COMBINED: Final = '/vd/estimates/combined'
# The alerts node's outputs.
ESTIMATES_ALERTS: Final = '/vd/estimates/alerts'
ESTIMATES_FRICTION_POTENTIAL: Final = '/vd/estimates/friction_potential'
# The simulator's true values, the references of the estimates.
TRUTH_WHEEL_STATES: Final = '/vd/truth/wheel_states'
TRUTH_BODY_ACCEL: Final = '/vd/truth/body_accel'
TRUTH_BODY_VELOCITY: Final = '/vd/truth/body_velocity'
TRUTH_TIRE_FORCES: Final = '/vd/truth/tire_forces'
TRUTH_FRICTION: Final = '/vd/truth/friction'
TRUTH_RESISTANCES: Final = '/vd/truth/resistances'
TRUTH_SLOPE: Final = '/vd/truth/slope'
TRUTH_FRICTION_POTENTIAL: Final = '/vd/truth/friction_potential'

SENSORS: Final = {
    SENSORS_WHEEL_ANGLES: 'vd_msgs/msg/WheelAngles',
    SENSORS_BODY_VELOCITY: 'geometry_msgs/msg/TwistStamped',
    SENSORS_WHEEL_TORQUES: 'vd_msgs/msg/WheelTorques',
}
#: Sensors a scenario or a car may add (the simulator's IMU where its scenario says ``imu``):
#: in the contract, but not among the three every drive has.
OPTIONAL_SENSORS: Final = {
    SENSORS_IMU: 'sensor_msgs/msg/Imu',
}
OBSERVER: Final = {
    OBSERVER_WHEEL_STATES: 'vd_msgs/msg/WheelStates',
    OBSERVER_BODY_ACCEL: 'geometry_msgs/msg/AccelStamped',
    OBSERVER_BODY_VELOCITY: 'geometry_msgs/msg/TwistStamped',
}
ESTIMATES: Final = {
    ESTIMATES_TIRE_FORCES: 'vd_msgs/msg/TireForces',
    ESTIMATES_FRICTION: 'vd_msgs/msg/Friction',
    ESTIMATES_RESISTANCES: 'vd_msgs/msg/Resistances',
    ESTIMATES_SLOPE: 'vd_msgs/msg/Slope',
    ESTIMATES_MASS: 'vd_msgs/msg/MassEstimate',
    ESTIMATES_ROLLING_RADIUS: 'vd_msgs/msg/RollingRadiusEstimate',
    ESTIMATES_TORQUE_OFFSET: 'vd_msgs/msg/TorqueOffsetEstimate',
}
ALERTS: Final = {
    ESTIMATES_ALERTS: 'vd_msgs/msg/Alerts',
    ESTIMATES_FRICTION_POTENTIAL: 'vd_msgs/msg/FrictionPotential',
}
TRUTH: Final = {
    TRUTH_WHEEL_STATES: 'vd_msgs/msg/WheelStates',
    TRUTH_BODY_ACCEL: 'geometry_msgs/msg/AccelStamped',
    TRUTH_BODY_VELOCITY: 'geometry_msgs/msg/TwistStamped',
    TRUTH_TIRE_FORCES: 'vd_msgs/msg/TireForces',
    TRUTH_FRICTION: 'vd_msgs/msg/Friction',
    TRUTH_RESISTANCES: 'vd_msgs/msg/Resistances',
    TRUTH_SLOPE: 'vd_msgs/msg/Slope',
    TRUTH_FRICTION_POTENTIAL: 'vd_msgs/msg/FrictionPotential',
}
#: Optional: one message per stamp with what the per-quantity topics above carry (not in
#: CONTRACT: the recorder records it where it is published, discovered like a user's topic).
COMBINED: Final = {
    ESTIMATES_COMBINED: 'vd_msgs/msg/Estimates',
}
# The recorder's progress: the newest stamp up to which every per-sample topic it records has
# been written (std_msgs/Header: stamp, frame_id ''), for sim_node's lockstep mode.
STATUS_RECORDER_PROGRESS: Final = '/vd/status/recorder_progress'
STATUS: Final = {
    STATUS_RECORDER_PROGRESS: 'std_msgs/msg/Header',
}
CONTRACT: Final = {
    **SENSORS,
    **OPTIONAL_SENSORS,
    **OBSERVER,
    **ESTIMATES,
    **ALERTS,
    **TRUTH,
    **STATUS,
}
#: Topics published only where their value changes, not once per sample.
ON_CHANGE: Final = frozenset({ESTIMATES_TORQUE_OFFSET})
