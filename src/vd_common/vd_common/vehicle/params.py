"""Vehicle parameter dataclasses and the validating loader of ``config/clio_rl_1_1.yaml``.

This is the one parser of the vehicle file: the simulator uses :class:`VehicleParams` as
is, and the estimators of vd_observer_node take their subset from it
(``EstimatorVehicle.from_params``), so a key is read, range-checked and named in errors in
one place.

All values are SI (angles in rad, engine speeds in rad/s). The loader refuses a missing or
out-of-range value with one :class:`~vd_common.errors.ParameterError` that names the
parameter by its dotted YAML path, e.g. ``chassis.mass must be > 0 kg, got -3``;
:func:`load_vehicle` puts the file in front: ``vehicle file x.yaml: chassis.mass must be ...``.

Both parsers of a vehicle file (this one and the estimators',
:func:`vd_common.vehicle.estimation.parse_estimation_vehicle`) refuse a key that is not in
:data:`VEHICLE_FILE_KEYS` before reading a value, naming the closest known key
(``brakes.gain_frnt is not a known key; did you mean brakes.gain_front?``): one schema, the
union of the simulator's keys and the estimators', so a full simulator file passes both and a
misspelt key is never ignored or reported as another key missing. The simulator does not read
the estimation-only keys (``gearbox.efficiency``, ``gearbox.reverse_ratio``, ``driveline``,
``torque_converter``, ``brakes.gain_*``). ``environment.gravity`` is optional in both, default
:data:`DEFAULT_GRAVITY` (9.81 m/s^2).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from vd_common.errors import ParameterError
from vd_common.yaml_reader import KeySchema, MappingReader, check_known_keys, load_yaml_mapping

__all__ = [
    'DEFAULT_GRAVITY',
    'VEHICLE_FILE_KEYS',
    'AeroParams',
    'BrakeParams',
    'ChassisParams',
    'ClutchParams',
    'EngineParams',
    'EnvironmentParams',
    'GearboxParams',
    'RollingResistanceParams',
    'SuspensionParams',
    'TireParams',
    'VehicleParams',
    'WheelParams',
    'check_vehicle_keys',
    'default_vehicle_file',
    'load_vehicle',
    'load_vehicle_if_full',
    'parse_vehicle',
    'read_aero',
    'read_environment',
    'read_rolling',
    'read_tire',
    'sprung_cg_to_front_axle',
]

#: [m/s^2] ``environment.gravity`` when the file does not give it.
DEFAULT_GRAVITY = 9.81


@dataclass(frozen=True)
class ChassisParams:
    """Whole-vehicle mass and geometry (CG refers to the whole vehicle)."""

    mass: float  # [kg] total, unsprung masses included
    unsprung_mass_front: float  # [kg] per front corner
    unsprung_mass_rear: float  # [kg] per rear corner
    wheelbase: float  # [m] L
    cg_to_front_axle: float  # [m] a (whole vehicle)
    cg_height: float  # [m] h above ground (whole vehicle)
    pitch_inertia: float  # [kg m^2] sprung mass about y through its CG
    track_front: float  # [m] unused in the x-z model
    track_rear: float  # [m] unused in the x-z model

    @property
    def sprung_cg_to_front_axle(self) -> float:
        """[m] the sprung mass's CG to the front axle (the unsprung masses sit on the axles)."""
        return sprung_cg_to_front_axle(
            self.mass,
            2.0 * self.unsprung_mass_front,
            2.0 * self.unsprung_mass_rear,
            self.wheelbase,
            self.cg_to_front_axle,
        )


def sprung_cg_to_front_axle(
    mass: float, unsprung_front: float, unsprung_rear: float, wheelbase: float, a: float
) -> float:
    """[m] the sprung mass's CG to the front axle from the whole vehicle's ``a`` [m], its mass
    and each axle's unsprung mass [kg] (both corners), which sit on the axles."""
    return (mass * a - unsprung_rear * wheelbase) / (mass - unsprung_front - unsprung_rear)


@dataclass(frozen=True)
class SuspensionParams:
    """Per-corner suspension spring and damper."""

    stiffness_front: float  # [N/m]
    stiffness_rear: float  # [N/m]
    damping_front: float  # [N s/m]
    damping_rear: float  # [N s/m]


@dataclass(frozen=True)
class WheelParams:
    """Wheel rotational inertia, radii and tyre vertical properties (per wheel)."""

    inertia_front: float  # [kg m^2]
    inertia_rear: float  # [kg m^2]
    unloaded_radius: float  # [m]
    effective_radius: float  # [m] R_eff
    tyre_vertical_stiffness: float  # [N/m]
    tyre_vertical_damping: float  # [N s/m]


@dataclass(frozen=True)
class AeroParams:
    """Aerodynamic drag F = 0.5 rho Cx A v^2."""

    drag_coefficient: float  # [-] Cx
    frontal_area: float  # [m^2] A
    air_density: float  # [kg/m^3] rho


@dataclass(frozen=True)
class RollingResistanceParams:
    """Paper eq. 7: F_r = c0 (1 + c1 v / 160) Fz, v in m/s."""

    c0: float  # [-]
    c1: float  # [km/h per m/s]
    regularisation_speed: float  # [m/s] tanh(v / v_r) replaces sign(v) near standstill


@dataclass(frozen=True)
class EnvironmentParams:
    """Environment constants."""

    gravity: float  # [m/s^2]


@dataclass(frozen=True)
class TireParams:
    """Magic Formula (MF 5.2 style) pure longitudinal slip coefficients.

    See ``docs/vehicle_model.md`` for the equations. ``low_speed_velocity`` is the floor
    of the slip denominator that keeps the model well behaved at standstill.
    """

    nominal_load: float  # [N] Fz0
    pCx1: float  # [-] shape factor C  # noqa: N815 (MF 5.2 name)
    pDx1: float  # [-] peak friction at Fz0  # noqa: N815 (MF 5.2 name)
    pDx2: float  # [-] variation of peak friction with load  # noqa: N815 (MF 5.2 name)
    pEx1: float  # [-] curvature at Fz0  # noqa: N815 (MF 5.2 name)
    pEx2: float  # [-] curvature variation with load  # noqa: N815 (MF 5.2 name)
    pEx3: float  # [-] curvature variation with load squared  # noqa: N815 (MF 5.2 name)
    pEx4: float  # [-] curvature asymmetry drive/brake  # noqa: N815 (MF 5.2 name)
    pKx1: float  # [-] slip stiffness / Fz at Fz0  # noqa: N815 (MF 5.2 name)
    pKx2: float  # [-] slip stiffness variation with load  # noqa: N815 (MF 5.2 name)
    pKx3: float  # [-] exponent of slip stiffness variation with load  # noqa: N815 (MF 5.2 name)
    pHx1: float  # [-] horizontal shift  # noqa: N815 (MF 5.2 name)
    pHx2: float  # [-] horizontal shift variation with load  # noqa: N815 (MF 5.2 name)
    pVx1: float  # [-] vertical shift / Fz  # noqa: N815 (MF 5.2 name)
    pVx2: float  # [-] vertical shift variation with load  # noqa: N815 (MF 5.2 name)
    low_speed_velocity: float  # [m/s] v_min in the slip denominator


@dataclass(frozen=True)
class EngineParams:
    """Petrol engine: full-load curve, drag, idle governor, rev limiter."""

    inertia: float  # [kg m^2] crankshaft + flywheel + clutch disc
    full_load_speed: tuple[float, ...]  # [rad/s] breakpoints, increasing
    full_load_torque: tuple[float, ...]  # [N m] full-load (throttle 1) torque at breakpoints
    drag_torque_c0: float  # [N m] closed-throttle drag at zero speed
    drag_torque_c1: float  # [N m s/rad] closed-throttle drag growth with speed
    idle_speed: float  # [rad/s]
    idle_gain: float  # [N m s/rad] proportional idle governor gain
    max_speed: float  # [rad/s] rev limiter: fuel cut-off ramp ends here


@dataclass(frozen=True)
class ClutchParams:
    """Automatic launch clutch, engagement scheduled on engine speed."""

    capacity: float  # [N m] transmissible torque when fully engaged
    slip_speed: float  # [rad/s] tanh regularisation of the friction sign
    engage_start_speed: float  # [rad/s] engine speed where engagement begins
    engage_full_speed: float  # [rad/s] engine speed of full engagement
    engage_time: float  # [s] engagement ramp 0 -> 1 when the clutch closes after a shift


@dataclass(frozen=True)
class GearboxParams:
    """Manual gearbox driven by an automatic shift logic, and the final drive."""

    ratios: tuple[float, ...]  # [-] gear 1..n, decreasing
    final_drive: float  # [-]
    upshift_speed_closed: float  # [rad/s] engine speed for an upshift at throttle 0
    upshift_speed_open: float  # [rad/s] engine speed for an upshift at throttle 1
    downshift_speed: float  # [rad/s] engine speed below which it shifts down
    shift_time: float  # [s] torque interruption (clutch open, throttle cut)


@dataclass(frozen=True)
class BrakeParams:
    """Brake torque capacity per wheel and friction-sign regularisation."""

    max_torque_front: float  # [N m] per front wheel at pedal 1
    max_torque_rear: float  # [N m] per rear wheel at pedal 1
    lock_speed: float  # [rad/s] tanh(omega / w_b) replaces sign(omega)


@dataclass(frozen=True)
class VehicleParams:
    """All parameters of the Clio model."""

    name: str
    chassis: ChassisParams
    suspension: SuspensionParams
    wheel: WheelParams
    aero: AeroParams
    rolling_resistance: RollingResistanceParams
    environment: EnvironmentParams
    tire: TireParams
    engine: EngineParams
    clutch: ClutchParams
    gearbox: GearboxParams
    brakes: BrakeParams


def _keys(*names: str) -> dict[str, KeySchema | None]:
    return dict.fromkeys(names)


#: Every key a vehicle file may hold, by section: the simulator's (:func:`parse_vehicle`) and
#: the estimators' (:mod:`vd_common.vehicle.estimation`). A key added to either parser is added
#: here, or the parser refuses its own key (tests load every shipped file through both).
VEHICLE_FILE_KEYS: KeySchema = {
    'name': None,
    'chassis': _keys(
        'mass',
        'unsprung_mass_front',
        'unsprung_mass_rear',
        'wheelbase',
        'cg_to_front_axle',
        'cg_height',
        'pitch_inertia',
        'track_front',
        'track_rear',
    ),
    'suspension': _keys('stiffness_front', 'stiffness_rear', 'damping_front', 'damping_rear'),
    'wheel': _keys(
        'inertia_front',
        'inertia_rear',
        'unloaded_radius',
        'effective_radius',
        'tyre_vertical_stiffness',
        'tyre_vertical_damping',
    ),
    'aero': _keys('drag_coefficient', 'frontal_area', 'air_density'),
    'rolling_resistance': _keys('c0', 'c1', 'regularisation_speed'),
    'environment': _keys('gravity'),
    'tire': _keys(*TireParams.__dataclass_fields__),
    'engine': _keys(
        'inertia',
        'full_load_speed',
        'full_load_torque',
        'drag_torque_c0',
        'drag_torque_c1',
        'idle_speed',
        'idle_gain',
        'max_speed',
    ),
    'clutch': _keys(
        'capacity', 'slip_speed', 'engage_start_speed', 'engage_full_speed', 'engage_time'
    ),
    'gearbox': _keys(
        'ratios',
        'final_drive',
        'upshift_speed_closed',
        'upshift_speed_open',
        'downshift_speed',
        'shift_time',
        'efficiency',
        'reverse_ratio',
    ),
    'brakes': _keys(
        'max_torque_front', 'max_torque_rear', 'lock_speed', 'gain_front', 'gain_rear'
    ),
    'driveline': _keys('layout', 'front_share'),
    'torque_converter': _keys('speed_ratio', 'torque_ratio', 'capacity_factor'),
}


def check_vehicle_keys(data: object) -> None:
    """Refuse the first key of a vehicle file that :data:`VEHICLE_FILE_KEYS` lacks.

    Raises:
        ParameterError: ``chassis.mas is not a known key; did you mean chassis.mass?``.
    """
    check_known_keys(data, VEHICLE_FILE_KEYS, ParameterError)


# The shipped parameter file, in ``config/`` of this package (vd_common).
_CLIO_FILE = 'clio_rl_1_1.yaml'


def _chassis(r: MappingReader) -> ChassisParams:
    mass = r.number('mass', 'kg', gt=0.0)
    mu_f = r.number('unsprung_mass_front', 'kg', gt=0.0)
    mu_r = r.number('unsprung_mass_rear', 'kg', gt=0.0)
    if 2.0 * (mu_f + mu_r) >= mass:
        raise ParameterError(
            f'chassis.unsprung_mass_front/rear: 2*(front+rear) = {2 * (mu_f + mu_r):g} kg must '
            f'be < chassis.mass = {mass:g} kg'
        )
    wheelbase = r.number('wheelbase', 'm', gt=0.0)
    a = r.number('cg_to_front_axle', 'm', gt=0.0, lt=wheelbase)
    a_sprung = sprung_cg_to_front_axle(mass, 2.0 * mu_f, 2.0 * mu_r, wheelbase, a)
    if not 0.0 < a_sprung < wheelbase:
        raise ParameterError(
            f'chassis.cg_to_front_axle = {a:g} m with these unsprung masses puts the sprung '
            f'mass CG at {a_sprung:.3f} m from the front axle, outside the wheelbase'
        )
    return ChassisParams(
        mass=mass,
        unsprung_mass_front=mu_f,
        unsprung_mass_rear=mu_r,
        wheelbase=wheelbase,
        cg_to_front_axle=a,
        cg_height=r.number('cg_height', 'm', gt=0.0),
        pitch_inertia=r.number('pitch_inertia', 'kg m^2', gt=0.0),
        track_front=r.number('track_front', 'm', gt=0.0),
        track_rear=r.number('track_rear', 'm', gt=0.0),
    )


def _suspension(r: MappingReader) -> SuspensionParams:
    return SuspensionParams(
        stiffness_front=r.number('stiffness_front', 'N/m', gt=0.0),
        stiffness_rear=r.number('stiffness_rear', 'N/m', gt=0.0),
        damping_front=r.number('damping_front', 'N s/m', ge=0.0),
        damping_rear=r.number('damping_rear', 'N s/m', ge=0.0),
    )


def _wheel(r: MappingReader) -> WheelParams:
    unloaded = r.number('unloaded_radius', 'm', gt=0.0)
    return WheelParams(
        inertia_front=r.number('inertia_front', 'kg m^2', gt=0.0),
        inertia_rear=r.number('inertia_rear', 'kg m^2', gt=0.0),
        unloaded_radius=unloaded,
        effective_radius=r.number('effective_radius', 'm', gt=0.0, le=unloaded),
        tyre_vertical_stiffness=r.number('tyre_vertical_stiffness', 'N/m', gt=0.0),
        tyre_vertical_damping=r.number('tyre_vertical_damping', 'N s/m', ge=0.0),
    )


def read_aero(r: MappingReader) -> AeroParams:
    return AeroParams(
        drag_coefficient=r.number('drag_coefficient', '', ge=0.0),
        frontal_area=r.number('frontal_area', 'm^2', ge=0.0),
        air_density=r.number('air_density', 'kg/m^3', ge=0.0),
    )


def read_rolling(r: MappingReader) -> RollingResistanceParams:
    return RollingResistanceParams(
        c0=r.number('c0', '', ge=0.0),
        c1=r.number('c1', '', ge=0.0),
        regularisation_speed=r.number('regularisation_speed', 'm/s', gt=0.0, default=0.05),
    )


def read_environment(r: MappingReader) -> EnvironmentParams:
    """``environment`` (optional, as its ``gravity``: default :data:`DEFAULT_GRAVITY`)."""
    env = r.optional_section('environment')
    if env is None:
        return EnvironmentParams(gravity=DEFAULT_GRAVITY)
    return EnvironmentParams(
        gravity=env.number('gravity', 'm/s^2', gt=0.0, default=DEFAULT_GRAVITY)
    )


def read_tire(r: MappingReader) -> TireParams:
    return TireParams(
        nominal_load=r.number('nominal_load', 'N', gt=0.0),
        pCx1=r.number('pCx1', '', gt=0.0, lt=2.0),
        pDx1=r.number('pDx1', '', gt=0.0),
        pDx2=r.number('pDx2', ''),
        pEx1=r.number('pEx1', '', le=1.0),
        pEx2=r.number('pEx2', ''),
        pEx3=r.number('pEx3', ''),
        pEx4=r.number('pEx4', ''),
        pKx1=r.number('pKx1', '', gt=0.0),
        pKx2=r.number('pKx2', ''),
        pKx3=r.number('pKx3', ''),
        pHx1=r.number('pHx1', '', default=0.0),
        pHx2=r.number('pHx2', '', default=0.0),
        pVx1=r.number('pVx1', '', default=0.0),
        pVx2=r.number('pVx2', '', default=0.0),
        low_speed_velocity=r.number('low_speed_velocity', 'm/s', gt=0.0),
    )


def _engine(r: MappingReader) -> EngineParams:
    speeds = r.number_list('full_load_speed', 'rad/s', min_len=2, ge=0.0, increasing=True)
    torques = r.number_list('full_load_torque', 'N m', min_len=2, ge=0.0)
    if len(torques) != len(speeds):
        raise ParameterError(
            f'engine.full_load_torque has {len(torques)} entries but engine.full_load_speed '
            f'has {len(speeds)}'
        )
    idle = r.number('idle_speed', 'rad/s', gt=0.0)
    max_speed = r.number('max_speed', 'rad/s', gt=idle)
    return EngineParams(
        inertia=r.number('inertia', 'kg m^2', gt=0.0),
        full_load_speed=speeds,
        full_load_torque=torques,
        drag_torque_c0=r.number('drag_torque_c0', 'N m', ge=0.0),
        drag_torque_c1=r.number('drag_torque_c1', 'N m s/rad', ge=0.0),
        idle_speed=idle,
        idle_gain=r.number('idle_gain', 'N m s/rad', gt=0.0),
        max_speed=max_speed,
    )


def _clutch(r: MappingReader, idle_speed: float) -> ClutchParams:
    start = r.number('engage_start_speed', 'rad/s', gt=idle_speed)
    return ClutchParams(
        capacity=r.number('capacity', 'N m', gt=0.0),
        slip_speed=r.number('slip_speed', 'rad/s', gt=0.0),
        engage_start_speed=start,
        engage_full_speed=r.number('engage_full_speed', 'rad/s', gt=start),
        engage_time=r.number('engage_time', 's', ge=0.0),
    )


def _gearbox(r: MappingReader) -> GearboxParams:
    ratios = r.number_list('ratios', '', min_len=1, gt=0.0, decreasing=True)
    down = r.number('downshift_speed', 'rad/s', gt=0.0)
    up_closed = r.number('upshift_speed_closed', 'rad/s', gt=down)
    up_open = r.number('upshift_speed_open', 'rad/s', ge=up_closed)
    # Hysteresis check: right after an upshift the engine must not already be below the
    # downshift threshold, otherwise the logic would hunt between two gears.
    for i in range(len(ratios) - 1):
        after = up_closed * ratios[i + 1] / ratios[i]
        if after <= down:
            raise ParameterError(
                f'gearbox.downshift_speed = {down:g} rad/s is too high: an upshift from gear '
                f'{i + 1} at gearbox.upshift_speed_closed lands at {after:.1f} rad/s'
            )
    return GearboxParams(
        ratios=ratios,
        final_drive=r.number('final_drive', '', gt=0.0),
        upshift_speed_closed=up_closed,
        upshift_speed_open=up_open,
        downshift_speed=down,
        shift_time=r.number('shift_time', 's', ge=0.0),
    )


def _brakes(r: MappingReader) -> BrakeParams:
    return BrakeParams(
        max_torque_front=r.number('max_torque_front', 'N m', ge=0.0),
        max_torque_rear=r.number('max_torque_rear', 'N m', ge=0.0),
        lock_speed=r.number('lock_speed', 'rad/s', gt=0.0),
    )


def parse_vehicle(data: object) -> VehicleParams:
    """Build :class:`VehicleParams` from an already parsed YAML document.

    Args:
        data: the top-level mapping of the parameter file.

    Returns:
        The validated parameters.

    Raises:
        ParameterError: naming the first missing or invalid parameter.
    """
    r = MappingReader(data, '', ParameterError)
    check_vehicle_keys(data)
    engine = _engine(r.section('engine'))
    return VehicleParams(
        name=r.string('name', default='vehicle'),
        chassis=_chassis(r.section('chassis')),
        suspension=_suspension(r.section('suspension')),
        wheel=_wheel(r.section('wheel')),
        aero=read_aero(r.section('aero')),
        rolling_resistance=read_rolling(r.section('rolling_resistance')),
        environment=read_environment(r),
        tire=read_tire(r.section('tire')),
        engine=engine,
        clutch=_clutch(r.section('clutch'), engine.idle_speed),
        gearbox=_gearbox(r.section('gearbox')),
        brakes=_brakes(r.section('brakes')),
    )


def load_vehicle(path: str | Path) -> VehicleParams:
    """Load and validate a vehicle parameter file.

    Args:
        path: YAML file, e.g. ``src/vd_common/config/clio_rl_1_1.yaml``.

    Returns:
        The validated parameters.

    Raises:
        ParameterError: one line: the file cannot be read (``cannot read vehicle file
            x.yaml: ...``, ``vehicle file x.yaml is not valid YAML: ...``), or a parameter
            is missing/invalid (``vehicle file x.yaml: chassis.mass must be > 0 kg, got -3``).
    """
    data = load_yaml_mapping(path, ParameterError, 'vehicle file')
    try:
        return parse_vehicle(data)
    except ParameterError as exc:
        # A node or tool prints this line alone: say which file holds the bad key.
        raise ParameterError(f'vehicle file {Path(path)}: {exc}') from exc


def load_vehicle_if_full(path: str | os.PathLike[str] | None) -> VehicleParams | None:
    """The full (simulator) vehicle file at ``path``, or None where it is not one (an
    estimation-only file, whose own reader says what it lacks); None: the shipped Clio."""
    try:
        return load_vehicle(default_vehicle_file() if path is None else Path(path))
    except ParameterError:
        return None


def default_vehicle_file() -> Path:
    """The shipped Clio RL 1.1 parameter file, the default of the simulator and estimator.

    The installed copy (``share/vd_common/config``, found through the ament index) comes
    first, so an installed node reads the file installed with it; without a ROS environment
    (tests, tools run from the source tree) the copy in this package's source tree is used.

    Returns:
        Path of ``clio_rl_1_1.yaml``.

    Raises:
        ParameterError: neither copy exists.
    """
    try:
        from ament_index_python.packages import get_package_share_directory

        installed = Path(get_package_share_directory('vd_common')) / 'config' / _CLIO_FILE
        if installed.is_file():
            return installed
    except (ImportError, LookupError, ValueError, OSError):
        pass  # not installed / no ROS environment: use the source tree
    # vd_common/vehicle/params.py -> parents[2] is the package source root holding config/.
    source = Path(__file__).resolve().parents[2] / 'config' / _CLIO_FILE
    if source.is_file():
        return source
    raise ParameterError(
        f'vehicle file {_CLIO_FILE} not found (vd_common not installed, no {source})'
    )
