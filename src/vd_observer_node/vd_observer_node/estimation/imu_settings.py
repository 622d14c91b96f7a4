"""Settings of the IMU fusion (`imu_grade`): what a vehicle file, an input mapping's
``imu.fusion`` and the inputs' rate set, checked once.

`ImuGradeConfig` holds them; `imu_grade_config` builds it from a vehicle's body pitch and a
sensor's settings; the low-pass time constants left unset follow the inputs' rate
(`tau_for_rate`, as the force balance's ``slope_filter_tau`` does, `rate_settings`).
`imu_grade.grade_params` turns it into the compiled step's parameter record.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Final

from vd_observer_node.errors import ConfigurationError
from vd_observer_node.estimation.body_pitch import BodyPitch
from vd_observer_node.estimation.rate_settings import REFERENCE_RATE_HZ

__all__ = [
    'RATE_FOLLOWING',
    'REFERENCE_RATE_FOLLOWING',
    'VEHICLE_FIELDS',
    'ImuGradeConfig',
    'imu_grade_config',
    'tau_for_rate',
]


@dataclass(frozen=True)
class ImuGradeConfig:
    """Settings of the IMU fusion.

    Attributes:
        tau: time constant of each of the 3 low-pass stages of the grade on f_x and the
            speed, [s] (the vibration, the speed's noise); None: it follows the inputs' rate
            (`tau_for_rate`: 0.3 s at and above 1 kHz, longer below), as the force balance's
            ``slope_filter_tau`` does.
        lag_compensation: the grade's low-pass has a lead that cancels its lag on ramps:
            ``(1 + 3 tau s) / (1 + tau s)^3`` (False: ``1 / (1 + tau s)^3``, 3 tau late).
        fit_tau: time constant of each of the 2 low-pass stages of the regression on f_x,
            the speed and the force balance, [s].
        warmup: the filters start after this long, on a line fitted through the speed (the
            car's acceleration at the start) and the mean f_x, [s].
        step_tau: time constant of each of the 3 stages of a short low-pass of the grade
            without lead, [s] (0: none; None: it follows the inputs' rate, 0.1 s at and above
            1 kHz, as ``tau``): where it differs from the grade by more than
            ``step_slope`` [rad] (a step of the grade, which the lead overshoots for a few
            ``tau``) the grade is the short one's (on the paper's 5 deg steps: 0.22 deg RMS
            without it, see docs/estimation.md).
        fit_delay: the regression starts this long after the filters, [s]: they have
            forgotten the force balance at their start (the estimator's own start-up), and
            the first seconds' single direction of excitation does not get half of the
            mass's error put into the bias (measured on seeds 0-9 of the everyday drives:
            1.5 s: slope p90 0.187 deg, 2.7 s: 0.165 deg).
        settle: time of regression stamps before the IMU's grade may be used, [s].
        max_age: an IMU sample older than this at a stamp is a dropout, [s].
        saturation: |f_x| at or above this is a saturated sensor, [m/s^2].
        max_slope: |fused slope| above this is invalid, [rad].
        min_speed: the regression uses stamps at or above this forward speed, [m/s].
        mass_std: prior standard deviation of the mass around the vehicle file's, [kg].
        bias_std: prior standard deviation of the IMU's bias, [m/s^2].
        pitch_compliance: body pitch (nose up) per newton of the longitudinal ground force,
            [rad/N] (`pitch_compliance`; 0: a rigid body). The body squats and dives with
            ``m (dv/dt + g sin(alpha))`` and the IMU with it, so it reads
            ``(1 + k) (dv/dt + g sin(alpha)) + b`` with ``k = g m pitch_compliance``.
        force_std: error of the filtered force balance per correlation time, [N].
        mass_drift: random walk of the mass, [kg/sqrt(s)].
        bias_drift: random walk of the bias, [m/s^2/sqrt(s)].
        mass_tol: the regression's mass has converged when its standard deviation is below
            this fraction of the mass, [-].
        bias_tol: the IMU's grade is used alone once the bias's standard deviation is below
            this (and ``settle`` has passed), [m/s^2]; before, the two slopes are weighted
            by their variances.
        alone_bias_std: where the force balance's slope is not valid (a braking on a switch,
            a shift, no torque at all) and the bias is not trusted yet, the IMU's grade alone
            is valid only while the bias's standard deviation is at or below this, [m/s^2]
            (0.1: 0.6 deg; the prior's 0.5 m/s^2 is 2.9 deg, a mounting pitch nobody
            measured: on the RAV4's windscreen the first 3 s read 4.5 deg low). A sensor whose
            mounting is measured (``mount_rpy_deg``) states a smaller ``bias_std``.
        force_slope_std: the force balance's slope error in that weighting, besides the one
            its mass error makes (which the regression measures), [rad] (0.01: on the
            everyday drives a larger one is better, 0.05: slope p90 0.174 deg against 0.184
            deg on seeds 0-9, but the nominal car's 0.128 deg becomes 0.136 deg).
        mass_feedback: once the regression's mass has converged, the estimator uses it (the
            force balance's slope, the tyre loads; `cascade_step`); False: the estimator
            keeps its own (the file's or the online mass).
        gyro: where the IMU gives its angular rate, the grade is a complementary filter of
            the pitch rate and the specific force (`gyro_grade`): no lag on ramps and steps,
            the accelerometer's vibration and the speed's noise filtered by ``gyro_tau``, a
            gyro bias rejected (the rate's path has no gain at 0 Hz); the lead and the step
            switch are then not used. False: the specific force alone, as without an
            angular rate.
        gyro_tau: time constant of each of the 3 stages of that filter, [s]: below
            ``1 / gyro_tau`` the grade is the specific force's, above it the integrated
            pitch rate's.
        pitch_frequency: the body's pitch mode on its springs, [Hz] (`body_pitch`; 0: it
            settles at once). With ``pitch_compliance`` and ``pitch_damping`` a vehicle's,
            not a sensor's (`imu_grade_config`).
        pitch_damping: the damping ratio of that mode, [-].
        lever_arm_z: the sensor's height above the body's pitch centre (about its centre of
            gravity), [m]: a sensor up there reads the pitch acceleration times this besides
            the car's acceleration (a windscreen mount: half a metre or more); where the
            IMU gives its angular rate that term is taken out of f_x, with the pitch
            acceleration the rate's difference from sample to sample low-passed with
            `imu_grade.LEVER_TAU` (0: none).
    """

    tau: float | None = None
    lag_compensation: bool = True
    fit_tau: float = 0.2
    fit_delay: float = 2.7
    step_tau: float | None = None
    step_slope: float = 0.015
    warmup: float = 0.3
    settle: float = 3.0
    max_age: float = 0.1
    saturation: float = 39.0
    max_slope: float = 0.5
    min_speed: float = 2.0
    mass_std: float = 500.0
    bias_std: float = 0.5
    pitch_compliance: float = 0.0
    force_std: float = 100.0
    mass_drift: float = 0.05
    bias_drift: float = 1e-4
    mass_tol: float = 0.015
    bias_tol: float = 0.05
    alone_bias_std: float = 0.1
    force_slope_std: float = 0.01
    mass_feedback: bool = True
    gyro: bool = True
    gyro_tau: float = 1.0
    pitch_frequency: float = 0.0
    pitch_damping: float = 0.5
    lever_arm_z: float = 0.0

    def __post_init__(self) -> None:
        for name in ('tau', 'fit_tau', 'max_age', 'saturation', 'max_slope', 'mass_std',
                     'bias_std', 'force_std', 'mass_tol', 'bias_tol', 'alone_bias_std',
                     'force_slope_std', 'gyro_tau'):  # fmt: skip
            value = getattr(self, name)
            if value is None and name in RATE_FOLLOWING:
                continue
            if not (math.isfinite(value) and value > 0.0):
                raise ConfigurationError(f'imu.{name} must be finite and > 0, got {value}')
        for name in ('settle', 'min_speed', 'mass_drift', 'bias_drift', 'pitch_compliance',
                     'warmup', 'fit_delay', 'step_tau', 'step_slope', 'pitch_frequency',
                     'pitch_damping'):  # fmt: skip
            value = getattr(self, name)
            if value is None and name in RATE_FOLLOWING:
                continue
            if not (math.isfinite(value) and value >= 0.0):
                raise ConfigurationError(f'imu.{name} must be finite and >= 0, got {value}')
        if not math.isfinite(self.lever_arm_z):
            raise ConfigurationError(f'imu.lever_arm_z must be finite, got {self.lever_arm_z}')
        if self.max_slope >= math.pi / 2:
            raise ConfigurationError(f'imu.max_slope must be < pi/2, got {self.max_slope}')

    @property
    def tau_in_use(self) -> float:
        """[s] ``tau``, or the reference rate's while it is left to a rate not known yet."""
        return REFERENCE_RATE_FOLLOWING['tau'] if self.tau is None else self.tau

    @property
    def step_tau_in_use(self) -> float:
        """[s] ``step_tau``, or the reference rate's while it is left to a rate not known."""
        return REFERENCE_RATE_FOLLOWING['step_tau'] if self.step_tau is None else self.step_tau

    def at_rate(self, rate_hz: float) -> tuple[ImuGradeConfig, dict[str, float]]:
        """These settings for inputs at `rate_hz`: the ones left unset follow the rate.

        Args:
            rate_hz: [Hz] the rate the estimator's settings follow (`rate_settings.
                follow_rate_hz`: the slower of the wheel and body-speed inputs); nan:
                unknown, nothing changes.

        Returns:
            The settings with the rate-dependent ones fixed, and those fixed here by name
            (``'tau'``, ``'step_tau'``) with their values (empty where the user set them).
        """
        if not math.isfinite(rate_hz):
            return self, {}
        fixed = {
            name: tau_for_rate(name, rate_hz)
            for name in RATE_FOLLOWING
            if getattr(self, name) is None
        }
        changes: dict[str, Any] = dict(fixed)
        return dataclasses.replace(self, **changes), fixed


#: the settings that follow the inputs' rate where left unset (None)
RATE_FOLLOWING: Final = ('tau', 'step_tau')
#: [s] their values at and above `rate_settings.REFERENCE_RATE_HZ` (where they were tuned)
REFERENCE_RATE_FOLLOWING: Final = {'tau': 0.3, 'step_tau': 0.1}


def tau_for_rate(name: str, rate_hz: float) -> float:
    """[s] the setting `name` (`RATE_FOLLOWING`) for inputs at `rate_hz`.

    The grade is the IMU's specific force less the derivative of the low-passed speed, so
    the speed's noise reaches it as it reaches the force balance's slope: the same law as
    ``slope_filter_tau`` (`rate_settings`), the reference value times
    ``(1000 Hz / f)^(1/4)`` below 1 kHz. Measured on standard-type bags with a 100 Hz IMU
    (``scripts/eval_imu_rate.py``; docs/estimation.md, section 8): at 50 Hz, 0.3 s gave a
    slope worse than the force balance alone (0.318 deg against 0.245 deg on paper_table1),
    0.53 s better (0.207 deg).

    Args:
        name: 'tau' or 'step_tau'.
        rate_hz: [Hz]; not finite or <= 0 (unknown): the reference rate's value.
    """
    reference = REFERENCE_RATE_FOLLOWING[name]
    if not (math.isfinite(rate_hz) and rate_hz > 0.0):
        return reference
    return float(reference * max(1.0, REFERENCE_RATE_HZ / rate_hz) ** 0.25)


#: the `ImuGradeConfig` fields a vehicle file sets (`imu_grade_config`), not a sensor's mapping
VEHICLE_FIELDS: Final = ('pitch_compliance', 'pitch_frequency', 'pitch_damping')


def imu_grade_config(
    body: BodyPitch, settings: tuple[tuple[str, float], ...] = ()
) -> ImuGradeConfig:
    """The settings of a vehicle (its body's pitch, `body_pitch.vehicle_body_pitch`) and of
    a sensor (the input mapping's ``imu.fusion``: field, value; the boolean fields as 0 or 1).

    Raises:
        ConfigurationError: a value out of its range (unknown fields the mapping rejects).
    """
    kinds = {f.name: f.type for f in dataclasses.fields(ImuGradeConfig)}
    changes: dict[str, Any] = {
        key: bool(value) if kinds.get(key) in (bool, 'bool') else value for key, value in settings
    }
    return ImuGradeConfig(
        pitch_compliance=body.compliance, pitch_frequency=body.frequency,
        pitch_damping=body.damping, **changes,
    )  # fmt: skip
