"""Everyday drives: seeded scenarios nobody designed to excite an estimator.

`everyday_scenario(seed)` draws one drive on the simulator's scenario format
(:mod:`.scenario`): a sequence of driver actions of 3-12 s each (pedal steps to a partial
throttle, lifts, brakings of 0.1-0.45 pedal), hills (grades of -6..+6 deg held 10-40 s,
joined by ramps of 40-120 m), a start speed in the 10-130 km/h band, a true car that is not
the vehicle file (load -50..+400 kg at a random place between the axles, tyre radius
-3..+1 %) and sensors with encoder and speed noise and an IMU with a bias and a mounting
pitch nobody told the estimator about.

The driver keeps the speed in 10-130 km/h by a look-ahead on a point-mass model of the car
(drive force from a constant power, drag, rolling, grade): an action that would leave the
band is replaced by one that turns back. The model is rough on purpose; the simulator then
drives the real car with these inputs, so the speed leaves the band a little at times.

Everything is drawn from ``numpy.random.default_rng(seed)``: a seed is a drive.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from vd_common.vehicle.params import VehicleParams

from vd_sim_node.vehicle.scenario import (
    PiecewiseConstant,
    Scenario,
    SensorSettings,
    VehicleVariant,
)

__all__ = ['EverydaySettings', 'everyday_scenario', 'start_gear']

_KMH = 1.0 / 3.6
_RAMP_STEP = 0.25  # [s] step of the staircase that makes a grade ramp
_MARGIN = 3.0  # [m/s] the driver's margin above the band's low end (the model is rough)


@dataclass(frozen=True)
class EverydaySettings:
    """What the drives draw from.

    Attributes:
        duration: length of a drive, [s].
        rate_hz: sensor rate, [Hz].
        speed_band: (low, high) speed the driver keeps, [m/s].
        max_grade_deg: largest |grade|, [deg].
        extra_mass: (low, high) load added to the car, [kg].
        radius_scale: (low, high) factor on the tyre's rolling radius, [-].
        encoder_counts: wheel encoder counts per revolution.
        speed_noise: body-speed noise, [m/s].
        imu_noise: IMU noise per axis, [m/s^2].
        imu_bias: largest |bias| of the IMU's longitudinal axis, [m/s^2].
        imu_mount_deg: largest |mounting pitch| not told to the estimator, [deg].
        gyro_noise: noise of the IMU's pitch rate, [rad/s] (a consumer MEMS gyro's 0.01
            deg/s/sqrt(Hz) over 500 Hz is 0.004 rad/s).
        gyro_bias: largest |bias| of the IMU's pitch rate, [rad/s] (0.3 deg/s, uncalibrated).
    """

    duration: float = 120.0
    rate_hz: float = 1000.0
    speed_band: tuple[float, float] = (10.0 * _KMH, 130.0 * _KMH)
    max_grade_deg: float = 6.0
    extra_mass: tuple[float, float] = (-50.0, 400.0)
    radius_scale: tuple[float, float] = (0.97, 1.01)
    encoder_counts: int = 96
    speed_noise: float = 0.05
    imu_noise: float = 0.05
    imu_bias: float = 0.1
    imu_mount_deg: float = 1.0
    gyro_noise: float = 0.004
    gyro_bias: float = 0.005


def _grid(t: float) -> float:
    """``t`` [s] on a 10 ms grid: every breakpoint falls on a sample of 100 Hz and above (two
    signals' breakpoints never fall between the same two samples)."""
    return round(t * 100.0) / 100.0


def start_gear(params: VehicleParams, speed: float) -> int:
    """The highest gear whose engine speed at ``speed`` [m/s] is above 2000 rpm (1 at least)."""
    ratios = np.asarray(params.gearbox.ratios) * params.gearbox.final_drive
    wheel = speed / params.wheel.effective_radius
    engine_rpm = wheel * ratios * 60.0 / (2.0 * math.pi)
    fits = np.flatnonzero(engine_rpm >= 2000.0)
    return int(fits[-1]) + 1 if fits.size else 1


def _accel(params: VehicleParams, mass: float, v: float, throttle: float, brake: float,
           grade: float) -> float:  # fmt: skip
    """Rough point-mass acceleration [m/s^2] for the driver's look-ahead."""
    power = 45e3 * throttle  # [W] a small car's power, at any speed
    drive = min(power / max(v, 3.0), 3500.0 * throttle)
    braking = brake * 12000.0
    aero = params.aero
    resist = (
        0.5 * aero.air_density * aero.drag_coefficient * aero.frontal_area * v * v
        + mass * 9.81 * (0.012 + math.sin(grade))
        + braking
    )  # fmt: skip
    return (drive - resist) / mass


def everyday_scenario(
    seed: int, params: VehicleParams, settings: EverydaySettings | None = None
) -> Scenario:
    """One everyday drive (see the module docstring).

    Args:
        seed: the drive.
        params: the vehicle file (the driver's model and the start gear).
        settings: what the drive draws from (defaults if None).

    Returns:
        The scenario, named ``everyday_<seed>``, with its true car and sensors.
    """
    s = settings or EverydaySettings()
    rng = np.random.default_rng(seed)
    low, high = s.speed_band
    extra = float(rng.uniform(*s.extra_mass))
    radius = float(rng.uniform(*s.radius_scale))
    mass = params.chassis.mass + extra
    v = float(rng.uniform(low + 3.0, min(high - 5.0, 25.0)))
    v0 = v
    # hills: grades held 10-40 s, joined by ramps of 40-120 m (at the start speed; a
    # staircase of 0.25 s steps, as the scenario's signals are piecewise constant)
    grade_t = [0.0]
    grade_v = [math.radians(float(rng.uniform(-2.0, 2.0)))]
    t = 0.0
    while t < s.duration:
        t = _grid(t + float(rng.uniform(10.0, 40.0)))
        target = math.radians(float(rng.uniform(-s.max_grade_deg, s.max_grade_deg)))
        ramp = max(float(rng.uniform(40.0, 120.0)) / max(v, 5.0), 1.0)
        steps = max(int(ramp / _RAMP_STEP), 1)
        start = grade_v[-1]
        for k in range(1, steps + 1):
            grade_t.append(t + (k - 1) * _RAMP_STEP)
            grade_v.append(start + (target - start) * k / steps)
        t += steps * _RAMP_STEP
    keep = [k for k, when in enumerate(grade_t) if when < s.duration]
    grades = PiecewiseConstant(tuple(grade_t[k] for k in keep), tuple(grade_v[k] for k in keep))
    # the driver's actions, checked with the look-ahead
    times: list[float] = []
    throttle: list[float] = []
    brake: list[float] = []
    t = 0.0
    while t < s.duration:
        hold = _grid(float(rng.uniform(3.0, 12.0)))
        kind = rng.choice(['pedal', 'pedal', 'lift', 'brake'])
        th = float(rng.uniform(0.15, 0.7)) if kind == 'pedal' else 0.0
        br = float(rng.uniform(0.1, 0.45)) if kind == 'brake' else 0.0
        if kind == 'brake':
            hold = min(hold, _grid(float(rng.uniform(1.0, 3.0))))
        # look ahead; turn back where the band would be left
        end = _speed_after(params, mass, v, th, br, grades, t, hold)
        if end < low + _MARGIN:
            th, br = float(rng.uniform(0.6, 1.0)), 0.0
        elif end > high:
            th, br = 0.0, float(rng.uniform(0.1, 0.3))
            hold = min(hold, 3.0)
        v = _speed_after(params, mass, v, th, br, grades, t, hold)
        times.append(t)
        throttle.append(th)
        brake.append(br)
        t += hold
    imu_mount = math.radians(float(rng.uniform(-s.imu_mount_deg, s.imu_mount_deg)))
    sensors = SensorSettings(
        rate_hz=s.rate_hz,
        seed=seed,
        encoder_counts_per_rev=s.encoder_counts,
        speed_noise_std=s.speed_noise,
        imu=True,
        imu_noise_std=s.imu_noise,
        imu_bias=float(rng.uniform(-s.imu_bias, s.imu_bias)),
        imu_mount_pitch=imu_mount,
    )
    car = VehicleVariant(
        extra_mass_kg=extra,
        load_position_m=float(rng.uniform(0.3, 2.2)),
        tyre_radius_scale=radius,
    )
    # drawn last: the drives' other draws stay what they were before the gyro
    gyro_bias = float(rng.uniform(-s.gyro_bias, s.gyro_bias))
    sensors = replace(sensors, imu_gyro_noise_std=s.gyro_noise, imu_gyro_bias=gyro_bias)
    return Scenario(
        name=f'everyday_{seed}',
        duration=s.duration,
        throttle=PiecewiseConstant(tuple(times), tuple(throttle)),
        brake=PiecewiseConstant(tuple(times), tuple(brake)),
        slope=grades,
        initial_gear=start_gear(params, v0),
        initial_speed=v0,
        hold_brake=True,
        sensors=sensors,
        description=f'everyday drive, seed {seed}: {extra:+.0f} kg, radius x{radius:.3f}',
        true_vehicle=car,
    )


def _speed_after(
    params: VehicleParams,
    mass: float,
    v: float,
    throttle: float,
    brake: float,
    grades: PiecewiseConstant,
    t: float,
    hold: float,
) -> float:
    """Speed [m/s] after ``hold`` s of the action, by the look-ahead model (0.1 s steps)."""
    step = 0.1
    for k in range(int(hold / step)):
        a = _accel(params, mass, v, throttle, brake, grades.at(t + k * step))
        v = max(v + step * a, 0.0)
    return v
