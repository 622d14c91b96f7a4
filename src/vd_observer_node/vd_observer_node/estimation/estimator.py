"""Online estimator of tire forces, loads, friction, slip, resistances and road slope.

Per stamp, from the observer outputs (omega, omega_dot, speed, accel) and the measured wheel
torques: Fx from the wheel spin balance, Fz from the whole-vehicle moment balance using the
previous slope estimate, mu = Fx/Fz, slip, rolling and aero resistance, and the slope from
the longitudinal force balance. See docs/estimation.md. The wheel torques are measured, or
derived from the engine torque and gear (`drivetrain`), or absent: the estimator's
`torque_source` says which, and every estimate carries it.

Online mass (`EstimatorConfig.mass_adaptation`, issue 16): per stamp, before the rest, a
`mass_grade.MassGradeEstimator` takes this stamp's sum of the tyre forces (from the wheel
torque balance, which never uses the mass) and the estimator's body speed. Its `mass_used`
(the estimate once converged, the file's mass before) is the mass of the load transfer (Fz),
hence mu and the rolling resistance, and of the slope balance. It runs on measured torques
only (the engine path cannot see the brakes, so a braking would teach it a wrong mass); a
stamp whose inputs were not all finite, or whose torque cannot be trusted, does not update it.
A mass that hits its clamp is counted as 'mass_clamped'. It restarts with the estimator (gap,
time jump, overflow).

Online rolling radius (`EstimatorConfig.radius_adaptation`, issue 16): per stamp, first of
all, a `rolling_radius.RollingRadiusEstimator` takes the wheel speeds, the wheel torques and
the body speed. Its `radius_used` (the estimate once converged, the file's R_eff before) is
the radius of the wheel spin balance Fx = (T - J*omega_dot)/R (hence the mass's force, Fz,
mu and the slope) and of the slip. Measured torques only (the engine path reports 0 on the
braked wheels, which would pass for free rolling); a stamp whose inputs were not all finite
or whose torque is untrusted does not update it; a clamp is counted as 'radius_clamped'.
With both adaptations on, the mass learnt so far is rescaled whenever the radius used changes
(`MassGradeEstimator.rescale_force`: Fx scales with 1/R, so 1/m with R_old/R_new); with
`mass_waits_for_radius` the mass is not updated at all (it stays the file's) until the radius
has converged.
The speed sensor's scale and R_eff are not separable from v and omega: the radius is the
one the speed sensor sees (see docs/estimation.md section 7.1).

All outputs are finite always: a non-finite input is replaced by its last finite value and
the affected validity flags are cleared; a non-finite, repeated or slightly older stamp
returns the previous estimates unchanged (counted in `rejected_count`); a stamp older by more
than `max_gap` (a looped bag) or a gap longer than `max_gap` resets the estimator; a wheel
lifting off, mu or slope outside their plausible range clear the flags. Every case is counted
per kind in `Estimator.faults` (see docs/faults.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Any, Final

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vd_observer_node.errors import ConfigurationError, InputShapeError
from vd_observer_node.estimation import formulas as phys
from vd_observer_node.estimation.drivetrain import (
    TORQUE_ENGINE,
    TORQUE_MEASURED,
    TORQUE_NONE,
    TORQUE_SOURCES,
)
from vd_observer_node.estimation.faults import ESTIMATOR_FAULTS, FaultCounter
from vd_observer_node.estimation.filters import LowPass
from vd_observer_node.estimation.mass_grade import MassGradeConfig, MassGradeEstimator
from vd_observer_node.estimation.rolling_radius import (
    RollingRadiusConfig,
    RollingRadiusEstimator,
)
from vd_observer_node.estimation.torque_offset import TorqueOffsetConfig
from vd_observer_node.estimation.vehicle import EstimatorVehicle

__all__ = [
    'LOAD_TRANSFER_SOURCES',
    'MASS_MESSAGE_FIELDS',
    'MASS_PREFIX',
    'RADIUS_MESSAGE_FIELDS',
    'RADIUS_PREFIX',
    'SLOPE_ACCEL_SOURCES',
    'TORQUE_OFFSET_PREFIX',
    'Estimates',
    'Estimator',
    'EstimatorConfig',
]

FloatArray = NDArray[np.float64]

#: How the load-transfer force G is obtained, see `EstimatorConfig.load_transfer_source`.
LOAD_TRANSFER_SOURCES: Final = ('tire_forces', 'acceleration')
#: Where m*v_dot in the slope balance comes from, see `EstimatorConfig.slope_accel_source`.
SLOPE_ACCEL_SOURCES: Final = ('speed', 'observer')
#: Prefix of the online mass settings in a flat mapping (`EstimatorConfig.from_mapping`).
MASS_PREFIX: Final = 'mass.'
#: Prefix of the online rolling-radius settings in a flat mapping.
RADIUS_PREFIX: Final = 'radius.'
#: Prefix of the engine-torque offset settings in a flat mapping.
TORQUE_OFFSET_PREFIX: Final = 'torque_offset.'
#: The nested settings: `EstimatorConfig` field -> (flat-key prefix, its config class).
_NESTED: Final[dict[str, tuple[str, Any]]] = {
    'mass': (MASS_PREFIX, MassGradeConfig),
    'radius': (RADIUS_PREFIX, RollingRadiusConfig),
    'torque_offset': (TORQUE_OFFSET_PREFIX, TorqueOffsetConfig),
}
#: The online mass as published (vd_msgs/MassEstimate): each field after the header, in CDR
#: order, and the attribute of `Estimates` (and `cascade.CascadeResult`) it carries.
MASS_MESSAGE_FIELDS: Final = (
    ('mass', 'mass'),
    ('mass_std', 'mass_std'),
    ('mass_used', 'mass_used'),
    ('converged', 'mass_converged'),
    ('excited', 'mass_excited'),
)
#: The online rolling radius as published (vd_msgs/RollingRadiusEstimate), as above.
RADIUS_MESSAGE_FIELDS: Final = (
    ('radius', 'radius'),
    ('radius_std', 'radius_std'),
    ('radius_used', 'radius_used'),
    ('converged', 'radius_converged'),
    ('free_wheels', 'radius_free_wheels'),
)


@dataclass(frozen=True)
class EstimatorConfig:
    """Settings of the estimator.

    Attributes:
        load_transfer_source: 'tire_forces' uses G = sum(Fx) - sum(F_r) (needs only
            cos(alpha)); 'acceleration' uses G = m*v_dot + m*g*sin(alpha_prev) + F_aero.
        force_filter_tau: time constant [s] of the low-pass on Fx and G (0 = off); it delays
            Fx, Fz and mu by filter_order * tau.
        slope_filter_tau: time constant [s] of the low-pass on the slope force balance
            (0 = off); it delays the slope by filter_order * tau.
        slope_accel_source: 'speed' (default) takes the filtered m*v_dot of the slope
            balance as the derivative of the SAME low-pass applied to the speed, so the
            force and inertia terms carry the same filter and noise on v is never
            differentiated raw; 'observer' low-passes the balance built with the observer's
            accel. With slope_filter_tau = 0 both use the observer's accel.
        filter_order: number of first-order stages of both filters.
        min_load_ratio: mu is invalid where Fz < min_load_ratio * static wheel load [-].
        min_excitation_ratio: mu is invalid where |Fx| < min_excitation_ratio * Fz [-].
        max_slope: |alpha| above this [rad] is clamped and flagged invalid.
        min_speed: below this |v| [m/s] the slope is flagged invalid and held (at standstill
            the brake torque is a reaction, not the applied torque the sensor reports).
        slip_eps: floor of the slip denominator [m/s].
        max_gap: a gap between stamps longer than this [s], or a stamp older than the last
            one by more than this (a looped bag), resets the estimator; must be > 0.
        max_mu: |mu| above this [-] is implausible for a tyre on a road: mu is flagged
            invalid (and counted as 'mu_out_of_range'); must be > 0.
        mass_adaptation: estimate the mass online (measured torques only) and use it, once
            converged, for Fz, mu, rolling resistance and the slope; False: the file's mass.
        mass: settings of the online mass estimator (flat keys ``mass.<name>`` in
            `from_mapping` and as node parameters).
        radius_adaptation: estimate the effective rolling radius online from the free-rolling
            wheels (measured torques only) and use it, once converged, in Fx and the slip;
            False: the file's R_eff.
        radius: settings of the online radius estimator (flat keys ``radius.<name>``).
        mass_waits_for_radius: with both adaptations on, the mass is not updated before the
            radius has converged. Off by default: the mass learnt on the file's radius is
            rescaled when the radius converges (docs/estimation.md 7.1), so waiting only
            delays the mass (~40 s on mass_drive).
        torque_offset_adaptation: on the engine path, learn the offset of the engine-torque
            signal while the gearbox is in neutral and subtract it once converged
            (`torque_offset`); no effect on measured torques. On by default: with an exact
            map it learns ~0 and changes nothing (docs/estimation.md 7.2). False: the signal
            as it is.
        torque_offset: settings of the offset estimator (flat keys ``torque_offset.<name>``).
    """

    load_transfer_source: str = 'tire_forces'
    force_filter_tau: float = 0.0
    slope_filter_tau: float = 0.1
    slope_accel_source: str = 'speed'
    filter_order: int = 2
    min_load_ratio: float = 0.1
    min_excitation_ratio: float = 0.02
    max_slope: float = 0.5
    min_speed: float = 0.5
    slip_eps: float = 0.1
    max_gap: float = 0.5
    max_mu: float = 2.0
    mass_adaptation: bool = False
    mass: MassGradeConfig = field(default_factory=MassGradeConfig)
    radius_adaptation: bool = False
    radius: RollingRadiusConfig = field(default_factory=RollingRadiusConfig)
    mass_waits_for_radius: bool = False
    torque_offset_adaptation: bool = True
    torque_offset: TorqueOffsetConfig = field(default_factory=TorqueOffsetConfig)

    def __post_init__(self) -> None:
        if self.load_transfer_source not in LOAD_TRANSFER_SOURCES:
            raise ConfigurationError(
                f'unknown load_transfer_source {self.load_transfer_source!r}; '
                f'use one of {LOAD_TRANSFER_SOURCES}'
            )
        if self.slope_accel_source not in SLOPE_ACCEL_SOURCES:
            raise ConfigurationError(
                f'unknown slope_accel_source {self.slope_accel_source!r}; '
                f'use one of {SLOPE_ACCEL_SOURCES}'
            )
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, float) and not (math.isfinite(value) and value >= 0.0):
                raise ConfigurationError(f'{f.name} must be finite and >= 0, got {value}')
        if self.filter_order < 1:
            raise ConfigurationError(f'filter_order must be >= 1, got {self.filter_order}')
        for name in ('max_gap', 'max_mu'):
            if not getattr(self, name) > 0.0:
                raise ConfigurationError(f'{name} must be > 0, got {getattr(self, name)}')
        if not 0.0 < self.max_slope < math.pi / 2:
            raise ConfigurationError(f'max_slope must be in (0, pi/2), got {self.max_slope}')

    @classmethod
    def setting_keys(cls) -> frozenset[str]:
        """The flat keys `from_mapping` takes: the field names, ``mass.<name>`` for `mass`,
        ``radius.<name>`` for `radius`, ``torque_offset.<name>`` for `torque_offset`."""
        nested = {f'{pre}{f.name}' for pre, kind in _NESTED.values() for f in fields(kind)}
        return frozenset({f.name for f in fields(cls)} - set(_NESTED) | nested)

    @classmethod
    def from_mapping(cls, data: dict[str, Any]) -> EstimatorConfig:
        """Build from a flat mapping (e.g. ROS parameters; `setting_keys`).

        Raises:
            ConfigurationError: unknown key or invalid value.
        """
        data = dict(data)
        for name, (prefix, _) in _NESTED.items():
            if isinstance(data.get(name), dict):  # a YAML section ``mass: {...}``
                data.update({f'{prefix}{k}': v for k, v in data.pop(name).items()})
        unknown = set(data) - cls.setting_keys()
        if unknown:
            raise ConfigurationError(f'unknown estimator settings: {sorted(unknown)}')
        nested = {
            name: kind.from_mapping(
                {k[len(prefix) :]: v for k, v in data.items() if k.startswith(prefix)}
            )
            for name, (prefix, kind) in _NESTED.items()
        }
        flat = {k: v for k, v in data.items() if '.' not in k}
        return cls(**flat, **nested)


@dataclass(frozen=True)
class Estimates:
    """Estimates for one stamp (per-wheel arrays shape (4,), order FL, FR, RL, RR).

    Attributes:
        t: stamp the estimates are for [s].
        fx: [N] tire longitudinal force, road -> tire, positive forward.
        fz: [N] wheel normal load.
        mu: [-] utilised friction Fx/Fz where mu_valid, else 0.
        slip: [-] longitudinal slip ratio, positive driving.
        mu_valid: bool, mu meaningful (loaded and excited wheel, finite inputs).
        rolling: [N] rolling resistance magnitude per wheel.
        aero: [N] aero drag magnitude.
        slope: [rad] road slope, positive uphill (held while invalid).
        slope_valid: slope meaningful (moving, in range, finite inputs).
        torque_source: where the wheel torques came from (`drivetrain.TORQUE_MEASURED`,
            `TORQUE_ENGINE` or `TORQUE_NONE`; with none, fx is 0 and mu and slope are
            invalid).
        mass: [kg] online mass estimate (the file's mass without adaptation).
        mass_std: [kg] its standard deviation (0 without adaptation).
        mass_converged: the estimate is trusted and used (latched until a restart).
        mass_used: [kg] the mass Fz, mu, rolling resistance and slope used at this stamp.
        mass_excited: this stamp updated the mass estimate.
        radius: [m] online effective rolling radius (the file's without adaptation).
        radius_std: [m] its standard deviation (0 without adaptation).
        radius_converged: the radius estimate is trusted and used (latched until a restart).
        radius_used: [m] the radius Fx and the slip used at this stamp.
        radius_free_wheels: wheels that updated the radius at this stamp (0: none).
    """

    t: float
    fx: FloatArray
    fz: FloatArray
    mu: FloatArray
    slip: FloatArray
    mu_valid: NDArray[np.bool_]
    rolling: FloatArray
    aero: float
    slope: float
    slope_valid: bool
    torque_source: int = TORQUE_MEASURED
    mass: float = 0.0
    mass_std: float = 0.0
    mass_converged: bool = False
    mass_used: float = 0.0
    mass_excited: bool = False
    radius: float = 0.0
    radius_std: float = 0.0
    radius_converged: bool = False
    radius_used: float = 0.0
    radius_free_wheels: int = 0


def _as_wheels(name: str, value: ArrayLike) -> FloatArray:
    array = np.asarray(value, dtype=np.float64)
    if array.shape != (4,):
        raise InputShapeError(f'{name} must have shape (4,), got {array.shape}')
    return array


def _all_finite(est: Estimates) -> bool:
    # One sum is the cheapest check at the sensor rate: NaN/Inf anywhere makes it non-finite
    # (so do values near 1e308, which are an overflow in all but name).
    total = float(np.sum(np.concatenate((est.fx, est.fz, est.mu, est.slip, est.rolling))))
    return math.isfinite(total + est.aero + est.slope)


class Estimator:
    """Stateful per-stamp estimator (the estimator node calls `update` per aligned stamp)."""

    def __init__(
        self,
        vehicle: EstimatorVehicle,
        config: EstimatorConfig | None = None,
        torque_source: int = TORQUE_MEASURED,
    ) -> None:
        """Create the estimator.

        Args:
            vehicle: parameters from the shared vehicle file.
            config: settings; defaults if None.
            torque_source: what the `torque` of `update` is: `drivetrain.TORQUE_MEASURED`
                (measured wheel torques), `TORQUE_ENGINE` (from the engine torque and gear,
                `drivetrain.engine_wheel_torques`) or `TORQUE_NONE` (no torque: the `torque`
                argument is ignored, Fx is 0, mu and slope are invalid and Fz takes the
                load transfer from the body acceleration).

        Raises:
            ConfigurationError: unknown torque_source.
        """
        if torque_source not in range(len(TORQUE_SOURCES)):
            raise ConfigurationError(f'unknown torque_source {torque_source!r}')
        self.vehicle = vehicle
        self.config = config or EstimatorConfig()
        self.torque_source = int(torque_source)
        self._force_filter = LowPass(self.config.force_filter_tau, self.config.filter_order)
        self._slope_filter = LowPass(self.config.slope_filter_tau, self.config.filter_order)
        self._speed_filter = LowPass(self.config.slope_filter_tau, self.config.filter_order)
        self._min_load = self.config.min_load_ratio * float(np.min(vehicle.static_wheel_loads))
        self.rejected_count = 0
        self.faults = FaultCounter(ESTIMATOR_FAULTS)
        # The online mass (None: the file's); on measured torques only (module docstring).
        self.mass_estimator = (
            MassGradeEstimator(vehicle, self.config.mass)
            if self.config.mass_adaptation and self.torque_source == TORQUE_MEASURED
            else None
        )
        self.radius_estimator = (
            RollingRadiusEstimator(vehicle, self.config.radius)
            if self.config.radius_adaptation and self.torque_source == TORQUE_MEASURED
            else None
        )
        self.reset()

    def reset(self) -> None:
        """Forget the history (slope back to 0, filters empty); fault counters stay."""
        self._t: float | None = None
        self._slope = 0.0
        # Last finite inputs, packed as omega (4), omega_dot (4), torque (4), speed, accel.
        self._held = np.zeros(14)
        self._radius_prev = math.nan  # [m] the radius of the last stamp's Fx (nan: none)
        self._force_filter.reset()
        self._slope_filter.reset()
        self._speed_filter.reset()
        if self.mass_estimator is not None:
            self.mass_estimator.reset()
        if self.radius_estimator is not None:
            self.radius_estimator.reset()
        self.last: Estimates | None = None

    def update(
        self,
        t: float,
        omega: ArrayLike,
        omega_dot: ArrayLike,
        speed: float,
        accel: float,
        torque: ArrayLike,
        torque_ok: bool = True,
    ) -> Estimates:
        """Estimate everything for stamp t.

        Args:
            t: stamp [s], normally increasing (see the module docstring for the others).
            omega: shape (4,), [rad/s] wheel speeds (observer).
            omega_dot: shape (4,), [rad/s^2] wheel accelerations (observer).
            speed: body speed [m/s] (measured, or the observer's).
            accel: body acceleration dv/dt [m/s^2] (observer).
            torque: shape (4,), [N m] drive minus brake torque per wheel.
            torque_ok: False where the torque source cannot be trusted at this stamp (the
                engine path while the clutch slips): mu and slope are then invalid.

        Raises:
            InputShapeError: a per-wheel input is not of shape (4,).
        """
        packed = np.empty(14)
        packed[0:4] = _as_wheels('omega', omega)
        packed[4:8] = _as_wheels('omega_dot', omega_dot)
        packed[8:12] = _as_wheels('torque', torque)
        packed[12] = speed
        packed[13] = accel
        if not math.isfinite(t):
            return self._reject('non_finite_stamp', t)
        if self._t is not None:
            if t <= self._t:
                if self._t - t <= self.config.max_gap:
                    return self._reject('duplicate_stamp' if t == self._t else 'out_of_order', t)
                self.faults.count('time_jump_back')
                self._restart()
            elif t - self._t > self.config.max_gap:
                self.faults.count('gap')
                self._restart()
        dt = 0.0 if self._t is None else t - self._t
        self._t = t
        ok = np.isfinite(packed)
        if ok.all():
            wheel_ok = np.ones(4, dtype=bool)
            body_ok = True
        else:
            self.faults.count('non_finite_value')
            packed = np.where(ok, packed, self._held)
            wheel_ok = ok[0:4] & ok[4:8] & ok[8:12] & ok[12]
            body_ok = bool(ok.all())
        self._held = packed
        if not torque_ok:
            wheel_ok = np.zeros(4, dtype=bool)
            body_ok = False
        est = self._estimate(t, dt, packed, wheel_ok, body_ok)
        if not _all_finite(est):
            # Overflow from absurd (finite) input: drop the poisoned state, report nothing valid.
            self.faults.count('non_finite_output')
            self.reset()
            self._t = t
            est = self._empty(t)
            self.last = est
        return est

    def _reject(self, kind: str, t: float) -> Estimates:
        self.faults.count(kind)
        self.rejected_count += 1
        return self.last if self.last is not None else self._empty(t)

    def _restart(self) -> None:
        """Reset after a time jump or gap, keeping the last finite inputs to hold."""
        held = self._held
        self.reset()
        self._held = held

    def _estimate(
        self,
        t: float,
        dt: float,
        x: FloatArray,
        wheel_ok: NDArray[np.bool_],
        body_ok: bool,
    ) -> Estimates:
        veh, cfg = self.vehicle, self.config
        omega, omega_dot, torque = x[0:4], x[4:8], x[8:12]
        no_torque = self.torque_source == TORQUE_NONE
        v = float(x[12])
        accel = float(x[13])
        all_ok = bool(wheel_ok.all()) and body_ok
        radius = self._radius_step(t, omega, torque, v, all_ok)
        r_used = radius[3]
        waiting = self.radius_estimator is not None and cfg.mass_waits_for_radius and not radius[2]
        # Fx uses another radius from now on: the mass learnt so far is rescaled to it
        rescale = not (waiting or math.isnan(self._radius_prev) or r_used == self._radius_prev)
        mass_est = self.mass_estimator
        if rescale and mass_est is not None and mass_est.rescale_force(self._radius_prev / r_used):
            self.faults.count('mass_clamped')
        self._radius_prev = r_used
        # Without the torque the balance has no force: Fx is 0 (not -J*omega_dot/R).
        fx_raw = (
            np.zeros(4)
            if no_torque
            else phys.tire_longitudinal_force(torque, omega_dot, veh, r_used)
        )
        if waiting:
            mass = self._fixed_mass()
        else:
            mass = self._mass_step(t, float(np.sum(fx_raw)), v, all_ok)
        m_used = mass[3]
        # Same smooth sign as the simulator's rolling resistance; drag is exactly k*v*|v|.
        direction = float(phys.motion_direction(v, veh.rolling_regularisation_speed))
        aero = float(phys.aero_drag(v, veh))
        aero_signed = math.copysign(aero, v)
        c_roll = float(phys.rolling_coefficient(v, veh))
        cos_prev, sin_prev = math.cos(self._slope), math.sin(self._slope)
        weight = m_used * veh.gravity

        # Sum of the rolling resistances follows from sum(Fz) = m*g*cos(alpha) in both
        # load-transfer forms, so it does not depend on the transfer itself.
        rolling_sum = c_roll * weight * cos_prev
        if cfg.load_transfer_source == 'tire_forces' and not no_torque:
            ground = float(np.sum(fx_raw)) - direction * rolling_sum
        else:
            ground = m_used * accel + weight * sin_prev + aero_signed
        filtered = self._force_filter.update(dt, np.append(fx_raw, ground))
        fx, ground_f = filtered[:4], float(filtered[4])

        # A load transfer beyond the axle's load means the wheel has lifted off: Fz = 0.
        fz = np.maximum(phys.wheel_loads(ground_f, cos_prev, veh, m_used), 0.0)
        rolling = phys.rolling_resistance(v, fz, veh)
        mu, mu_valid = phys.utilised_friction(fx, fz, self._min_load, cfg.min_excitation_ratio)
        mu_valid &= wheel_ok & (not no_torque)
        if bool(np.any(fz < self._min_load)):
            self.faults.count('wheel_lift')
        implausible = mu_valid & (np.abs(mu) > cfg.max_mu)
        if implausible.any():
            self.faults.count('mu_out_of_range')
            mu_valid &= ~implausible
        mu = np.where(mu_valid, mu, 0.0)
        slip = phys.slip_ratio(omega, v, veh, cfg.slip_eps, r_used)

        forces = float(np.sum(fx_raw)) - direction * rolling_sum - aero_signed
        if cfg.slope_accel_source == 'speed' and cfg.slope_filter_tau > 0.0:
            self._speed_filter.update(dt, v)
            accel_f = float(self._speed_filter.derivative())
            net_f = float(self._slope_filter.update(dt, forces)) - m_used * accel_f
        else:
            net_f = float(self._slope_filter.update(dt, forces - m_used * accel))
        slope, in_range = phys.slope_from_forces(net_f, veh, cfg.max_slope, m_used)
        usable = body_ok and abs(v) >= cfg.min_speed and not no_torque
        if usable and not in_range:
            # |N| > m g has no arcsin at all; below that the slope is only implausible.
            sine = net_f / weight
            self.faults.count('arcsin_domain' if abs(sine) > 1.0 else 'slope_out_of_range')
        slope_valid = bool(in_range) and usable
        if self.torque_source == TORQUE_ENGINE and usable and not in_range:
            # The balance needs a force the engine path cannot know of (the brakes): the
            # torques are wrong, so is mu.
            mu_valid = np.zeros(4, dtype=bool)
            mu = np.zeros(4)
        if slope_valid:
            # An invalid stamp keeps the last valid slope (it is published as invalid).
            self._slope = float(slope)
        self.last = Estimates(
            t=t,
            fx=fx,
            fz=fz,
            mu=mu,
            slip=slip,
            mu_valid=mu_valid,
            rolling=rolling,
            aero=aero,
            slope=self._slope,
            slope_valid=slope_valid,
            torque_source=self.torque_source,
            mass=mass[0],
            mass_std=mass[1],
            mass_converged=bool(mass[2]),
            mass_used=m_used,
            mass_excited=bool(mass[4]),
            radius=radius[0],
            radius_std=radius[1],
            radius_converged=bool(radius[2]),
            radius_used=r_used,
            radius_free_wheels=int(radius[4]),
        )
        return self.last

    def _radius_step(
        self, t: float, omega: FloatArray, torque: FloatArray, v: float, ok: bool
    ) -> tuple[float, ...]:
        """Advance the online radius: (radius, radius_std, converged, radius_used, free).

        Args:
            t: stamp [s] (accepted by the estimator).
            omega: shape (4,), [rad/s] wheel speeds.
            torque: shape (4,), [N m] reported wheel torques.
            v: the estimator's body speed [m/s].
            ok: every input of the stamp was finite and the torque trusted; else the radius
                holds (its estimator is not called).
        """
        est = self.radius_estimator
        if est is None or not ok:
            return self._fixed_radius()
        clamped = est.faults['radius_clamped']
        out = est.update(t, omega, torque, v)
        if est.faults['radius_clamped'] != clamped:
            self.faults.count('radius_clamped')
        return out.radius, out.radius_std, float(out.converged), out.radius_used, out.free_wheels

    def _fixed_radius(self) -> tuple[float, ...]:
        """The radius fields where nothing was estimated: the file's or the estimator's."""
        r0 = self.vehicle.effective_radius
        if self.radius_estimator is None:
            return r0, 0.0, 0.0, r0, 0
        out = self.radius_estimator.current()
        return out.radius, out.radius_std, float(out.converged), out.radius_used, 0

    def _mass_step(self, t: float, sum_fx: float, v: float, ok: bool) -> tuple[float, ...]:
        """Advance the online mass: (mass, mass_std, converged, mass_used, excited).

        Args:
            t: stamp [s] (accepted by the estimator).
            sum_fx: sum of the four tyre forces [N] from the wheel torque balance.
            v: the estimator's body speed [m/s].
            ok: every input of the stamp was finite and the torque trusted; else the mass
                estimator holds (it is given a non-finite force, which it skips).
        """
        est = self.mass_estimator
        if est is None:
            return self._fixed_mass()
        clamped = est.faults['mass_clamped']
        out = est.update(t, sum_fx if ok else math.nan, v)
        if est.faults['mass_clamped'] != clamped:
            self.faults.count('mass_clamped')
        # a held stamp (skipped here) did not update the mass, whatever the last one did
        excited = float(out.excited and ok)
        return out.mass, out.mass_std, float(out.converged), out.mass_used, excited

    def _fixed_mass(self) -> tuple[float, ...]:
        """The mass fields where nothing was estimated: the file's or the mass estimator's."""
        m0 = self.vehicle.mass
        if self.mass_estimator is None:
            return m0, 0.0, 0.0, m0, 0.0
        out = self.mass_estimator.current()
        return out.mass, out.mass_std, float(out.converged), out.mass_used, 0.0

    def _empty(self, t: float) -> Estimates:
        zeros = np.zeros(4)
        mass = self._fixed_mass()
        radius = self._fixed_radius()
        return Estimates(
            t=t if math.isfinite(t) else 0.0,
            fx=zeros,
            fz=self.vehicle.static_wheel_loads,
            mu=zeros,
            slip=zeros,
            mu_valid=np.zeros(4, dtype=bool),
            rolling=zeros,
            aero=0.0,
            slope=0.0,
            slope_valid=False,
            torque_source=self.torque_source,
            mass=mass[0],
            mass_std=mass[1],
            mass_converged=False,
            mass_used=mass[3],
            radius=radius[0],
            radius_std=radius[1],
            radius_used=radius[3],
        )
