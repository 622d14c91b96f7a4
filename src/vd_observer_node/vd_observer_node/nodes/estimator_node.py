"""ROS 2 node: tire forces, loads, friction, resistances and road slope from the observers.

Subscribes ``/vd/observer/wheel_states``, ``/vd/observer/body_accel``,
``/vd/observer/body_velocity`` (or the measured body speed) and ``/vd/sensors/wheel_torques``
(the sensor topics as the input mapping gives them: ``input_mapping`` or ``inputs.*``,
docs/input_mapping.md), matches them by header stamp (an input without header stamp, or derived
from one, joins each match with its latest value: :func:`held_inputs`) and publishes, with that
stamp,
``/vd/estimates/tire_forces`` (TireForces), ``/vd/estimates/friction`` (Friction),
``/vd/estimates/resistances`` (Resistances) and ``/vd/estimates/slope`` (Slope). Health and
fault counters go to ``/diagnostics`` once per second, with a WARN naming a mapped input
topic that stopped. All math is in
:mod:`vd_observer_node.estimation.estimator` (its compiled step). Messages travel as CDR
bytes (:mod:`vd_observer_node.bag.cdr_message`).
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import AccelStamped, TwistStamped
from rclpy.node import Node
from vd_common.ros.diagnostics import node_status
from vd_common.ros.lifecycle import run_node
from vd_common.ros.parameters import declare_parameters, log_settings
from vd_common.ros.publishing import PublishRefusals
from vd_common.ros.qos import DIAGNOSTICS_QOS, STREAM_QOS
from vd_common.topics import (
    ESTIMATES_FRICTION,
    ESTIMATES_MASS,
    ESTIMATES_RESISTANCES,
    ESTIMATES_ROLLING_RADIUS,
    ESTIMATES_SLOPE,
    ESTIMATES_TIRE_FORCES,
    OBSERVER_BODY_ACCEL,
    OBSERVER_BODY_VELOCITY,
    OBSERVER_WHEEL_STATES,
)
from vd_common.vehicle.params import default_vehicle_file

from vd_msgs.msg import (
    Friction,
    MassEstimate,
    Resistances,
    RollingRadiusEstimate,
    Slope,
    TireForces,
    WheelStates,
)
from vd_observer_node.estimation.estimator import Estimator
from vd_observer_node.estimation.faults import merge_reports, summarise
from vd_observer_node.estimation.imu_grade import SOURCE_FORCE
from vd_observer_node.estimation.rate_settings import RateMeter
from vd_observer_node.inputs.decode import has_header
from vd_observer_node.inputs.mapping import InputMapping
from vd_observer_node.nodes.node_params import (
    ESTIMATOR_PARAMS,
    INPUT_PARAMS,
    input_message_class,
    take_input_mapping,
    undeclared_inputs,
)
from vd_observer_node.nodes.raw_io import (
    Encoders,
    InputWatch,
    aligned_input,
    follow_input_rate,
    input_matcher,
    mapped_input,
    mass_values,
    merge_status,
    queued_by_topic,
    radius_values,
)
from vd_observer_node.situation.chain_settings import chain_settings, parameter_sections

__all__ = ['EstimatorNode', 'main']

PARAMS = [*ESTIMATOR_PARAMS, *INPUT_PARAMS]

TOPICS = ('states', 'accel', 'speed', 'torques')
_INPUT_TYPES = {
    'states': 'vd_msgs/msg/WheelStates',
    'accel': 'geometry_msgs/msg/AccelStamped',
    'speed': 'geometry_msgs/msg/TwistStamped',
    'torques': 'vd_msgs/msg/WheelTorques',
}


def held_inputs(mapping: InputMapping) -> list[str]:
    """The estimator's inputs taken at their latest value instead of matched by stamp.

    The wheel states carry the wheel angles' stamps and drive. The body acceleration and
    speed carry the body speed's stamps and the torques their own: each is held when its
    sensor has no header (stamped on receipt), and all are when the wheel angles have none.
    """
    if not has_header(mapping.wheels):
        return ['accel', 'speed', 'torques']
    held = [] if has_header(mapping.body_speed) else ['accel', 'speed']
    return held + ([] if has_header(mapping.wheel_torques) else ['torques'])


class EstimatorNode(Node):
    """Thin wrapper: stamp-matched raw messages -> Estimator.update -> four raw messages."""

    def __init__(self) -> None:
        super().__init__('estimator_node')
        self.refusals = PublishRefusals(self)  # a refused publish is counted, not fatal
        values = declare_parameters(self, PARAMS)
        log_settings(self, PARAMS, values)
        mapping = take_input_mapping(values, undeclared_inputs(self), estimates=True)
        if mapping.imu is not None:
            # one params file for every node may map an IMU: said once, not refused
            self.get_logger().info(
                f'imu ({mapping.imu.topic}) is fused by pipeline_node only: this node publishes '
                "the force balance's slope"
            )
        vehicle_file = values.pop('vehicle_file') or str(default_vehicle_file())
        capacity = values.pop('align_capacity')
        measured = values['speed_source'] == 'measured'
        # the measured speed and the torques are the mapping's topics and types
        sensors = {'torques': mapping.wheel_torques}
        if measured:
            sensors['speed'] = mapping.body_speed
        classes = {key: input_message_class(spec) for key, spec in sensors.items()}
        settings = chain_settings(mapping, vehicle_file, parameter_sections(values))
        self.vehicle = settings.vehicle
        config = settings.estimator
        self.estimator = Estimator(self.vehicle, config)
        # compile (or load from numba's cache) now, on a scratch estimator, not at the first
        # sample
        zeros = np.zeros(4)
        Estimator(self.vehicle, config).update(0.0, zeros, zeros, 0.0, 0.0, zeros)
        max_gap_ns = round(self.estimator.config.max_gap * 1e9)
        # TOPICS: the wheel sensor's stamps first; they drive, as in the replay
        self.aligner = input_matcher(
            mapping, TOPICS, capacity, max_gap_ns, max_gap_ns, held=held_inputs(mapping)
        )
        self.watch = InputWatch([spec.topic for spec in sensors.values()], max_gap_ns)
        # the wheel stamps (the observer's) and a measured speed's set what follows the rate
        self._wheel_rate: RateMeter | None = RateMeter()
        self._speed_topic = (
            mapping.body_speed.topic if measured and has_header(mapping.body_speed) else None
        )
        # the matcher's queue per input topic, reported against its capacity
        self._queue_topics = {key: spec.topic for key, spec in sensors.items()}
        self._capacity = capacity
        self._align_reported: dict[str, int] = {}
        self.pub_forces = self.refusals.publisher(TireForces, ESTIMATES_TIRE_FORCES, STREAM_QOS)
        self.pub_friction = self.refusals.publisher(Friction, ESTIMATES_FRICTION, STREAM_QOS)
        self.pub_resist = self.refusals.publisher(Resistances, ESTIMATES_RESISTANCES, STREAM_QOS)
        self.pub_slope = self.refusals.publisher(Slope, ESTIMATES_SLOPE, STREAM_QOS)
        # The online mass and radius only when adapted: with the file's constants they would
        # add two 1 kHz streams to a graph that is at its limit on two cores.
        self.pub_mass = (
            self.refusals.publisher(MassEstimate, ESTIMATES_MASS, STREAM_QOS)
            if config.mass_adaptation
            else None
        )
        self.pub_radius = (
            self.refusals.publisher(RollingRadiusEstimate, ESTIMATES_ROLLING_RADIUS, STREAM_QOS)
            if config.radius_adaptation
            else None
        )
        self.pub_diag = self.refusals.publisher(DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
        self._codec = Encoders()
        self.counts = {
            'estimates': 0,
            'mu_invalid_wheel_samples': 0,
            'slope_invalid': 0,
            'undecodable': 0,
            'unfit': 0,
        }
        observed = [
            ('states', WheelStates, OBSERVER_WHEEL_STATES),
            ('accel', AccelStamped, OBSERVER_BODY_ACCEL),
        ]
        if not measured:
            observed.append(('speed', TwistStamped, OBSERVER_BODY_VELOCITY))
        for key, kind, topic in observed:
            callback = aligned_input(
                _INPUT_TYPES[key], key, self.aligner, self.estimate, self.counts,
                lambda: self.get_clock().now().nanoseconds,
            )  # fmt: skip
            self.create_subscription(kind, topic, callback, STREAM_QOS, raw=True)
        clock = self.get_clock()
        for key, spec in sensors.items():
            callback = mapped_input(
                spec,
                self.aligner,
                self.estimate,
                self.counts,
                self.watch,
                lambda: clock.now().nanoseconds,
                key=key,
            )
            self.create_subscription(classes[key], spec.topic, callback, STREAM_QOS, raw=True)
        self.create_timer(1.0, self.publish_diagnostics)
        self.get_logger().info(
            f'estimator ready: vehicle {self.vehicle.name!r} '
            f'({vehicle_file})' + (f', inputs from {mapping.source}' if mapping.source else '')
        )

    def estimate(self, stamp_ns: int, m: dict[str, Any]) -> None:
        frame, (_, omega, omega_dot) = m['states']
        est = self.estimator.update(
            stamp_ns * 1e-9,
            np.array(omega, dtype=np.float64),
            np.array(omega_dot, dtype=np.float64),
            float(m['speed'][1][0]),  # twist.linear.x, or the mapped speed [m/s]
            float(m['accel'][1][0]),  # accel.linear.x
            np.array(m['torques'][1], dtype=np.float64),  # mapped, SI [N m]
        )
        if self._wheel_rate is not None and self._wheel_rate.add(stamp_ns):
            # from the next stamp on, as vd replay does (rate_settings.FOLLOW_AFTER)
            speed_stamps = self.watch.first_stamps(self._speed_topic)
            follow_input_rate(self.estimator, self._wheel_rate.stamps, speed_stamps, self)
            self._wheel_rate = None
        self.counts['estimates'] += 1
        self.counts['mu_invalid_wheel_samples'] += int(4 - np.count_nonzero(est.mu_valid))
        self.counts['slope_invalid'] += int(not est.slope_valid)
        codec = self._codec
        self.pub_forces.publish(
            codec('vd_msgs/msg/TireForces', frame).encode(
                stamp_ns, [*est.fx.tolist(), *est.fz.tolist(), est.torque_source]
            )
        )
        self.pub_friction.publish(
            codec('vd_msgs/msg/Friction', frame).encode(
                stamp_ns,
                [*est.mu.tolist(), *est.slip.tolist(), *est.mu_valid.tolist(), est.torque_source],
            )
        )
        self.pub_resist.publish(
            codec('vd_msgs/msg/Resistances', frame).encode(
                stamp_ns, [*est.rolling.tolist(), float(est.aero)]
            )
        )
        self.pub_slope.publish(
            codec('vd_msgs/msg/Slope', frame).encode(
                stamp_ns,
                # no IMU here: the force balance's slope (pipeline_node fuses an IMU)
                [
                    float(est.slope),
                    bool(est.slope_valid),
                    est.torque_source,
                    SOURCE_FORCE if est.slope_valid else 0,
                ],
            )
        )
        if self.pub_mass is not None:
            self.pub_mass.publish(
                codec('vd_msgs/msg/MassEstimate', frame).encode(stamp_ns, mass_values(est))
            )
        if self.pub_radius is not None:
            self.pub_radius.publish(
                codec('vd_msgs/msg/RollingRadiusEstimate', frame).encode(
                    stamp_ns, radius_values(est)
                )
            )

    def publish_diagnostics(self) -> None:
        # Level and message name the faults of the last period; the counters are totals.
        # Stale (older) messages at the aligner are the out-of-order/duplicate stamps of the
        # inputs; its restarts are the looped bag seen before the estimator core sees it.
        align = {
            'out_of_order': self.aligner.aligner.stale_count,
            'time_jump_back': self.aligner.aligner.jump_back_count,
        }
        report = merge_reports(
            {
                'estimator': self.estimator.faults.report(),
                'align': summarise(align, self._align_reported),
            }
        )
        self._align_reported = align
        values: dict[str, object] = {
            **self.counts,
            **self.aligner.counts(),
            **report.counts,
        }
        level, message, watch_values = merge_status(
            report.level,
            report.message,
            self.watch,
            time.monotonic_ns(),
            queued_by_topic(self.aligner, self._queue_topics),
            self._capacity,
            log=self.get_logger().warning,  # inputs whose stamps never meet: once
        )
        values.update(watch_values)
        self.pub_diag.publish(
            node_status(
                self, 'vd: estimator', 'estimator_node', level, message, values, self.refusals
            )
        )


def main(args: list[str] | None = None) -> int:
    """Entry point of ``ros2 run vd_observer_node estimator_node``."""
    return run_node(EstimatorNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
