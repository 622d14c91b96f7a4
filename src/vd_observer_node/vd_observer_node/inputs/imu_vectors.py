"""The IMU's whole vectors in the sensor's own frame, before any mounting is applied.

The replay and the nodes read the IMU through its mounting (`decode.decode_input`: the body's
forward specific force and pitch rate). Learning the mounting (``vd calibrate``,
`tools.calibrate.mounting`) needs what the sensor itself measured: the three axes of the
specific force and of the angular rate, in the sensor's frame, in SI units.
"""

from __future__ import annotations

import math

import numpy as np

from vd_observer_node.bag.reader import TopicArrays
from vd_observer_node.bag.typestore import deserialize
from vd_observer_node.inputs.decode import InputSeries
from vd_observer_node.inputs.errors import MappingError
from vd_observer_node.inputs.mapping import ACCEL_STAMPED, FLOAT64_ARRAY, IMU_TYPE, InputSpec

__all__ = ['decode_imu_vectors', 'has_three_axes']

_NS = 1_000_000_000


def has_three_axes(spec: InputSpec) -> bool:
    """True when the IMU input gives the three axes of its specific force (an Imu, an
    AccelStamped, or a Float64MultiArray with the indices of x, y and z)."""
    return spec.msgtype != FLOAT64_ARRAY or len(spec.indices) == 3


def decode_imu_vectors(spec: InputSpec, arrays: TopicArrays) -> InputSeries:
    """Decode the IMU topic's messages to the sensor-frame vectors.

    Args:
        spec: the mapping's ``imu`` input (its mounting is not applied; its unit, scale and
            sign are, to the specific force).
        arrays: the topic's raw messages, of type ``spec.msgtype``.

    Returns:
        values of shape (N, 6): the specific force (x, y, z) [m/s^2] and the angular rate
        (x, y, z) [rad/s] in the sensor's frame, the rate nan where the type has none or the
        Imu marks it unknown (REP 145: ``angular_velocity_covariance[0]`` = -1); stamps as
        the replay takes them (header stamps; log times for a Float64MultiArray).

    Raises:
        MappingError: a Float64MultiArray with one element (already the forward specific
            force: it has no axes to learn), or an index beyond the message.
        BagFormatError: a message cannot be decoded.
    """
    if not has_three_axes(spec):
        raise MappingError(
            f'{spec.name}: one element of {spec.topic} is already the forward specific force; '
            'its mounting needs the 3 axes (indices of x, y, z)'
        )
    n = len(arrays.datas)
    stamps = np.empty(n, dtype=np.int64)
    values = np.full((n, 6), math.nan)
    frames: list[bytes] = []
    for k, data in enumerate(arrays.datas):
        msg = deserialize(data, spec.msgtype)
        if spec.msgtype == FLOAT64_ARRAY:
            if max(spec.indices) >= len(msg.data):
                raise MappingError(
                    f'{spec.name}.indices: element {max(spec.indices)} is beyond the '
                    f'{len(msg.data)} values of the messages on {spec.topic}'
                )
            stamps[k] = int(arrays.log_time_ns[k])
            values[k, :3] = [float(msg.data[i]) for i in spec.indices]
            frames.append(b'')
            continue
        stamp = msg.header.stamp
        stamps[k] = int(stamp.sec) * _NS + int(stamp.nanosec)
        frames.append(msg.header.frame_id.encode())
        a = msg.accel.linear if spec.msgtype == ACCEL_STAMPED else msg.linear_acceleration
        values[k, :3] = (float(a.x), float(a.y), float(a.z))
        if spec.msgtype == IMU_TYPE and msg.angular_velocity_covariance[0] != -1.0:
            w = msg.angular_velocity
            values[k, 3:] = (float(w.x), float(w.y), float(w.z))
    values[:, :3] *= spec.factor * spec.sign[0]
    return InputSeries(stamps, values, np.array(frames, dtype=np.bytes_).reshape(n))
