"""ROS 2 node: road-friction potential and early alerts for ABS / TCS / ADAS nodes.

Subscribes, matched by header stamp: ``/vd/sensors/wheel_angles`` (for its own fast wheel
observer), ``/vd/sensors/body_velocity``, ``/vd/sensors/wheel_torques``,
``/vd/observer/wheel_states`` (the cascade's omega), ``/vd/estimates/friction`` (mu, validity)
and ``/vd/estimates/tire_forces`` (Fz). Publishes with that stamp
``/vd/estimates/friction_potential`` (vd_msgs/FrictionPotential: mu_max per axle, confidence,
road class) and ``/vd/estimates/alerts`` (vd_msgs/Alerts: traction, lock and low-friction
alerts per wheel, with hysteresis and onset stamps). Health goes to ``/diagnostics``. All logic
is in :mod:`vd_observer_node.situation` (see docs/alerts.md); offline replay runs the same.
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
    dataclass_param_specs,
    declare_parameters,
    node_status,
    ns_to_time,
    run_node,
    time_to_ns,
)
from vd_sim_node.vehicle.params import load_vehicle

from vd_msgs.msg import (
    Alert,
    Alerts,
    Friction,
    FrictionPotential,
    TireForces,
    WheelAngles,
    WheelStates,
    WheelTorques,
)
from vd_observer_node.alerts import ALERT_KINDS, AlertConfig
from vd_observer_node.alignment import StampAligner
from vd_observer_node.bag.replay import default_vehicle_file
from vd_observer_node.friction_potential import FrictionPotentialConfig, TyreCurves
from vd_observer_node.situation import SituationConfig, SituationMonitor
from vd_observer_node.vehicle import load_estimator_vehicle

__all__ = ['PARAMS', 'AlertsNode', 'main']

_THRESHOLD_DEFAULTS = AlertConfig()

PARAMS = [
    ParamSpec(
        'vehicle_file',
        '',
        "vehicle parameter YAML shared with the simulator ('' = the installed Clio RL 1.1)",
    ),
    ParamSpec(
        'align_capacity',
        200,
        'messages buffered per topic while matching stamps',
        low=1,
        high=100000,
    ),
    *dataclass_param_specs(SituationConfig),
    *dataclass_param_specs(AlertConfig, skip=ALERT_KINDS),
    *(
        ParamSpec(
            f'{kind}.{name}',
            float(getattr(getattr(_THRESHOLD_DEFAULTS, kind), name)),
            f'{kind} alert hysteresis threshold {name} '
            f'[{"-" if kind != "low_friction" else "utilisation |mu|/mu_max"}] '
            '(see docs/alerts.md)',
        )
        for kind in ALERT_KINDS
        for name in ('warning_on', 'warning_off', 'critical_on', 'critical_off')
    ),
    *dataclass_param_specs(FrictionPotentialConfig, skip=('road_scales', 'class_bounds')),
]

TOPICS = ('angles', 'speed', 'torques', 'states', 'friction', 'forces')


def _stamp(t: float) -> Any:
    return ns_to_time(round(t * 1e9)) if math.isfinite(t) else ns_to_time(0)


class AlertsNode(Node):  # type: ignore[misc]
    """Thin wrapper: stamp-matched messages -> SituationMonitor -> two messages."""

    def __init__(self) -> None:
        super().__init__('alerts_node')
        values = declare_parameters(self, PARAMS)
        vehicle_file = values.pop('vehicle_file') or str(default_vehicle_file())
        capacity = values.pop('align_capacity')
        vehicle = load_estimator_vehicle(vehicle_file)
        situation_keys = set(SituationConfig.__dataclass_fields__)
        friction_keys = set(FrictionPotentialConfig.__dataclass_fields__)
        self.monitor = SituationMonitor(
            TyreCurves.from_tire(load_vehicle(vehicle_file).tire),
            vehicle.static_wheel_loads[[0, 2]],
            vehicle.effective_radius,
            situation=SituationConfig.from_mapping(
                {k: v for k, v in values.items() if k in situation_keys}
            ),
            alerts=AlertConfig.from_mapping(
                {k: v for k, v in values.items() if k not in situation_keys | friction_keys}
            ),
            friction=FrictionPotentialConfig.from_mapping(
                {k: v for k, v in values.items() if k in friction_keys}
            ),
        )
        self.aligner = StampAligner(
            TOPICS,
            capacity=capacity,
            max_jump_back_ns=round(self.monitor.observer_config.max_gap * 1e9),
        )
        self.pub_alerts = self.create_publisher(Alerts, '/vd/estimates/alerts', STREAM_QOS)
        self.pub_potential = self.create_publisher(
            FrictionPotential, '/vd/estimates/friction_potential', STREAM_QOS
        )
        self.pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
        for key, kind, topic in (
            ('angles', WheelAngles, '/vd/sensors/wheel_angles'),
            ('speed', TwistStamped, '/vd/sensors/body_velocity'),
            ('torques', WheelTorques, '/vd/sensors/wheel_torques'),
            ('states', WheelStates, '/vd/observer/wheel_states'),
            ('friction', Friction, '/vd/estimates/friction'),
            ('forces', TireForces, '/vd/estimates/tire_forces'),
        ):
            self.create_subscription(kind, topic, self._make_callback(key), STREAM_QOS)
        self.counts = {'estimates': 0, 'alerts_raised': 0}
        self.create_timer(1.0, self.publish_diagnostics)
        self.get_logger().info(f'alerts ready: vehicle {vehicle.name!r} ({vehicle_file})')

    def _make_callback(self, key: str) -> Any:
        def callback(msg: Any) -> None:
            matched = self.aligner.push(key, time_to_ns(msg.header.stamp), msg)
            if matched is not None:
                self.evaluate(matched)

        return callback

    def evaluate(self, m: dict[str, Any]) -> None:
        friction, header = m['friction'], m['friction'].header
        active_before = sum(a.active for a in self.monitor.monitor.last)
        out = self.monitor.update(
            time_to_ns(header.stamp) * 1e-9,
            np.asarray(m['angles'].angle, dtype=np.float64),
            float(m['speed'].twist.linear.x),
            np.asarray(m['torques'].torque, dtype=np.float64),
            np.asarray(m['states'].omega, dtype=np.float64),
            np.asarray(friction.mu, dtype=np.float64),
            np.asarray(friction.valid, dtype=bool),
            np.asarray(m['forces'].fz, dtype=np.float64),
        )
        self.counts['estimates'] += 1
        self.counts['alerts_raised'] += max(0, sum(a.active for a in out.alerts) - active_before)
        pot = out.potential
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
                        kind=a.kind_code,
                        wheel=a.wheel,
                        level=a.level,
                        active=a.active,
                        onset=_stamp(a.onset),
                        detected=_stamp(a.detected),
                    )
                    for a in out.alerts
                ],
            )
        )

    def publish_diagnostics(self) -> None:
        active = self.monitor.monitor.active()
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
            'time_jump_back': self.aligner.jump_back_count,
        }
        self.pub_diag.publish(
            node_status(self, 'vd: alerts', 'alerts_node', level, message, values)
        )


def main(args: list[str] | None = None) -> int:
    """Entry point of ``ros2 run vd_observer_node alerts_node``."""
    return run_node(AlertsNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
