"""ROS 2 node: the whole estimation chain in one process, for the lowest latency.

Observer, estimator and alerts nodes in one: subscribes the three sensor topics
(``/vd/sensors/wheel_angles``, ``/vd/sensors/body_velocity``, ``/vd/sensors/wheel_torques``,
or the topics and types of an input mapping: ``input_mapping`` or ``inputs.*``, see
docs/input_mapping.md), matches them by header stamp (an input without header, Float64MultiArray,
is stamped with its receive time, on the stamped inputs' clock where that is not the node's, see
`raw_io.ReceiptStamps`; with 'exact' alignment it joins each match with its latest value),
runs :mod:`vd_observer_node.chain` (observers -> estimator ->
situation monitor, compiled) and publishes, with the sensors' stamp,
every topic those three nodes publish: ``/vd/observer/{wheel_states, body_accel,
body_velocity}``, ``/vd/estimates/{tire_forces, friction, resistances, slope,
friction_potential, alerts}``, and ``/diagnostics`` once per second. Its parameters are the
union of the three nodes' (one ``max_gap``, ``vehicle_file`` and ``align_capacity``) and
the input mapping. A mapped topic that stops arriving is reported on
``/diagnostics`` (WARN naming it and the time since its last message).

The mapping's ``torque_source`` (docs/input_mapping.md) picks the torque path, as ``vd replay``
does:
``measured`` reads the wheel torques; ``engine`` reads the ``engine_torque`` input (engine
torque, gear, engine speed; vd's own WheelTorques topic unless mapped) instead and derives
the wheel torques through the vehicle file's drivetrain; ``none`` reads no torque topic (Fx,
mu and slope invalid). The estimates' ``torque_source`` field says which.

What differs from the three nodes: the observers run on stamp-matched sensor sets only (as
offline replay does, so the pipeline's output equals ``vd replay``'s on the same stamps), and
messages travel as CDR bytes (raw subscriptions, :mod:`vd_observer_node.bag.cdr_message`),
never as Python message objects.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import AccelStamped, TwistStamped
from rclpy.node import Node
from vd_common.ros.diagnostics import node_status
from vd_common.ros.lifecycle import run_node
from vd_common.ros.parameters import declare_parameters, log_settings
from vd_common.ros.publishing import PublishRefusals
from vd_common.ros.qos import DIAGNOSTICS_QOS, STATE_QOS, STREAM_QOS
from vd_common.topics import (
    ESTIMATES_ALERTS,
    ESTIMATES_COMBINED,
    ESTIMATES_FRICTION,
    ESTIMATES_FRICTION_POTENTIAL,
    ESTIMATES_MASS,
    ESTIMATES_RESISTANCES,
    ESTIMATES_ROLLING_RADIUS,
    ESTIMATES_SLOPE,
    ESTIMATES_TIRE_FORCES,
    ESTIMATES_TORQUE_OFFSET,
    OBSERVER_BODY_ACCEL,
    OBSERVER_BODY_VELOCITY,
    OBSERVER_WHEEL_STATES,
)
from vd_common.vehicle.params import default_vehicle_file

from vd_msgs.msg import (
    Alerts,
    Estimates,
    Friction,
    FrictionPotential,
    MassEstimate,
    Resistances,
    RollingRadiusEstimate,
    Slope,
    TireForces,
    TorqueOffsetEstimate,
    WheelStates,
)
from vd_observer_node.bag.cdr_message import MessageCodec
from vd_observer_node.bag.errors import BagFormatError
from vd_observer_node.chain import Chain, ChainOutput
from vd_observer_node.estimation.alignment import SampleQueue
from vd_observer_node.estimation.estimator_step import SPEED_SAMPLES_MAX
from vd_observer_node.estimation.faults import ERROR
from vd_observer_node.estimation.rate_settings import RateMeter, follow_rate_hz
from vd_observer_node.inputs.decode import InputDecoder, has_header
from vd_observer_node.inputs.errors import MappingError
from vd_observer_node.inputs.imu_hold import ImuHold
from vd_observer_node.inputs.mapping import BRAKE_INPUT, ENGINE_INPUT, InputSpec
from vd_observer_node.inputs.mount_learner import (
    learnt_line,
    new_learner,
    project_sample,
    unstated_mounting_note,
)
from vd_observer_node.nodes.node_params import (
    INPUT_PARAMS,
    PIPELINE_PARAMS,
    input_message_class,
    take_input_mapping,
    undeclared_inputs,
)
from vd_observer_node.nodes.raw_io import (
    Encoders,
    InputWatch,
    follow_input_rate,
    input_matcher,
    mapped_input,
    mass_values,
    merge_status,
    offset_values,
    queued_by_topic,
    radius_values,
    wheel_lipschitz_value,
)
from vd_observer_node.situation.chain_settings import chain_settings, parameter_sections

__all__ = ['PARAMS', 'PipelineNode', 'main']

PARAMS = [*PIPELINE_PARAMS, *INPUT_PARAMS]
_OUTPUTS = (
    ('states', WheelStates, OBSERVER_WHEEL_STATES, 'vd_msgs/msg/WheelStates'),
    ('accel', AccelStamped, OBSERVER_BODY_ACCEL, 'geometry_msgs/msg/AccelStamped'),
    ('velocity', TwistStamped, OBSERVER_BODY_VELOCITY, 'geometry_msgs/msg/TwistStamped'),
    ('forces', TireForces, ESTIMATES_TIRE_FORCES, 'vd_msgs/msg/TireForces'),
    ('friction', Friction, ESTIMATES_FRICTION, 'vd_msgs/msg/Friction'),
    ('resistances', Resistances, ESTIMATES_RESISTANCES, 'vd_msgs/msg/Resistances'),
    ('slope', Slope, ESTIMATES_SLOPE, 'vd_msgs/msg/Slope'),
    ('mass', MassEstimate, ESTIMATES_MASS, 'vd_msgs/msg/MassEstimate'),
    (
        'radius',
        RollingRadiusEstimate,
        ESTIMATES_ROLLING_RADIUS,
        'vd_msgs/msg/RollingRadiusEstimate',
    ),
    (
        'potential',
        FrictionPotential,
        ESTIMATES_FRICTION_POTENTIAL,
        'vd_msgs/msg/FrictionPotential',
    ),
    ('alerts', Alerts, ESTIMATES_ALERTS, 'vd_msgs/msg/Alerts'),
    ('offset', TorqueOffsetEstimate, ESTIMATES_TORQUE_OFFSET, 'vd_msgs/msg/TorqueOffsetEstimate'),
    ('combined', Estimates, ESTIMATES_COMBINED, 'vd_msgs/msg/Estimates'),
)
#: the per-quantity outputs that ``estimate_topics: combined`` carries in one message
_SEPARATE = ('states', 'accel', 'velocity', 'forces', 'friction', 'resistances', 'slope')
#: [s] how far a held input (the IMU) may be behind the newest completed stamp before the
#: stamps go on without it (`ImuHold`): a busy executor taking its queue late is not a dropout
#: (the part that reads it judges the sample's age by its stamp); as the lockstep demo's window
_HELD_WAIT = 0.5
#: What a stamp carries through the held inputs' holds: its matched set, and the samples
#: known so far by held input
_HeldItem = tuple[dict[str, Any], dict[str, Any]]


def _stamp_ns(t: float) -> int:
    return round(t * 1e9) if math.isfinite(t) else 0


class PipelineNode(Node):
    """Thin wrapper: raw sensor messages -> stamp matching -> Chain.update -> raw messages."""

    def __init__(self) -> None:
        super().__init__('pipeline_node')
        self.refusals = PublishRefusals(self)  # a refused publish is counted, not fatal
        values = declare_parameters(self, PARAMS)
        log_settings(self, PARAMS, values)
        mapping = take_input_mapping(
            values, undeclared_inputs(self), estimates=True, torque_paths=True
        )
        specs = mapping.used_specs  # wheels, body speed, and the torque path's input if any
        classes = [input_message_class(spec) for spec in specs]
        capacity = values.pop('align_capacity')
        layout = values.pop('estimate_topics')
        vehicle_file = values.pop('vehicle_file') or str(default_vehicle_file())
        # the sensors (wheel angles or speeds, torque path, brakes, IMU) are the mapping's
        settings = chain_settings(mapping, vehicle_file, parameter_sections(values))
        self._situation_off = settings.situation_off
        # Builds (or loads from numba's disk cache) the compiled chain now, before any sample.
        self.chain = Chain(settings)
        max_gap_ns = round(settings.estimator.max_gap * 1e9)
        names = tuple(spec.name for spec in specs)
        self._wheels = mapping.wheels.name  # 'wheel_angles' or 'wheel_speeds'
        self.torque_source = mapping.torque_source
        self._no_torque = np.zeros(4)  # the chain reads no wheel torques off the measured path
        self.aligner = input_matcher(
            mapping, names, capacity, max_jump_back_ns=max_gap_ns, max_age_ns=max_gap_ns
        )
        # the held inputs (the IMU) are watched like the others: a stopped one is a WARN on
        # /diagnostics
        held_topics = [spec.topic for spec in mapping.held_specs]
        self.watch = InputWatch(
            list(dict.fromkeys([*(spec.topic for spec in specs), *held_topics])), max_gap_ns
        )
        # the wheel stamps and a stamped body speed's set what follows the rate
        self._wheel_rate: RateMeter | None = RateMeter()
        self._speed_topic = mapping.body_speed.topic if has_header(mapping.body_speed) else None
        # the matcher's queue per input topic, reported against its capacity
        self._queue_topics = {spec.name: spec.topic for spec in specs}
        self._capacity = capacity
        # The online mass and radius only when adapted: with the file's constants they would
        # add two 1 kHz streams to a graph that is at its limit on two cores.
        # The engine-torque offset only where learnt, and only where it changes (STATE_QOS).
        adapted = {
            # with an IMU the mass is the IMU regression's (`imu_grade`)
            'mass': settings.estimator.mass_adaptation or settings.imu is not None,
            'radius': settings.estimator.radius_adaptation,
            'offset': self.torque_source == 'engine'
            and settings.estimator.torque_offset_adaptation,
            'combined': layout != 'separate',
            **dict.fromkeys(_SEPARATE, layout != 'combined'),
            # without a tyre, no friction potential and no alerts (`no_tire_note`)
            'potential': self._situation_off is None,
            'alerts': self._situation_off is None,
        }
        self.pubs = {
            key: self.refusals.publisher(cls, topic, STATE_QOS if key == 'offset' else STREAM_QOS)
            for key, cls, topic, _ in _OUTPUTS
            if adapted.get(key, True)
        }
        self._offset_last: tuple[int, bool] | None = None  # (episodes, converged) published
        self.pub_diag = self.refusals.publisher(DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
        self._types = {key: msgtype for key, _, _, msgtype in _OUTPUTS if key != 'alerts'}
        self.encoders = Encoders()
        self.counts = {
            'estimates': 0,
            'undecodable': 0,
            'unfit': 0,
            'withheld_non_finite': 0,
            'alerts_raised': 0,
        }
        # every stamped body-speed sample reaches the speed observer at its own stamp, also
        # those whose wheel stamp is lost (as vd replay's queue); a held speed (headerless,
        # 'exact') is taken at the stamps it is held at
        speed_name = mapping.body_speed.name
        self._speed_samples = (
            None if speed_name in self.aligner.held else SampleQueue(SPEED_SAMPLES_MAX)
        )
        self.aligner.taps[speed_name] = self._speed_sample
        clock = self.get_clock()
        for spec, cls in zip(specs, classes, strict=True):
            callback = mapped_input(
                spec,
                self.aligner,
                self.process,
                self.counts,
                self.watch,
                lambda: clock.now().nanoseconds,
                radius=settings.vehicle.effective_radius,
            )
            self.create_subscription(cls, spec.topic, callback, STREAM_QOS, raw=True)
        # the held inputs' samples (the IMU's: stamp [s], forward specific force [m/s^2],
        # pitch rate [rad/s] or nan): each stamp takes the newest not later than it, as the
        # replay holds them, whatever the order the executor takes the subscriptions in (one
        # `ImuHold` a held input; a stamp passes each in turn); the part that reads a sample
        # judges its age
        self._holds: list[tuple[str, ImuHold[_HeldItem]]] = []
        self._oldest_before: list[int | None] = []
        for spec in mapping.held_specs:
            self._subscribe_held(spec, len(self._holds))
            self._holds.append((spec.name, ImuHold(_HELD_WAIT)))
            self._oldest_before.append(None)
        self._imu_said = False  # the learnt bias logged once it is trusted
        # the IMU's mounting where the mapping does not state it: learnt from the stamps
        # estimated and the IMU's samples, as vd replay learns it (`mount_learner`)
        self._mounting = new_learner(mapping, settings.vehicle.effective_radius)
        self._mounting_said = False
        self._active = 0
        self._last_alerts = ''
        self.create_timer(1.0, self.publish_diagnostics)
        self.get_logger().info(
            f'pipeline ready: vehicle {settings.vehicle.name!r} '
            f'({vehicle_file}), torque source {self.torque_source}'
            + (f', inputs from {mapping.source}' if mapping.source else '')
        )
        mounting_note = unstated_mounting_note(mapping.imu)
        if mounting_note:
            self.get_logger().warning(mounting_note)
        if self._situation_off is not None:
            # a configuration, not a fault: said once here, and as a value on /diagnostics
            self.get_logger().info(
                f'friction potential and alerts {self._situation_off}; every estimate runs'
            )

    def _subscribe_held(self, spec: InputSpec, index: int) -> None:
        """Subscribe to held input `index` (``InputMapping.held_specs``)."""
        decoder = InputDecoder(spec)
        topic, stamped = spec.topic, has_header(spec)
        clock = self.get_clock()

        def on_sample(data: bytes) -> None:
            self.watch.seen(topic, time.monotonic_ns())
            now = clock.now().nanoseconds
            try:
                stamp, _, row = decoder.decode(data, now)
            except BagFormatError:
                self.counts['undecodable'] += 1
                return
            except MappingError as exc:  # as the other inputs (`raw_io.mapped_input`)
                self.counts['unfit'] = self.counts.get('unfit', 0) + 1
                self.watch.unfit(topic, str(exc))
                return
            if stamped:
                self.watch.stamped(topic, stamp, now - stamp)
            if self._mounting is not None and spec.learns_mounting:
                self._mounting.imu(stamp, row)
            self._pass(index, self._holds[index][1].sample((stamp * 1e-9, *row)))

        self.create_subscription(input_message_class(spec), topic, on_sample, STREAM_QOS, raw=True)

    def _hold(self, index: int, stamp_ns: int, m: dict[str, Any], samples: dict[str, Any]) -> None:
        """A completed stamp into held input `index`'s hold (estimated after the last)."""
        if index == len(self._holds):
            self._estimate(stamp_ns, m, samples)
            return
        self._pass(index, self._holds[index][1].stamp(stamp_ns, (m, samples)))

    def _pass(self, index: int, released: list[tuple[int, _HeldItem, Any]]) -> None:
        """The stamps held input `index` released, each with its sample, on to the next."""
        name = self._holds[index][0]
        for stamp_ns, (m, samples), sample in released:
            samples[name] = sample
            self._hold(index + 1, stamp_ns, m, samples)

    def _speed_sample(self, stamp_ns: int, values: tuple[float, ...]) -> None:
        if self._speed_samples is not None:
            self._speed_samples.add(stamp_ns, values[0])

    def _codec(self, key: str, frame: bytes) -> MessageCodec:
        return self.encoders(self._types[key], frame)

    def process(self, stamp_ns: int, m: dict[str, Any]) -> None:
        """A completed set of inputs: estimated now, or once the held inputs' samples of its
        stamp are known."""
        if self._mounting is not None:
            self._mounting.wheels(stamp_ns, m[self._wheels][1])
        self._hold(0, stamp_ns, dict(m) if self._holds else m, {})

    def _estimate(self, stamp_ns: int, m: dict[str, Any], held: dict[str, Any]) -> None:
        # SI values with the mapping's signs (raw_io.mapped_input)
        frame, angles = m[self._wheels]  # angles [rad] or speeds [rad/s]
        speed = float(m['body_speed'][1][0])
        source = self.torque_source
        torques = m['wheel_torques'][1] if source == 'measured' else self._no_torque
        engine = m[ENGINE_INPUT][1] if source == 'engine' else None
        brake = m[BRAKE_INPUT][1] if BRAKE_INPUT in m else None
        if self._mounting is not None:  # read through the mounting once it is learnt
            held['imu'] = project_sample(self._mounting.learnt, held.get('imu'))
            if self._mounting.learnt is not None and not self._mounting_said:
                self._mounting_said = True
                self.get_logger().info(f'IMU {learnt_line(self._mounting.learnt, "")}')
        t = stamp_ns * 1e-9
        if self._speed_samples is not None:
            self.chain.speed_samples(*self._speed_samples.take_one(stamp_ns))
        out = self.chain.update(t, angles, speed, torques, engine, brake=brake, held=held)
        if self._wheel_rate is not None and self._wheel_rate.add(stamp_ns):
            # from the next stamp on, as vd replay does (rate_settings.FOLLOW_AFTER)
            speed_stamps = self.watch.first_stamps(self._speed_topic)
            follow_input_rate(
                self.chain.parts.estimator, self._wheel_rate.stamps, speed_stamps, self
            )
            if self.chain.parts.imu_on:  # the IMU fusion's low-passes too, as vd replay
                rate = follow_rate_hz(self._wheel_rate.stamps, speed_stamps)
                fixed = self.chain.parts.imu_grade.follow_rate(rate)
                if fixed:
                    self.get_logger().info(
                        'IMU fusion settings following the input rate '
                        f'({rate:g} Hz): '
                        + ', '.join(f'imu.fusion.{k} {v:.3g} s' for k, v in fixed.items())
                    )
            self._wheel_rate = None
        self.counts['estimates'] += 1
        if self.chain.parts.imu_on and not self._imu_said and self.chain.imu_trusted:
            self._say_imu_learnt(t)
        if not self._finite(out):
            self.counts['withheld_non_finite'] += 1
            return
        self._publish(stamp_ns, frame, out)

    def _say_imu_learnt(self, t: float) -> None:
        """Log once what the IMU fusion learnt, at the stamp [s] its bias became trusted."""
        self._imu_said = True
        learnt = self.chain.imu_learnt()
        assert learnt is not None  # an IMU is fused
        self.get_logger().info(
            f'IMU bias learnt at {t:.3f} s: {learnt.bias:+.3f} +- {learnt.bias_std:.3f} m/s^2 '
            f'(a sensor pitched {learnt.pitch_deg:+.2f} deg, nose up +); the slope is the '
            "IMU's grade from now on" + (' (with its angular rate)' if learnt.gyro else '')
        )

    @staticmethod
    def _finite(out: ChainOutput) -> bool:
        # One sum: NaN or inf anywhere makes it non-finite (the cores never emit them).
        w, e = out.wheel, out.estimates
        total = float(np.sum(w.angle) + np.sum(w.omega) + np.sum(w.omega_dot))
        total += out.speed.speed + out.speed.accel + e.aero + e.slope
        total += float(np.sum(e.fx) + np.sum(e.fz) + np.sum(e.mu) + np.sum(e.slip))
        return math.isfinite(total)

    def _publish(self, stamp_ns: int, frame: bytes, out: ChainOutput) -> None:
        w, s, e = out.wheel, out.speed, out.estimates
        pubs, codec = self.pubs, self._codec
        if 'combined' in pubs:
            pubs['combined'].publish(
                codec('combined', frame).encode(
                    stamp_ns,
                    [
                        *w.angle.tolist(),
                        *w.omega.tolist(),
                        *w.omega_dot.tolist(),
                        s.speed,
                        s.accel,
                        *e.fx.tolist(),
                        *e.fz.tolist(),
                        *e.mu.tolist(),
                        *e.slip.tolist(),
                        *e.mu_valid.tolist(),
                        *e.rolling.tolist(),
                        e.aero,
                        e.slope,
                        e.slope_valid,
                        out.slope_sources,
                        e.torque_source,
                    ],
                )
            )
        if 'states' in pubs:
            self._publish_separate(stamp_ns, frame, out)
        self._publish_rest(stamp_ns, frame, out)

    def _publish_separate(self, stamp_ns: int, frame: bytes, out: ChainOutput) -> None:
        w, s, e = out.wheel, out.speed, out.estimates
        pubs, codec = self.pubs, self._codec
        pubs['states'].publish(
            codec('states', frame).encode(
                stamp_ns, [*w.angle.tolist(), *w.omega.tolist(), *w.omega_dot.tolist()]
            )
        )
        pubs['accel'].publish(
            codec('accel', frame).encode(stamp_ns, [s.accel, 0.0, 0.0, 0.0, 0.0, 0.0])
        )
        pubs['velocity'].publish(
            codec('velocity', frame).encode(stamp_ns, [s.speed, 0.0, 0.0, 0.0, 0.0, 0.0])
        )
        pubs['forces'].publish(
            codec('forces', frame).encode(
                stamp_ns, [*e.fx.tolist(), *e.fz.tolist(), e.torque_source]
            )
        )
        pubs['friction'].publish(
            codec('friction', frame).encode(
                stamp_ns,
                [*e.mu.tolist(), *e.slip.tolist(), *e.mu_valid.tolist(), e.torque_source],
            )
        )
        pubs['resistances'].publish(
            codec('resistances', frame).encode(stamp_ns, [*e.rolling.tolist(), e.aero])
        )
        pubs['slope'].publish(
            codec('slope', frame).encode(
                stamp_ns, [e.slope, e.slope_valid, e.torque_source, out.slope_sources]
            )
        )

    def _publish_rest(self, stamp_ns: int, frame: bytes, out: ChainOutput) -> None:
        e, sit = out.estimates, out.situation
        pubs, codec = self.pubs, self._codec
        if 'mass' in pubs:
            pubs['mass'].publish(codec('mass', frame).encode(stamp_ns, mass_values(e)))
        if 'radius' in pubs:
            pubs['radius'].publish(codec('radius', frame).encode(stamp_ns, radius_values(e)))
        offset = out.torque_offset
        if offset is not None and 'offset' in pubs:
            changed = (offset.episodes, offset.converged)
            if changed != self._offset_last:  # as vd replay writes it (publish_mask)
                self._offset_last = changed
                pubs['offset'].publish(
                    codec('offset', frame).encode(stamp_ns, offset_values(offset))
                )
        if sit is None:  # no tyre: no situation monitor
            return
        pot = sit.potential
        pubs['potential'].publish(
            codec('potential', frame).encode(
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
        level = [a.level for a in sit.alerts]
        active = sum(a.active for a in sit.alerts)
        self.counts['alerts_raised'] += max(0, active - self._active)
        self._active = active
        if active:
            self._last_alerts = ', '.join(
                f'{a.kind} wheel {a.wheel} level {a.level}' for a in sit.alerts if a.active
            )
        codec_alerts = self.encoders.alerts(frame)
        pubs['alerts'].publish(
            codec_alerts.encode(
                stamp_ns,
                level,
                [_stamp_ns(a.onset) for a in sit.alerts],
                [_stamp_ns(a.detected) for a in sit.alerts],
            )
        )

    def publish_diagnostics(self) -> None:
        for index, (_, hold) in enumerate(self._holds):
            # the oldest stamp held back is still the one of a period ago: its sample is not
            # coming (the drive ended before the input's last sample came); estimated with
            # what there is
            oldest = hold.oldest
            if oldest is not None and oldest == self._oldest_before[index]:
                self._pass(index, hold.flush())
            self._oldest_before[index] = hold.oldest
        # Level and message name the faults of the last period; the counters are totals.
        report = self.chain.fault_report()
        level, message = report.level, report.message
        if self._active:
            level = max(level, int.from_bytes(DiagnosticStatus.WARN, 'little'))
            message += f'; alerts: {self._last_alerts}'
        if self._situation_off is not None:
            message += '; friction potential and alerts off: no tire in the vehicle file'
        if self.counts['withheld_non_finite']:
            level = max(level, ERROR)
            message += f'; {self.counts["withheld_non_finite"]} non-finite outputs withheld'
        level, message, watch_values = merge_status(
            level,
            message,
            self.watch,
            time.monotonic_ns(),
            queued_by_topic(self.aligner, self._queue_topics),
            self._capacity,
            log=self.get_logger().warning,  # inputs whose stamps never meet: once
        )
        learnt = self.chain.imu_learnt()
        imu_values: dict[str, Any] = {}
        if learnt is not None:
            # what the IMU fusion has learnt (logged once, when it is trusted: `_estimate`)
            imu_values = {
                'imu_late_samples': dict(self._holds)['imu'].late,  # an IMU is mapped
                'imu_bias_mps2': round(learnt.bias, 4),
                'imu_bias_std_mps2': round(learnt.bias_std, 4),
                'imu_sensor_pitch_deg': round(learnt.pitch_deg, 3),
                'imu_trusted': learnt.trusted,
                'imu_angular_rate_used': learnt.gyro,
            }
        if self._mounting is not None:
            mounted = self._mounting.learnt
            imu_values['imu_mount_rpy_deg'] = (
                'not learnt yet'
                if mounted is None
                else str([round(a, 2) for a in mounted.fit.rpy_deg])
            )
        values = {
            'torque_source': self.torque_source,
            'wheel_lipschitz_in_use': wheel_lipschitz_value(self.chain.parts.wheels),
            **({'situation': self._situation_off} if self._situation_off is not None else {}),
            **self.counts,
            **self.aligner.counts(),
            **report.counts,
            **watch_values,
            **imu_values,
        }
        self.pub_diag.publish(
            node_status(
                self, 'vd: pipeline', 'pipeline_node', level, message, values, self.refusals
            )
        )


def main(args: list[str] | None = None) -> int:
    """Entry point of ``ros2 run vd_observer_node pipeline_node``."""
    return run_node(PipelineNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
