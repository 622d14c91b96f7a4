"""ROS 2 node: runs a scenario on the bond-graph Clio model and publishes sensors and truth.

Publishes (stamps = simulation time of the sample, starting at 0):

* sensors: ``/vd/sensors/wheel_angles`` (WheelAngles), ``/vd/sensors/body_velocity``
  (TwistStamped), ``/vd/sensors/wheel_torques`` (WheelTorques);
* truth: ``/vd/truth/{wheel_states, body_accel, body_velocity, tire_forces, friction,
  resistances, slope, friction_potential}`` (the last: the tyre's Magic-Formula peak at the
  true load and road μ per axle, confidence 1, see :mod:`vd_sim_node.vehicle.friction_truth`);
* ``/clock`` once per publishing batch (so nodes with ``use_sim_time`` follow the simulation),
  and ``/diagnostics`` once per wall second.

Pacing runs on the steady wall clock (the node ignores ``use_sim_time``: it *is* the clock):
``real_time_factor`` 1.0 follows the wall clock, 5.0 runs five times faster, 0 runs as fast as
the machine can. In lockstep (``lockstep_topics``, :mod:`vd_sim_node.lockstep`) it also
waits for its consumers: it runs at most ``lockstep_window`` of sample time ahead of the
newest header stamp on each of those topics, so that nothing is lost on a slow machine
and the estimates do not depend on it; the real-time factor is then a cap. The node exits by
itself (code 0) at the end of the scenario, in lockstep once its consumers have taken the last
sample.
All physics is in :mod:`vd_sim_node.vehicle`; this file only maps parameters and messages.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import AccelStamped, TwistStamped
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.node import Node
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import Imu
from std_msgs.msg import Header
from vd_common.ros.diagnostics import diagnostic_array
from vd_common.ros.lifecycle import finish, run_node
from vd_common.ros.parameters import ParamSpec, declare_parameters, log_settings
from vd_common.ros.publishing import (
    PublishRefusals,
    SubscriberGate,
    deliver_pending,
    ros_message_class,
)
from vd_common.ros.qos import CLOCK_QOS, DIAGNOSTICS_QOS, STREAM_QOS
from vd_common.ros.stamps import header_stamp_ns, ns_to_time
from vd_common.topics import (
    SENSORS_BODY_VELOCITY,
    SENSORS_IMU,
    SENSORS_WHEEL_ANGLES,
    SENSORS_WHEEL_TORQUES,
    TRUTH_BODY_ACCEL,
    TRUTH_BODY_VELOCITY,
    TRUTH_FRICTION,
    TRUTH_FRICTION_POTENTIAL,
    TRUTH_NAMESPACE,
    TRUTH_RESISTANCES,
    TRUTH_SLOPE,
    TRUTH_TIRE_FORCES,
    TRUTH_WHEEL_STATES,
)
from vd_common.vehicle.friction import road_class_of
from vd_common.vehicle.params import default_vehicle_file, load_vehicle

from vd_msgs.msg import (
    Friction,
    FrictionPotential,
    Resistances,
    Slope,
    TireForces,
    WheelAngles,
    WheelStates,
    WheelTorques,
)
from vd_sim_node.errors import ScenarioError
from vd_sim_node.lockstep import Lockstep
from vd_sim_node.vehicle.scenario import Scenario, load_scenario
from vd_sim_node.vehicle.simulation import SampleFrame, Simulator

__all__ = ['SimNode', 'main', 'resolve_config_file']

PARAMS = [
    ParamSpec(
        'vehicle_file',
        '',
        "vehicle parameter YAML: a path or an installed name ('' = the installed Clio RL 1.1)",
    ),
    ParamSpec(
        'scenario_file',
        'paper_table1',
        'scenario YAML path, or the name of an installed scenario (config/scenarios)',
    ),
    ParamSpec('rate_hz', 1000.0, 'sensor sample rate [Hz]', low=1.0, high=100000.0),
    ParamSpec(
        'real_time_factor',
        1.0,
        'simulated seconds per wall second (0 = as fast as possible)',
        low=0.0,
        high=1e6,
    ),
    ParamSpec(
        'encoder_counts_per_rev',
        -1,
        'wheel encoder counts per revolution (0 = ideal angle, -1 = scenario setting)',
        low=-1,
        high=1_000_000,
    ),
    ParamSpec(
        'speed_noise_std',
        -1.0,
        'body-speed noise standard deviation [m/s] (-1 = scenario setting)',
        low=-1.0,
        high=100.0,
    ),
    ParamSpec(
        'imu_noise_std',
        -1.0,
        'publish the IMU (the imu topic of the sensors) with this noise per axis [m/s^2] '
        "and the scenario's IMU bias and mounting (-1 = scenario setting)",
        low=-1.0,
        high=100.0,
    ),
    ParamSpec(
        'imu_gyro_noise_std',
        -1.0,
        "noise of the IMU's pitch rate [rad/s] (-1 = scenario setting)",
        low=-1.0,
        high=10.0,
    ),
    ParamSpec('seed', -1, 'noise seed (-1 = scenario setting)', low=-1, high=2**31 - 1),
    ParamSpec('publish_truth', True, f'publish the {TRUTH_NAMESPACE}* topics'),
    ParamSpec('frame_id', 'base_link', 'frame_id of every header'),
    ParamSpec(
        'start_delay',
        1.0,
        'wall time between start-up and the first sample, so that subscribers started at '
        'the same time are matched and miss nothing [s]',
        low=0.0,
        high=600.0,
    ),
    ParamSpec(
        'wait_for_subscribers',
        5.0,
        'after start_delay, wait up to this long until every sensor (and truth) topic has a '
        'subscriber and discovery has settled for 1 s, so that nodes started with the '
        'simulator miss no sample [s]',
        low=0.0,
        high=600.0,
    ),
    ParamSpec(
        'min_sensor_subscribers',
        1,
        'subscribers every sensor topic must have before the first sample (within '
        'wait_for_subscribers), e.g. 2 for a recorder and the estimation started with the '
        'simulator; the truth topics need one',
        low=1,
        high=100,
    ),
    ParamSpec(
        'lockstep_topics',
        '',
        'comma-separated topics whose header stamps pace the simulator, one per consumer, e.g. '
        "the estimator's slope and the recorder's progress ('' = real-time mode, no waiting)",
    ),
    ParamSpec(
        'lockstep_window',
        0.5,
        'lockstep: how far the simulator may run ahead of its slowest consumer [s of sample '
        "time]; keep it below the consumers' queues (1000 messages: 1 s at 1 kHz)",
        low=1e-6,
        high=60.0,
    ),
    ParamSpec(
        'lockstep_timeout',
        10.0,
        'lockstep: wall time without progress after which a consumer is given up (it died or '
        'never started) and the simulator goes on without it [s]',
        low=0.1,
        high=3600.0,
    ),
    ParamSpec(
        'progress_period',
        10.0,
        'log progress every this much simulated time [s]',
        low=0.0,
        high=1e6,
    ),
]

_BATCH_PERIOD = 0.01  # [s] wall time between publishing batches
_BATCH_BUDGET = 0.05  # [s] wall time one batch may take before yielding to the executor


def resolve_config_file(
    value: str, kind: str, default: str, packages: tuple[str, ...] = ('vd_sim_node',)
) -> Path:
    """A parameter file from a path or an installed name (``config/<kind>/<name>.yaml``).

    Args:
        value: a path, or the name of an installed file ('' = `default`).
        kind: the sub-folder of ``config/`` ('scenarios'; '' for ``config/`` itself).
        default: the name used when `value` is empty.
        packages: whose ``share/<package>/config`` to search, in this order (the vehicle
            files: vd_sim_node's, then vd_common's, which holds the default Clio file).

    Raises:
        ScenarioError: no such file.
    """
    from ament_index_python.packages import get_package_share_directory

    name = value or default
    path = Path(name).expanduser()
    if path.is_file():
        return path
    shares = [Path(get_package_share_directory(package)) / 'config' for package in packages]
    for share in shares:
        for candidate in (share / kind / f'{name}.yaml', share / kind / name, share / name):
            if candidate.is_file():
                return candidate
    share = shares[0]
    installed = sorted(p.stem for p in (share / kind).glob('*.yaml')) if kind else []
    hint = f'; installed: {", ".join(installed)}' if installed else ''
    raise ScenarioError(f'{kind or "config"} file {name!r} not found{hint}')


def _with_sensor_overrides(scenario: Scenario, values: dict[str, Any]) -> Scenario:
    sensors = scenario.sensors
    changes: dict[str, Any] = {'rate_hz': values['rate_hz']}
    if values['encoder_counts_per_rev'] >= 0:
        changes['encoder_counts_per_rev'] = values['encoder_counts_per_rev']
    if values['speed_noise_std'] >= 0.0:
        changes['speed_noise_std'] = values['speed_noise_std']
    if values['imu_noise_std'] >= 0.0:
        changes['imu'] = True
        changes['imu_noise_std'] = values['imu_noise_std']
    if values['imu_gyro_noise_std'] >= 0.0:
        changes['imu_gyro_noise_std'] = values['imu_gyro_noise_std']
    if values['seed'] >= 0:
        changes['seed'] = values['seed']
    return dataclasses.replace(scenario, sensors=dataclasses.replace(sensors, **changes))


class SimNode(Node):
    """Steps :class:`Simulator` against the wall clock and publishes each sample."""

    def __init__(self) -> None:
        super().__init__('sim_node')
        v = declare_parameters(self, PARAMS)
        log_settings(self, PARAMS, v)
        # '' = the shipped Clio file (vd_common's); a name is looked up as before the file
        # moved to vd_common, in vd_sim_node's config/ first
        vehicle_path = (
            resolve_config_file(v['vehicle_file'], '', '', packages=('vd_sim_node', 'vd_common'))
            if v['vehicle_file']
            else default_vehicle_file()
        )
        scenario_path = resolve_config_file(v['scenario_file'], 'scenarios', 'paper_table1')
        self.scenario = _with_sensor_overrides(load_scenario(scenario_path), v)
        self.sim = Simulator(load_vehicle(vehicle_path), self.scenario)
        self.rtf = v['real_time_factor']
        self.publish_truth = v['publish_truth']
        self.frame_id = v['frame_id']
        self.progress_period = v['progress_period']
        self._next_progress = 0.0

        self.streams: list[Any] = []
        self.refusals = PublishRefusals(self)

        def pub(kind: Any, topic: str) -> Any:
            self.streams.append(self.refusals.publisher(kind, topic, STREAM_QOS))
            return self.streams[-1]

        self.p_angles = pub(WheelAngles, SENSORS_WHEEL_ANGLES)
        self.p_speed = pub(TwistStamped, SENSORS_BODY_VELOCITY)
        self.p_torques = pub(WheelTorques, SENSORS_WHEEL_TORQUES)
        # the IMU only where the scenario's car has one (the other runs keep their topics)
        self.p_imu = pub(Imu, SENSORS_IMU) if self.sim.scenario.sensors.imu else None
        if self.publish_truth:
            self.t_states = pub(WheelStates, TRUTH_WHEEL_STATES)
            self.t_accel = pub(AccelStamped, TRUTH_BODY_ACCEL)
            self.t_speed = pub(TwistStamped, TRUTH_BODY_VELOCITY)
            self.t_forces = pub(TireForces, TRUTH_TIRE_FORCES)
            self.t_friction = pub(Friction, TRUTH_FRICTION)
            self.t_resist = pub(Resistances, TRUTH_RESISTANCES)
            self.t_slope = pub(Slope, TRUTH_SLOPE)
            self.t_potential = pub(FrictionPotential, TRUTH_FRICTION_POTENTIAL)
        self.p_clock = self.refusals.publisher(ClockMsg, '/clock', CLOCK_QOS)
        self.p_diag = self.refusals.publisher(DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)

        self.lockstep = self._lockstep(v)

        self.published = 0
        self.last_stamp_ns = 0
        self.held = False  # the last batch waited for a lockstep consumer
        self.wall_start: float | None = None
        self.first_sample_at = time.monotonic() + v['start_delay']
        self.wait_for_subscribers = v['wait_for_subscribers']
        self.min_sensor_subscribers = v['min_sensor_subscribers']
        self.gate: SubscriberGate | None = None
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.batch_timer = self.create_timer(_BATCH_PERIOD, self.publish_batch, clock=steady)
        self.create_timer(1.0, self.publish_diagnostics, clock=steady)
        pacing = (
            f'lockstep on {", ".join(self.lockstep.topics)} '
            f'(window {v["lockstep_window"]:g} s), real-time factor cap {self.rtf:g}'
            if self.lockstep
            else f'real-time factor {self.rtf:g}'
        )
        self.get_logger().info(
            f'scenario {self.scenario.name!r} ({self.scenario.duration:g} s) at '
            f'{self.sim.rate_hz:g} Hz, {pacing}; vehicle {vehicle_path}'
        )

    def _lockstep(self, v: dict[str, Any]) -> Lockstep | None:
        """The lockstep pacing of the `lockstep_*` parameters, subscribed; None: real time."""
        topics = [t.strip() for t in v['lockstep_topics'].split(',') if t.strip()]
        if not topics:
            return None
        lockstep = Lockstep(topics, round(v['lockstep_window'] * 1e9), v['lockstep_timeout'])
        self._given_up: set[str] = set()
        self._unsubscribed = list(topics)
        self._next_discovery = 0.0
        return lockstep

    def _subscribe_lockstep(self) -> None:
        """Subscribe to the lockstep topics whose publishers have appeared, with their type.

        Any message type that begins with a std_msgs/Header will do: the bytes are taken and
        only the stamp is read. A topic that never appears is given up after the timeout.
        """
        types = dict(self.get_topic_names_and_types())
        for topic in [t for t in self._unsubscribed if types.get(t)]:
            self._unsubscribed.remove(topic)
            kind = ros_message_class(types[topic][0])
            self.create_subscription(
                kind, topic, self._progress_callback(topic), STREAM_QOS, raw=True
            )

    def _progress_callback(self, topic: str) -> Any:
        def on_progress(data: bytes) -> None:
            stamp = header_stamp_ns(data)
            if stamp is not None and self.lockstep is not None:
                self.lockstep.seen(topic, stamp, time.monotonic())

        return on_progress

    def _lockstep_allows(self, now: float) -> bool:
        assert self.lockstep is not None
        if self._unsubscribed and now >= self._next_discovery:
            self._next_discovery = now + 0.5  # a graph query costs ms: not once per sample
            self._subscribe_lockstep()
        allowed = self.lockstep.allows(round(self.sim.t * 1e9), now)
        for topic in set(self.lockstep.given_up) - self._given_up:
            self._given_up.add(topic)
            self.get_logger().warning(
                f'lockstep: no progress on {topic} for {self.lockstep.timeout_s:g} s; '
                'going on without it'
            )
        return allowed

    # -- publishing --------------------------------------------------------------------------

    def publish_batch(self) -> None:
        now = time.monotonic()
        if now < self.first_sample_at:
            return
        if self.wall_start is None:
            if self.gate is None:
                sensors = (self.p_angles, self.p_speed, self.p_torques)
                least = [self.min_sensor_subscribers if p in sensors else 1 for p in self.streams]
                self.gate = SubscriberGate(
                    self.streams, now + self.wait_for_subscribers, 1.0, least
                )
            if not self.gate.ready(now):
                return
            if self.gate.missing:
                missing = ', '.join(self.gate.missing)
                self.get_logger().info(f'starting without subscribers on {missing}')
            self.wall_start = now
        target = self._target(now)
        deadline = now + _BATCH_BUDGET
        last: SampleFrame | None = None
        while not self.sim.done and self.sim.t <= target and time.monotonic() < deadline:
            if self.lockstep is not None and not self._lockstep_allows(now):
                self.held = True
                break
            last = self.sim.step()
            self.publish_frame(last)  # a refused publish is counted by self.refusals
        if last is not None:
            self.last_stamp_ns = round(last.t * 1e9)
            self.p_clock.publish(ClockMsg(clock=self._stamp(last.t)))
            self._log_progress(last)
        if self.sim.done and self._consumers_done(now):
            self.get_logger().info(
                f'scenario finished: {self.published} samples, '
                f'{self.sim.t:.3f} s simulated in {time.monotonic() - self.wall_start:.1f} s'
            )
            deliver_pending(self)
            self.batch_timer.cancel()
            finish(self)

    def _target(self, now: float) -> float:
        """Sample time [s] up to which this batch may publish: the real-time factor's pace.

        Real time follows the wall clock from the start, catching up after a late batch. In
        lockstep the pace restarts after each wait for the consumers, so the wait's backlog is
        not sent at once: 0.5 s of samples on 11 topics in one burst overflowed the recorder's
        transport queue, each overflow was repaired only at the next heartbeat, and the graph
        ran at 0.2x real time with idle cores.
        """
        rtf = float(self.rtf)
        if rtf <= 0:
            return float('inf')
        assert self.wall_start is not None
        if self.held:
            self.held = False
            self.wall_start = now - self.sim.t / rtf
        return (now - self.wall_start) * rtf

    def _consumers_done(self, now: float) -> bool:
        """In lockstep: every consumer took the last sample (or was given up)."""
        if self.lockstep is None:
            return True
        done = self.lockstep.caught_up(self.last_stamp_ns, now)
        self._lockstep_allows(now)  # log consumers given up meanwhile
        return done

    def _stamp(self, t: float) -> Any:
        return ns_to_time(round(t * 1e9))

    def publish_frame(self, f: SampleFrame) -> None:
        header = Header(stamp=self._stamp(f.t), frame_id=self.frame_id)
        # the IMU first: a node that holds the newest IMU sample then has this stamp's when
        # the wheel sensors of the stamp complete it (what a replay holds)
        if self.p_imu is not None:
            imu = Imu(header=header)
            imu.orientation_covariance[0] = -1.0  # REP 145: no orientation
            # the pitch rate only (y): the car does not roll or yaw; its covariance the noise's
            gyro_var = self.sim.scenario.sensors.imu_gyro_noise_std**2
            imu.angular_velocity_covariance[0] = gyro_var
            imu.angular_velocity_covariance[4] = gyro_var
            imu.angular_velocity_covariance[8] = gyro_var
            imu.angular_velocity.y = float(f.gyro)
            imu.linear_acceleration.x = float(f.imu[0])
            imu.linear_acceleration.z = float(f.imu[1])
            self.p_imu.publish(imu)
        self.p_angles.publish(WheelAngles(header=header, angle=f.wheel_angle.tolist()))
        speed = TwistStamped(header=header)
        speed.twist.linear.x = float(f.body_speed)
        self.p_speed.publish(speed)
        self.p_torques.publish(
            WheelTorques(
                header=header,
                torque=f.wheel_torque.tolist(),
                engine_torque=float(f.engine_torque),
                engine_speed=float(f.engine_speed),
                gear=int(f.gear),
            )
        )
        if self.publish_truth:
            self.t_states.publish(
                WheelStates(
                    header=header,
                    angle=f.angle_true.tolist(),
                    omega=f.omega.tolist(),
                    omega_dot=f.omega_dot.tolist(),
                )
            )
            accel = AccelStamped(header=header)
            accel.accel.linear.x = float(f.accel_true)
            self.t_accel.publish(accel)
            true_speed = TwistStamped(header=header)
            true_speed.twist.linear.x = float(f.speed_true)
            self.t_speed.publish(true_speed)
            self.t_forces.publish(TireForces(header=header, fx=f.fx.tolist(), fz=f.fz.tolist()))
            self.t_friction.publish(
                Friction(
                    header=header,
                    mu=f.mu.tolist(),
                    slip=f.slip.tolist(),
                    valid=[bool(fz > 0.0) for fz in f.fz],
                )
            )
            self.t_resist.publish(
                Resistances(header=header, rolling=f.rolling.tolist(), aero=float(f.aero))
            )
            self.t_slope.publish(Slope(header=header, angle=float(f.slope), valid=True))
            self.t_potential.publish(_potential_message(header, f))
        self.published += 1

    def _log_progress(self, f: SampleFrame) -> None:
        if self.progress_period <= 0 or f.t + 1e-9 < self._next_progress:
            return
        self._next_progress = f.t + self.progress_period
        self.get_logger().info(
            f'progress t={f.t:.1f}/{self.scenario.duration:g} s, gear {f.gear}, '
            f'v={f.speed_true * 3.6:.1f} km/h'
        )

    def publish_diagnostics(self) -> None:
        elapsed = time.monotonic() - (self.wall_start or time.monotonic())
        achieved = self.sim.t / elapsed if elapsed > 0 else 0.0
        # in lockstep, running behind the real-time factor is the point, not a fault
        lagging = (
            self.lockstep is None and self.rtf > 0 and elapsed > 2.0 and achieved < 0.9 * self.rtf
        )
        problems = []
        if lagging:
            problems.append(f'behind real-time factor {self.rtf:g} (achieved {achieved:.2f})')
        lockstep: dict[str, object] = {}
        notes = []
        if self.lockstep is not None:
            stamp_ns = round(self.sim.t * 1e9)
            if self.lockstep.given_up:
                problems.append(f'lockstep gave up on {", ".join(self.lockstep.given_up)}')
            waiting = self.lockstep.waiting_for(stamp_ns)
            if waiting and not self.sim.done:
                notes.append(f'lockstep: waiting for {", ".join(waiting)}')
            for topic, lag in self.lockstep.lag_ns(stamp_ns).items():
                lockstep[f'lockstep_lag_s[{topic}]'] = '-' if lag is None else f'{lag * 1e-9:.3f}'
        level, message, refused = self.refusals.status(
            1 if problems else 0, '; '.join(problems + notes) or 'ok'
        )
        values = {
            'sim_time_s': f'{self.sim.t:.3f}',
            'samples_published': self.published,
            'achieved_real_time_factor': f'{achieved:.2f}',
            'requested_real_time_factor': self.rtf,
            **lockstep,
            **refused,
        }
        self.p_diag.publish(
            diagnostic_array(
                self._stamp(self.sim.t), 'vd: simulator', 'sim_node', level, message, values
            )
        )


def _potential_message(header: Header, f: SampleFrame) -> FrictionPotential:
    """The true friction potential of one sample: axle means of the wheels' MF peaks.

    Plain floats rather than numpy calls: this runs per sample (about 9 us instead of 75).
    Same values as ``vd_common.vehicle.friction`` ``axle_mean`` / ``road_class`` /
    ``vehicle_road_class``.
    """
    mu = f.peak_mu.tolist()
    slip = f.peak_slip.tolist()
    mu_max = [0.5 * (mu[0] + mu[1]), 0.5 * (mu[2] + mu[3])]
    return FrictionPotential(
        header=header,
        mu_max=mu_max,
        slip_peak=[0.5 * (slip[0] + slip[1]), 0.5 * (slip[2] + slip[3])],
        confidence=[1.0, 1.0],
        road_class=[road_class_of(m) for m in mu_max],
        vehicle_road_class=road_class_of(min(mu_max)),
    )


def main(args: list[str] | None = None) -> int:
    """Entry point of ``ros2 run vd_sim_node sim_node``."""
    return run_node(SimNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
