"""Driving scenarios: piecewise-constant driver and road inputs over time, sensor settings.

A scenario file (``config/scenarios/*.yaml``)::

    name: paper_table1
    duration: 150.0              # [s]
    initial_gear: 1              # optional, default 1
    initial_speed: 0.0           # optional [m/s]: start rolling freely at this speed
    neutral: false               # optional: clutch held open all run (coast-down test)
    hold_brake: true             # optional: automatic brake hold at standstill, throttle 0
    signals:                     # each a list of [t_start, value], first t_start = 0
      throttle: [[0, 0.0], [8, 1.0], [100, 0.0]]   # [0..1]
      brake: [[0, 0.0]]                             # [0..1] pedal
      slope_deg: [[0, 0], [10, 5]]                  # [deg] positive uphill (or slope: [rad])
      road_mu: [[0, 1.0]]                           # [-] road friction scale
    sensors:                     # optional, defaults shown
      rate_hz: 1000.0
      seed: 0
      encoder_counts_per_rev: 0  # 0 = ideal wheel angle, N > 0 = quantised encoder
      speed_noise_std: 0.0       # [m/s] Gaussian noise on the body speed, 0 = ideal
      torque_noise_std: 0.0      # [N m] Gaussian noise on the wheel torques, 0 = ideal
      imu: false                 # publish an IMU (specific force, /vd/sensors/imu)
      imu_noise_std: 0.0         # [m/s^2] Gaussian noise on each specific-force axis
      imu_bias: 0.0              # [m/s^2] constant bias of the longitudinal axis
      imu_mount_pitch_deg: 0.0   # [deg] IMU's pitch on the body (about y, REP 103: + nose down)
      imu_gyro_noise_std: 0.0    # [rad/s] Gaussian noise on the IMU's pitch rate
      imu_gyro_bias: 0.0         # [rad/s] constant bias of the IMU's pitch rate
    true_vehicle:                # optional: the car driven is not the vehicle file
      extra_mass_kg: 0.0         # [kg] load added to the body (negative: removed)
      cg_shift_m: 0.1            # [m] rearward CG shift it causes, or instead:
      load_position_m: 1.6       # [m] load behind the front axle (default 1.6)
      load_height_m: 0.55        # [m] load height (default the CG height)
      tyre_radius_scale: 1.0     # [-] R_eff factor (worn tyre 0.97)
      engine_torque_offset_nm: 0.0  # [N m] offset of the torque SIGNALS, not the physics

The simulator drives the true vehicle (``vd_sim_node.vehicle.variants``) while the
estimators keep reading the vehicle file.

Each signal is right-continuous: the value given at ``t_start`` holds from ``t_start``
(inclusive) to the next breakpoint. Missing signals default to throttle 0, brake 0, slope 0,
road_mu 1.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from vd_common.yaml_reader import MappingReader, load_yaml_mapping

from vd_sim_node.errors import ScenarioError

__all__ = [
    'PiecewiseConstant',
    'Scenario',
    'SensorSettings',
    'VehicleVariant',
    'load_scenario',
    'parse_scenario',
]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class PiecewiseConstant:
    """A right-continuous piecewise-constant signal of time.

    Attributes:
        times: breakpoints, shape (k,), [s], strictly increasing, ``times[0] == 0``.
        values: value from each breakpoint on, shape (k,).
    """

    times: tuple[float, ...]
    values: tuple[float, ...]

    def __post_init__(self) -> None:
        """Check the breakpoints."""
        if len(self.times) != len(self.values) or not self.times:
            raise ScenarioError('a signal needs as many values as breakpoints, at least one')
        if self.times[0] != 0.0:
            raise ScenarioError(f'a signal must start at t = 0, got {self.times[0]}')
        if any(b <= a for a, b in zip(self.times, self.times[1:], strict=False)):
            raise ScenarioError(f'signal breakpoints must increase strictly: {self.times}')

    @classmethod
    def constant(cls, value: float) -> PiecewiseConstant:
        """A signal that keeps ``value`` for all time."""
        return cls((0.0,), (float(value),))

    def at(self, t: float) -> float:
        """Value at time ``t`` [s] (the first value before 0)."""
        i = int(np.searchsorted(self.times, t, side='right')) - 1
        return self.values[max(i, 0)]

    def sample(self, t: FloatArray) -> FloatArray:
        """Values at times ``t``, any shape, [s]."""
        idx = np.clip(np.searchsorted(self.times, t, side='right') - 1, 0, None)
        out: FloatArray = np.asarray(self.values, dtype=float)[idx]
        return out


@dataclass(frozen=True)
class SensorSettings:
    """What the simulated sensors deliver.

    Attributes:
        rate_hz: sample rate of all sensors, [Hz].
        seed: seed of the noise generator.
        encoder_counts_per_rev: 0 for the exact wheel angle, N > 0 for a quantised encoder.
        speed_noise_std: standard deviation of the body-speed noise, [m/s].
        torque_noise_std: standard deviation of the wheel-torque noise, [N m].
        imu: the car carries an IMU (its specific force is published, at ``rate_hz``).
        imu_noise_std: standard deviation of the noise on each specific-force axis, [m/s^2].
        imu_bias: constant bias of the longitudinal specific force, [m/s^2].
        imu_mount_pitch: pitch of the IMU's frame in the body frame, about the body's y axis
            (REP 103: positive nose down, as an input mapping's ``mount_rpy_deg``), [rad].
        imu_gyro_noise_std: standard deviation of the noise on the IMU's pitch rate (its y
            axis), [rad/s].
        imu_gyro_bias: constant bias of the IMU's pitch rate, [rad/s].
    """

    rate_hz: float = 1000.0
    seed: int = 0
    encoder_counts_per_rev: int = 0
    speed_noise_std: float = 0.0
    torque_noise_std: float = 0.0
    imu: bool = False
    imu_noise_std: float = 0.0
    imu_bias: float = 0.0
    imu_mount_pitch: float = 0.0
    imu_gyro_noise_std: float = 0.0
    imu_gyro_bias: float = 0.0


@dataclass(frozen=True)
class VehicleVariant:
    """How the car driven differs from the vehicle file (see ``vd_sim_node.vehicle.variants``).

    Attributes:
        extra_mass_kg: point load added to the body, [kg]; negative removes mass.
        cg_shift_m: rearward whole-vehicle CG shift the load causes, [m]; None: the load
            sits at ``load_position_m``.
        load_position_m: load position behind the front axle, [m]; None: the default 1.6 m.
        load_height_m: load height above ground, [m]; None: the CG height.
        tyre_radius_scale: factor on the effective rolling radius, [-].
        engine_torque_offset_nm: offset of the engine torque signal, [N m], passed to the
            driven wheels' torque signals through the engaged gear (the physics unchanged).
    """

    extra_mass_kg: float = 0.0
    cg_shift_m: float | None = None
    load_position_m: float | None = None
    load_height_m: float | None = None
    tyre_radius_scale: float = 1.0
    engine_torque_offset_nm: float = 0.0

    @property
    def changes_physics(self) -> bool:
        """True if the bond graph differs from the vehicle file's."""
        return self.extra_mass_kg != 0.0 or self.tyre_radius_scale != 1.0


@dataclass(frozen=True)
class Scenario:
    """Inputs of one simulation run.

    Attributes:
        name: scenario name.
        duration: simulated time, [s].
        throttle: accelerator position, [0..1].
        brake: brake pedal, [0..1] (fraction of the per-wheel brake capacity).
        slope: road slope alpha, [rad], positive uphill.
        road_mu: road friction scale, [-] (1 = dry asphalt, the tyre's own peak).
        initial_gear: gear at t = 0.
        initial_speed: speed at t = 0, [m/s]; wheels roll freely, engine follows the gear.
        neutral: hold the clutch open for the whole run (no drive, no engine braking).
        hold_brake: apply the hold brake automatically at standstill with throttle 0.
        sensors: sensor settings.
        description: free text.
        true_vehicle: how the car driven differs from the vehicle file (default: not).
    """

    name: str
    duration: float
    throttle: PiecewiseConstant = field(default_factory=lambda: PiecewiseConstant.constant(0))
    brake: PiecewiseConstant = field(default_factory=lambda: PiecewiseConstant.constant(0))
    slope: PiecewiseConstant = field(default_factory=lambda: PiecewiseConstant.constant(0))
    road_mu: PiecewiseConstant = field(default_factory=lambda: PiecewiseConstant.constant(1))
    initial_gear: int = 1
    initial_speed: float = 0.0
    neutral: bool = False
    hold_brake: bool = True
    sensors: SensorSettings = field(default_factory=SensorSettings)
    description: str = ''
    true_vehicle: VehicleVariant = field(default_factory=VehicleVariant)

    def breakpoints(self) -> tuple[float, ...]:
        """All input discontinuities inside (0, duration), sorted, [s]."""
        ts: set[float] = set()
        for sig in (self.throttle, self.brake, self.slope, self.road_mu):
            ts.update(t for t in sig.times if 0.0 < t < self.duration)
        return tuple(sorted(ts))


def _signal(
    r: MappingReader, key: str, default: float, lo: float, hi: float, scale: float = 1.0
) -> PiecewiseConstant:
    if not r.has(key):
        return PiecewiseConstant.constant(default)
    raw: Any = r.raw(key)
    name = f'signals.{key}'
    if not isinstance(raw, list) or not raw:
        raise ScenarioError(f'{name} must be a non-empty list of [t_start, value] pairs')
    times: list[float] = []
    values: list[float] = []
    for i, pair in enumerate(raw):
        if (
            not isinstance(pair, list)
            or len(pair) != 2
            or any(isinstance(x, bool) or not isinstance(x, int | float) for x in pair)
        ):
            raise ScenarioError(f'{name}[{i}] must be a [t_start, value] pair, got {pair!r}')
        t, v = float(pair[0]), float(pair[1])
        if not (math.isfinite(t) and math.isfinite(v)):
            raise ScenarioError(f'{name}[{i}] must be finite, got {pair!r}')
        if not lo <= v <= hi:
            raise ScenarioError(f'{name}[{i}] value must be in [{lo:g}, {hi:g}], got {v:g}')
        times.append(t)
        values.append(v * scale)
    if times[0] != 0.0:
        raise ScenarioError(f'{name} must start at t = 0, got {times[0]:g}')
    for i in range(1, len(times)):
        if times[i] <= times[i - 1]:
            raise ScenarioError(f'{name}: breakpoint times must increase strictly: {times}')
    return PiecewiseConstant(tuple(times), tuple(values))


def parse_scenario(data: object, default_name: str = 'scenario') -> Scenario:
    """Build a :class:`Scenario` from a parsed YAML document.

    Args:
        data: the top-level mapping.
        default_name: name used when the document has none.

    Returns:
        The validated scenario.

    Raises:
        ScenarioError: naming the first missing or invalid entry.
    """
    r = MappingReader(data, '', ScenarioError)
    duration = r.number('duration', 's', gt=0.0)
    sig = r.optional_section('signals') or MappingReader({}, 'signals', ScenarioError)
    if sig.has('slope') and sig.has('slope_deg'):
        raise ScenarioError('signals: give either slope [rad] or slope_deg [deg], not both')
    if sig.has('slope_deg'):
        slope = _signal(sig, 'slope_deg', 0.0, -45.0, 45.0, math.pi / 180.0)
    else:
        slope = _signal(sig, 'slope', 0.0, -math.pi / 4, math.pi / 4)
    sens = r.optional_section('sensors') or MappingReader({}, 'sensors', ScenarioError)
    sensors = SensorSettings(
        rate_hz=sens.number('rate_hz', 'Hz', gt=0.0, default=1000.0),
        seed=sens.integer('seed', ge=0, default=0),
        encoder_counts_per_rev=sens.integer('encoder_counts_per_rev', ge=0, default=0),
        speed_noise_std=sens.number('speed_noise_std', 'm/s', ge=0.0, default=0.0),
        torque_noise_std=sens.number('torque_noise_std', 'N m', ge=0.0, default=0.0),
        imu=sens.boolean('imu', default=False),
        imu_noise_std=sens.number('imu_noise_std', 'm/s^2', ge=0.0, default=0.0),
        imu_bias=sens.number('imu_bias', 'm/s^2', ge=-5.0, le=5.0, default=0.0),
        imu_mount_pitch=math.radians(
            sens.number('imu_mount_pitch_deg', 'deg', ge=-30.0, le=30.0, default=0.0)
        ),
        imu_gyro_noise_std=sens.number('imu_gyro_noise_std', 'rad/s', ge=0.0, default=0.0),
        imu_gyro_bias=sens.number('imu_gyro_bias', 'rad/s', ge=-1.0, le=1.0, default=0.0),
    )
    truth = r.optional_section('true_vehicle')
    true_vehicle = VehicleVariant() if truth is None else _variant(truth)
    return Scenario(
        name=r.string('name', default=default_name),
        duration=duration,
        throttle=_signal(sig, 'throttle', 0.0, 0.0, 1.0),
        brake=_signal(sig, 'brake', 0.0, 0.0, 1.0),
        slope=slope,
        road_mu=_signal(sig, 'road_mu', 1.0, 0.0, 2.0),
        initial_gear=r.integer('initial_gear', ge=1, default=1),
        initial_speed=r.number('initial_speed', 'm/s', ge=0.0, le=100.0, default=0.0),
        neutral=r.boolean('neutral', default=False),
        hold_brake=r.boolean('hold_brake', default=True),
        sensors=sensors,
        description=r.string('description', default=''),
        true_vehicle=true_vehicle,
    )


def _variant(r: MappingReader) -> VehicleVariant:
    def optional(key: str, unit: str, **bounds: float) -> float | None:
        return r.number(key, unit, **bounds) if r.has(key) else None

    if r.has('cg_shift_m') and r.has('load_position_m'):
        raise ScenarioError('true_vehicle: give cg_shift_m or load_position_m, not both')
    extra = r.number('extra_mass_kg', 'kg', ge=-500.0, le=2000.0, default=0.0)
    shift = optional('cg_shift_m', 'm', ge=-1.0, le=1.0)
    if shift and extra == 0.0:
        raise ScenarioError('true_vehicle.cg_shift_m needs a non-zero extra_mass_kg')
    return VehicleVariant(
        extra_mass_kg=extra,
        cg_shift_m=shift,
        load_position_m=optional('load_position_m', 'm', ge=-2.0, le=6.0),
        load_height_m=optional('load_height_m', 'm', gt=0.0, le=3.0),
        tyre_radius_scale=r.number('tyre_radius_scale', '', gt=0.5, lt=1.5, default=1.0),
        engine_torque_offset_nm=r.number(
            'engine_torque_offset_nm', 'N m', ge=-500.0, le=500.0, default=0.0
        ),
    )


def load_scenario(path: str | Path) -> Scenario:
    """Load and validate a scenario file.

    Args:
        path: YAML file, e.g. ``src/vd_sim_node/config/scenarios/paper_table1.yaml``.

    Returns:
        The validated scenario.

    Raises:
        ScenarioError: the file cannot be read or an entry is missing/invalid.
    """
    return parse_scenario(load_yaml_mapping(path, ScenarioError), Path(path).stem)
