"""Online vehicle mass and road grade: recursive least squares with separate memories.

Run per stamp inside `estimator.Estimator` (``EstimatorConfig.mass_adaptation``), whose
Fz, mu, rolling resistance and slope then use ``mass_used``; also usable alone
(:func:`run_mass_grade`).

Model (after Vahidi, Stefanopoulou, Peng, "Recursive least squares with forgetting for
online estimation of vehicle mass and road grade", Vehicle System Dynamics 43(1), 2005).
The longitudinal balance ``sum(Fx) - F_aero - c_r(v) m g cos(alpha) = m (dv/dt + g
sin(alpha))`` is linear in ``theta = [1/m, sin(alpha)]``::

    y = dv/dt + g c_r(v) cos(alpha)  =  F / m - g sin(alpha),   F = sum(Fx) - F_aero

(rolling resistance ``c_r m g cos(alpha)`` is proportional to the mass, so it moves to the
known side as a specific force). The force F comes from the wheel torque balance, which
never uses the mass; the acceleration is the output, so its noise is not in the regressor.

Separate memories. The grade changes along the road within seconds; the mass changes only
at a stop. Vahidi et al. give each parameter its own forgetting factor in one joint RLS.
Tried here first, that leaks every fast grade change into the mass (at constant force a
step in grade and a step in 1/m look alike, and the joint gain splits the innovation
between them): on ``paper_table1`` (grade steps of 5 deg) the mass ended 15-34 % off, even
with ideal sensors. So the grade is given a memory of ``grade_tau`` seconds by
*eliminating* it from the mass regression: F and y are high-passed alike
(``x - lowpass(x, grade_tau)``), which removes any grade that is constant over
``grade_tau``::

    y_hp = F_hp / m          (scalar RLS on 1/m, forgetting time mass_tau)

and the grade is then taken from the level with the current mass, fast:
``sin(alpha) = (F / m_used - y) / g``, low-passed by two first-order stages of
``filter_tau`` (as the estimator's slope). ``m_used`` is the estimated mass once its
standard deviation is within ``use_std_ratio`` (10 %: after the first excitation) or it has
converged, and the nominal mass before.

Excitation. 1/m is observable only from force changes faster than ``grade_tau`` (a throttle
step, a gear change, a braking). The mass is updated (and forgotten) only where

* the filters have warmed up after a (re)start (``3 (2 filter_tau + grade_tau)``),
* ``|v| >= min_speed`` (at standstill the brake torque is a reaction, not the applied one),
* ``|dv/dt| >= min_accel`` or ``|F| >= min_force_ratio * m_nominal * g`` (the car
  accelerates or brakes),
* ``|F_hp| >= min_force_change_ratio * m_nominal * g`` (the force has changed within
  ``grade_tau``: this is what makes 1/m observable), and
* ``|d(F_lp)/dt| <= max_force_rate * m_nominal * g`` (not inside a gear shift or pedal
  step, where the wheel and speed observers lag differently and F and dv/dt are not
  simultaneous).

Wheel slip needs no gate: F comes from the wheel torque balance, not from a tyre model.

Robustness: 1/m is clamped to ``[1/mass_max, 1/mass_min]`` (counted as ``mass_clamped``),
so a wrong mass never diverges; a non-finite input or stamp is rejected and counted; a
repeated or slightly older stamp is rejected; a gap longer than ``max_gap`` or a jump back
in time resets the estimator to the nominal mass (as the observers re-initialise).

The per-stamp math is compiled, in `mass_grade_step` (`mass_update`, over named records);
:class:`MassGradeEstimator` keeps its records and calls it, and so does the estimator's own
step. The RLS step is :func:`rls_step` (any number of parameters, vector forgetting, partial
update), the same compiled `mass_grade_step.rls_update` the estimators run.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vd_observer_node.errors import ConfigurationError, InputShapeError
from vd_observer_node.estimation.mass_grade_step import (
    MASS_GRADE_FAULTS,
    MASS_PARAMS,
    MASS_STATE,
    forgetting_factor,
    mass_held,
    mass_rescale,
    mass_reset,
    mass_update,
    rls_update,
)
from vd_observer_node.estimation.track import Track, record_track
from vd_observer_node.estimation.vehicle import EstimatorVehicle
from vd_observer_node.kernel._jit import new_record

__all__ = [
    'MASS_GRADE_FAULTS',
    'MassGradeConfig',
    'MassGradeEstimate',
    'MassGradeEstimator',
    'forgetting_factor',
    'mass_estimate',
    'mass_params',
    'rls_step',
    'run_mass_grade',
    'slope_with_mass',
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


def rls_step(
    theta: ArrayLike,
    cov: ArrayLike,
    phi: ArrayLike,
    y: float,
    forgetting: ArrayLike,
    noise_var: float,
    update: ArrayLike,
) -> tuple[FloatArray, FloatArray]:
    """One recursive-least-squares step with vector forgetting and a partial update.

    Time update ``P <- D P D`` with ``D = diag(forgetting)^(-1/2)``; then the measurement
    ``y = phi . theta + e``, ``var(e) = noise_var``, corrects only the parameters selected
    by ``update`` (the gain of the others is zero: a Schmidt, or "consider", update, whose
    innovation variance still counts their uncertainty). The covariance update is the Joseph form
    ``(I - K phi^T) P (I - K phi^T)^T + K noise_var K^T``, valid for any gain, so P stays
    symmetric positive definite; with every parameter updated it is the usual RLS.
    (`mass_grade_step.rls_update`, on new arrays.)

    Args:
        theta: parameters, shape (n,).
        cov: their covariance P, shape (n, n), symmetric positive definite.
        phi: regressor, shape (n,).
        y: measurement.
        forgetting: per-parameter forgetting factors, shape (n,), in (0, 1]; 1 is no
            forgetting. A parameter that is not updated should get 1 (else its variance
            grows without information).
        noise_var: measurement noise variance, > 0, in units of ``y`` squared.
        update: which parameters the measurement corrects, shape (n,), bool.

    Returns:
        (theta, P) after the step, new arrays of the same shapes.
    """
    # copies: the step works in place
    theta_out = np.array(theta, dtype=np.float64, ndmin=1)
    n = theta_out.shape[0]
    cov_out = np.array(cov, dtype=np.float64).reshape(n, n)
    rls_update(
        theta_out,
        cov_out,
        np.ascontiguousarray(phi, dtype=np.float64).reshape(n),
        float(y),
        np.ascontiguousarray(forgetting, dtype=np.float64).reshape(n),
        float(noise_var),
        np.ascontiguousarray(update, dtype=np.bool_).reshape(n),
    )
    return theta_out, cov_out


def slope_with_mass(
    slope_nominal: ArrayLike,
    net_force: ArrayLike,
    mass_nominal: float,
    mass: ArrayLike,
    gravity: float,
    max_slope: float = 0.5,
) -> FloatArray:
    """A slope computed with the nominal mass, re-expressed with another mass.

    The estimator's slope is ``sin(alpha_0) = F / (m_0 g) - c_r cos(alpha) - (dv/dt) / g``
    (rolling resistance ``c_r m_0 g cos(alpha)`` summed over the quasi-static loads), so with
    a mass m only the first term changes: ``sin(alpha) = sin(alpha_0) + F / g (1/m - 1/m_0)``.
    Exact when F carries the same low-pass as the estimator's slope balance (the filter is
    linear) and m is constant over the filter's memory.

    Args:
        slope_nominal: alpha_0, shape (...), [rad].
        net_force: F = sum(Fx) - F_aero (signed), shape (...), [N], low-passed like the
            slope.
        mass_nominal: m_0, [kg].
        mass: m, shape (...) or scalar, [kg], > 0.
        gravity: g, [m/s^2].
        max_slope: |alpha| bound, [rad].

    Returns:
        alpha, shape (...), [rad], clamped to +-max_slope.
    """
    sine = np.sin(np.asarray(slope_nominal, dtype=np.float64)) + np.asarray(
        net_force, dtype=np.float64
    ) / gravity * (1.0 / np.asarray(mass, dtype=np.float64) - 1.0 / mass_nominal)
    bound = math.sin(max_slope)
    out: FloatArray = np.arcsin(np.clip(sine, -bound, bound))
    return out


@dataclass(frozen=True)
class MassGradeConfig:
    """Settings of :class:`MassGradeEstimator` (defaults chosen with
    ``scripts/eval_mass_adaptation.py``).

    Attributes:
        mass_tau: memory of the mass while excited, [s] of excited driving; ``inf``: none.
        grade_tau: the grade is taken as constant over this time, [s]: the mass regression
            sees only force changes faster than this (high-pass of F and y).
        filter_tau: time constant of each of the two first-order stages applied alike to F
            and to the speed (whose derivative is dv/dt), [s] (0: off); as the estimator's
            ``slope_filter_tau``, it sets the published slope's delay (2 filter_tau).
        accel_noise_density: the regression's error in y as a density, [m/s^2 sqrt(s)];
            the per-sample variance is ``accel_noise_density**2 / dt``, so the reported
            covariance does not depend on the sample rate.
        initial_mass_std_ratio: prior standard deviation of the mass / nominal mass, [-].
        min_speed: excitation (a mass update) needs ``|v| >=`` this, [m/s].
        slope_min_speed: the published slope is computed (else held and invalid) where
            ``|v| >=`` this, [m/s] (as the estimator's ``min_speed``).
        min_accel: the car accelerates or brakes if ``|dv/dt| >=`` this, [m/s^2] ...
        min_force_ratio: ... or ``|F| >=`` this times the nominal weight, [-].
        min_force_change_ratio: excitation needs ``|F_hp| >=`` this times the nominal
            weight, [-].
        max_force_rate: no excitation while ``|d(F_lp)/dt|`` exceeds this times the
            nominal weight, [1/s] (shifts, pedal steps); ``inf``: no such gate.
        mass_min_ratio: lower bound of the mass / nominal mass, [-].
        mass_max_ratio: upper bound of the mass / nominal mass, [-].
        converged_std_ratio: converged once the mass standard deviation / mass is below
            this ... [-] (1 %: two standard deviations within 2 %)
        min_excited_time: ... after at least this much excited driving, [s].
        use_std_ratio: ``mass_used`` is the estimate (not the nominal mass) from the first
            stamp at which its standard deviation / mass is at most this, before it has
            converged (latched until a reset), [-]; 0: only once converged. The estimate is
            the posterior mean of the nominal prior and what was learnt, so from its first
            excitation it is a better mass than the nominal one; the slope, Fz and mu no
            longer carry the whole load error until the converged flag.
        max_slope: |alpha| bound of the published slope, [rad].
        max_gap: a gap longer than this, or a stamp older by more than this, resets, [s].
    """

    mass_tau: float = 300.0
    grade_tau: float = 0.5
    filter_tau: float = 0.1
    accel_noise_density: float = 0.02
    initial_mass_std_ratio: float = 0.3
    min_speed: float = 3.0
    slope_min_speed: float = 0.5
    min_accel: float = 0.3
    min_force_ratio: float = 0.05
    min_force_change_ratio: float = 0.02
    max_force_rate: float = 1.0
    mass_min_ratio: float = 0.7
    mass_max_ratio: float = 2.0
    converged_std_ratio: float = 0.01
    min_excited_time: float = 1.0
    use_std_ratio: float = 0.1
    max_slope: float = 0.5
    max_gap: float = 0.5

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not (isinstance(value, float | int) and not math.isnan(value) and value >= 0):
                raise ConfigurationError(f'{f.name} must be a number >= 0, got {value!r}')
            if math.isinf(value) and f.name not in ('mass_tau', 'max_force_rate'):
                raise ConfigurationError(f'{f.name} must be finite, got {value!r}')
        for name in (
            'grade_tau',
            'mass_tau',
            'accel_noise_density',
            'initial_mass_std_ratio',
            'max_gap',
            'converged_std_ratio',
        ):
            if not getattr(self, name) > 0.0:
                raise ConfigurationError(f'{name} must be > 0, got {getattr(self, name)}')
        if not 0.0 < self.mass_min_ratio <= 1.0 <= self.mass_max_ratio:
            raise ConfigurationError(
                'need 0 < mass_min_ratio <= 1 <= mass_max_ratio, got '
                f'{self.mass_min_ratio}, {self.mass_max_ratio}'
            )
        if not 0.0 < self.max_slope < math.pi / 2:
            raise ConfigurationError(f'max_slope must be in (0, pi/2), got {self.max_slope}')

    @classmethod
    def from_mapping(cls, data: dict[str, Any]) -> MassGradeConfig:
        """Build from a flat mapping (e.g. ROS parameters).

        Raises:
            ConfigurationError: unknown key or invalid value.
        """
        unknown = set(data) - {f.name for f in fields(cls)}
        if unknown:
            raise ConfigurationError(f'unknown mass/grade settings: {sorted(unknown)}')
        return cls(**data)


@dataclass(frozen=True)
class MassGradeEstimate:
    """The estimate after one stamp.

    Attributes:
        mass: estimated mass, [kg] (the nominal mass until the first excitation).
        mass_std: its standard deviation, [kg] (delta method from the variance of 1/m, and
            in the estimator the radius's relative uncertainty: `mass_grade_step`).
        converged: the mass estimate is trusted (latched until a reset).
        mass_used: ``mass`` once converged or once its standard deviation is within
            ``use_std_ratio``, the nominal mass before, [kg]: what Fz, mu, rolling resistance
            and the slope should use.
        excited: this stamp updated the mass.
        slope: published road slope, [rad], positive uphill (held where invalid).
        slope_valid: ``|v| >= slope_min_speed`` and ``|slope| <= max_slope``.
        excited_time: excited driving so far, [s].
    """

    mass: float
    mass_std: float
    converged: bool
    mass_used: float
    excited: bool
    slope: float
    slope_valid: bool
    excited_time: float


def mass_params(vehicle: EstimatorVehicle, config: MassGradeConfig) -> np.record:
    """The `mass_grade_step.MASS_PARAMS` record of a vehicle and settings."""
    p = new_record(MASS_PARAMS)
    p.mass = vehicle.mass
    p.gravity = vehicle.gravity
    p.drag = vehicle.drag_factor
    p.rolling_c0 = vehicle.rolling_c0
    p.rolling_c1 = vehicle.rolling_c1
    p.mass_tau = config.mass_tau
    p.grade_tau = config.grade_tau
    p.filter_tau = config.filter_tau
    p.noise_density = config.accel_noise_density
    p.std_ratio = config.initial_mass_std_ratio
    p.min_speed = config.min_speed
    p.slope_min_speed = config.slope_min_speed
    p.min_accel = config.min_accel
    p.min_force_ratio = config.min_force_ratio
    p.min_change_ratio = config.min_force_change_ratio
    p.max_force_rate = config.max_force_rate
    p.theta_min = 1.0 / (vehicle.mass * config.mass_max_ratio)
    p.theta_max = 1.0 / (vehicle.mass * config.mass_min_ratio)
    p.converged_std_ratio = config.converged_std_ratio
    p.min_excited_time = config.min_excited_time
    p.use_std_ratio = config.use_std_ratio
    p.max_sine = math.sin(config.max_slope)
    p.max_gap = config.max_gap
    # no mass update this long after a (re)start: the filters start from the first sample
    # as if it were steady, so until they have forgotten it F_hp and y_hp are not
    # simultaneous (three times the longest delay of the chain)
    p.warmup = 3.0 * (2.0 * config.filter_tau + config.grade_tau)
    return p


def mass_estimate(out: np.record) -> MassGradeEstimate:
    """The `MassGradeEstimate` of a `mass_grade_step.MASS_OUT` record."""
    return MassGradeEstimate(
        mass=float(out.mass),
        mass_std=float(out.mass_std),
        converged=bool(out.converged),
        mass_used=float(out.mass_used),
        excited=bool(out.excited),
        slope=float(out.slope),
        slope_valid=bool(out.slope_valid),
        excited_time=float(out.excited_time),
    )


class MassGradeEstimator:
    """Stateful mass and grade estimator: feed it one stamp at a time (the records of
    `mass_grade_step.mass_update`).

    Example::

        est = MassGradeEstimator(vehicle)
        for k in range(n):
            out = est.update(t[k], sum_fx[k], speed[k])

    Attributes:
        config: the settings.
        vehicle: the nominal vehicle (the file's values).
        params: the `MASS_PARAMS` record.
        state: the `MASS_STATE` record.
    """

    def __init__(self, vehicle: EstimatorVehicle, config: MassGradeConfig | None = None) -> None:
        """Start at the nominal mass.

        Args:
            vehicle: nominal vehicle (mass, aero, rolling resistance, gravity).
            config: settings; default :class:`MassGradeConfig`.
        """
        self.vehicle = vehicle
        self.config = config or MassGradeConfig()
        self.params = mass_params(vehicle, self.config)
        self.state = new_record(MASS_STATE)
        self.reset()

    @property
    def warmup(self) -> float:
        """[s] no mass update this long after a (re)start (`mass_params`)."""
        return float(self.params.warmup)

    @property
    def faults(self) -> dict[str, int]:
        """Counts per kind of :data:`MASS_GRADE_FAULTS`."""
        return dict(zip(MASS_GRADE_FAULTS, self.state.counts.tolist(), strict=True))

    @property
    def theta(self) -> FloatArray:
        """shape (1,): the estimate of 1/m [1/kg]."""
        return np.array(self.state.theta)

    @property
    def cov(self) -> FloatArray:
        """shape (1, 1): its variance."""
        return np.array(self.state.cov)

    def reset(self) -> None:
        """Forget everything: nominal mass, prior covariance, filters empty."""
        mass_reset(self.params, self.state)
        self._last: MassGradeEstimate | None = None

    def rescale_force(self, ratio: float) -> bool:
        """The force fed from now on is ``ratio`` times what it was (the radius `Fx` is
        computed with changed from R to R' = R / ratio): keep what was learnt consistent.

        ``Fx = (T - J*omega_dot)/R`` scales exactly with 1/R, so the 1/m learnt on the old
        forces is 1/m * ratio on the new ones (its variance * ratio^2), and the filters' force
        states scale by ratio (no false step in F). The air drag, which does not scale, is
        small against the high-passed excitation force. Nothing is changed before the first
        excited stamp (the prior is not learnt from any force). Returns whether the
        rescaled 1/m had to be clamped.
        """
        return bool(mass_rescale(self.params, self.state, float(ratio)))

    def current(self) -> MassGradeEstimate:
        """The last estimate (the nominal mass and prior deviation before any stamp)."""
        if self._last is not None:
            return self._last
        mass_held(self.params, self.state)
        return mass_estimate(self.state.out)

    def update(self, t: float, sum_fx: float, speed: float) -> MassGradeEstimate:
        """Process one stamp.

        Args:
            t: stamp, [s].
            sum_fx: sum of the four tyre longitudinal forces, [N] (from the wheel torque
                balance, independent of the mass).
            speed: measured body speed v, [m/s]; dv/dt is the derivative of its low-pass,
                so that F and dv/dt carry the same filter (no lag between them).

        Returns:
            The estimate after this stamp (the previous one, unchanged, for a rejected
            stamp).
        """
        if mass_update(self.params, self.state, float(t), float(sum_fx), float(speed)):
            self._last = mass_estimate(self.state.out)
            return self._last
        return self.current()


def run_mass_grade(
    t: ArrayLike,
    sum_fx: ArrayLike,
    speed: ArrayLike,
    vehicle: EstimatorVehicle,
    config: MassGradeConfig | None = None,
) -> Track:
    """Run :class:`MassGradeEstimator` over arrays (offline; evaluation, tests).

    Args:
        t: stamps, shape (N,), [s].
        sum_fx: sum of the tyre forces, shape (N,), [N].
        speed: measured body speed, shape (N,), [m/s].
        vehicle: the nominal vehicle.
        config: settings.

    Returns:
        The estimates at every stamp (`MassGradeEstimate`'s fields, e.g. ``track['mass']``).

    Raises:
        InputShapeError: the arrays are not all of shape (N,).
    """
    arrays = [np.asarray(x, dtype=np.float64) for x in (t, sum_fx, speed)]
    if any(a.ndim != 1 or a.shape != arrays[0].shape for a in arrays):
        raise InputShapeError(
            'run_mass_grade: t, sum_fx and speed must all have shape (N,), got '
            + ', '.join(str(a.shape) for a in arrays)
        )
    tt, fx, v = arrays
    est = MassGradeEstimator(vehicle, config)
    rows = [est.update(float(tt[k]), float(fx[k]), float(v[k])) for k in range(tt.size)]
    return record_track(tt, MassGradeEstimate, rows, est.faults)
