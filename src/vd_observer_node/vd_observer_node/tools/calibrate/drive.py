"""A drive as the calibration reads it: every signal on one time grid, averaged over a window.

The fits compare signals of different sensors (wheel encoders, engine speed, a GNSS or truth
speed) that are stamped at different rates and quantised differently. Each signal is
therefore taken as its **mean over the same centred window** (``WINDOW_S``) on one grid: a
rate from the difference of its integral (a wheel angle is already one) and a derivative
from the difference of the signal at the window's ends. Every relation the fits use is
linear in these signals (``v = r omega``, ``engine = k omega``, the force balance up to its
speed-squared and grade terms), so a common boxcar keeps it exact while it averages the
encoder quantisation (96 counts/rev: 0.13 rad/s over 0.5 s) and the speed noise out.

What the bag has decides what is read: the wheels and the speed reference always; the
measured wheel torques, the engine input (torque, gear, engine and turbine speed), the
brake and the IMU's three axes (its mounting) where the mapping names them and the bag has
their topic.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt
from vd_common.topics import TRUTH, TRUTH_BODY_VELOCITY, TRUTH_SLOPE

from vd_observer_node.bag.cdr_batch import decode_batch
from vd_observer_node.bag.reader import BagReader, TopicArrays
from vd_observer_node.bag.typestore import deserialize
from vd_observer_node.inputs.decode import (
    decode_brake,
    decode_engine,
    decode_imu_vectors,
    decode_input,
)
from vd_observer_node.inputs.mapping import (
    GRADE_INPUT,
    NAVSATFIX,
    SLOPE_TYPE,
    InputMapping,
    InputSpec,
    default_mapping,
)
from vd_observer_node.tools.calibrate.errors import CalibrationError

__all__ = [
    'GRADE_WINDOW_M',
    'GRID_HZ',
    'WINDOW_S',
    'CalibrationDrive',
    'altitude_grade',
    'read_drive',
]

FloatArray = npt.NDArray[np.float64]

#: Width of the centred averaging window [s]: long against the encoder quantisation and
#: the reference's noise, short against a gear's duration and a brake application.
WINDOW_S = 0.5
#: Rate of the common grid [Hz]: ten samples per window are plenty for fits whose samples
#: are correlated over the window anyway.
GRID_HZ = 20.0
#: A measured wheel torque below this [N m] is a brake acting (the measured path's braking).
_BRAKE_TORQUE_NM = -20.0
#: Path length over which a GNSS altitude is differenced to a grade [m]: a fix's altitude is
#: good to a metre or so, 40 m makes that ~1.4 deg at worst and averages over ~4 s at 36 km/h.
GRADE_WINDOW_M = 40.0
#: Shortest drive worth calibrating on [s].
MIN_DURATION_S = 10.0
_NS = 1e-9


@dataclass(frozen=True)
class CalibrationDrive:
    """One drive's signals on a common grid, each the mean over a centred ``WINDOW_S`` window.

    Attributes:
        source: the bag it was read from (named in the report).
        t: shape (N,), [s] since the first wheel stamp.
        wheel_radps: shape (N, 4), [rad/s], FL, FR, RL, RR.
        wheel_accel_radps2: shape (N, 4), [rad/s^2].
        circumferential: the wheel speeds were logged as a circumferential speed (m/s,
            km/h) and divided by the base file's radius: the radius is then not determined.
        speed_mps: shape (N,), [m/s], the reference's longitudinal speed.
        accel_mps2: shape (N,), [m/s^2], its derivative.
        grade_rad: shape (N,), [rad] positive uphill, nan where the reference is invalid;
            None without a grade reference.
        wheel_torque_nm: shape (N, 4), [N m], measured drive minus brake torque; None where
            the bag has no measured torques.
        engine_torque_nm: shape (N,), [N m]; None without the engine input.
        engine_radps: shape (N,), [rad/s]; None without the engine input.
        engine_accel_radps2: shape (N,), [rad/s^2]; None without the engine input.
        turbine_radps: shape (N,), [rad/s]; None where the turbine speed is not logged.
        gear: shape (N,), int, the gear as the bus logs it (the mapping's ``gear_offset``
            taken off again: the calibration fits the offset), 0 in neutral, -1 where it
            changes within the window; None without the engine input.
        mapped_gear_offset: the mapping's ``engine_torque.gear_offset`` (0 without one).
        braking: shape (N,), bool: the brake input on, or a measured wheel torque below
            -20 N m, somewhere in the window.
        brake_bar: shape (N, 4), the brake pressure per wheel (the mapping's unit, bar by
            default); None without a pressure input.
        has_brake_input: the mapping has a brake input and the bag its topic.
        engine_path: the mapping's torque source is the engine (no measured torques).
        grade_source: where the grade comes from, for the file's comments.
        imu_force_mps2: shape (N, 3), [m/s^2], the IMU's specific force in its own frame (no
            mounting applied); None where the mapping has no IMU with three axes or the bag
            not its topic.
        imu_mapped_axes: the rows of the mapping's IMU mounting it uses (the body's forward
            axis in the sensor's frame, and for an Imu the lateral one its pitch rate is read
            about; () without an IMU).
    """

    source: str
    t: FloatArray
    wheel_radps: FloatArray
    wheel_accel_radps2: FloatArray
    circumferential: bool
    speed_mps: FloatArray
    accel_mps2: FloatArray
    grade_rad: FloatArray | None
    wheel_torque_nm: FloatArray | None
    engine_torque_nm: FloatArray | None
    engine_radps: FloatArray | None
    engine_accel_radps2: FloatArray | None
    turbine_radps: FloatArray | None
    gear: npt.NDArray[np.int64] | None
    mapped_gear_offset: int
    braking: npt.NDArray[np.bool_]
    brake_bar: FloatArray | None
    has_brake_input: bool
    engine_path: bool
    grade_source: str = 'the reference'
    imu_force_mps2: FloatArray | None = None
    imu_mapped_axes: tuple[tuple[float, ...], ...] = ()

    @property
    def duration_s(self) -> float:
        """Length of the grid [s]."""
        return float(self.t[-1] - self.t[0]) if self.t.size else 0.0


class _Windows:
    """Window means of stamped series on one grid of centres ``t``."""

    def __init__(self, t: FloatArray, window: float) -> None:
        self.lo = t - 0.5 * window
        self.hi = t + 0.5 * window
        self.window = window

    def mean(self, stamps: FloatArray, values: FloatArray) -> FloatArray:
        """Mean of each column of ``values`` (shape (M,) or (M, K)) over each window: the
        difference of its trapezoidal integral; nan where a sample in the window is nan."""
        y = values.reshape(len(stamps), -1)
        bad = ~np.isfinite(y)
        y = np.where(bad, 0.0, y)
        area = np.concatenate(
            [
                np.zeros((1, y.shape[1])),
                np.cumsum(0.5 * (y[1:] + y[:-1]) * np.diff(stamps)[:, None], axis=0),
            ]
        )
        out = np.column_stack(
            [
                (np.interp(self.hi, stamps, a) - np.interp(self.lo, stamps, a)) / self.window
                for a in area.T
            ]
        )
        out[self.count(stamps, bad.any(axis=1)) > 0] = np.nan
        return out.reshape((-1, *values.shape[1:]))

    def rate(self, stamps: FloatArray, values: FloatArray) -> FloatArray:
        """Mean derivative of each column over each window: the difference of its ends."""
        y = values.reshape(len(stamps), -1)
        out = np.column_stack(
            [
                (np.interp(self.hi, stamps, c) - np.interp(self.lo, stamps, c)) / self.window
                for c in y.T
            ]
        )
        return out.reshape((-1, *values.shape[1:]))

    def count(self, stamps: FloatArray, flags: npt.ArrayLike) -> npt.NDArray[np.int64]:
        """How many flagged samples fall in each window."""
        cum = np.concatenate([[0], np.cumsum(np.asarray(flags, dtype=np.int64))])
        first = np.searchsorted(stamps, self.lo, side='left')
        last = np.searchsorted(stamps, self.hi, side='right')
        return np.asarray(cum[last] - cum[first], dtype=np.int64)


def _sorted(
    stamp_ns: npt.NDArray[np.int64], values: FloatArray, t0: int
) -> tuple[FloatArray, FloatArray]:
    order = np.argsort(stamp_ns, kind='stable')
    stamps = (stamp_ns[order] - t0) * _NS
    keep = np.concatenate([[True], np.diff(stamps) > 0.0])  # interp needs rising stamps
    return stamps[keep], values[order][keep]


def _truth_spec(name: str, topic: str) -> InputSpec:
    return InputSpec(name=name, topic=topic, msgtype=TRUTH[topic], sign=(1.0,))


def _grade(spec: InputSpec, arrays: TopicArrays) -> tuple[npt.NDArray[np.int64], FloatArray]:
    """The reference grade [rad], nan where a Slope message says it is not valid."""
    if spec.msgtype != SLOPE_TYPE:
        series = decode_input(spec, arrays)
        return series.stamp_ns, series.values[:, 0]
    fields = decode_batch(arrays.decode_as or spec.msgtype, arrays.datas)
    angle = fields.values['angle'].astype(np.float64) * spec.factor
    return fields.stamp_ns.astype(np.int64), np.where(fields.values['valid'], angle, np.nan)


def _altitude(arrays: TopicArrays) -> tuple[npt.NDArray[np.int64], FloatArray]:
    """NavSatFix altitudes [m] and their header stamps; nan where the receiver has no fix."""
    stamps, heights = [], []
    for data in arrays.datas:
        msg = deserialize(bytes(data), NAVSATFIX)
        stamps.append(int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec))
        heights.append(float(msg.altitude) if int(msg.status.status) >= 0 else math.nan)
    return np.asarray(stamps, dtype=np.int64), np.asarray(heights, dtype=np.float64)


def altitude_grade(
    t: FloatArray,
    altitude_t: FloatArray,
    altitude_m: FloatArray,
    speed_t: FloatArray,
    speed_mps: FloatArray,
) -> FloatArray:
    """The grade [rad] at ``t`` from altitudes along the path the reference speed travels.

    ``sin(alpha) = (h(s + L/2) - h(s - L/2)) / L`` with ``s`` the distance (the speed's
    integral) and ``L`` = ``GRADE_WINDOW_M``: a window in distance, so a stop does not
    difference one altitude with itself. nan where the window leaves the fixes.
    """
    distance = np.concatenate(
        [[0.0], np.cumsum(0.5 * (speed_mps[1:] + speed_mps[:-1]) * np.diff(speed_t))]
    )
    ok = np.isfinite(altitude_m)
    along = np.interp(altitude_t[ok], speed_t, distance)
    heights = altitude_m[ok]
    rising = np.concatenate([[True], np.diff(along) > 0.0]) if along.size else along.astype(bool)
    along, heights = along[rising], heights[rising]
    if along.size < 2:
        return np.full(t.shape, np.nan)
    centre = np.interp(t, speed_t, distance)
    lo, hi = centre - 0.5 * GRADE_WINDOW_M, centre + 0.5 * GRADE_WINDOW_M
    rise = np.interp(hi, along, heights) - np.interp(lo, along, heights)
    inside = (lo >= along[0]) & (hi <= along[-1])
    return np.where(inside, np.arcsin(np.clip(rise / GRADE_WINDOW_M, -1.0, 1.0)), np.nan)


def _references(
    mapping: InputMapping, topics: Mapping[str, object]
) -> tuple[InputSpec, InputSpec | None]:
    """The speed and grade references: the mapping's ``reference`` where it names one, else
    the bag's truth topics.

    Raises:
        CalibrationError: no speed reference at all.
    """
    given = mapping.reference
    speed = given.speed if given is not None else None
    grade = given.grade if given is not None else None
    if speed is None and TRUTH_BODY_VELOCITY in topics:
        speed = _truth_spec('body_speed', TRUTH_BODY_VELOCITY)
    if grade is None and TRUTH_SLOPE in topics:
        grade = _truth_spec(GRADE_INPUT, TRUTH_SLOPE)
    if speed is None:
        raise CalibrationError(
            f'no speed reference: the bag has no {TRUTH_BODY_VELOCITY} and the mapping no '
            'reference.speed (a GNSS or pose speed; docs/calibrate.md)'
        )
    for spec in (speed, grade):
        if spec is not None and spec.topic not in topics:
            raise CalibrationError(f'reference {spec.name}: the bag has no topic {spec.topic}')
    return speed, grade


def read_drive(
    bag: str | os.PathLike[str],
    mapping: InputMapping | None,
    base_radius_m: float,
    level_road: bool = False,
) -> CalibrationDrive:
    """Read one bag into a :class:`CalibrationDrive`.

    Args:
        bag: the bag folder or .mcap file.
        mapping: the input mapping (None: vd's own topics).
        base_radius_m: the base file's effective rolling radius [m]: divides wheel speeds
            logged as a circumferential speed.
        level_road: the drive is on level road (a test track's coast-downs): the grade is
            0 throughout; refused where the bag or mapping has a grade reference.

    Returns:
        The drive on a ``GRID_HZ`` grid over the span every read signal covers.

    Raises:
        CalibrationError: no speed reference, no wheel topic, a drive shorter than 10 s, or
            ``level_road`` with a grade reference.
        MappingError, BagFormatError: as the replay raises them.
    """
    mapping = mapping or default_mapping()
    reader = BagReader(bag)
    topics = reader.topics
    speed_spec, grade_spec = _references(mapping, topics)
    if level_road and grade_spec is not None:
        raise CalibrationError(
            f'--level-road: the drive has a grade reference ({grade_spec.topic}); it is for '
            'drives without one'
        )
    if mapping.wheels.topic not in topics:
        raise CalibrationError(
            f'{mapping.wheels.name}: the bag has no topic {mapping.wheels.topic}'
        )
    measured = mapping.torque_source == 'measured' and mapping.wheel_torques.topic in topics
    engine_spec = mapping.engine if mapping.engine.topic in topics else None
    brake_spec = (
        mapping.brake if mapping.brake is not None and mapping.brake.topic in topics else None
    )
    imu_spec = mapping.imu
    if imu_spec is not None and (imu_spec.topic not in topics or not imu_spec.three_axes):
        imu_spec = None
    wanted = [mapping.wheels, speed_spec, grade_spec, engine_spec, brake_spec, imu_spec]
    if measured:
        wanted.append(mapping.wheel_torques)
    arrays = reader.topic_arrays({s.topic for s in wanted if s is not None})
    wheels = decode_input(mapping.wheels, arrays[mapping.wheels.topic], radius=base_radius_m)
    if wheels.stamp_ns.size < 2:
        raise CalibrationError(f'{mapping.wheels.topic}: fewer than 2 messages')
    t0 = int(wheels.stamp_ns.min())
    wheel_t, wheel_v = _sorted(wheels.stamp_ns, wheels.values, t0)
    speed = decode_input(speed_spec, arrays[speed_spec.topic])
    speed_t, speed_v = _sorted(speed.stamp_ns, speed.values[:, 0], t0)
    spans = [(wheel_t[0], wheel_t[-1]), (speed_t[0], speed_t[-1])]
    grade_t = grade_v = None
    if grade_spec is not None:
        raw = arrays[grade_spec.topic]
        found = _altitude(raw) if grade_spec.msgtype == NAVSATFIX else _grade(grade_spec, raw)
        grade_t, grade_v = _sorted(*found, t0)
        spans.append((grade_t[0], grade_t[-1]))
    start = max(s for s, _ in spans) + 0.5 * WINDOW_S
    stop = min(e for _, e in spans) - 0.5 * WINDOW_S
    if stop - start < MIN_DURATION_S:
        raise CalibrationError(
            f'{bag}: {max(stop - start, 0.0):.1f} s of drive with every signal, need '
            f'{MIN_DURATION_S:.0f} s'
        )
    t = np.arange(start, stop, 1.0 / GRID_HZ)
    w = _Windows(t, WINDOW_S)
    angles = mapping.wheel_input == 'angle'
    omega = w.rate(wheel_t, wheel_v) if angles else w.mean(wheel_t, wheel_v)
    # the mean wheel acceleration: the windowed speed's own window rate
    omega_dot = w.rate(t, omega)
    torque = None
    braking = np.zeros(t.shape, dtype=bool)
    brake_bar = None
    if measured:
        series = decode_input(mapping.wheel_torques, arrays[mapping.wheel_torques.topic])
        torque_t, torque_v = _sorted(series.stamp_ns, series.values, t0)
        torque = w.mean(torque_t, torque_v)
        braking |= w.count(torque_t, (torque_v < _BRAKE_TORQUE_NM).any(axis=1)) > 0
    if brake_spec is not None:
        series = decode_brake(brake_spec, arrays[brake_spec.topic])
        brake_t, brake_v = _sorted(series.stamp_ns, series.values, t0)
        braking |= w.count(brake_t, (brake_v > 0.0).any(axis=1)) > 0
        if brake_spec.signal == 'pressure':
            brake_bar = w.mean(brake_t, brake_v)
    engine = _engine(engine_spec, arrays, w, t0) if engine_spec is not None else None
    imu_force = None
    if imu_spec is not None:
        vectors = decode_imu_vectors(imu_spec, arrays[imu_spec.topic])
        imu_t, imu_v = _sorted(vectors.stamp_ns, vectors.values[:, :3], t0)
        imu_force = w.mean(imu_t, imu_v)
        imu_force[(w.lo < imu_t[0]) | (w.hi > imu_t[-1])] = np.nan  # beyond the IMU's span
    return CalibrationDrive(
        source=str(bag),
        t=t,
        wheel_radps=omega,
        wheel_accel_radps2=omega_dot,
        circumferential=mapping.wheels.per_radius,
        speed_mps=w.mean(speed_t, speed_v),
        accel_mps2=w.rate(speed_t, speed_v),
        grade_rad=np.zeros(t.shape)
        if level_road
        else _grade_on(w, grade_spec, grade_t, grade_v, speed_t, speed_v),
        wheel_torque_nm=torque,
        engine_torque_nm=None if engine is None else engine[0],
        engine_radps=None if engine is None else engine[1],
        engine_accel_radps2=None if engine is None else engine[2],
        turbine_radps=None if engine is None else engine[3],
        gear=None if engine is None else engine[4],
        mapped_gear_offset=0 if engine_spec is None else engine_spec.gear_offset,
        braking=braking,
        brake_bar=brake_bar,
        has_brake_input=brake_spec is not None,
        engine_path=mapping.torque_source == 'engine',
        grade_source='level road (--level-road)' if level_road else 'the reference',
        imu_force_mps2=imu_force,
        imu_mapped_axes=()
        if imu_spec is None
        else tuple(a for a in (imu_spec.axis, imu_spec.pitch_axis) if a),
    )


def _grade_on(
    w: _Windows,
    spec: InputSpec | None,
    stamps: FloatArray | None,
    values: FloatArray | None,
    speed_t: FloatArray,
    speed_v: FloatArray,
) -> FloatArray | None:
    """The grade on the grid: a reference grade's window mean, or a NavSatFix altitude's
    difference over distance."""
    if spec is None or stamps is None or values is None:
        return None
    if spec.msgtype == NAVSATFIX:
        return altitude_grade(w.lo + 0.5 * w.window, stamps, values, speed_t, speed_v)
    return w.mean(stamps, values)


def _engine(
    spec: InputSpec, arrays: Mapping[str, TopicArrays], w: _Windows, t0: int
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray | None, npt.NDArray[np.int64]]:
    """Engine torque, engine speed and acceleration, turbine speed (None if not logged) and
    the logged gear (-1 where it changes within the window)."""
    series = decode_engine(spec, arrays[spec.topic])
    t, v = _sorted(series.stamp_ns, series.values, t0)
    logged = v[:, 1] - spec.gear_offset
    shifts = np.concatenate([[False], np.diff(logged) != 0.0])
    gear = np.interp(w.lo + 0.5 * w.window, t, logged, left=0.0, right=0.0)
    gear = np.where(w.count(t, shifts) > 0, -1.0, np.rint(gear))
    turbine = v[:, 3]
    return (
        w.mean(t, v[:, 0]),
        w.mean(t, v[:, 2]),
        w.rate(t, v[:, 2]),
        w.mean(t, turbine) if np.isfinite(turbine).any() else None,
        gear.astype(np.int64),
    )


def concatenated(drives: Sequence[CalibrationDrive]) -> CalibrationDrive:
    """Several drives as one sample set (the fits do not care about time order)."""
    if len(drives) == 1:
        return drives[0]

    def cat(name: str) -> npt.NDArray[np.generic] | None:
        parts = [getattr(d, name) for d in drives]
        return None if any(p is None for p in parts) else np.concatenate(parts)

    first = drives[0]
    return CalibrationDrive(
        source=', '.join(Path(d.source).name for d in drives),
        t=np.concatenate([d.t for d in drives]),
        wheel_radps=np.concatenate([d.wheel_radps for d in drives]),
        wheel_accel_radps2=np.concatenate([d.wheel_accel_radps2 for d in drives]),
        circumferential=any(d.circumferential for d in drives),
        speed_mps=np.concatenate([d.speed_mps for d in drives]),
        accel_mps2=np.concatenate([d.accel_mps2 for d in drives]),
        grade_rad=cat('grade_rad'),  # type: ignore[arg-type]
        wheel_torque_nm=cat('wheel_torque_nm'),  # type: ignore[arg-type]
        engine_torque_nm=cat('engine_torque_nm'),  # type: ignore[arg-type]
        engine_radps=cat('engine_radps'),  # type: ignore[arg-type]
        engine_accel_radps2=cat('engine_accel_radps2'),  # type: ignore[arg-type]
        turbine_radps=cat('turbine_radps'),  # type: ignore[arg-type]
        gear=cat('gear'),  # type: ignore[arg-type]
        mapped_gear_offset=first.mapped_gear_offset,
        braking=np.concatenate([d.braking for d in drives]),
        brake_bar=cat('brake_bar'),  # type: ignore[arg-type]
        has_brake_input=all(d.has_brake_input for d in drives),
        engine_path=first.engine_path,
        grade_source=first.grade_source,
        imu_force_mps2=cat('imu_force_mps2'),  # type: ignore[arg-type]
        imu_mapped_axes=first.imu_mapped_axes,
    )
