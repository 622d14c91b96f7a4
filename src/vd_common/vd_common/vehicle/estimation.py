"""The vehicle file as the estimators read it: only what they use.

A car that is estimated, not simulated, needs no suspension, tyre vertical model, engine map,
clutch or brakes in its file. :func:`parse_estimation_vehicle` reads the same YAML layout as
:func:`~vd_common.vehicle.params.parse_vehicle` (a full simulator file works as it is) but
only these keys, each range-checked and named by its dotted path when missing or invalid:

* ``chassis``: ``mass`` [kg], ``wheelbase`` [m], ``cg_to_front_axle`` [m], ``cg_height`` [m];
* ``wheel``: ``inertia_front``, ``inertia_rear`` [kg m^2], ``effective_radius`` [m];
* ``aero``, ``rolling_resistance``, ``environment.gravity``: as the simulator's file;
* optional ``tire`` (the Magic Formula of the friction potential and the alerts: the alerts
  node refuses a file without it, `vd replay` skips them and says so);
* optional ``gearbox.ratios`` and ``gearbox.final_drive`` with ``engine.inertia`` (the
  engine torque path; refused, naming the key, when that path is asked for without them).
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
    read_aero,
    read_rolling,
    read_tire,
)
from vd_common.yaml_reader import MappingReader, load_yaml_mapping

__all__ = [
    'EstimationChassis',
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


@dataclass(frozen=True)
class EstimationDriveline:
    """What the engine torque path needs: gear ratios, final drive, engine inertia."""

    ratios: tuple[float, ...]  # [-] gear 1..n
    final_drive: float  # [-]
    engine_inertia: float  # [kg m^2]


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


def _driveline(r: MappingReader) -> EstimationDriveline | None:
    gearbox = r.optional_section('gearbox')
    if gearbox is None:
        return None
    ratios = gearbox.number_list('ratios', '', min_len=1, gt=0.0)
    final_drive = gearbox.number('final_drive', '', gt=0.0)
    engine = r.optional_section('engine')
    if engine is None:
        raise ParameterError('engine.inertia is missing (needed with gearbox)')
    return EstimationDriveline(
        ratios=tuple(ratios),
        final_drive=final_drive,
        engine_inertia=engine.number('inertia', 'kg m^2', gt=0.0),
    )


def parse_estimation_vehicle(data: object, source: str = '') -> EstimationVehicleParams:
    """Build :class:`EstimationVehicleParams` from an already parsed YAML document.

    Raises:
        ParameterError: naming the first missing or invalid parameter by its dotted path.
    """
    r = MappingReader(data, '', ParameterError)
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
        environment=EnvironmentParams(
            gravity=r.section('environment').number('gravity', 'm/s^2', gt=0.0)
        ),
        tire=None if r.optional_section('tire') is None else read_tire(r.section('tire')),
        driveline=_driveline(r),
        source=source,
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
