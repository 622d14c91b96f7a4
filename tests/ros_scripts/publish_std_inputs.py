"""Test helper: publish a car's inputs with standard ROS types only (no vd_msgs).

    python publish_std_inputs.py RATE_HZ DURATION_S [PAUSE_FROM_S PAUSE_TO_S]

At RATE_HZ, for DURATION_S: sensor_msgs/JointState on /joint_states (four wheel joints and a
steering joint, in an order unlike FL, FR, RL, RR; the right wheels' positions negated, as
a URDF axis convention gives them), nav_msgs/Odometry on /odom in km/h (twist.twist.linear.x)
and std_msgs/Float64MultiArray on /can/wheel_torques in kN m (no header). JointState and
Odometry share each header stamp. The car rolls at 10 m/s with a slow speed ripple. Between
PAUSE_FROM_S and PAUSE_TO_S the torque topic is silent (a stopped CAN decoder). Prints
'PUBLISHING' when every publisher has a subscriber, 'DONE' at the end.
"""

from __future__ import annotations

import math
import sys
import time

import rclpy
from nav_msgs.msg import Odometry
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

RADIUS = 0.3  # [m]
#: published joint order; the mapping names FL, FR, RL, RR among them
JOINTS = ['steer_joint', 'wheel_rr_joint', 'wheel_fl_joint', 'wheel_rl_joint', 'wheel_fr_joint']
SIGNS = {
    'wheel_fl_joint': 1.0,
    'wheel_fr_joint': -1.0,
    'wheel_rl_joint': 1.0,
    'wheel_rr_joint': -1.0,
}


def main() -> int:
    rate, duration = float(sys.argv[1]), float(sys.argv[2])
    pause = (float(sys.argv[3]), float(sys.argv[4])) if len(sys.argv) > 4 else (-1.0, -1.0)
    rclpy.init()
    node = rclpy.create_node('vd_test_std_inputs')
    qos = QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE
    )
    p_joints = node.create_publisher(JointState, '/joint_states', qos)
    p_odom = node.create_publisher(Odometry, '/odom', qos)
    p_torque = node.create_publisher(Float64MultiArray, '/can/wheel_torques', qos)
    deadline = time.monotonic() + 60.0
    while time.monotonic() < deadline and not all(
        p.get_subscription_count() > 0 for p in (p_joints, p_odom, p_torque)
    ):
        time.sleep(0.05)
    print('PUBLISHING', flush=True)
    dt = 1.0 / rate
    t0 = time.monotonic()
    stamp0 = node.get_clock().now().nanoseconds
    k = 0
    while k * dt < duration:
        t = k * dt
        speed = 10.0 + 0.5 * math.sin(0.5 * t)  # [m/s]
        travelled = 10.0 * t + 1.0 * (1.0 - math.cos(0.5 * t))  # [m], integral of speed
        stamp = stamp0 + round(t * 1e9)
        js = JointState()
        js.header.stamp.sec, js.header.stamp.nanosec = divmod(stamp, 1_000_000_000)
        js.header.frame_id = 'base_link'
        js.name = JOINTS
        js.position = [
            0.0 if j == 'steer_joint' else SIGNS[j] * travelled / RADIUS for j in JOINTS
        ]
        odom = Odometry()
        odom.header = js.header
        odom.twist.twist.linear.x = speed * 3.6  # km/h
        p_joints.publish(js)
        p_odom.publish(odom)
        if not pause[0] <= t < pause[1]:
            p_torque.publish(Float64MultiArray(data=[0.05, 0.05, 0.0, 0.0, 99.0]))  # kN m
        k += 1
        time.sleep(max(0.0, t0 + k * dt - time.monotonic()))
    print('DONE', flush=True)
    time.sleep(0.5)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
