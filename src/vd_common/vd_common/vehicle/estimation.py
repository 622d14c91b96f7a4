"""The vehicle file as the estimators read it: only what they use.

A car that is estimated, not simulated, needs no suspension, tyre vertical model, engine map,
clutch or brakes in its file. :func:`parse_estimation_vehicle` reads the same YAML layout as
:func:`~vd_common.vehicle.params.parse_vehicle` (a full simulator file works as it is) but
only these keys, each range-checked and named by its dotted path when missing or invalid:

* ``chassis``: ``mass`` [kg], ``wheelbase`` [m], ``cg_to_front_axle`` [m], ``cg_height`` [m];
* ``wheel``: ``inertia_front``, ``inertia_rear`` [kg m^2], ``effective_radius`` [m];
* ``aero``, ``rolling_resistance``: as the simulator's file;
* optional ``environment.gravity`` [m/s^2], default 9.81;
* optional ``tire`` (the Magic Formula of the friction potential and the alerts that compare
  the utilised friction with it: without it they are off, said once, and the rest runs);
* optional ``gearbox.ratios`` and ``gearbox.final_drive`` with ``engine.inertia`` (the
  engine torque path; refused, naming the key, when that path is asked for without them),
  and with them, optional: ``gearbox.efficiency`` (one number, or one per gear; default 1),
  ``gearbox.reverse_ratio`` (default the first gear's), ``driveline.layout`` (FWD, RWD or
  AWD; default FWD) with ``driveline.front_share`` (AWD: the share of the drive torque on the
  front axle, default 0.5), and ``torque_converter`` (an automatic gearbox: the converter's
  characteristic as tables over the speed ratio turbine/pump, ``speed_ratio``,
  ``torque_ratio`` and ``capacity_factor`` K [rpm / sqrt(N m)]);
* optional ``brakes.gain_front`` and ``brakes.gain_rear``: brake torque per wheel per unit
  of the mapped brake pressure [N m per unit] (the brake input; a simulator file's
  ``brakes.max_torque_*`` are not read).

A key that neither this parser nor the simulator's knows is refused before any value is read,
naming the closest known key (:data:`~vd_common.vehicle.params.VEHICLE_FILE_KEYS`, shared
with the simulator's parser). docs/vehicle_file.md has the table of these keys.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from vd_common.errors import ParameterError
from vd_common.vehicle.params import (
    AeroParams,
    EnvironmentParams,
    RollingResistanceParams,
    TireParams,
    check_vehicle_keys,
    read_aero,
    read_environment,
    read_rolling,
    read_tire,
)
from vd_common.yaml_reader import MappingReader, load_yaml_mapping

__all__ = [
    'DRIVE_LAYOUTS',
    'EstimationBrakes',
    'EstimationChassis',
    'EstimationConverter',
    'EstimationDriveline',
    'EstimationVehicleParams',
    'EstimationWheel',
    'load_estimation_vehicle',
    'parse_estimation_vehicle',
]


@dataclass(frozen=True)
class EstimationChassis:
    """Whole-vehicle mass and CG (the estimators' load transfer and force balance)."""

    mass: float  # [kg]
    wheelbase: float  # [m] L
    cg_to_front_axle: float  # [m] a
    cg_height: float  # [m] h


@dataclass(frozen=True)
class EstimationWheel:
    """Wheel spin inertias and the effective rolling radius."""

    inertia_front: float  # [kg m^2] per wheel
    inertia_rear: float  # [kg m^2] per wheel
    effective_radius: float  # [m] R_eff


#: ``driveline.layout``: front-, rear- or all-wheel drive.
DRIVE_LAYOUTS = ('FWD', 'RWD', 'AWD')


@dataclass(frozen=True)
class EstimationConverter:
    """A torque converter's characteristic, tables over the speed ratio (turbine / pump).

    Attributes:
        speed_ratio: [-] increasing, in [0, 1].
        torque_ratio: [-] turbine / pump torque at each speed ratio (1 from the coupling
            point on; 1 beyond the table and in overrun).
        capacity_factor: K [rpm / sqrt(N m)]: pump speed over the root of the pump torque
            at each speed ratio (increasing towards the coupling point).
    """

    speed_ratio: tuple[float, ...]
    torque_ratio: tuple[float, ...]
    capacity_factor: tuple[float, ...]


@dataclass(frozen=True)
class EstimationDriveline:
    """What the engine torque path needs: gear ratios, final drive, engine inertia, and
    optionally the efficiency per gear, the layout and a torque converter."""

    ratios: tuple[float, ...]  # [-] gear 1..n
    final_drive: float  # [-]
    engine_inertia: float  # [kg m^2]
    efficiency: tuple[float, ...] = ()  # [-] per gear (empty: 1)
    reverse_ratio: float | None = None  # [-] None: the first gear's
    layout: str = 'FWD'  # one of DRIVE_LAYOUTS
    front_share: float = 1.0  # [-] share of the drive torque on the front axle
    converter: EstimationConverter | None = None  # None: a clutch (manual gearbox)


@dataclass(frozen=True)
class EstimationBrakes:
    """Brake torque per wheel per unit of the mapped brake pressure [N m per unit]."""

    gain_front: float
    gain_rear: float


@dataclass(frozen=True)
class EstimationVehicleParams:
    """A vehicle file as the estimators read it (see the module docstring).

    Attributes:
        name: the file's ``name`` ('vehicle' when absent).
        source: the file it was read from ('' when parsed from data).
        tire: None when the file has no ``tire`` section.
        driveline: None when the file has no ``gearbox`` section.
    """

    name: str
    chassis: EstimationChassis
    wheel: EstimationWheel
    aero: AeroParams
    rolling_resistance: RollingResistanceParams
    environment: EnvironmentParams
    tire: TireParams | None = None
    driveline: EstimationDriveline | None = None
    source: str = ''
    brakes: EstimationBrakes | None = None

    def _where(self) -> str:
        return f'vehicle file {self.source}' if self.source else 'the vehicle file'

    def require_tire(self) -> TireParams:
        """The tyre, for the friction potential and the alerts.

        Raises:
            ParameterError: one line naming the missing ``tire`` section.
        """
        if self.tire is None:
            raise ParameterError(
                f'{self._where()}: tire is missing (the friction potential and the alerts '
                'need the Magic Formula coefficients)'
            )
        return self.tire

    def require_driveline(self) -> EstimationDriveline:
        """The driveline, for the engine torque path.

        Raises:
            ParameterError: one line naming the missing ``gearbox`` section.
        """
        if self.driveline is None:
            raise ParameterError(
                f'{self._where()}: gearbox is missing (the engine torque path needs '
                'gearbox.ratios, gearbox.final_drive and engine.inertia)'
            )
        return self.driveline


def _converter(r: MappingReader) -> EstimationConverter | None:
    c = r.optional_section('torque_converter')
    if c is None:
        return None
    speed = c.number_list('speed_ratio', '', min_len=2, ge=0.0, increasing=True)
    if speed[-1] > 1.0:
        raise ParameterError(f'torque_converter.speed_ratio must end <= 1, got {speed[-1]}')
    torque = c.number_list('torque_ratio', '', min_len=2, gt=0.0)
    capacity = c.number_list('capacity_factor', 'rpm/sqrt(N m)', min_len=2, gt=0.0)
    for name, table in (('torque_ratio', torque), ('capacity_factor', capacity)):
        if len(table) != len(speed):
            raise ParameterError(
                f'torque_converter.{name} must have one value per speed_ratio '
                f'({len(speed)}), got {len(table)}'
            )
    return EstimationConverter(speed, torque, capacity)


def _driveline(r: MappingReader) -> EstimationDriveline | None:
    gearbox = r.optional_section('gearbox')
    if gearbox is None:
        return None
    ratios = gearbox.number_list('ratios', '', min_len=1, gt=0.0)
    final_drive = gearbox.number('final_drive', '', gt=0.0)
    engine = r.optional_section('engine')
    if engine is None:
        raise ParameterError('engine.inertia is missing (needed with gearbox)')
    efficiency: tuple[float, ...] = ()
    if gearbox.has('efficiency'):
        raw = gearbox.raw('efficiency')
        if isinstance(raw, list):
            efficiency = gearbox.number_list('efficiency', '', min_len=len(ratios), gt=0.0)
            if len(efficiency) != len(ratios):
                raise ParameterError(
                    f'gearbox.efficiency must list one value per gear ({len(ratios)}), '
                    f'got {len(efficiency)}'
                )
        else:
            efficiency = (gearbox.number('efficiency', '', gt=0.0),) * len(ratios)
        if any(e > 1.0 for e in efficiency):
            raise ParameterError(f'gearbox.efficiency must be in (0, 1], got {list(efficiency)}')
    reverse = gearbox.number('reverse_ratio', '', gt=0.0) if gearbox.has('reverse_ratio') else None
    layout, front_share = 'FWD', 1.0
    line = r.optional_section('driveline')
    if line is not None:
        layout = line.string('layout', default='FWD')
        if layout not in DRIVE_LAYOUTS:
            raise ParameterError(
                f'driveline.layout must be one of {", ".join(DRIVE_LAYOUTS)}, got {layout!r}'
            )
        front_share = {'FWD': 1.0, 'RWD': 0.0}.get(layout, 0.5)
        if layout == 'AWD':
            front_share = line.number('front_share', '', gt=0.0, lt=1.0, default=0.5)
    return EstimationDriveline(
        ratios=tuple(ratios),
        final_drive=final_drive,
        engine_inertia=engine.number('inertia', 'kg m^2', gt=0.0),
        efficiency=efficiency,
        reverse_ratio=reverse,
        layout=layout,
        front_share=front_share,
        converter=_converter(r),
    )


def _brakes(r: MappingReader) -> EstimationBrakes | None:
    b = r.optional_section('brakes')
    if b is None or not (b.has('gain_front') or b.has('gain_rear')):
        return None  # a simulator file's brakes (max torque per pedal) are not a gain
    return EstimationBrakes(
        gain_front=b.number('gain_front', 'N m per unit', ge=0.0),
        gain_rear=b.number('gain_rear', 'N m per unit', ge=0.0),
    )


def parse_estimation_vehicle(data: object, source: str = '') -> EstimationVehicleParams:
    """Build :class:`EstimationVehicleParams` from an already parsed YAML document.

    Raises:
        ParameterError: naming the first missing or invalid parameter by its dotted path.
    """
    r = MappingReader(data, '', ParameterError)
    check_vehicle_keys(data)
    c = r.section('chassis')
    wheelbase = c.number('wheelbase', 'm', gt=0.0)
    w = r.section('wheel')
    return EstimationVehicleParams(
        name=r.string('name', default='vehicle'),
        chassis=EstimationChassis(
            mass=c.number('mass', 'kg', gt=0.0),
            wheelbase=wheelbase,
            cg_to_front_axle=c.number('cg_to_front_axle', 'm', gt=0.0, lt=wheelbase),
            cg_height=c.number('cg_height', 'm', gt=0.0),
        ),
        wheel=EstimationWheel(
            inertia_front=w.number('inertia_front', 'kg m^2', gt=0.0),
            inertia_rear=w.number('inertia_rear', 'kg m^2', gt=0.0),
            effective_radius=w.number('effective_radius', 'm', gt=0.0),
        ),
        aero=read_aero(r.section('aero')),
        rolling_resistance=read_rolling(r.section('rolling_resistance')),
        environment=read_environment(r),
        tire=None if r.optional_section('tire') is None else read_tire(r.section('tire')),
        driveline=_driveline(r),
        source=source,
        brakes=_brakes(r),
    )


def load_estimation_vehicle(path: str | Path) -> EstimationVehicleParams:
    """Load a vehicle file for the estimators (a full simulator file works too).

    Raises:
        ParameterError: one line: the file cannot be read, or a parameter is missing or
            invalid (``vehicle file x.yaml: chassis.mass must be > 0 kg, got -3``).
    """
    data = load_yaml_mapping(path, ParameterError, 'vehicle file')
    try:
        return parse_estimation_vehicle(data, str(Path(path)))
    except ParameterError as exc:
        raise ParameterError(f'vehicle file {Path(path)}: {exc}') from exc
