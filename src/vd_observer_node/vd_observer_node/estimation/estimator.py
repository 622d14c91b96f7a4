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
the affected validity flags are cleared, except a wheel torque, which is never held (Fx 0,
the load transfer from the acceleration, mu and slope invalid at that stamp); a non-finite,
repeated or slightly older stamp returns the previous estimates unchanged (counted in
`rejected_count`); a stamp older by more than `max_gap` (a looped bag) or a gap longer than
`max_gap` resets the estimator; a wheel lifting off, mu or slope outside their plausible range
clear the flags. Every case is counted
per kind in `Estimator.faults` (see docs/faults.md).

The per-stamp math is compiled, in `estimator_step` (`estimator_update` over named records);
`Estimator` builds its records (`estimator_params`, `EstimatorState`) and calls it, and so
does the cascade loop (`cascade_step.cascade_block`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace
from typing import Any, Final

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vd_observer_node.errors import ConfigurationError, InputShapeError
from vd_observer_node.estimation.axle_loads import load_model_params
from vd_observer_node.estimation.drivetrain import TORQUE_MEASURED, TORQUE_SOURCES
from vd_observer_node.estimation.estimator_step import (
    ESTIMATES,
    ESTIMATOR_PARAMS,
    ESTIMATOR_STATE,
    REJECTED_SLOT,
    EstimatorParts,
    estimator_reset,
    estimator_update_arrays,
    new_estimator_input,
)
from vd_observer_node.estimation.faults import ESTIMATOR_FAULTS, FaultCounter
from vd_observer_node.estimation.mass_grade import MassGradeConfig, mass_params
from vd_observer_node.estimation.rate_settings import (
    REFERENCE_SLOPE_FILTER_TAU,
    slope_filter_tau_for_rate,
)
from vd_observer_node.estimation.rolling_radius import RollingRadiusConfig, radius_params
from vd_observer_node.estimation.torque_offset import TorqueOffsetConfig
from vd_observer_node.estimation.vehicle import EstimatorVehicle
from vd_observer_node.kernel._jit import new_record, record_array

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
    'EstimatorState',
    'estimates_from_record',
    'estimator_params',
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
            (0 = off); it delays the slope by filter_order * tau. Unset (default): it follows
            the rate f of the slower of the wheel and body-speed inputs, 0.1 s at and above
            1 kHz and 0.1 s * (1000 Hz / f)^(1/4) below (0.178 s at 100 Hz), from the first
            stamps on (0.1 s until the rate is measured); docs/estimation.md.
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
            its standard deviation is within ``mass.use_std_ratio`` (or it has converged),
            for Fz, mu, rolling resistance and the slope; False: the file's mass.
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
    slope_filter_tau: float | None = None
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
        if isinstance(self.slope_filter_tau, int) and not isinstance(self.slope_filter_tau, bool):
            # a YAML or ROS parameter 1 means 1.0 (frozen: set through object)
            object.__setattr__(self, 'slope_filter_tau', float(self.slope_filter_tau))
        if self.slope_filter_tau is not None and not isinstance(self.slope_filter_tau, float):
            raise ConfigurationError(
                f'slope_filter_tau must be a number of seconds or unset, got '
                f'{self.slope_filter_tau!r}'
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

    @property
    def slope_tau(self) -> float:
        """[s] the slope low-pass time constant in use: ``slope_filter_tau``, or the
        reference rate's value while it is left to a rate not known yet."""
        if self.slope_filter_tau is None:
            return REFERENCE_SLOPE_FILTER_TAU
        return self.slope_filter_tau

    def at_rate(self, rate_hz: float) -> tuple[EstimatorConfig, dict[str, float]]:
        """These settings for inputs at `rate_hz`: the ones left unset follow the rate.

        Args:
            rate_hz: [Hz] the rate of the slower of the wheel and body-speed inputs
                (`rate_settings.sample_rate_hz`); nan: unknown, nothing changes.

        Returns:
            The settings with every rate-dependent one fixed, and the ones fixed here by
            name with their values (empty where the user set them all).
        """
        if self.slope_filter_tau is not None or not math.isfinite(rate_hz):
            return self, {}
        tau = slope_filter_tau_for_rate(rate_hz)
        return replace(self, slope_filter_tau=tau), {'slope_filter_tau': tau}

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


def estimator_params(
    vehicle: EstimatorVehicle, config: EstimatorConfig, torque_source: int = TORQUE_MEASURED
) -> np.record:
    """The `estimator_step.ESTIMATOR_PARAMS` record of a vehicle, settings and torque source.

    The online mass and radius run on measured torques only (module docstring).
    """
    static = vehicle.static_wheel_loads
    p = new_record(ESTIMATOR_PARAMS)
    p.mass = vehicle.mass
    p.gravity = vehicle.gravity
    p.radius = vehicle.effective_radius
    p.inertia_front = vehicle.inertia_front
    p.inertia_rear = vehicle.inertia_rear
    p.drag = vehicle.drag_factor
    p.rolling_c0 = vehicle.rolling_c0
    p.rolling_c1 = vehicle.rolling_c1
    p.rolling_reg = vehicle.rolling_regularisation_speed
    p.cg_height = vehicle.cg_height
    p.cg_to_front = vehicle.cg_to_front_axle
    p.cg_to_rear = vehicle.cg_to_rear_axle
    p.wheelbase = vehicle.wheelbase
    p.load_transfer = LOAD_TRANSFER_SOURCES.index(config.load_transfer_source)
    p.force_tau = config.force_filter_tau
    p.slope_tau = config.slope_tau
    p.slope_accel = SLOPE_ACCEL_SOURCES.index(config.slope_accel_source)
    p.min_load = config.min_load_ratio * float(np.min(static))
    p.min_excitation = config.min_excitation_ratio
    p.max_sine = math.sin(config.max_slope)
    p.min_speed = config.min_speed
    p.slip_eps = config.slip_eps
    p.max_gap = config.max_gap
    p.max_mu = config.max_mu
    p.static_front = static[0]
    p.static_rear = static[2]
    p.torque_source = torque_source
    measured = torque_source == TORQUE_MEASURED
    p.mass_on = config.mass_adaptation and measured
    p.radius_on = config.radius_adaptation and measured
    p.mass_waits = config.mass_waits_for_radius
    p.mass_p = mass_params(vehicle, config.mass)
    p.radius_p = radius_params(vehicle, config.radius)
    p.loads = load_model_params(vehicle.vertical)
    return p


#: the `ESTIMATES` fields in their order (what ``item()`` returns)
_ESTIMATE_FIELDS: tuple[str, ...] = tuple(ESTIMATES.names or ())


def estimates_from_record(est: np.record) -> Estimates:
    """The `Estimates` of an `estimator_step.ESTIMATES` record (copies).

    Read in one ``item()`` call (Python scalars; its arrays are views into the record, so
    they are copied): a record's attribute access costs about 2 us in Python, and the live
    chain builds one `Estimates` per stamp.
    """
    v = dict(zip(_ESTIMATE_FIELDS, est.item(), strict=True))
    return Estimates(
        t=float(v['t']),
        fx=v['fx'].copy(),
        fz=v['fz'].copy(),
        mu=v['mu'].copy(),
        slip=v['slip'].copy(),
        mu_valid=np.array(v['mu_valid'], dtype=np.bool_),
        rolling=v['rolling'].copy(),
        aero=float(v['aero']),
        slope=float(v['slope']),
        slope_valid=bool(v['slope_valid']),
        torque_source=int(v['torque_source']),
        mass=float(v['mass']),
        mass_std=float(v['mass_std']),
        mass_converged=bool(v['mass_converged']),
        mass_used=float(v['mass_used']),
        mass_excited=bool(v['mass_excited']),
        radius=float(v['radius']),
        radius_std=float(v['radius_std']),
        radius_converged=bool(v['radius_converged']),
        radius_used=float(v['radius_used']),
        radius_free_wheels=int(v['radius_free_wheels']),
    )


class EstimatorState:
    """The records and arrays `estimator_step.estimator_update` advances.

    Attributes:
        record: the `ESTIMATOR_STATE` record (stamps, slope, held inputs, the online mass
            and radius, the last estimate, the fault counts).
        force_stages: shape (order, 5), the force low-pass's stages (Fx (4), G).
        slope_stages: shape (order, 1), the slope balance's low-pass stages.
        speed_stages: shape (order, 1), the speed low-pass's stages.
    """

    def __init__(self, params: np.record, order: int) -> None:
        """A reset state for filters of `order` stages."""
        self.record = new_record(ESTIMATOR_STATE)
        self.force_stages = np.zeros((order, 5))
        self.slope_stages = np.zeros((order, 1))
        self.speed_stages = np.zeros((order, 1))
        estimator_reset(params, self.record)

    @property
    def args(self) -> tuple[np.record, FloatArray, FloatArray, FloatArray]:
        """(record, force, slope, speed stages): the state arguments of `estimator_update`."""
        return self.record, self.force_stages, self.slope_stages, self.speed_stages


def _as_wheels(name: str, value: ArrayLike) -> FloatArray:
    array = np.ascontiguousarray(value, dtype=np.float64)
    if array.shape != (4,):
        raise InputShapeError(f'{name} must have shape (4,), got {array.shape}')
    return array


class Estimator:
    """Stateful per-stamp estimator (the estimator node calls `update` per aligned stamp):
    the records of `estimator_step.estimator_update`, and its fault counts as a
    `FaultCounter`.

    Attributes:
        vehicle: parameters from the shared vehicle file.
        config: the settings.
        torque_source: the torque source code (`drivetrain.TORQUE_*`).
        params: the `ESTIMATOR_PARAMS` record.
        state: the `EstimatorState`.
    """

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
        self.params = estimator_params(vehicle, self.config, self.torque_source)
        self.state = EstimatorState(self.params, self.config.filter_order)
        self._faults = FaultCounter(ESTIMATOR_FAULTS)
        self._synced = np.zeros(len(ESTIMATOR_FAULTS), dtype=np.int64)
        self._est = new_record(ESTIMATES)
        self._input = new_estimator_input()  # a stamp's speed only (the estimator node's)
        #: the records (never replaced: a reset works in place) as `estimator_update` takes
        #: them; input and output as the arrays they live in (`update`'s fast numba call)
        self.parts = EstimatorParts(
            record_array(self.params), record_array(self.state.record), *self.state.args[1:]
        )
        self._io = (record_array(self._input), record_array(self._est))
        self._last: Estimates | None = None  # what `last` and a rejected stamp return
        # compile (or load from numba's cache) now, on copies, not at the first stamp
        copies = EstimatorParts(*(a.copy() for a in self.parts))
        estimator_update_arrays(copies, 0.0, *(a.copy() for a in self._io))

    def reset(self) -> None:
        """Forget the history (slope back to 0, filters empty); fault counters stay."""
        estimator_reset(self.params, self.state.record)
        self._last = None

    def follow_rate(self, rate_hz: float) -> dict[str, float]:
        """Fix the settings left to the inputs' rate, now that it is known (a live node
        measures it over its first stamps); the filters keep their state.

        Args:
            rate_hz: [Hz] rate of the slower of the wheel and body-speed inputs.

        Returns:
            The settings fixed here, by name, with their values (empty: none was left
            unset, or they were fixed before).
        """
        self.config, fixed = self.config.at_rate(rate_hz)
        if fixed:
            self.params.slope_tau = self.config.slope_tau
        return fixed

    @property
    def mass_adaptation(self) -> bool:
        """Whether the online mass runs (configured, and the torques are measured)."""
        return bool(self.params.mass_on)

    @property
    def radius_adaptation(self) -> bool:
        """Whether the online radius runs (configured, and the torques are measured)."""
        return bool(self.params.radius_on)

    @property
    def rejected_count(self) -> int:
        """Stamps rejected (non-finite, repeated or slightly older)."""
        return int(self.state.record.counts[REJECTED_SLOT])

    @property
    def last(self) -> Estimates | None:
        """The last estimate (None before the first, and after a reset)."""
        return self._last if self.state.record.has_last else None

    @property
    def faults(self) -> FaultCounter:
        """Input faults per kind (synced from the state's counts)."""
        counts = np.array(self.state.record.counts[:REJECTED_SLOT])
        delta = counts - self._synced
        for slot in np.flatnonzero(delta).tolist():
            self._faults.count(ESTIMATOR_FAULTS[slot], int(delta[slot]))
        self._synced = counts
        return self._faults

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
        rejected = self.rejected_count
        inp = self._input
        inp.omega[:] = _as_wheels('omega', omega)
        inp.omega_dot[:] = _as_wheels('omega_dot', omega_dot)
        inp.torque[:] = _as_wheels('torque', torque)
        inp.speed, inp.accel, inp.torque_ok = float(speed), float(accel), bool(torque_ok)
        estimator_update_arrays(self.parts, float(t), *self._io)
        if self.rejected_count != rejected:
            # a rejected stamp: the last estimate itself, or a new empty one before any
            if self._last is not None and self.state.record.has_last:
                return self._last
            return estimates_from_record(self._est)
        self._last = estimates_from_record(self._est)
        return self._last
