#!/usr/bin/env python3
"""A real drive as a car's CAN-to-ROS bridge would have logged it: comma2k19 to an MCAP bag.

Reads a comma2k19 segment (``../shared/realdata/comma2k19-rav4-seg40``: a 2017 Toyota RAV4,
60 s of highway; its README lists the signals), decodes the raw CAN frames with the car's DBC
(cantools) and writes a bag on standard ROS types only, one topic per group of signals, as a
decoding bridge publishes them:

==========================  ==================================  ==================================
topic                       type                                values, units (as on the bus)
==========================  ==================================  ==================================
``/can/wheel_speeds``       std_msgs/msg/Float64MultiArray      VXFL, VXFR, VXRL, VXRR [km/h]
``/can/vehicle_speed``      std_msgs/msg/Float64MultiArray      SP1 [km/h]
``/can/powertrain``         std_msgs/msg/Float64MultiArray      ETQREAL [N m], SFTOUT gear, NE1
                                                                engine speed [rpm], NT turbine
                                                                speed [rpm], EACCP pedal [%]
``/can/brake``              std_msgs/msg/Float64MultiArray      BRKON switch (0/1), BRAKE_PRESSURE
                                                                (uncalibrated; 0 on this car but
                                                                in 5 of 2 487 frames: the drive
                                                                has a brake switch only)
``/imu``                    sensor_msgs/msg/Imu                 the windscreen device's own axes
``/vd/truth/slope``         vd_msgs/msg/Slope                   reference grade from the pose
``/pose/odom``              nav_msgs/msg/Odometry               the pose's speed (twist.linear.x,
                                                                the norm of its velocity [m/s])
``/gnss/fix``               sensor_msgs/msg/NavSatFix           the u-blox receiver's fixes, 10 Hz
                                                                (latitude, longitude [deg],
                                                                altitude [m], its accuracy [m]
                                                                as the covariance's diagonal)
==========================  ==================================  ==================================

Each CAN topic is written at the rate of the frame that leads it (wheel speeds 0xAA, vehicle
speed 0xB4, powertrain ENG1S01 0x2C1 with the newest gear, engine and turbine speed of their
own frames, brake BRAKE_MODULE 0x224 with the newest switch); Float64MultiArray has no header,
so its samples carry their frame's time as log time. Times are the device's boot clock [s].

The reference grade is not a measurement: the pose's altitude (ECEF to WGS-84 height) over the
horizontal distance travelled, as a central difference over ``--grade-window`` metres (default
40 m), stamped at the pose's frames (20 Hz). GNSS altitude is good to a few tenths of a degree
of grade at best (the segment's README); it is written as vd's truth topic so that ``vd
report`` compares the slope estimate with it.

Usage:
    python scripts/import_comma2k19.py [SEGMENT] [--out BAG] [--grade-window M]
"""

from __future__ import annotations

import argparse
import math
import re
import sys
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

import numpy as np
from numpy.typing import NDArray

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'src' / 'vd_observer_node'))
sys.path.insert(0, str(ROOT / 'src' / 'vd_common'))

from vd_common.topics import TRUTH_SLOPE  # noqa: E402
from vd_observer_node.bag.typestore import message_class, serialize  # noqa: E402
from vd_observer_node.bag.writer import BagWriter  # noqa: E402
from vd_observer_node.testing.standard_bags import float64_array, header  # noqa: E402

FloatArray = NDArray[np.float64]

#: where the segment lies next to a checkout (the workplace's shared data)
DEFAULT_SEGMENT: Final = ROOT.parent / 'shared' / 'realdata' / 'comma2k19-rav4-seg40'
WHEEL_SPEEDS: Final = '/can/wheel_speeds'
VEHICLE_SPEED: Final = '/can/vehicle_speed'
POWERTRAIN: Final = '/can/powertrain'
BRAKE: Final = '/can/brake'
IMU: Final = '/imu'
POSE_ODOM: Final = '/pose/odom'
GNSS_FIX: Final = '/gnss/fix'
FLOAT_ARRAY: Final = 'std_msgs/msg/Float64MultiArray'
_NS: Final = 1_000_000_000
#: WGS-84
_A: Final = 6378137.0
_F: Final = 1.0 / 298.257223563


@dataclass(frozen=True)
class CanMessage:
    """One CAN message of the DBC: its frame id, DBC file and the signals the bag takes."""

    frame_id: int
    dbc: str
    signals: tuple[str, ...]


#: the messages vd needs, from the DBCs of the segment's ``dbc/`` folder (bus 0)
MESSAGES: Final = {
    'wheels': CanMessage(0xAA, 'toyota_2017_ref_pt.dbc', ('VXFL', 'VXFR', 'VXRL', 'VXRR')),
    'speed': CanMessage(0xB4, 'toyota_2017_ref_pt.dbc', ('SP1',)),
    'engine': CanMessage(0x2C1, 'toyota_2017_ref_pt.dbc', ('ETQREAL', 'EACCP')),
    'engine_speed': CanMessage(0x1C4, 'toyota_2017_ref_pt.dbc', ('NE1',)),
    'gearbox': CanMessage(0x1D0, 'toyota_2017_ref_pt.dbc', ('NT', 'SFTOUT')),
    'brake_switch': CanMessage(0x320, 'toyota_2017_ref_pt.dbc', ('BRKON',)),
    'brake_pressure': CanMessage(0x224, 'toyota_new_mc_pt.dbc', ('BRAKE_PRESSURE',)),
}


@dataclass(frozen=True)
class Signals:
    """The decoded frames of one message: times (N,) [s] and one (N,) array per signal."""

    t: FloatArray
    values: dict[str, FloatArray]


def dbc_subset(text: str, frame_ids: Iterable[int]) -> str:
    """The ``BO_`` blocks (with their ``SG_`` lines) of `frame_ids` from a DBC's text.

    The full reference DBC declares extended ids without the extended flag, which cantools
    refuses; the messages vd reads are plain 11-bit ones, so only they are loaded.
    """
    wanted = set(frame_ids)
    blocks = ['VERSION ""\n\nBS_:\n\nBU_: XXX\n']
    for match in re.finditer(r'^BO_ (\d+) .*?(?=^\s*$)', text, flags=re.M | re.S):
        if int(match.group(1)) in wanted:
            blocks.append(match.group(0).strip() + '\n')
    return '\n'.join(blocks) + '\n'


def decode_can(segment: Path) -> dict[str, Signals]:
    """Every message of `MESSAGES` decoded from the segment's raw CAN log (bus 0).

    Raises:
        FileNotFoundError: the segment lacks its raw CAN log or DBC files.
        ValueError: a message vd needs is not in the log.
    """
    import cantools

    raw = segment / 'processed_log' / 'CAN' / 'raw_can'
    address = np.load(raw / 'address')
    data = np.load(raw / 'data')
    bus = np.load(raw / 'src')
    t = np.load(raw / 't')
    databases: dict[str, Any] = {}
    out: dict[str, Signals] = {}
    for name, spec in MESSAGES.items():
        if spec.dbc not in databases:
            text = (segment / 'dbc' / spec.dbc).read_text(encoding='utf-8', errors='replace')
            ids = [m.frame_id for m in MESSAGES.values() if m.dbc == spec.dbc]
            databases[spec.dbc] = cantools.database.load_string(dbc_subset(text, ids), 'dbc')
        message = databases[spec.dbc].get_message_by_frame_id(spec.frame_id)
        rows = np.flatnonzero((address == spec.frame_id) & (bus == 0))
        if rows.size == 0:
            raise ValueError(f'no frame 0x{spec.frame_id:X} ({message.name}) on bus 0')
        values = {signal: np.empty(rows.size) for signal in spec.signals}
        for k, row in enumerate(rows.tolist()):
            # numpy's S8 drops trailing zero bytes: give the frame its length back
            frame = bytes(data[row]).ljust(message.length, b'\0')
            decoded = message.decode(frame, decode_choices=False, scaling=True)
            for signal in spec.signals:
                values[signal][k] = float(decoded[signal])
        out[name] = Signals(t[rows].astype(np.float64), values)
    return out


def newest(at: FloatArray, source: Signals, signal: str) -> FloatArray:
    """The newest value of `signal` not later than each time of `at` (nan before the first)."""
    k = np.searchsorted(source.t, at, side='right') - 1
    values = source.values[signal][np.clip(k, 0, None)]
    return np.where(k >= 0, values, math.nan)


def geodetic_height(ecef: FloatArray) -> FloatArray:
    """WGS-84 ellipsoidal height [m] of ECEF points (N, 3) [m] (Bowring, then 3 iterations)."""
    x, y, z = ecef[:, 0], ecef[:, 1], ecef[:, 2]
    e2 = _F * (2.0 - _F)
    p = np.hypot(x, y)
    lat = np.arctan2(z, p * (1.0 - e2))
    for _ in range(3):
        n = _A / np.sqrt(1.0 - e2 * np.sin(lat) ** 2)
        h = p / np.cos(lat) - n
        lat = np.arctan2(z, p * (1.0 - e2 * n / (n + h)))
    n = _A / np.sqrt(1.0 - e2 * np.sin(lat) ** 2)
    return np.asarray(p / np.cos(lat) - n, dtype=np.float64)


def reference_grade(positions: FloatArray, window: float) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Grade [rad] at each pose from ECEF positions (N, 3) [m]: height change over the
    horizontal distance travelled, central over `window` [m]; valid where the window fits."""
    height = geodetic_height(positions)
    step = np.linalg.norm(np.diff(positions, axis=0), axis=1)
    rise = np.diff(height)
    run = np.sqrt(np.maximum(step**2 - rise**2, 0.0))
    s = np.concatenate(([0.0], np.cumsum(run)))
    lo, hi = s - window / 2.0, s + window / 2.0
    valid = (lo >= s[0]) & (hi <= s[-1])
    h_lo = np.interp(np.clip(lo, s[0], s[-1]), s, height)
    h_hi = np.interp(np.clip(hi, s[0], s[-1]), s, height)
    return np.arctan2(h_hi - h_lo, window), valid


def _imu(stamp_ns: int, accel: FloatArray, gyro: FloatArray) -> Any:
    vec = message_class('geometry_msgs/msg/Vector3')
    quat = message_class('geometry_msgs/msg/Quaternion')(x=0.0, y=0.0, z=0.0, w=1.0)
    unknown = np.zeros(9)
    unknown[0] = -1.0  # REP 145: no orientation estimate
    return message_class('sensor_msgs/msg/Imu')(
        header=header(stamp_ns, 'device'),
        orientation=quat,
        orientation_covariance=unknown,
        angular_velocity=vec(x=float(gyro[0]), y=float(gyro[1]), z=float(gyro[2])),
        angular_velocity_covariance=np.zeros(9),
        linear_acceleration=vec(x=float(accel[0]), y=float(accel[1]), z=float(accel[2])),
        linear_acceleration_covariance=np.zeros(9),
    )


def _slope(stamp_ns: int, angle: float, valid: bool) -> Any:
    return message_class('vd_msgs/msg/Slope')(
        header=header(stamp_ns), angle=angle, valid=valid, torque_source=0, sources=0
    )


def _odometry(stamp_ns: int, speed: float) -> Any:
    """The pose's speed as a GNSS/INS receiver's Odometry gives it (twist in the body frame)."""
    twist = message_class('geometry_msgs/msg/Twist')(
        linear=message_class('geometry_msgs/msg/Vector3')(x=speed, y=0.0, z=0.0),
        angular=message_class('geometry_msgs/msg/Vector3')(x=0.0, y=0.0, z=0.0),
    )
    return message_class('nav_msgs/msg/Odometry')(
        header=header(stamp_ns, 'map'),
        child_frame_id='base_link',
        pose=message_class('geometry_msgs/msg/PoseWithCovariance')(
            pose=message_class('geometry_msgs/msg/Pose')(
                position=message_class('geometry_msgs/msg/Point')(x=0.0, y=0.0, z=0.0),
                orientation=message_class('geometry_msgs/msg/Quaternion')(
                    x=0.0, y=0.0, z=0.0, w=1.0
                ),
            ),
            covariance=np.zeros(36),
        ),
        twist=message_class('geometry_msgs/msg/TwistWithCovariance')(
            twist=twist, covariance=np.zeros(36)
        ),
    )


def _fix(stamp_ns: int, fix: FloatArray) -> Any:
    """A u-blox fix row (latitude, longitude [deg], speed, GPS time, altitude [m], accuracy
    [m]) as a NavSatFix (covariance type 2: diagonal known)."""
    status = message_class('sensor_msgs/msg/NavSatStatus')(status=0, service=1)
    return message_class('sensor_msgs/msg/NavSatFix')(
        header=header(stamp_ns, 'gnss'),
        status=status,
        latitude=float(fix[0]),
        longitude=float(fix[1]),
        altitude=float(fix[4]),
        position_covariance=np.diag([float(fix[5]) ** 2] * 3).ravel(),
        position_covariance_type=2,
    )


def _ns(t: float) -> int:
    return round(t * _NS)


def import_segment(segment: Path, out: Path, grade_window: float = 40.0) -> dict[str, int]:
    """Write the segment's bag to `out`; returns the message count per topic.

    Raises:
        FileNotFoundError: a file of the segment is missing.
        ValueError: a needed CAN message is not in the log.
    """
    can = decode_can(segment)
    rows: list[tuple[int, str, bytes]] = []
    wheels = can['wheels']
    wheel_kmh = np.stack([wheels.values[s] for s in MESSAGES['wheels'].signals], axis=1)
    rows += [
        (_ns(t), WHEEL_SPEEDS, serialize(float64_array(v)))
        for t, v in zip(wheels.t, wheel_kmh, strict=True)
    ]
    speed = can['speed']
    rows += [
        (_ns(t), VEHICLE_SPEED, serialize(float64_array([v])))
        for t, v in zip(speed.t, speed.values['SP1'], strict=True)
    ]
    engine = can['engine']
    power = np.stack(
        [
            engine.values['ETQREAL'],
            newest(engine.t, can['gearbox'], 'SFTOUT'),
            newest(engine.t, can['engine_speed'], 'NE1'),
            newest(engine.t, can['gearbox'], 'NT'),
            engine.values['EACCP'],
        ],
        axis=1,
    )
    rows += [
        (_ns(t), POWERTRAIN, serialize(float64_array(v)))
        for t, v in zip(engine.t, power, strict=True)
    ]
    pressure = can['brake_pressure']
    brake = np.stack(
        [newest(pressure.t, can['brake_switch'], 'BRKON'), pressure.values['BRAKE_PRESSURE']],
        axis=1,
    )
    rows += [
        (_ns(t), BRAKE, serialize(float64_array(v)))
        for t, v in zip(pressure.t, brake, strict=True)
    ]
    imu_dir = segment / 'processed_log' / 'IMU'
    t_acc = np.load(imu_dir / 'accelerometer' / 't')
    accel = np.load(imu_dir / 'accelerometer' / 'value')
    gyro_t = np.load(imu_dir / 'gyro' / 't')
    gyro = np.load(imu_dir / 'gyro' / 'value')
    # the two streams come from one device, usually on the same stamps: take the nearest
    near = np.clip(np.searchsorted(gyro_t, t_acc), 0, gyro_t.size - 1)
    rows += [
        (_ns(t), IMU, serialize(_imu(_ns(t), a, gyro[k])))
        for t, a, k in zip(t_acc, accel, near.tolist(), strict=True)
    ]
    pose = segment / 'global_pose'
    pose_t = np.load(pose / 'frame_times')
    grade, valid = reference_grade(np.load(pose / 'frame_positions'), grade_window)
    rows += [
        (_ns(t), TRUTH_SLOPE, serialize(_slope(_ns(t), float(g), bool(ok))))
        for t, g, ok in zip(pose_t, grade, valid, strict=True)
    ]
    speed_mps = np.linalg.norm(np.load(pose / 'frame_velocities'), axis=1)
    rows += [
        (_ns(t), POSE_ODOM, serialize(_odometry(_ns(t), float(v))))
        for t, v in zip(pose_t, speed_mps, strict=True)
    ]
    gnss = segment / 'processed_log' / 'GNSS' / 'live_gnss_ublox'
    rows += [
        (_ns(t), GNSS_FIX, serialize(_fix(_ns(t), fix)))
        for t, fix in zip(np.load(gnss / 't'), np.load(gnss / 'value'), strict=True)
    ]
    rows.sort(key=lambda row: row[0])
    types = {
        WHEEL_SPEEDS: FLOAT_ARRAY,
        VEHICLE_SPEED: FLOAT_ARRAY,
        POWERTRAIN: FLOAT_ARRAY,
        BRAKE: FLOAT_ARRAY,
        IMU: 'sensor_msgs/msg/Imu',
        TRUTH_SLOPE: 'vd_msgs/msg/Slope',
        POSE_ODOM: 'nav_msgs/msg/Odometry',
        GNSS_FIX: 'sensor_msgs/msg/NavSatFix',
    }
    counts = dict.fromkeys(types, 0)
    with BagWriter(out) as writer:
        for topic, msgtype in types.items():
            writer.add_topic(topic, msgtype)
        for stamp, topic, data in rows:
            writer.write(topic, data, stamp)
            counts[topic] += 1
    return counts


def main(argv: list[str] | None = None) -> int:
    """Command line; exit code 0, 2 on a missing segment or message."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('segment', type=Path, nargs='?', default=DEFAULT_SEGMENT)
    parser.add_argument('--out', type=Path, default=ROOT / 'bags' / 'rav4_seg40')
    parser.add_argument('--grade-window', type=float, default=40.0, help='metres (default 40)')
    args = parser.parse_args(argv)
    try:
        counts = import_segment(args.segment, args.out, args.grade_window)
    except (FileNotFoundError, ValueError) as exc:
        print(f'import_comma2k19: {exc}', file=sys.stderr)
        return 2
    print(f'{args.out}: ' + ', '.join(f'{topic} {n}' for topic, n in counts.items()))
    return 0


if __name__ == '__main__':
    sys.exit(main())
