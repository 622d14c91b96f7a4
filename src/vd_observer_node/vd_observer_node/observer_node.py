"""ROS 2 node: Levant sliding-mode differentiators on wheel angles and body speed.

Subscribes ``/vd/sensors/wheel_angles`` (vd_msgs/WheelAngles) and
``/vd/sensors/body_velocity`` (geometry_msgs/TwistStamped); publishes, stamped with the
measurement's own stamp, ``/vd/observer/wheel_states`` (vd_msgs/WheelStates),
``/vd/observer/body_accel`` (geometry_msgs/AccelStamped) and the differentiator's filtered
speed ``/vd/observer/body_velocity`` (geometry_msgs/TwistStamped, which the estimator uses so
that the live graph computes exactly what the offline cascade does). Health and fault
counters go to ``/diagnostics`` once per second. All math is in
:mod:`vd_observer_node.observer`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import AccelStamped, TwistStamped
from rclpy.node import Node
from vd_sim_node.ros_common import (
    DIAGNOSTICS_QOS,
    STREAM_QOS,
    ParamSpec,
    dataclass_param_specs,
    declare_parameters,
    node_status,
    run_node,
    time_to_ns,
)

from vd_msgs.msg import WheelAngles, WheelStates
from vd_observer_node.differentiator import DEFAULT_GAINS, DISCRETIZATIONS, INIT_POLICIES
from vd_observer_node.faults import ERROR, merge_reports
from vd_observer_node.observer import ObserverConfig, SpeedObserver, WheelObserver

__all__ = ['ObserverNode', 'main']

PARAMS = [
    *dataclass_param_specs(
        ObserverConfig,
        skip=('gains',),
        choices={'discretization': DISCRETIZATIONS, 'init': INIT_POLICIES},
    ),
    ParamSpec('l0', DEFAULT_GAINS.l0, 'Levant gain lambda0 [-]'),
    ParamSpec('l1', DEFAULT_GAINS.l1, 'Levant gain lambda1 [-]'),
    ParamSpec('l2', DEFAULT_GAINS.l2, 'Levant gain lambda2 [-], > 1'),
]

_NS = 1e-9


class ObserverNode(Node):  # type: ignore[misc]
    """Thin wrapper: messages -> numpy -> WheelObserver/SpeedObserver -> messages."""

    def __init__(self) -> None:
        super().__init__('observer_node')
        values = declare_parameters(self, PARAMS)
        self.config = ObserverConfig.from_mapping(values)
        self.wheels = WheelObserver(self.config)
        self.speed = SpeedObserver(self.config)
        self.pub_states = self.create_publisher(
            WheelStates, '/vd/observer/wheel_states', STREAM_QOS
        )
        self.pub_accel = self.create_publisher(AccelStamped, '/vd/observer/body_accel', STREAM_QOS)
        self.pub_speed = self.create_publisher(
            TwistStamped, '/vd/observer/body_velocity', STREAM_QOS
        )
        self.pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
        self.create_subscription(
            WheelAngles, '/vd/sensors/wheel_angles', self.on_wheel_angles, STREAM_QOS
        )
        self.create_subscription(
            TwistStamped, '/vd/sensors/body_velocity', self.on_body_velocity, STREAM_QOS
        )
        self.counts = {'wheel_samples': 0, 'speed_samples': 0, 'withheld_non_finite': 0}
        self.create_timer(1.0, self.publish_diagnostics)
        self.get_logger().info(
            f'observer ready: {self.config.discretization} discretization, '
            f'L_wheel={self.config.wheel_lipschitz:g}, L_speed={self.config.speed_lipschitz:g}'
        )

    def on_wheel_angles(self, msg: Any) -> None:
        t = time_to_ns(msg.header.stamp) * _NS
        state = self.wheels.update(t, np.asarray(msg.angle, dtype=np.float64))
        self.counts['wheel_samples'] += 1
        if not (
            np.all(np.isfinite(state.angle))
            and np.all(np.isfinite(state.omega))
            and np.all(np.isfinite(state.omega_dot))
        ):
            self.counts['withheld_non_finite'] += 1
            return
        out = WheelStates(header=msg.header)
        out.angle = state.angle.tolist()
        out.omega = state.omega.tolist()
        out.omega_dot = state.omega_dot.tolist()
        self.pub_states.publish(out)

    def on_body_velocity(self, msg: Any) -> None:
        t = time_to_ns(msg.header.stamp) * _NS
        state = self.speed.update(t, float(msg.twist.linear.x))
        self.counts['speed_samples'] += 1
        if not (np.isfinite(state.speed) and np.isfinite(state.accel)):
            self.counts['withheld_non_finite'] += 1
            return
        accel = AccelStamped(header=msg.header)
        accel.accel.linear.x = state.accel
        self.pub_accel.publish(accel)
        speed = TwistStamped(header=msg.header)
        speed.twist.linear.x = state.speed
        self.pub_speed.publish(speed)

    def publish_diagnostics(self) -> None:
        # Level and message name the faults of the last period; the counters are totals.
        report = merge_reports(
            {'wheel': self.wheels.faults.report(), 'speed': self.speed.faults.report()}
        )
        level = report.level
        message = report.message
        if self.counts['withheld_non_finite']:
            level = max(level, ERROR)
            message += f'; {self.counts["withheld_non_finite"]} non-finite outputs withheld'
        values = {
            **self.counts,
            'rejected_wheel_stamps': self.wheels.rejected_count,
            'rejected_speed_stamps': self.speed.rejected_count,
            **report.counts,
        }
        self.pub_diag.publish(
            node_status(self, 'vd: observer', 'observer_node', level, message, values)
        )


def main(args: list[str] | None = None) -> int:
    """Entry point of ``ros2 run vd_observer_node observer_node``."""
    return run_node(ObserverNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
