"""Online effective rolling radius from free-rolling wheels (issue 16, deliverable 2, part).

Run per stamp inside `estimator.Estimator` (``EstimatorConfig.radius_adaptation``), whose
Fx and slip then use ``radius_used``; also usable alone (:func:`run_rolling_radius`).

A wheel that carries (almost) no longitudinal force rolls without slip, so the measured
body speed is ``v = R_eff * omega``. On a front-wheel-drive car the rear wheels roll freely
whenever they are not braked, the front ones only when the drive torque is ~0 (coasting
with the clutch open). So a wheel enters the regression only when

* ``|v| >= min_speed`` (the relative noise of v and omega falls with speed),
* ``|T_i| <= max_wheel_torque`` (not driven, not braked: ``T_i`` is the wheel torque the
  sensors report), and
* ``|dv/dt| <= max_accel`` (its own inertia torque, and so its slip, stays negligible).

The regression ``v = R * mean(omega_i over the free wheels)`` is solved by scalar recursive
least squares (:func:`~vd_observer_node.estimation.mass_grade.rls_step`) with a forgetting
time ``tau`` of free rolling. The measured speed's scale error, if any, is inseparable from
R_eff here (both scale ``v / omega``): the estimate is the radius *as the speed sensor sees
it*, which is what the slip and the tyre force need.

Robustness as in :mod:`.mass_grade`: the radius is clamped to ``[scale_min, scale_max]``
times the file's value (counted as ``radius_clamped``); bad stamps and values are dropped and
counted; a gap or a jump back in time resets to the file's value.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vd_observer_node.errors import ConfigurationError, InputShapeError
from vd_observer_node.estimation.faults import RESTART_FAULTS, STAMP_FAULTS, classify_stamp
from vd_observer_node.estimation.mass_grade import rls_step
from vd_observer_node.estimation.vehicle import EstimatorVehicle

__all__ = [
    'ROLLING_RADIUS_FAULTS',
    'RollingRadiusConfig',
    'RollingRadiusEstimate',
    'RollingRadiusEstimator',
    'RollingRadiusTrack',
    'run_rolling_radius',
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: Fault kinds :class:`RollingRadiusEstimator` counts (all handled).
ROLLING_RADIUS_FAULTS = (*STAMP_FAULTS, 'radius_clamped')


@dataclass(frozen=True)
class RollingRadiusConfig:
    """Settings of :class:`RollingRadiusEstimator`.

    Attributes:
        tau: memory of the radius, [s] of free rolling; ``inf``: none.
        min_speed: a wheel is used only where ``|v| >=`` this, [m/s].
        max_wheel_torque: a wheel is used only where its reported torque ``|T_i| <=`` this
            (not driven, not braked), [N m].
        max_accel: no wheel is used where ``|dv/dt| >`` this, [m/s^2].
        accel_filter_tau: time constant of the low-pass whose derivative is dv/dt, [s].
        speed_noise_density: error of v in the regression as a density, [m/s sqrt(s)];
            per-sample variance ``speed_noise_density**2 / dt``.
        initial_std_ratio: prior standard deviation of R / R_file, [-].
        scale_min: lower bound of R / R_file, [-].
        scale_max: upper bound of R / R_file, [-].
        converged_std_ratio: converged once std(R) / R is below this (after
            ``min_free_time``), [-].
        min_free_time: converged only after at least this much free rolling, [s].
        max_gap: a gap longer than this, or a stamp older by more than this, resets, [s].
    """

    tau: float = 600.0
    min_speed: float = 5.0
    max_wheel_torque: float = 2.0
    max_accel: float = 1.0
    accel_filter_tau: float = 0.2
    speed_noise_density: float = 0.05
    initial_std_ratio: float = 0.03
    scale_min: float = 0.9
    scale_max: float = 1.1
    converged_std_ratio: float = 0.001
    min_free_time: float = 10.0
    max_gap: float = 0.5

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not (isinstance(value, float | int) and not math.isnan(value) and value >= 0):
                raise ConfigurationError(f'{f.name} must be a number >= 0, got {value!r}')
            if math.isinf(value) and f.name != 'tau':
                raise ConfigurationError(f'{f.name} must be finite, got {value!r}')
        for name in (
            'tau',
            'speed_noise_density',
            'initial_std_ratio',
            'converged_std_ratio',
            'max_gap',
        ):
            if not getattr(self, name) > 0.0:
                raise ConfigurationError(f'{name} must be > 0, got {getattr(self, name)}')
        if not 0.0 < self.scale_min <= 1.0 <= self.scale_max:
            raise ConfigurationError(
                f'need 0 < scale_min <= 1 <= scale_max, got {self.scale_min}, {self.scale_max}'
            )

    @classmethod
    def from_mapping(cls, data: dict[str, Any]) -> RollingRadiusConfig:
        """Build from a flat mapping (e.g. ROS parameters).

        Raises:
            ConfigurationError: unknown key or invalid value.
        """
        unknown = set(data) - {f.name for f in fields(cls)}
        if unknown:
            raise ConfigurationError(f'unknown rolling-radius settings: {sorted(unknown)}')
        return cls(**data)


@dataclass(frozen=True)
class RollingRadiusEstimate:
    """The estimate after one stamp.

    Attributes:
        radius: estimated effective rolling radius, [m].
        radius_std: its standard deviation, [m].
        converged: the estimate is trusted (latched until a reset).
        radius_used: ``radius`` once converged, the file's value before, [m].
        free_wheels: number of wheels used at this stamp (0: no update).
        free_time: free rolling so far, [s].
    """

    radius: float
    radius_std: float
    converged: bool
    radius_used: float
    free_wheels: int
    free_time: float


class RollingRadiusEstimator:
    """Stateful rolling-radius estimator: feed it one stamp at a time.

    Attributes:
        config: the settings.
        vehicle: the nominal vehicle (the file's R_eff).
        faults: counts per kind of :data:`ROLLING_RADIUS_FAULTS`.
    """

    def __init__(
        self, vehicle: EstimatorVehicle, config: RollingRadiusConfig | None = None
    ) -> None:
        """Start at the file's radius.

        Args:
            vehicle: nominal vehicle.
            config: settings; default :class:`RollingRadiusConfig`.
        """
        self.vehicle = vehicle
        self.config = config or RollingRadiusConfig()
        self.faults: dict[str, int] = dict.fromkeys(ROLLING_RADIUS_FAULTS, 0)
        r0 = vehicle.effective_radius
        self._bounds = (self.config.scale_min * r0, self.config.scale_max * r0)
        self.reset()

    def reset(self) -> None:
        """Forget everything: the file's radius, the prior covariance, empty filter."""
        r0 = self.vehicle.effective_radius
        self.theta: FloatArray = np.array([r0])
        # products, not ** 2: pow() and the compiled kernel's square differ in the last bit
        sigma = self.config.initial_std_ratio * r0
        self.cov: FloatArray = np.array([[sigma * sigma]])
        self._t: float | None = None
        self._v_lp: list[float] | None = None
        self._free_time = 0.0
        self._converged = False
        self._last: RollingRadiusEstimate | None = None

    def _estimate(self, free: int) -> RollingRadiusEstimate:
        radius = float(self.theta[0])
        return RollingRadiusEstimate(
            radius=radius,
            radius_std=math.sqrt(max(float(self.cov[0, 0]), 0.0)),
            converged=self._converged,
            radius_used=radius if self._converged else self.vehicle.effective_radius,
            free_wheels=free,
            free_time=self._free_time,
        )

    def current(self) -> RollingRadiusEstimate:
        """The last estimate (the file's radius and the prior deviation before any stamp)."""
        return self._last or self._estimate(0)

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

    def update(
        self, t: float, omega: ArrayLike, wheel_torque: ArrayLike, speed: float
    ) -> RollingRadiusEstimate:
        """Process one stamp.

        Args:
            t: stamp, [s].
            omega: wheel speeds, shape (4,), [rad/s] (the wheel observer's).
            wheel_torque: reported drive minus brake torque per wheel, shape (4,), [N m].
            speed: measured body speed, [m/s].

        Returns:
            The estimate after this stamp (the previous one for a rejected stamp).

        Raises:
            InputShapeError: omega or wheel_torque is not of shape (4,).
        """
        w = np.asarray(omega, dtype=np.float64)
        tq = np.asarray(wheel_torque, dtype=np.float64)
        if w.shape != (4,) or tq.shape != (4,):
            raise InputShapeError(
                f'omega and wheel_torque must have shape (4,), got {w.shape}, {tq.shape}'
            )
        if not (np.all(np.isfinite(w)) and np.all(np.isfinite(tq)) and math.isfinite(speed)):
            key = 'non_finite_value' if math.isfinite(t) else 'non_finite_stamp'
            self.faults[key] += 1
            return self._last or self._estimate(0)
        dt = self._accept_stamp(t)
        if dt is None:
            return self._last or self._estimate(0)
        c = self.config
        # dv/dt as the derivative of a two-stage low-pass of v (noise never differentiated raw).
        if dt == 0.0 or self._v_lp is None:
            self._v_lp = [speed, speed]
            accel = 0.0
        else:
            a = 1.0 if c.accel_filter_tau <= 0.0 else -math.expm1(-dt / c.accel_filter_tau)
            v1, v2 = self._v_lp
            v1 += a * (speed - v1)
            v2_new = v2 + a * (v1 - v2)
            accel = (v2_new - v2) / dt
            self._v_lp = [v1, v2_new]
        free = np.abs(tq) <= c.max_wheel_torque
        n_free = int(free.sum())
        # the mean as an explicit left-to-right sum, as the compiled twin adds it
        mean_omega = 0.0
        for i in range(4):
            if free[i]:
                mean_omega += float(w[i])
        mean_omega /= max(n_free, 1)
        if not (dt > 0.0 and n_free and abs(speed) >= c.min_speed and abs(accel) <= c.max_accel):
            self._last = self._estimate(0)
            return self._last
        theta, cov = rls_step(
            self.theta,
            self.cov,
            (mean_omega,),
            speed,
            (math.exp(-dt / c.tau) if math.isfinite(c.tau) else 1.0,),
            c.speed_noise_density * c.speed_noise_density / dt,
            (True,),
        )
        if math.isfinite(float(theta[0])) and math.isfinite(float(cov[0, 0])):
            lo, hi = self._bounds
            if not lo <= theta[0] <= hi:
                self.faults['radius_clamped'] += 1
                theta[0] = min(max(float(theta[0]), lo), hi)
            self.theta, self.cov = theta, cov
        self._free_time += dt
        if self._free_time >= c.min_free_time and math.sqrt(
            float(self.cov[0, 0])
        ) <= c.converged_std_ratio * float(self.theta[0]):
            self._converged = True
        self._last = self._estimate(n_free)
        return self._last


@dataclass(frozen=True)
class RollingRadiusTrack:
    """:class:`RollingRadiusEstimator` over a whole record (N stamps).

    Attributes:
        t: shape (N,), [s].
        radius: shape (N,), [m].
        radius_std: shape (N,), [m].
        converged: shape (N,), bool.
        radius_used: shape (N,), [m].
        free_wheels: shape (N,), int.
        faults: counts per kind at the end.
    """

    t: FloatArray
    radius: FloatArray
    radius_std: FloatArray
    converged: BoolArray
    radius_used: FloatArray
    free_wheels: NDArray[np.int64]
    faults: dict[str, int]


def run_rolling_radius(
    t: ArrayLike,
    omega: ArrayLike,
    wheel_torque: ArrayLike,
    speed: ArrayLike,
    vehicle: EstimatorVehicle,
    config: RollingRadiusConfig | None = None,
) -> RollingRadiusTrack:
    """Run :class:`RollingRadiusEstimator` over arrays (offline; evaluation, tests).

    Args:
        t: stamps, shape (N,), [s].
        omega: wheel speeds, shape (N, 4), [rad/s].
        wheel_torque: reported wheel torques, shape (N, 4), [N m].
        speed: measured body speed, shape (N,), [m/s].
        vehicle: the nominal vehicle.
        config: settings.

    Returns:
        The estimates at every stamp.

    Raises:
        InputShapeError: inconsistent shapes.
    """
    tt = np.asarray(t, dtype=np.float64)
    w = np.asarray(omega, dtype=np.float64)
    tq = np.asarray(wheel_torque, dtype=np.float64)
    v = np.asarray(speed, dtype=np.float64)
    n = tt.shape[0] if tt.ndim == 1 else -1
    if tt.ndim != 1 or v.shape != (n,) or w.shape != (n, 4) or tq.shape != (n, 4):
        raise InputShapeError(
            'run_rolling_radius: need t, speed of shape (N,) and omega, wheel_torque of '
            f'shape (N, 4), got {tt.shape}, {v.shape}, {w.shape}, {tq.shape}'
        )
    est = RollingRadiusEstimator(vehicle, config)
    radius, radius_std, used = (np.empty(n) for _ in range(3))
    converged = np.zeros(n, dtype=np.bool_)
    free = np.zeros(n, dtype=np.int64)
    for k in range(n):
        e = est.update(float(tt[k]), w[k], tq[k], float(v[k]))
        radius[k], radius_std[k], used[k] = e.radius, e.radius_std, e.radius_used
        converged[k], free[k] = e.converged, e.free_wheels
    return RollingRadiusTrack(
        t=tt,
        radius=radius,
        radius_std=radius_std,
        converged=converged,
        radius_used=used,
        free_wheels=free,
        faults=dict(est.faults),
    )
