"""Soak test of the live graph: sensors at a fixed rate through observer_node and
estimator_node for minutes; prints each node's RSS at start and end and the messages lost.

    . ./env.sh && python scripts/bench_soak.py                 # 1 min at 1 kHz (make bench)
    . ./env.sh && python scripts/bench_soak.py --minutes 10    # the full soak

This process publishes the three sensor topics (a synthetic drive whose motion repeats every
minute, stamps always increasing) paced in real time, and a child process counts what the
nodes publish and keeps their last /diagnostics. Nothing is asserted: the figures are printed
for docs/faults.md.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from vd_common.topics import (
    ESTIMATES_FRICTION,
    ESTIMATES_RESISTANCES,
    ESTIMATES_SLOPE,
    ESTIMATES_TIRE_FORCES,
    OBSERVER_BODY_ACCEL,
    OBSERVER_WHEEL_STATES,
    SENSORS_BODY_VELOCITY,
    SENSORS_WHEEL_ANGLES,
    SENSORS_WHEEL_TORQUES,
)

ROOT = Path(__file__).resolve().parents[1]
LIB = ROOT / 'install' / 'vd_observer_node' / 'lib' / 'vd_observer_node'
COUNTED = {
    OBSERVER_WHEEL_STATES: 'WheelStates',
    OBSERVER_BODY_ACCEL: 'AccelStamped',
    ESTIMATES_TIRE_FORCES: 'TireForces',
    ESTIMATES_FRICTION: 'Friction',
    ESTIMATES_RESISTANCES: 'Resistances',
    ESTIMATES_SLOPE: 'Slope',
}


def rss_mib(pid: int) -> float:
    """Resident set size of a process [MiB] from /proc."""
    for line in Path(f'/proc/{pid}/status').read_text().splitlines():
        if line.startswith('VmRSS:'):
            return int(line.split()[1]) / 1024.0
    return float('nan')


def count_role(out_path: str) -> None:
    """Child: count messages per topic and keep the last diagnostics, until SIGINT."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import AccelStamped
    from rclpy.node import Node
    from vd_common.ros.qos import DIAGNOSTICS_QOS, STREAM_QOS

    from vd_msgs.msg import Friction, Resistances, Slope, TireForces, WheelStates

    kinds: dict[str, Any] = {
        'WheelStates': WheelStates,
        'AccelStamped': AccelStamped,
        'TireForces': TireForces,
        'Friction': Friction,
        'Resistances': Resistances,
        'Slope': Slope,
    }
    rclpy.init()
    node = Node('soak_counter')
    counts = dict.fromkeys(COUNTED, 0)
    diag: dict[str, Any] = {}

    def counter(topic: str) -> Any:
        def callback(_msg: Any) -> None:
            counts[topic] += 1

        return callback

    for topic, kind in COUNTED.items():
        node.create_subscription(kinds[kind], topic, counter(topic), STREAM_QOS)

    def on_diag(msg: Any) -> None:
        for s in msg.status:
            level = s.level[0] if isinstance(s.level, bytes) else int(s.level)
            diag[s.name] = {
                'level': level,
                'message': s.message,
                'values': {kv.key: kv.value for kv in s.values if kv.value != '0'},
            }

    node.create_subscription(DiagnosticArray, '/diagnostics', on_diag, DIAGNOSTICS_QOS)
    print('counter ready', flush=True)
    with contextlib.suppress(KeyboardInterrupt):
        rclpy.spin(node)
    Path(out_path).write_text(json.dumps({'counts': counts, 'diagnostics': diag}))
    os._exit(0)


def feed(minutes: float, rate_hz: float, node_pids: dict[str, int]) -> dict[str, Any]:
    """Publish the sensors at rate_hz for `minutes`; return sent count, rate and RSS figures."""
    import numpy as np
    import rclpy
    from geometry_msgs.msg import TwistStamped
    from rclpy.node import Node
    from vd_common.ros.qos import STREAM_QOS
    from vd_common.ros.stamps import ns_to_time
    from vd_common.vehicle.params import default_vehicle_file
    from vd_observer_node.estimation.vehicle import load_estimator_vehicle
    from vd_observer_node.testing.synthetic import synthetic_trajectory

    from vd_msgs.msg import WheelAngles, WheelTorques

    period = 1.0 / rate_hz
    cycle = round(60.0 * rate_hz)  # one minute of drive, repeated with increasing stamps
    vehicle = load_estimator_vehicle(default_vehicle_file())
    traj = synthetic_trajectory(np.arange(cycle) * period, vehicle)
    distance_per_cycle = traj.angle[-1] - traj.angle[0] + traj.omega[-1] * period
    rclpy.init()
    node = Node('soak_feed')
    pub_a = node.create_publisher(WheelAngles, SENSORS_WHEEL_ANGLES, STREAM_QOS)
    pub_v = node.create_publisher(TwistStamped, SENSORS_BODY_VELOCITY, STREAM_QOS)
    pub_t = node.create_publisher(WheelTorques, SENSORS_WHEEL_TORQUES, STREAM_QOS)
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and not (
        pub_a.get_subscription_count() >= 1
        and pub_v.get_subscription_count() >= 2
        and pub_t.get_subscription_count() >= 1
    ):
        time.sleep(0.05)
    time.sleep(1.0)
    total = round(minutes * 60.0 * rate_hz)
    warmup = min(round(5.0 * rate_hz), total // 4)
    rss_start: dict[str, float] = {}
    a, v, q = WheelAngles(), TwistStamped(), WheelTorques()
    for msg in (a, v, q):
        msg.header.frame_id = 'base_link'
    t0_ns = 1_000_000_000
    started = time.perf_counter()
    late = 0
    for k in range(total):
        if k == warmup:
            rss_start = {name: rss_mib(pid) for name, pid in node_pids.items()}
        target = started + k * period
        now = time.perf_counter()
        if now < target:
            time.sleep(target - now)
        elif now - target > 0.01:
            late += 1
        i, lap = k % cycle, k // cycle
        stamp = ns_to_time(t0_ns + round(k * period * 1e9))
        a.header.stamp = v.header.stamp = q.header.stamp = stamp
        a.angle = (traj.angle[i] + lap * distance_per_cycle).tolist()
        v.twist.linear.x = float(traj.speed[i])
        q.torque = traj.torque[i].tolist()
        pub_a.publish(a)
        pub_v.publish(v)
        pub_t.publish(q)
    elapsed = time.perf_counter() - started
    rss_end = {name: rss_mib(pid) for name, pid in node_pids.items()}
    node.destroy_node()
    rclpy.try_shutdown()
    return {
        'sent': total,
        'achieved_rate_hz': total / elapsed,
        'late_over_10ms': late,
        'rss_start_mib': rss_start,
        'rss_end_mib': rss_end,
    }


def main() -> int:
    """Run the soak and print its figures."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--minutes', type=float, default=1.0, help='duration (default 1)')
    parser.add_argument('--rate', type=float, default=1000.0, help='sensor rate [Hz]')
    parser.add_argument(
        '--role', default='feed', choices=('feed', 'count'), help=argparse.SUPPRESS
    )
    parser.add_argument('--out', default='', help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.role == 'count':
        count_role(args.out)
        return 0
    if not LIB.is_dir():
        print('install/ missing: run `make setup` and `. ./env.sh` first', file=sys.stderr)
        return 2
    if args.minutes < 10:
        print(f'soak: {args.minutes:g} min at {args.rate:g} Hz (the full soak is --minutes 10)')
    env = dict(os.environ)
    env.setdefault('ROS_DOMAIN_ID', '87')
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    os.environ.update(env)
    out = Path(f'/tmp/vd_soak_{os.getpid()}.json')
    procs = {
        'observer_node': subprocess.Popen([str(LIB / 'observer_node')], env=env,
                                          stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                          start_new_session=True),
        'estimator_node': subprocess.Popen([str(LIB / 'estimator_node')], env=env,
                                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                           start_new_session=True),
    }  # fmt: skip
    counter = subprocess.Popen(
        [sys.executable, __file__, '--role', 'count', '--out', str(out)],
        env=env,
        stdout=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    try:
        assert counter.stdout is not None
        counter.stdout.readline()  # 'counter ready'
        figures = feed(args.minutes, args.rate, {n: p.pid for n, p in procs.items()})
        time.sleep(3.0)  # the last messages through the cascade, one more diagnostics period
        os.killpg(counter.pid, signal.SIGINT)
        counter.wait(20)
        result = json.loads(out.read_text())
    finally:
        for proc in [*procs.values(), counter]:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGINT)
                try:
                    proc.wait(10)
                except subprocess.TimeoutExpired:
                    os.killpg(proc.pid, signal.SIGKILL)
        out.unlink(missing_ok=True)
    sent = figures['sent']
    print(
        f'sent {sent} samples x 3 sensor topics in {args.minutes:g} min; achieved '
        f'{figures["achieved_rate_hz"]:.1f} Hz; {figures["late_over_10ms"]} samples > 10 ms late'
    )
    print(f'load average at the end: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores')
    print(f'{"topic":32s} {"received":>9s} {"lost":>7s}')
    for topic, n in result['counts'].items():
        print(f'{topic:32s} {n:9d} {sent - n:7d}')
    print(f'{"node":16s} {"RSS start MiB":>14s} {"RSS end MiB":>12s} {"growth":>8s}')
    for name in procs:
        start, end = figures['rss_start_mib'][name], figures['rss_end_mib'][name]
        print(f'{name:16s} {start:14.1f} {end:12.1f} {end - start:8.1f}')
    for name, status in result['diagnostics'].items():
        print(f'diagnostics {name}: level {status["level"]}, {status["message"]}; '
              f'non-zero counters {status["values"]}')  # fmt: skip
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
