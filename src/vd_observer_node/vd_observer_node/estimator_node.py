"""ROS 2 node: tire forces, loads, friction, resistances and road slope from the observers.

Subscribes ``/vd/observer/wheel_states``, ``/vd/observer/body_accel``,
``/vd/observer/body_velocity`` and ``/vd/sensors/wheel_torques``, matches them by header
stamp (:class:`vd_observer_node.alignment.StampAligner`) and publishes, with that stamp,
``/vd/estimates/tire_forces`` (TireForces), ``/vd/estimates/friction`` (Friction),
``/vd/estimates/resistances`` (Resistances) and ``/vd/estimates/slope`` (Slope). Health and
fault counters go to ``/diagnostics`` once per second. All math is in
:mod:`vd_observer_node.estimator`.
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

from vd_msgs.msg import Friction, Resistances, Slope, TireForces, WheelStates, WheelTorques
from vd_observer_node.alignment import StampAligner
from vd_observer_node.bag.replay import default_vehicle_file
from vd_observer_node.estimator import (
    LOAD_TRANSFER_SOURCES,
    SLOPE_ACCEL_SOURCES,
    Estimator,
    EstimatorConfig,
)
from vd_observer_node.faults import merge_reports, summarise
from vd_observer_node.vehicle import load_estimator_vehicle

__all__ = ['EstimatorNode', 'main']

SPEED_TOPICS_CHOICES = ('measured', 'observer')

PARAMS = [
    ParamSpec(
        'vehicle_file',
        '',
        "vehicle parameter YAML shared with the simulator ('' = the installed Clio RL 1.1 file)",
    ),
    ParamSpec(
        'speed_source',
        'measured',
        "body speed fed to the estimator: 'measured' (/vd/sensors/body_velocity; the slope "
        "low-pass smooths it) or 'observer' (/vd/observer/body_velocity, filtered); must "
        'match the offline cascade (run_cascade estimator_speed) for identical results',
        choices=SPEED_TOPICS_CHOICES,
    ),
    ParamSpec(
        'align_capacity',
        200,
        'messages buffered per topic while matching stamps',
        low=1,
        high=100000,
    ),
    *dataclass_param_specs(
        EstimatorConfig,
        choices={
            'load_transfer_source': LOAD_TRANSFER_SOURCES,
            'slope_accel_source': SLOPE_ACCEL_SOURCES,
        },
    ),
]

TOPICS = ('states', 'accel', 'speed', 'torques')
SPEED_TOPICS = {
    'measured': '/vd/sensors/body_velocity',
    'observer': '/vd/observer/body_velocity',
}


class EstimatorNode(Node):  # type: ignore[misc]
    """Thin wrapper: stamp-matched messages -> Estimator.update -> four estimate messages."""

    def __init__(self) -> None:
        super().__init__('estimator_node')
        values = declare_parameters(self, PARAMS)
        vehicle_file = values.pop('vehicle_file') or str(default_vehicle_file())
        capacity = values.pop('align_capacity')
        speed_topic = SPEED_TOPICS[values.pop('speed_source')]
        self.vehicle = load_estimator_vehicle(vehicle_file)
        self.estimator = Estimator(self.vehicle, EstimatorConfig.from_mapping(values))
        self.aligner = StampAligner(
            TOPICS,
            capacity=capacity,
            max_jump_back_ns=round(self.estimator.config.max_gap * 1e9),
        )
        self._align_reported: dict[str, int] = {}
        self.pub_forces = self.create_publisher(
            TireForces, '/vd/estimates/tire_forces', STREAM_QOS
        )
        self.pub_friction = self.create_publisher(Friction, '/vd/estimates/friction', STREAM_QOS)
        self.pub_resist = self.create_publisher(
            Resistances, '/vd/estimates/resistances', STREAM_QOS
        )
        self.pub_slope = self.create_publisher(Slope, '/vd/estimates/slope', STREAM_QOS)
        self.pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
        for key, kind, topic in (
            ('states', WheelStates, '/vd/observer/wheel_states'),
            ('accel', AccelStamped, '/vd/observer/body_accel'),
            ('speed', TwistStamped, speed_topic),
            ('torques', WheelTorques, '/vd/sensors/wheel_torques'),
        ):
            self.create_subscription(kind, topic, self._make_callback(key), STREAM_QOS)
        self.counts = {'estimates': 0, 'mu_invalid_wheel_samples': 0, 'slope_invalid': 0}
        self.create_timer(1.0, self.publish_diagnostics)
        self.get_logger().info(f'estimator ready: vehicle {self.vehicle.name!r} ({vehicle_file})')

    def _make_callback(self, key: str) -> Any:
        def callback(msg: Any) -> None:
            matched = self.aligner.push(key, time_to_ns(msg.header.stamp), msg)
            if matched is not None:
                self.estimate(matched)

        return callback

    def estimate(self, m: dict[str, Any]) -> None:
        states, header = m['states'], m['states'].header
        t = time_to_ns(header.stamp) * 1e-9
        est = self.estimator.update(
            t,
            np.asarray(states.omega),
            np.asarray(states.omega_dot),
            float(m['speed'].twist.linear.x),
            float(m['accel'].accel.linear.x),
            np.asarray(m['torques'].torque),
        )
        self.counts['estimates'] += 1
        self.counts['mu_invalid_wheel_samples'] += int(4 - np.count_nonzero(est.mu_valid))
        self.counts['slope_invalid'] += int(not est.slope_valid)
        self.pub_forces.publish(TireForces(header=header, fx=est.fx.tolist(), fz=est.fz.tolist()))
        self.pub_friction.publish(
            Friction(
                header=header,
                mu=est.mu.tolist(),
                slip=est.slip.tolist(),
                valid=[bool(v) for v in est.mu_valid],
            )
        )
        self.pub_resist.publish(
            Resistances(header=header, rolling=est.rolling.tolist(), aero=float(est.aero))
        )
        self.pub_slope.publish(
            Slope(header=header, angle=float(est.slope), valid=bool(est.slope_valid))
        )

    def publish_diagnostics(self) -> None:
        # Level and message name the faults of the last period; the counters are totals.
        # Stale (older) messages at the aligner are the out-of-order/duplicate stamps of the
        # inputs; its restarts are the looped bag seen before the estimator core sees it.
        align = {
            'out_of_order': self.aligner.stale_count,
            'time_jump_back': self.aligner.jump_back_count,
        }
        report = merge_reports(
            {
                'estimator': self.estimator.faults.report(),
                'align': summarise(align, self._align_reported),
            }
        )
        self._align_reported = align
        values = {
            **self.counts,
            'unmatched_dropped': self.aligner.dropped_count,
            'stale': self.aligner.stale_count,
            **report.counts,
        }
        level, message = report.level, report.message
        self.pub_diag.publish(
            node_status(self, 'vd: estimator', 'estimator_node', level, message, values)
        )


def main(args: list[str] | None = None) -> int:
    """Entry point of ``ros2 run vd_observer_node estimator_node``."""
    return run_node(EstimatorNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
