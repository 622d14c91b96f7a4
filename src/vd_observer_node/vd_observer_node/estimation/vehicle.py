"""The estimators' view of the vehicle parameter file.

The estimators read a vehicle file with :mod:`vd_common.vehicle.estimation`: only the keys
they use, the simulator's sections optional (a full simulator file such as
`vd_common/config/clio_rl_1_1.yaml` works as it is); it range-checks and names every key.
:class:`EstimatorVehicle` is the numeric subset, taken from that or from the simulator's
:class:`~vd_common.vehicle.params.VehicleParams` by :meth:`EstimatorVehicle.from_params`;
there is no second key table here.
"""

from __future__ import annotations

import dataclasses
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from vd_common.errors import ParameterError
from vd_common.vehicle.estimation import EstimationVehicleParams, load_estimation_vehicle
from vd_common.vehicle.params import (
    TireParams,
    VehicleParams,
    default_vehicle_file,
    load_vehicle_if_full,
)

from vd_observer_node.errors import VehicleParameterError
from vd_observer_node.estimation.axle_loads import VerticalModel

__all__ = [
    'EstimatorVehicle',
    'estimator_vehicle',
    'load_estimator_vehicle',
    'load_vehicle_params',
    'mapped_without_vehicle_warning',
    'no_tire_note',
    'vehicle_tire',
]

# c0 = 0, c1 = 0, Cx = 0, A = 0 or rho = 0 switch a resistance off, as the simulator's
# parser allows; every other quantity is a divisor or a physical size and must be > 0.
_ZERO_ALLOWED = frozenset(
    ('rolling_c0', 'rolling_c1', 'drag_coefficient', 'frontal_area', 'air_density')
)


@dataclass(frozen=True)
class EstimatorVehicle:
    """Vehicle parameters used by the estimators (SI units, whole-vehicle quantities).

    Attributes:
        mass: total mass m including unsprung masses [kg].
        wheelbase: L [m].
        cg_to_front_axle: a, whole-vehicle CG to front axle [m], 0 < a < L.
        cg_height: h, whole-vehicle CG height above ground [m].
        inertia_front: spin inertia of one front wheel J_f [kg m^2].
        inertia_rear: spin inertia of one rear wheel J_r [kg m^2].
        effective_radius: R_eff [m].
        drag_coefficient: Cx [-].
        frontal_area: A [m^2].
        air_density: rho [kg/m^3].
        rolling_c0: c0 of paper eq. 7 [-].
        rolling_c1: c1 of paper eq. 7 [km/h per m/s].
        gravity: g [m/s^2].
        rolling_regularisation_speed: v_r [m/s] of tanh(v / v_r), the smooth sign the
            simulator applies to rolling resistance (optional key, default 0.05).
        name: free text.
        vertical: the chassis's vertical dynamics (`axle_loads.VerticalModel`, from a full
            file's suspension, tyres and masses): the load transfer follows the ground force
            through them. None: a rigid body, as an estimation-only file describes.
    """

    mass: float
    wheelbase: float
    cg_to_front_axle: float
    cg_height: float
    inertia_front: float
    inertia_rear: float
    effective_radius: float
    drag_coefficient: float
    frontal_area: float
    air_density: float
    rolling_c0: float
    rolling_c1: float
    gravity: float
    rolling_regularisation_speed: float = 0.05
    name: str = ''
    vertical: VerticalModel | None = None

    def __post_init__(self) -> None:
        # The file's values are checked by the shared parser (with their YAML names); this
        # guards vehicles built directly, e.g. by tests and the kernel's warm-up.
        for key, value in self.__dict__.items():
            if key in ('name', 'vertical'):
                continue
            zero_ok = key in _ZERO_ALLOWED
            allowed = 'a finite number >= 0' if zero_ok else 'a finite number > 0'
            if (
                not (isinstance(value, int | float) and math.isfinite(value))
                or value < 0.0
                or (value == 0.0 and not zero_ok)
            ):
                raise VehicleParameterError(
                    f'EstimatorVehicle.{key} must be {allowed}, got {value!r}'
                )
        if self.cg_to_front_axle >= self.wheelbase:
            raise VehicleParameterError(
                f'cg_to_front_axle ({self.cg_to_front_axle}) must be < '
                f'wheelbase ({self.wheelbase})'
            )

    @classmethod
    def from_params(cls, params: VehicleParams | EstimationVehicleParams) -> EstimatorVehicle:
        """The estimators' subset of the simulator's validated parameters.

        The file already holds whole-vehicle quantities (``chassis.mass`` includes the
        unsprung masses, ``chassis.cg_to_front_axle`` and ``cg_height`` locate the
        whole-vehicle CG), so every field is the parsed value itself, unchanged: the
        estimators and the simulator see the same numbers bit for bit. The vertical model is
        the full file's (`VehicleParams`: suspension, tyres, masses); the estimators' own
        parse (`EstimationVehicleParams`) reads no suspension: rigid, which
        `load_estimator_vehicle` completes from the file.

        Args:
            params: parameters from :func:`vd_common.vehicle.estimation.load_estimation_vehicle`
                (or the simulator's :func:`vd_common.vehicle.params.load_vehicle`).

        Returns:
            The estimator vehicle.
        """
        chassis, wheel, aero = params.chassis, params.wheel, params.aero
        rolling = params.rolling_resistance
        vertical = VerticalModel.from_params(params) if isinstance(params, VehicleParams) else None
        return cls(
            mass=chassis.mass,
            wheelbase=chassis.wheelbase,
            cg_to_front_axle=chassis.cg_to_front_axle,
            cg_height=chassis.cg_height,
            inertia_front=wheel.inertia_front,
            inertia_rear=wheel.inertia_rear,
            effective_radius=wheel.effective_radius,
            drag_coefficient=aero.drag_coefficient,
            frontal_area=aero.frontal_area,
            air_density=aero.air_density,
            rolling_c0=rolling.c0,
            rolling_c1=rolling.c1,
            gravity=params.environment.gravity,
            rolling_regularisation_speed=rolling.regularisation_speed,
            name=params.name,
            vertical=vertical,
        )

    def with_vertical(self, vertical: VerticalModel | None) -> EstimatorVehicle:
        """This vehicle with that vertical model (None: rigid)."""
        return dataclasses.replace(self, vertical=vertical)

    @property
    def cg_to_rear_axle(self) -> float:
        """b = L - a [m]."""
        return self.wheelbase - self.cg_to_front_axle

    @property
    def wheel_inertia(self) -> NDArray[np.float64]:
        """shape (4,), [kg m^2], spin inertia per wheel, order FL, FR, RL, RR."""
        jf, jr = self.inertia_front, self.inertia_rear
        return np.array([jf, jf, jr, jr])

    @property
    def drag_factor(self) -> float:
        """0.5 * rho * Cx * A [N s^2/m^2]: aero drag is drag_factor * v^2."""
        return 0.5 * self.air_density * self.drag_coefficient * self.frontal_area

    @property
    def static_wheel_loads(self) -> NDArray[np.float64]:
        """shape (4,), [N], wheel loads on level ground at rest, order FL, FR, RL, RR."""
        weight = self.mass * self.gravity
        front = 0.5 * weight * self.cg_to_rear_axle / self.wheelbase
        rear = 0.5 * weight * self.cg_to_front_axle / self.wheelbase
        return np.array([front, front, rear, rear])


def load_vehicle_params(
    path: str | os.PathLike[str] | None = None,
) -> EstimationVehicleParams:
    """Read the vehicle file for the estimators, refusing it as vd_observer_node does.

    For callers that need more than :class:`EstimatorVehicle` from the same file (the tyre
    of the friction potential, the driveline of the engine path): one read gives all.

    Args:
        path: YAML file; None: the shipped Clio file
            (:func:`vd_common.vehicle.params.default_vehicle_file`).

    Returns:
        The estimators' validated parameters (``source`` says which file).

    Raises:
        VehicleParameterError: the parser's one-line message, e.g. ``vehicle file x.yaml:
            chassis.mass must be > 0 kg, got -1200.0`` (an ObserverError, so the nodes and
            the vd tool report it as one line like their other refusals).
    """
    try:
        return load_estimation_vehicle(default_vehicle_file() if path is None else Path(path))
    except ParameterError as exc:
        raise VehicleParameterError(str(exc)) from exc


def vehicle_tire(params: EstimationVehicleParams) -> TireParams:
    """The file's tyre (the friction potential and the alerts need it).

    Raises:
        VehicleParameterError: the file has no ``tire`` section; one line naming it.
    """
    try:
        return params.require_tire()
    except ParameterError as exc:
        raise VehicleParameterError(str(exc)) from exc


def no_tire_note(params: EstimationVehicleParams) -> str | None:
    """Why the friction potential and the alerts are off, or None when the file has a tyre.

    A vehicle file without ``tire`` (an estimation-only file) is a configuration, not a fault:
    every estimate runs; the friction potential and the alerts, which compare the utilised
    friction with the Magic Formula's peak, are off. The nodes log this once and show it on
    ``/diagnostics`` (key ``situation``); `vd replay` prints it.

    Returns:
        One line, e.g. ``off (no tire in vehicle file car.yaml: the friction potential and
        the alerts need its Magic Formula coefficients)``.
    """
    if params.tire is not None:
        return None
    where = f'vehicle file {params.source}' if params.source else 'the vehicle file'
    return (
        f'off (no tire in {where}: the friction potential and the alerts need its Magic '
        'Formula coefficients)'
    )


def mapped_without_vehicle_warning() -> str:
    """The one warning line of `vd replay` / `vd report` given ``--mapping`` without
    ``--vehicle``: a mapped bag is a user's car, almost never the Clio whose file is the
    default, and its mass, radius and resistances set every estimate."""
    return (
        f'warning: no --vehicle: the shipped Renault Clio file ({default_vehicle_file()}) is '
        "used for this mapped bag; give your car's file with --vehicle (docs/vehicle_file.md)"
    )


def load_estimator_vehicle(path: str | os.PathLike[str] | None) -> EstimatorVehicle:
    """Read the vehicle parameter file (the simulator's YAML) for the estimators, with the
    vertical model where the file is a full one (`estimator_vehicle`).

    Args:
        path: YAML file, e.g. vd_common/config/clio_rl_1_1.yaml; None: the shipped Clio.

    Returns:
        The estimator vehicle.

    Raises:
        VehicleParameterError: unreadable file, missing key or invalid value (one line that
            names the file and the dotted key).
    """
    return estimator_vehicle(load_vehicle_params(path), load_vehicle_if_full(path))


def estimator_vehicle(
    params: EstimationVehicleParams, full: VehicleParams | None
) -> EstimatorVehicle:
    """The estimators' vehicle of a file read both ways: its numbers from the estimators' own
    reading ``params``, the vertical model from the simulator's ``full`` (None, an
    estimation-only file: a rigid body)."""
    vertical = None if full is None else VerticalModel.from_params(full)
    return EstimatorVehicle.from_params(params).with_vertical(vertical)
