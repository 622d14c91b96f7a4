"""ROS 2 node: Levant sliding-mode differentiators on wheel angles and body speed.

Subscribes ``/vd/sensors/wheel_angles`` (vd_msgs/WheelAngles) and
``/vd/sensors/body_velocity`` (geometry_msgs/TwistStamped), or the topics and types the input
mapping gives (``input_mapping`` or ``inputs.*``, docs/input_mapping.md; a Float64MultiArray is
stamped with its receive time by the node clock); publishes, stamped with the
measurement's own stamp, ``/vd/observer/wheel_states`` (vd_msgs/WheelStates),
``/vd/observer/body_accel`` (geometry_msgs/AccelStamped) and the differentiator's filtered
speed ``/vd/observer/body_velocity`` (geometry_msgs/TwistStamped, which the estimator uses so
that the live graph computes exactly what the offline cascade does). Health and fault
counters go to ``/diagnostics`` once per second, with a WARN naming an input topic that
stopped. All math is in
:mod:`vd_observer_node.estimation.observer`, whose differentiator step is compiled.
Messages travel as CDR bytes: raw subscriptions decoded with ``struct`` and bytes published
(:mod:`vd_observer_node.bag.cdr_message`), never Python message objects.
"""

from __future__ import annotations

import math
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
    OBSERVER_BODY_ACCEL,
    OBSERVER_BODY_VELOCITY,
    OBSERVER_WHEEL_STATES,
)

from vd_msgs.msg import WheelStates
from vd_observer_node.bag.errors import BagFormatError
from vd_observer_node.estimation.faults import ERROR, merge_reports
from vd_observer_node.estimation.observer import SpeedObserver, WheelObserver
from vd_observer_node.inputs.decode import InputDecoder, has_header
from vd_observer_node.inputs.errors import MappingError
from vd_observer_node.nodes.node_params import (
    INPUT_PARAMS,
    OBSERVER_PARAMS,
    VEHICLE_FILE,
    input_message_class,
    take_input_mapping,
    undeclared_inputs,
)
from vd_observer_node.nodes.raw_io import (
    Encoders,
    InputWatch,
    merge_status,
    wheel_lipschitz_value,
)
from vd_observer_node.situation.chain_settings import chain_settings, parameter_sections

__all__ = ['ObserverNode', 'main']

PARAMS = [VEHICLE_FILE, *OBSERVER_PARAMS, *INPUT_PARAMS]

_NS = 1e-9
_ZEROS5 = (0.0, 0.0, 0.0, 0.0, 0.0)


class ObserverNode(Node):
    """Thin wrapper: raw CDR messages -> WheelObserver/SpeedObserver -> raw CDR messages."""

    def __init__(self) -> None:
        super().__init__('observer_node')
        self.refusals = PublishRefusals(self)  # a refused publish is counted, not fatal
        values = declare_parameters(self, PARAMS)
        log_settings(self, PARAMS, values)
        mapping = take_input_mapping(values, undeclared_inputs(self))
        angles_spec, speed_spec = mapping.wheels, mapping.body_speed
        classes = [input_message_class(spec) for spec in (angles_spec, speed_spec)]
        vehicle_file = values.pop('vehicle_file') or None
        settings = chain_settings(mapping, vehicle_file, parameter_sections(values))
        # the vehicle file matters here only for wheel speeds given in m/s or km/h
        radius = settings.vehicle.effective_radius if angles_spec.per_radius else None
        # angles or ABS wheel speeds: the mapping says which
        self.config = settings.observer
        # the differentiator's step is compiled (or loaded from numba's disk cache) here,
        # before the first sample
        self.wheels = WheelObserver(self.config)
        self.speed = SpeedObserver(self.config)
        self.pub_states = self.refusals.publisher(WheelStates, OBSERVER_WHEEL_STATES, STREAM_QOS)
        self.pub_accel = self.refusals.publisher(AccelStamped, OBSERVER_BODY_ACCEL, STREAM_QOS)
        self.pub_speed = self.refusals.publisher(TwistStamped, OBSERVER_BODY_VELOCITY, STREAM_QOS)
        self.pub_diag = self.refusals.publisher(DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
        # SI values with the mapping's signs, one message at a time (struct for vd's types)
        self._angles_in = InputDecoder(angles_spec, radius)
        self._speed_in = InputDecoder(speed_spec)
        self._stamp_angles = not has_header(angles_spec)
        self._stamp_speed = not has_header(speed_spec)
        self.watch = InputWatch(
            [angles_spec.topic, speed_spec.topic], round(self.config.max_gap * 1e9)
        )
        self._codec = Encoders()
        # raw: the bytes are decoded with struct, never built into Python message objects
        self.create_subscription(
            classes[0], angles_spec.topic, self.on_wheel_angles, STREAM_QOS, raw=True
        )
        self.create_subscription(
            classes[1], speed_spec.topic, self.on_body_velocity, STREAM_QOS, raw=True
        )
        self.counts = {
            'wheel_samples': 0,
            'speed_samples': 0,
            'withheld_non_finite': 0,
            'undecodable': 0,
            'unfit': 0,
        }
        self.create_timer(1.0, self.publish_diagnostics)
        follows = self.wheels.differentiator.params.follow_resolution
        self.get_logger().info(
            f'observer ready: {self.config.discretization} '
            f'discretization, L_wheel={self.config.wheel_lipschitz:g}'
            + (" (rises with the angles' resolution)" if follows else '')
            + f', L_speed={self.config.speed_lipschitz:g}'
            + (f', inputs from {mapping.source}' if mapping.source else '')
        )

    def _decode(
        self, decoder: InputDecoder, data: bytes, stamp_now: bool
    ) -> tuple[int, bytes, tuple[float, ...]] | None:
        """One mapped input message, or None when dropped (counted, never raised)."""
        self.watch.seen(decoder.spec.topic, time.monotonic_ns())
        try:
            now = self.get_clock().now().nanoseconds
            decoded = decoder.decode(data, now if stamp_now else 0)
            if not stamp_now:
                self.watch.stamped(decoder.spec.topic, decoded[0], now - decoded[0])
            return decoded
        except BagFormatError:
            self.counts['undecodable'] += 1
        except MappingError as exc:
            self.counts['unfit'] += 1
            self.watch.unfit(decoder.spec.topic, str(exc))
        return None

    def on_wheel_angles(self, data: bytes) -> None:
        decoded = self._decode(self._angles_in, data, self._stamp_angles)
        if decoded is None:
            return
        stamp_ns, frame, angles = decoded
        state = self.wheels.update(stamp_ns * _NS, np.array(angles, dtype=np.float64))
        self.counts['wheel_samples'] += 1
        values = [*state.angle.tolist(), *state.omega.tolist(), *state.omega_dot.tolist()]
        if not math.isfinite(sum(values)):
            self.counts['withheld_non_finite'] += 1
            return
        self.pub_states.publish(
            self._codec('vd_msgs/msg/WheelStates', frame).encode(stamp_ns, values)
        )

    def on_body_velocity(self, data: bytes) -> None:
        decoded = self._decode(self._speed_in, data, self._stamp_speed)
        if decoded is None:
            return
        stamp_ns, frame, values = decoded
        state = self.speed.update(stamp_ns * _NS, float(values[0]))
        self.counts['speed_samples'] += 1
        if not (math.isfinite(state.speed) and math.isfinite(state.accel)):
            self.counts['withheld_non_finite'] += 1
            return
        self.pub_accel.publish(
            self._codec('geometry_msgs/msg/AccelStamped', frame).encode(
                stamp_ns, (state.accel, *_ZEROS5)
            )
        )
        self.pub_speed.publish(
            self._codec('geometry_msgs/msg/TwistStamped', frame).encode(
                stamp_ns, (state.speed, *_ZEROS5)
            )
        )

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
        level, message, watch_values = merge_status(
            level, message, self.watch, time.monotonic_ns()
        )
        values: dict[str, Any] = {
            **self.counts,
            'rejected_wheel_stamps': self.wheels.rejected_count,
            'rejected_speed_stamps': self.speed.rejected_count,
            'wheel_lipschitz_in_use': wheel_lipschitz_value(self.wheels.differentiator),
            **report.counts,
            **watch_values,
        }
        self.pub_diag.publish(
            node_status(
                self, 'vd: observer', 'observer_node', level, message, values, self.refusals
            )
        )


def main(args: list[str] | None = None) -> int:
    """Entry point of ``ros2 run vd_observer_node observer_node``."""
    return run_node(ObserverNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
