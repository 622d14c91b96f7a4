"""ROS 2 node: road-friction potential and early alerts for ABS / TCS / ADAS nodes.

Subscribes, matched by header stamp: ``/vd/sensors/wheel_angles`` (for its own fast wheel
observer), ``/vd/sensors/body_velocity``, ``/vd/sensors/wheel_torques``,
``/vd/observer/wheel_states`` (the cascade's omega), ``/vd/estimates/friction`` (mu, validity)
and ``/vd/estimates/tire_forces`` (Fz); the three sensor topics as the input mapping gives them
(``input_mapping`` or ``inputs.*``, docs/input_mapping.md; an input without header stamp joins each
match with its latest value, see :func:`held_inputs`). Publishes with that stamp
``/vd/estimates/friction_potential`` (vd_msgs/FrictionPotential: mu_max per axle, confidence,
road class) and ``/vd/estimates/alerts`` (vd_msgs/Alerts: traction, lock and low-friction
alerts per wheel, with hysteresis and onset stamps). Health goes to ``/diagnostics``, with a
WARN naming a mapped input topic that stopped. With a vehicle file without ``tire`` the node
subscribes and publishes nothing but ``/diagnostics`` (OK, ``situation: off (no tire ...)``),
says so once in its log and stays up (docs/alerts.md). All logic
is in :mod:`vd_observer_node.situation.monitor` (see docs/alerts.md); offline replay runs the same.
Its step functions are compiled (numba); messages travel as CDR bytes
(:mod:`vd_observer_node.bag.cdr_message`).
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from vd_common.ros.diagnostics import node_status
from vd_common.ros.lifecycle import run_node
from vd_common.ros.parameters import declare_parameters, log_settings
from vd_common.ros.publishing import PublishRefusals
from vd_common.ros.qos import DIAGNOSTICS_QOS, STREAM_QOS
from vd_common.topics import (
    ESTIMATES_ALERTS,
    ESTIMATES_FRICTION,
    ESTIMATES_FRICTION_POTENTIAL,
    ESTIMATES_TIRE_FORCES,
    OBSERVER_WHEEL_STATES,
)
from vd_common.vehicle.params import default_vehicle_file

from vd_msgs.msg import (
    Alerts,
    Friction,
    FrictionPotential,
    TireForces,
    WheelStates,
)
from vd_observer_node.estimation.faults import OK, WARN
from vd_observer_node.inputs.decode import has_header
from vd_observer_node.inputs.mapping import InputMapping
from vd_observer_node.nodes.node_params import (
    ALERTS_PARAMS,
    INPUT_PARAMS,
    input_message_class,
    take_input_mapping,
    undeclared_inputs,
)
from vd_observer_node.nodes.raw_io import (
    Encoders,
    InputWatch,
    aligned_input,
    input_matcher,
    mapped_input,
    merge_status,
    queued_by_topic,
)
from vd_observer_node.situation.chain_settings import chain_settings, parameter_sections
from vd_observer_node.situation.monitor import SituationMonitor

__all__ = ['PARAMS', 'AlertsNode', 'main']

PARAMS = [*ALERTS_PARAMS, *INPUT_PARAMS]

TOPICS = ('angles', 'speed', 'torques', 'states', 'friction', 'forces')
#: the node's name of each mapped sensor input
_SENSORS = {'angles': 'wheels', 'speed': 'body_speed', 'torques': 'wheel_torques'}
_DERIVED = (
    ('states', WheelStates, OBSERVER_WHEEL_STATES, 'vd_msgs/msg/WheelStates'),
    ('friction', Friction, ESTIMATES_FRICTION, 'vd_msgs/msg/Friction'),
    ('forces', TireForces, ESTIMATES_TIRE_FORCES, 'vd_msgs/msg/TireForces'),
)


def held_inputs(mapping: InputMapping) -> list[str]:
    """The sensor inputs taken at their latest value instead of matched by stamp.

    The cascade's outputs carry the wheel angles' stamps (or the observer's receive time when
    the angles have no header, and then every sensor input is held); a sensor without header
    is held.
    """
    specs = {key: getattr(mapping, name) for key, name in _SENSORS.items()}
    if not has_header(specs['angles']):
        return list(_SENSORS)
    return [key for key, spec in specs.items() if not has_header(spec)]


def _ns(t: float) -> int:
    return round(t * 1e9) if math.isfinite(t) else 0


class AlertsNode(Node):
    """Thin wrapper: stamp-matched raw messages -> SituationMonitor -> two raw messages."""

    def __init__(self) -> None:
        super().__init__('alerts_node')
        self.refusals = PublishRefusals(self)  # a refused publish is counted, not fatal
        values = declare_parameters(self, PARAMS)
        log_settings(self, PARAMS, values)
        mapping = take_input_mapping(values, undeclared_inputs(self), estimates=True)
        sensors = {key: getattr(mapping, name) for key, name in _SENSORS.items()}
        classes = {key: input_message_class(spec) for key, spec in sensors.items()}
        vehicle_file = values.pop('vehicle_file') or str(default_vehicle_file())
        capacity = values.pop('align_capacity')
        # the monitor's settings as the pipeline's: one read of the file, the mapping's sensors
        settings = chain_settings(mapping, vehicle_file, parameter_sections(values))
        vehicle = settings.vehicle
        self.pub_diag = self.refusals.publisher(DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
        self._off = settings.situation_off
        if settings.curves is None:
            # Every alert is off: low friction compares mu with the Magic Formula's peak, and
            # the 12 channels of vd_msgs/Alerts have no 'not computed' level, so a traction or
            # lock alert alone would publish the low-friction channels as OK. The node stays
            # up (a launch file of the whole graph must not die) and says why, once.
            self.get_logger().info(
                f'alerts and friction potential {self._off}: nothing to do; staying up, '
                'reporting on /diagnostics'
            )
            self.create_timer(1.0, self.publish_off)
            return
        self.monitor = SituationMonitor(
            settings.curves,
            vehicle.static_wheel_loads[[0, 2]],
            vehicle.effective_radius,
            # its fast wheel observer reads the wheel sensor: angles or ABS speeds
            observer=settings.observer,
            situation=settings.situation,
            alerts=settings.alerts,
            friction=settings.friction,
        )
        max_gap_ns = round(self.monitor.observer_config.max_gap * 1e9)
        # TOPICS: the wheel sensor's stamps first; they drive, as in the replay
        self.aligner = input_matcher(
            mapping, TOPICS, capacity, max_gap_ns, max_gap_ns, held=held_inputs(mapping)
        )
        self.watch = InputWatch([spec.topic for spec in sensors.values()], max_gap_ns)
        # the matcher's queue per input topic, reported against its capacity
        self._queue_topics = {key: spec.topic for key, spec in sensors.items()}
        self._capacity = capacity
        self.pub_alerts = self.refusals.publisher(Alerts, ESTIMATES_ALERTS, STREAM_QOS)
        self.pub_potential = self.refusals.publisher(
            FrictionPotential, ESTIMATES_FRICTION_POTENTIAL, STREAM_QOS
        )
        self.encoders = Encoders()
        self.counts = {'estimates': 0, 'alerts_raised': 0, 'undecodable': 0, 'unfit': 0}
        clock = self.get_clock()
        for key, spec in sensors.items():
            callback = mapped_input(
                spec,
                self.aligner,
                self.evaluate,
                self.counts,
                self.watch,
                lambda: clock.now().nanoseconds,
                key=key,
                radius=vehicle.effective_radius,
            )
            self.create_subscription(classes[key], spec.topic, callback, STREAM_QOS, raw=True)
        for key, kind, topic, msgtype in _DERIVED:
            callback = aligned_input(msgtype, key, self.aligner, self.evaluate, self.counts)
            self.create_subscription(kind, topic, callback, STREAM_QOS, raw=True)
        self._active: tuple[Any, ...] = ()
        self.create_timer(1.0, self.publish_diagnostics)
        self.get_logger().info(
            f'alerts ready: vehicle {vehicle.name!r} ({vehicle_file})'
            + (f', inputs from {mapping.source}' if mapping.source else '')
        )

    def evaluate(self, stamp_ns: int, m: dict[str, Any]) -> None:
        frame = m['states'][0]  # the outputs' frame, as the cascade's outputs carry it
        angles = m['angles'][1]  # mapped: SI values with the mapping's signs
        mu, _, valid = m['friction'][1][:3]  # mu, slip, valid (then torque_source)
        out = self.monitor.update(
            stamp_ns * 1e-9,
            np.array(angles, dtype=np.float64),
            float(m['speed'][1][0]),
            np.array(m['torques'][1], dtype=np.float64),
            np.array(m['states'][1][1], dtype=np.float64),  # omega
            np.array(mu, dtype=np.float64),
            np.array(valid, dtype=np.bool_),
            np.array(m['forces'][1][1], dtype=np.float64),  # fz
        )
        self.counts['estimates'] += 1
        active = tuple(a for a in out.alerts if a.active)
        self.counts['alerts_raised'] += max(0, len(active) - len(self._active))
        self._active = active
        pot = out.potential
        self.pub_potential.publish(
            self.encoders('vd_msgs/msg/FrictionPotential', frame).encode(
                stamp_ns,
                [
                    *pot.mu_max.tolist(),
                    *pot.slip_peak.tolist(),
                    *pot.confidence.tolist(),
                    *pot.road_class.tolist(),
                    pot.vehicle_road_class(),
                ],
            )
        )
        self.pub_alerts.publish(
            self.encoders.alerts(frame).encode(
                stamp_ns,
                [a.level for a in out.alerts],
                [_ns(a.onset) for a in out.alerts],
                [_ns(a.detected) for a in out.alerts],
            )
        )

    def publish_off(self) -> None:
        """Diagnostics of a node that has nothing to do (a vehicle file without tyre): OK,
        it is a configuration, with the reason as the ``situation`` value."""
        message = 'off: no tire in the vehicle file (friction potential and alerts need it)'
        values: dict[str, object] = {'situation': self._off}
        self.pub_diag.publish(
            node_status(self, 'vd: alerts', 'alerts_node', OK, message, values, self.refusals)
        )

    def publish_diagnostics(self) -> None:
        active = self._active
        level = WARN if active else OK
        message = (
            ', '.join(f'{a.kind} wheel {a.wheel} level {a.level}' for a in active)
            if active
            else 'no alert'
        )
        values: dict[str, object] = {
            **self.counts,
            **self.aligner.counts(),
        }
        level, message, watch_values = merge_status(
            level,
            message,
            self.watch,
            time.monotonic_ns(),
            queued_by_topic(self.aligner, self._queue_topics),
            self._capacity,
            log=self.get_logger().warning,  # inputs whose stamps never meet: once
        )
        values.update(watch_values)
        self.pub_diag.publish(
            node_status(self, 'vd: alerts', 'alerts_node', level, message, values, self.refusals)
        )


def main(args: list[str] | None = None) -> int:
    """Entry point of ``ros2 run vd_observer_node alerts_node``."""
    return run_node(AlertsNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
