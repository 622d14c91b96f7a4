"""ROS 2 node: road-friction potential and early alerts for ABS / TCS / ADAS nodes.

Subscribes ``/vd/estimates/friction`` (utilised μ, slip, validity), ``/vd/observer/wheel_states``
(ω) and ``/vd/sensors/body_velocity`` (v), matched by header stamp, and publishes with that
stamp ``/vd/estimates/friction_potential`` (vd_msgs/FrictionPotential: μ_max per axle,
confidence, road class) and ``/vd/estimates/alerts`` (vd_msgs/Alerts: traction, lock and
low-friction alerts per wheel, with hysteresis and onset stamps). Fault counters go to
``/diagnostics``. All logic is in :mod:`vd_observer_node.alerts` and
:mod:`vd_observer_node.friction_potential` (see docs/alerts.md).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import TwistStamped
from rclpy.node import Node
from vd_sim_node.ros_common import (
    DIAGNOSTICS_QOS,
    STREAM_QOS,
    ParamSpec,
    declare_parameters,
    diagnostic_array,
    ns_to_time,
    run_node,
    time_to_ns,
)

from vd_msgs.msg import Alert, Alerts, Friction, FrictionPotential, WheelStates
from vd_observer_node.alerts import AlertConfig, AlertMonitor, slip_velocity
from vd_observer_node.alignment import StampAligner
from vd_observer_node.bag.replay import default_vehicle_file
from vd_observer_node.friction_potential import (
    FrictionPotentialConfig,
    FrictionPotentialEstimator,
)
from vd_observer_node.vehicle import load_estimator_vehicle

__all__ = ['AlertsNode', 'main']

PARAMS = [
    ParamSpec(
        'vehicle_file',
        '',
        "vehicle parameter YAML shared with the simulator ('' = the installed Clio RL 1.1)",
    ),
]

_KIND_CODES = {
    'traction': Alert.KIND_TRACTION,
    'lock': Alert.KIND_LOCK,
    'low_friction': Alert.KIND_LOW_FRICTION,
}


def _stamp(t: float) -> Any:
    return ns_to_time(round(t * 1e9)) if math.isfinite(t) else ns_to_time(0)


class AlertsNode(Node):  # type: ignore[misc]
    """Thin wrapper: stamp-matched estimates -> FrictionPotentialEstimator, AlertMonitor."""

    def __init__(self) -> None:
        super().__init__('alerts_node')
        values = declare_parameters(self, PARAMS)
        vehicle = load_estimator_vehicle(values['vehicle_file'] or default_vehicle_file())
        self.radius = vehicle.effective_radius
        self.friction = FrictionPotentialEstimator(FrictionPotentialConfig())
        self.monitor = AlertMonitor(AlertConfig())
        self.aligner = StampAligner(('friction', 'states', 'speed'))
        self.pub_alerts = self.create_publisher(Alerts, '/vd/estimates/alerts', STREAM_QOS)
        self.pub_potential = self.create_publisher(
            FrictionPotential, '/vd/estimates/friction_potential', STREAM_QOS
        )
        self.pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
        for key, kind, topic in (
            ('friction', Friction, '/vd/estimates/friction'),
            ('states', WheelStates, '/vd/observer/wheel_states'),
            ('speed', TwistStamped, '/vd/sensors/body_velocity'),
        ):
            self.create_subscription(kind, topic, self._make_callback(key), STREAM_QOS)
        self.counts = {'estimates': 0, 'alerts_raised': 0}
        self.create_timer(1.0, self.publish_diagnostics)
        self.get_logger().info('alerts ready')

    def _make_callback(self, key: str) -> Any:
        def callback(msg: Any) -> None:
            matched = self.aligner.push(key, time_to_ns(msg.header.stamp), msg)
            if matched is not None:
                self.evaluate(matched)

        return callback

    def evaluate(self, m: dict[str, Any]) -> None:
        friction, header = m['friction'], m['friction'].header
        t = time_to_ns(header.stamp) * 1e-9
        v = float(m['speed'].twist.linear.x)
        mu = np.asarray(friction.mu, dtype=np.float64)
        valid = np.asarray(friction.valid, dtype=bool)
        sv = slip_velocity(np.asarray(m['states'].omega, dtype=np.float64), v, self.radius)
        pot = self.friction.update(t, self.friction.fit_slip(sv, v), mu, valid)
        before = sum(a.active for a in self.monitor.active())
        alerts = self.monitor.update(
            t, np.asarray(friction.slip), sv, mu, valid, pot.wheel_mu_max()
        )
        self.counts['estimates'] += 1
        self.counts['alerts_raised'] += max(0, sum(a.active for a in alerts) - before)
        self.pub_potential.publish(
            FrictionPotential(
                header=header,
                mu_max=[float(x) for x in pot.mu_max],
                slip_peak=[float(x) for x in pot.slip_peak],
                confidence=[float(x) for x in pot.confidence],
                road_class=[int(x) for x in pot.road_class],
                vehicle_road_class=int(pot.vehicle_road_class()),
            )
        )
        self.pub_alerts.publish(
            Alerts(
                header=header,
                alerts=[
                    Alert(
                        kind=_KIND_CODES[a.kind],
                        wheel=a.wheel,
                        level=a.level,
                        active=a.active,
                        onset=_stamp(a.onset),
                        detected=_stamp(a.detected),
                    )
                    for a in alerts
                ],
            )
        )

    def publish_diagnostics(self) -> None:
        active = self.monitor.active()
        level = DiagnosticStatus.WARN if active else DiagnosticStatus.OK
        message = (
            ', '.join(f'{a.kind} wheel {a.wheel} level {a.level}' for a in active)
            if active
            else 'no alert'
        )
        values = {
            **self.counts,
            'unmatched_dropped': self.aligner.dropped_count,
            'stale': self.aligner.stale_count,
        }
        self.pub_diag.publish(
            diagnostic_array(
                self.get_clock().now().to_msg(),
                'vd: alerts',
                'alerts_node',
                level,
                message,
                values,
            )
        )


def main(args: list[str] | None = None) -> int:
    """Entry point of ``ros2 run vd_observer_node alerts_node``."""
    return run_node(AlertsNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
