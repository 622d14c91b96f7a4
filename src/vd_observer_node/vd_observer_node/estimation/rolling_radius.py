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

The per-stamp math is compiled (`radius_update`, over the named records `RADIUS_PARAMS`,
`RADIUS_STATE`): :class:`RollingRadiusEstimator` keeps the records and calls it, and so does
the estimator's own step (`estimator_step`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any, Final

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vd_observer_node.errors import ConfigurationError, InputShapeError
from vd_observer_node.estimation.faults import STAMP_FAULTS, stamp_step
from vd_observer_node.estimation.mass_grade_step import forgetting_factor, rls_update
from vd_observer_node.estimation.track import Track, record_track
from vd_observer_node.estimation.vehicle import EstimatorVehicle
from vd_observer_node.kernel._jit import jit, new_record

__all__ = [
    'RADIUS_OUT',
    'RADIUS_PARAMS',
    'RADIUS_STATE',
    'ROLLING_RADIUS_FAULTS',
    'RollingRadiusConfig',
    'RollingRadiusEstimate',
    'RollingRadiusEstimator',
    'radius_estimate',
    'radius_held',
    'radius_params',
    'radius_reset',
    'radius_update',
    'run_rolling_radius',
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: Fault kinds :class:`RollingRadiusEstimator` counts (all handled).
ROLLING_RADIUS_FAULTS: Final = (*STAMP_FAULTS, 'radius_clamped')
_NON_FINITE_STAMP, _NON_FINITE_VALUE = 0, 1
_CLAMPED: Final = len(STAMP_FAULTS)

#: The settings as the step uses them (`radius_params`): the file's radius [m], the
#: `RollingRadiusConfig` fields, the radius bounds [m].
RADIUS_PARAMS: Final = np.dtype(
    [
        ('radius', 'f8'),
        ('tau', 'f8'),
        ('min_speed', 'f8'),
        ('max_wheel_torque', 'f8'),
        ('max_accel', 'f8'),
        ('accel_filter_tau', 'f8'),
        ('noise_density', 'f8'),
        ('std_ratio', 'f8'),
        ('lo', 'f8'),
        ('hi', 'f8'),
        ('converged_std_ratio', 'f8'),
        ('min_free_time', 'f8'),
        ('max_gap', 'f8'),
    ],
    align=True,
)
#: One estimate (`RollingRadiusEstimate`'s fields).
RADIUS_OUT: Final = np.dtype(
    [
        ('radius', 'f8'),
        ('radius_std', 'f8'),
        ('converged', 'b1'),
        ('radius_used', 'f8'),
        ('free_wheels', 'i8'),
        ('free_time', 'f8'),
    ],
    align=True,
)
#: The estimator's memory: last stamp (nan: none), the two low-pass stages of v (``lp_on``:
#: started), R and its variance, free rolling time [s], the last estimate (``has_last``) and
#: the fault counts (`ROLLING_RADIUS_FAULTS` order).
RADIUS_STATE: Final = np.dtype(
    [
        ('t', 'f8'),
        ('lp_on', 'b1'),
        ('v1', 'f8'),
        ('v2', 'f8'),
        ('theta', 'f8', (1,)),
        ('cov', 'f8', (1, 1)),
        ('free_time', 'f8'),
        ('converged', 'b1'),
        ('has_last', 'b1'),
        ('out', RADIUS_OUT),
        ('counts', 'i8', (len(ROLLING_RADIUS_FAULTS),)),
    ],
    align=True,
)


@jit
def radius_reset(p: np.record, s: np.record) -> None:
    """Forget everything: the file's radius, the prior covariance, empty filter."""
    s.t = math.nan
    s.lp_on = False
    s.theta[0] = p.radius
    sigma = p.std_ratio * p.radius
    s.cov[0, 0] = sigma * sigma
    s.free_time = 0.0
    s.converged = False
    s.has_last = False


@jit
def _radius_out(p: np.record, s: np.record, free: int) -> None:
    radius = s.theta[0]
    o = s.out
    o.radius = radius
    o.radius_std = math.sqrt(max(s.cov[0, 0], 0.0))
    o.converged = s.converged
    o.radius_used = radius if s.converged else p.radius
    o.free_wheels = free
    o.free_time = s.free_time


@jit
def radius_held(p: np.record, s: np.record) -> None:
    """``s.out`` as `RollingRadiusEstimator.current`: the last estimate, or the fresh one."""
    if not s.has_last:
        _radius_out(p, s, 0)


@jit
def radius_update(
    p: np.record, s: np.record, t: float, omega: FloatArray, torque: FloatArray, speed: float
) -> bool:
    """One stamp (`RollingRadiusEstimator.update`) into ``s.out``.

    Args:
        p: `RADIUS_PARAMS` record.
        s: `RADIUS_STATE` record; its fault counts are incremented.
        t: stamp [s].
        omega: shape (4,), [rad/s] wheel speeds.
        torque: shape (4,), [N m] reported wheel torques.
        speed: body speed [m/s].

    Returns:
        Whether the stamp was accepted (else ``s.out`` is the held estimate).
    """
    finite = math.isfinite(speed)
    for i in range(4):
        finite = finite and math.isfinite(omega[i]) and math.isfinite(torque[i])
    if not finite:
        s.counts[_NON_FINITE_VALUE if math.isfinite(t) else _NON_FINITE_STAMP] += 1
        radius_held(p, s)
        return False
    kind, dt = stamp_step(s.t, t, p.max_gap)
    if kind >= 0:
        s.counts[kind] += 1
    if math.isnan(dt):
        radius_held(p, s)
        return False
    if kind >= 0:  # a gap or a jump back: start again from this sample
        radius_reset(p, s)
    s.t = t
    # dv/dt as the derivative of a two-stage low-pass of v (noise never differentiated raw)
    if dt == 0.0 or not s.lp_on:
        s.lp_on = True
        s.v1, s.v2 = speed, speed
        accel = 0.0
    else:
        a = 1.0 if p.accel_filter_tau <= 0.0 else -math.expm1(-dt / p.accel_filter_tau)
        v1 = s.v1 + a * (speed - s.v1)
        v2 = s.v2 + a * (v1 - s.v2)
        accel = (v2 - s.v2) / dt
        s.v1, s.v2 = v1, v2
    n_free = 0
    mean_omega = 0.0
    for i in range(4):
        if abs(torque[i]) <= p.max_wheel_torque:
            n_free += 1
            mean_omega += omega[i]
    mean_omega /= max(n_free, 1)
    if not (dt > 0.0 and n_free > 0 and abs(speed) >= p.min_speed and abs(accel) <= p.max_accel):
        _radius_out(p, s, 0)
        s.has_last = True
        return True
    theta = s.theta.copy()
    cov = s.cov.copy()
    rls_update(
        theta, cov, np.full(1, mean_omega), speed, np.full(1, forgetting_factor(dt, p.tau)),
        p.noise_density * p.noise_density / dt, np.ones(1, np.bool_),
    )  # fmt: skip
    if math.isfinite(theta[0]) and math.isfinite(cov[0, 0]):
        if not p.lo <= theta[0] <= p.hi:
            s.counts[_CLAMPED] += 1
            theta[0] = min(max(theta[0], p.lo), p.hi)
        s.theta[0] = theta[0]
        s.cov[0, 0] = cov[0, 0]
    s.free_time += dt
    if (
        s.free_time >= p.min_free_time
        and math.sqrt(s.cov[0, 0]) <= p.converged_std_ratio * s.theta[0]
    ):
        s.converged = True
    _radius_out(p, s, n_free)
    s.has_last = True
    return True


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


def radius_params(vehicle: EstimatorVehicle, config: RollingRadiusConfig) -> np.record:
    """The `RADIUS_PARAMS` record of a vehicle and settings."""
    r0 = vehicle.effective_radius
    p = new_record(RADIUS_PARAMS)
    p.radius = r0
    p.tau = config.tau
    p.min_speed = config.min_speed
    p.max_wheel_torque = config.max_wheel_torque
    p.max_accel = config.max_accel
    p.accel_filter_tau = config.accel_filter_tau
    p.noise_density = config.speed_noise_density
    p.std_ratio = config.initial_std_ratio
    p.lo = config.scale_min * r0
    p.hi = config.scale_max * r0
    p.converged_std_ratio = config.converged_std_ratio
    p.min_free_time = config.min_free_time
    p.max_gap = config.max_gap
    return p


def radius_estimate(out: np.record) -> RollingRadiusEstimate:
    """The `RollingRadiusEstimate` of a `RADIUS_OUT` record."""
    return RollingRadiusEstimate(
        radius=float(out.radius),
        radius_std=float(out.radius_std),
        converged=bool(out.converged),
        radius_used=float(out.radius_used),
        free_wheels=int(out.free_wheels),
        free_time=float(out.free_time),
    )


class RollingRadiusEstimator:
    """Stateful rolling-radius estimator: feed it one stamp at a time (the records of
    `radius_update`).

    Attributes:
        config: the settings.
        vehicle: the nominal vehicle (the file's R_eff).
        params: the `RADIUS_PARAMS` record.
        state: the `RADIUS_STATE` record.
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
        self.params = radius_params(vehicle, self.config)
        self.state = new_record(RADIUS_STATE)
        self.reset()

    @property
    def faults(self) -> dict[str, int]:
        """Counts per kind of :data:`ROLLING_RADIUS_FAULTS`."""
        return dict(zip(ROLLING_RADIUS_FAULTS, self.state.counts.tolist(), strict=True))

    def reset(self) -> None:
        """Forget everything: the file's radius, the prior covariance, empty filter."""
        radius_reset(self.params, self.state)
        self._last: RollingRadiusEstimate | None = None

    def current(self) -> RollingRadiusEstimate:
        """The last estimate (the file's radius and the prior deviation before any stamp)."""
        if self._last is not None:
            return self._last
        radius_held(self.params, self.state)
        return radius_estimate(self.state.out)

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
        w = np.ascontiguousarray(omega, dtype=np.float64)
        tq = np.ascontiguousarray(wheel_torque, dtype=np.float64)
        if w.shape != (4,) or tq.shape != (4,):
            raise InputShapeError(
                f'omega and wheel_torque must have shape (4,), got {w.shape}, {tq.shape}'
            )
        if radius_update(self.params, self.state, float(t), w, tq, float(speed)):
            self._last = radius_estimate(self.state.out)
            return self._last
        return self.current()


def run_rolling_radius(
    t: ArrayLike,
    omega: ArrayLike,
    wheel_torque: ArrayLike,
    speed: ArrayLike,
    vehicle: EstimatorVehicle,
    config: RollingRadiusConfig | None = None,
) -> Track:
    """Run :class:`RollingRadiusEstimator` over arrays (offline; evaluation, tests).

    Args:
        t: stamps, shape (N,), [s].
        omega: wheel speeds, shape (N, 4), [rad/s].
        wheel_torque: reported wheel torques, shape (N, 4), [N m].
        speed: measured body speed, shape (N,), [m/s].
        vehicle: the nominal vehicle.
        config: settings.

    Returns:
        The estimates at every stamp (`RollingRadiusEstimate`'s fields, e.g.
        ``track['radius']``).

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
    rows = [est.update(float(tt[k]), w[k], tq[k], float(v[k])) for k in range(n)]
    return record_track(tt, RollingRadiusEstimate, rows, est.faults)
