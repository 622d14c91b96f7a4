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
``filter_tau`` (as the estimator's slope). ``m_used`` is the estimated mass once it has
converged and the nominal mass before, so before convergence the slope is the estimator's.

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

The RLS step is a pure function, :func:`rls_step` (any number of parameters, vector
forgetting, partial update); :class:`MassGradeEstimator` wraps it with the filters, the
gating, the clamping, the slope output and the fault counts.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vd_observer_node.errors import ConfigurationError, InputShapeError
from vd_observer_node.estimation.faults import RESTART_FAULTS, STAMP_FAULTS, classify_stamp
from vd_observer_node.estimation.vehicle import EstimatorVehicle

__all__ = [
    'MASS_GRADE_FAULTS',
    'MassGradeConfig',
    'MassGradeEstimate',
    'MassGradeEstimator',
    'MassGradeTrack',
    'forgetting_factor',
    'rls_step',
    'run_mass_grade',
    'slope_with_mass',
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: Fault kinds :class:`MassGradeEstimator` counts (all handled: the output stays finite).
MASS_GRADE_FAULTS = (*STAMP_FAULTS, 'mass_clamped')

_KMH_REFERENCE = 160.0  # [km/h] speed scale of paper eq. 7 (as estimation.formulas)


def forgetting_factor(dt: float, tau: float) -> float:
    """Forgetting factor of one step ``dt`` for a memory of ``tau`` seconds.

    Args:
        dt: step, [s], >= 0.
        tau: memory time constant, [s]; ``inf`` (or 0 steps) means no forgetting.

    Returns:
        ``exp(-dt / tau)`` in (0, 1], [-].
    """
    if math.isinf(tau) or dt <= 0.0:
        return 1.0
    return math.exp(-dt / tau)


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
    th = np.asarray(theta, dtype=np.float64)
    p = np.asarray(cov, dtype=np.float64)
    f = np.asarray(phi, dtype=np.float64)
    d = 1.0 / np.sqrt(np.asarray(forgetting, dtype=np.float64))
    p = p * np.outer(d, d)
    sel = np.asarray(update, dtype=bool)
    if not sel.any():
        return th.copy(), p
    # Schmidt ("consider") gain: the held parameters' uncertainty still enters the
    # innovation variance, so the selected ones do not over-trust the measurement.
    p_phi = p @ f
    k = np.zeros_like(th)
    k[sel] = p_phi[sel] / (float(f @ p_phi) + noise_var)
    innovation = y - float(f @ th)
    a = np.eye(th.size) - np.outer(k, f)
    p_new = a @ p @ a.T + noise_var * np.outer(k, k)
    p_new = 0.5 * (p_new + p_new.T)
    return th + k * innovation, p_new


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
            this ... [-]
        min_excited_time: ... after at least this much excited driving, [s].
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
    converged_std_ratio: float = 0.02
    min_excited_time: float = 5.0
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
        mass_std: its standard deviation, [kg] (delta method from the variance of 1/m).
        converged: the mass estimate is trusted (latched until a reset).
        mass_used: ``mass`` once converged, the nominal mass before, [kg]: what Fz, mu,
            rolling resistance and the slope should use.
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


class MassGradeEstimator:
    """Stateful mass and grade estimator: feed it one stamp at a time.

    Example::

        est = MassGradeEstimator(vehicle)
        for k in range(n):
            out = est.update(t[k], sum_fx[k], speed[k])

    Attributes:
        config: the settings.
        vehicle: the nominal vehicle (the file's values).
        faults: counts per kind of :data:`MASS_GRADE_FAULTS`.
    """

    def __init__(self, vehicle: EstimatorVehicle, config: MassGradeConfig | None = None) -> None:
        """Start at the nominal mass.

        Args:
            vehicle: nominal vehicle (mass, aero, rolling resistance, gravity).
            config: settings; default :class:`MassGradeConfig`.
        """
        self.vehicle = vehicle
        self.config = config or MassGradeConfig()
        self.faults: dict[str, int] = dict.fromkeys(MASS_GRADE_FAULTS, 0)
        #: [s] no mass update this long after a (re)start: the filters start from the first
        #: sample as if it were steady, so until they have forgotten it F_hp and y_hp are
        #: not simultaneous (three times the longest delay of the chain).
        self.warmup = 3.0 * (2.0 * self.config.filter_tau + self.config.grade_tau)
        self._theta_min = 1.0 / (vehicle.mass * self.config.mass_max_ratio)
        self._theta_max = 1.0 / (vehicle.mass * self.config.mass_min_ratio)
        self.reset()

    def reset(self) -> None:
        """Forget everything: nominal mass, prior covariance, filters empty."""
        c, m0 = self.config, self.vehicle.mass
        self.theta: FloatArray = np.array([1.0 / m0])
        sigma_inv_m = c.initial_mass_std_ratio / m0  # d(1/m) = dm / m^2
        self.cov: FloatArray = np.array([[sigma_inv_m * sigma_inv_m]])
        self._t: float | None = None
        self._lp: list[float] | None = None  # two low-pass stages of F, then of v
        self._f_slow = math.nan  # grade_tau low-pass of F_lp and y (F_hp = F_lp - F_slow)
        self._y_slow = math.nan
        self._slope = 0.0
        self._excited_time = 0.0
        self._running = 0.0  # [s] since the (re)start: the filters' warm-up
        self._converged = False
        self._last: MassGradeEstimate | None = None

    # -- helpers ----------------------------------------------------------------------

    def _mass_std(self) -> float:
        # products, not ** 2: pow() and the compiled kernel's square differ in the last bit
        theta = float(self.theta[0])
        return math.sqrt(max(float(self.cov[0, 0]), 0.0)) / (theta * theta)

    def _estimate(self, excited: bool, valid: bool) -> MassGradeEstimate:
        mass = 1.0 / float(self.theta[0])
        return MassGradeEstimate(
            mass=mass,
            mass_std=self._mass_std(),
            converged=self._converged,
            mass_used=mass if self._converged else self.vehicle.mass,
            excited=excited,
            slope=self._slope,
            slope_valid=valid,
            excited_time=self._excited_time,
        )

    def _accept_stamp(self, t: float) -> float | None:
        """dt [s] of a usable stamp (0.0: (re)start); None to hold the last estimate."""
        kind, dt = classify_stamp(self._t, t, self.config.max_gap)
        if kind is not None:
            self.faults[kind] += 1
        if kind in RESTART_FAULTS:
            self.reset()
        if dt is not None:
            self._t = t
        return dt

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
        if self._excited_time <= 0.0:
            return False
        theta = float(self.theta[0]) / ratio
        clamped = not self._theta_min <= theta <= self._theta_max
        theta = min(max(theta, self._theta_min), self._theta_max)
        self.theta = np.array([theta])
        self.cov = self.cov / (ratio * ratio)
        if self._lp is not None:
            self._lp[0] *= ratio
            self._lp[1] *= ratio
        if not math.isnan(self._f_slow):
            self._f_slow *= ratio
        return clamped

    def current(self) -> MassGradeEstimate:
        """The last estimate (the nominal mass and prior deviation before any stamp)."""
        return self._last or self._estimate(False, False)

    # -- the step ---------------------------------------------------------------------

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
        c, veh = self.config, self.vehicle
        if not (math.isfinite(sum_fx) and math.isfinite(speed)):
            if math.isfinite(t):
                self.faults['non_finite_value'] += 1
            else:
                self.faults['non_finite_stamp'] += 1
            return self._last or self._estimate(False, False)
        dt = self._accept_stamp(t)
        if dt is None:
            return self._last or self._estimate(False, False)
        g = veh.gravity
        weight = veh.mass * g
        direction = 1.0 if speed >= 0.0 else -1.0
        force = sum_fx - direction * veh.drag_factor * speed * speed

        # F and v through the same two first-order stages (the estimator's slope filter);
        # dv/dt is the backward difference of the filtered speed.
        if dt == 0.0 or self._lp is None:
            self._lp = [force, force, speed, speed]
            accel = 0.0
            force_rate = 0.0
        else:
            w = 1.0 if c.filter_tau <= 0.0 else -math.expm1(-dt / c.filter_tau)
            f1, f2, v1, v2 = self._lp
            f1 += w * (force - f1)
            f2_new = f2 + w * (f1 - f2)
            v1 += w * (speed - v1)
            v2_new = v2 + w * (v1 - v2)
            accel = (v2_new - v2) / dt
            force_rate = (f2_new - f2) / dt
            self._lp = [f1, f2_new, v1, v2_new]
        f_lp, v_lp = self._lp[1], self._lp[3]
        c_r = veh.rolling_c0 * (1.0 + veh.rolling_c1 * abs(v_lp) / _KMH_REFERENCE)
        y = accel + direction * g * c_r * math.cos(self._slope)

        # The high-pass removes a grade that is constant over grade_tau (same on both sides).
        if dt == 0.0 or math.isnan(self._f_slow):
            self._f_slow, self._y_slow = f_lp, y
        else:
            w_slow = -math.expm1(-dt / c.grade_tau)
            self._f_slow += w_slow * (f_lp - self._f_slow)
            self._y_slow += w_slow * (y - self._y_slow)
        f_hp = f_lp - self._f_slow
        y_hp = y - self._y_slow

        self._running += dt
        excited = (
            dt > 0.0
            and self._running >= self.warmup
            and abs(speed) >= c.min_speed
            and (abs(accel) >= c.min_accel or abs(f_lp) >= c.min_force_ratio * weight)
            and abs(f_hp) >= c.min_force_change_ratio * weight
            and abs(force_rate) <= c.max_force_rate * weight
        )
        if excited:
            theta, cov = rls_step(
                self.theta,
                self.cov,
                (f_hp,),
                y_hp,
                (forgetting_factor(dt, c.mass_tau),),
                c.accel_noise_density * c.accel_noise_density / dt,
                (True,),
            )
            if math.isfinite(float(theta[0])) and math.isfinite(float(cov[0, 0])):
                if not self._theta_min <= theta[0] <= self._theta_max:
                    self.faults['mass_clamped'] += 1
                    theta[0] = min(max(float(theta[0]), self._theta_min), self._theta_max)
                self.theta, self.cov = theta, cov
            self._excited_time += dt
            if (
                self._excited_time >= c.min_excited_time
                and self._mass_std() * float(self.theta[0]) <= c.converged_std_ratio
            ):
                self._converged = True

        valid = False
        if abs(speed) >= c.slope_min_speed:
            m_used = 1.0 / float(self.theta[0]) if self._converged else veh.mass
            sine = (f_lp / m_used - y) / g
            bound = math.sin(c.max_slope)
            self._slope = math.asin(min(max(sine, -bound), bound))
            valid = abs(sine) <= bound
        self._last = self._estimate(excited, valid)
        return self._last


@dataclass(frozen=True)
class MassGradeTrack:
    """:class:`MassGradeEstimator` over a whole record (N stamps).

    Attributes:
        t: shape (N,), [s].
        mass: shape (N,), [kg].
        mass_std: shape (N,), [kg].
        converged: shape (N,), bool.
        mass_used: shape (N,), [kg].
        excited: shape (N,), bool.
        slope: shape (N,), [rad].
        slope_valid: shape (N,), bool.
        faults: counts per kind at the end.
    """

    t: FloatArray
    mass: FloatArray
    mass_std: FloatArray
    converged: BoolArray
    mass_used: FloatArray
    excited: BoolArray
    slope: FloatArray
    slope_valid: BoolArray
    faults: dict[str, int]


def run_mass_grade(
    t: ArrayLike,
    sum_fx: ArrayLike,
    speed: ArrayLike,
    vehicle: EstimatorVehicle,
    config: MassGradeConfig | None = None,
) -> MassGradeTrack:
    """Run :class:`MassGradeEstimator` over arrays (offline; evaluation, tests).

    Args:
        t: stamps, shape (N,), [s].
        sum_fx: sum of the tyre forces, shape (N,), [N].
        speed: measured body speed, shape (N,), [m/s].
        vehicle: the nominal vehicle.
        config: settings.

    Returns:
        The estimates at every stamp.

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
    n = tt.size
    mass, mass_std, mass_used, slope = (np.empty(n) for _ in range(4))
    converged, excited, slope_valid = (np.zeros(n, dtype=np.bool_) for _ in range(3))
    for k in range(n):
        e = est.update(float(tt[k]), float(fx[k]), float(v[k]))
        mass[k], mass_std[k], mass_used[k], slope[k] = e.mass, e.mass_std, e.mass_used, e.slope
        converged[k], excited[k], slope_valid[k] = e.converged, e.excited, e.slope_valid
    return MassGradeTrack(
        t=tt,
        mass=mass,
        mass_std=mass_std,
        converged=converged,
        mass_used=mass_used,
        excited=excited,
        slope=slope,
        slope_valid=slope_valid,
        faults=dict(est.faults),
    )
