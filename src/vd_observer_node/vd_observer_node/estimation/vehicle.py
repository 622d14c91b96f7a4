"""The estimators' view of the vehicle parameter file shared with the simulator.

Only the keys the estimators need are read from `vd_sim_node/config/clio_rl_1_1.yaml`;
extra keys are ignored so the simulator may add its own.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from numpy.typing import NDArray

from vd_observer_node.errors import VehicleParameterError

__all__ = ['EstimatorVehicle', 'load_estimator_vehicle', 'vehicle_from_mapping']


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

    def __post_init__(self) -> None:
        for key, value in self.__dict__.items():
            if key == 'name':
                continue
            # c0 = 0 or Cx = 0 switch a resistance off; every other quantity must be > 0.
            zero_ok = key in ('rolling_c0', 'rolling_c1', 'drag_coefficient')
            allowed = 'a finite number >= 0' if zero_ok else 'a finite number > 0'
            # Name the key as it is written in the YAML file, so the user finds it.
            where = '.'.join(_KEYS.get(key, ('rolling_resistance', 'regularisation_speed')))
            if (
                not (isinstance(value, int | float) and math.isfinite(value))
                or value < 0.0
                or (value == 0.0 and not zero_ok)
            ):
                raise VehicleParameterError(f'{where} ({key}) must be {allowed}, got {value!r}')
        if self.cg_to_front_axle >= self.wheelbase:
            raise VehicleParameterError(
                f'cg_to_front_axle ({self.cg_to_front_axle}) must be < '
                f'wheelbase ({self.wheelbase})'
            )

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


_KEYS = {
    'mass': ('chassis', 'mass'),
    'wheelbase': ('chassis', 'wheelbase'),
    'cg_to_front_axle': ('chassis', 'cg_to_front_axle'),
    'cg_height': ('chassis', 'cg_height'),
    'inertia_front': ('wheel', 'inertia_front'),
    'inertia_rear': ('wheel', 'inertia_rear'),
    'effective_radius': ('wheel', 'effective_radius'),
    'drag_coefficient': ('aero', 'drag_coefficient'),
    'frontal_area': ('aero', 'frontal_area'),
    'air_density': ('aero', 'air_density'),
    'rolling_c0': ('rolling_resistance', 'c0'),
    'rolling_c1': ('rolling_resistance', 'c1'),
    'gravity': ('environment', 'gravity'),
}


def vehicle_from_mapping(data: Any) -> EstimatorVehicle:
    """Build the parameters from the parsed YAML mapping.

    Raises:
        VehicleParameterError: a key is missing or a value is not a positive finite number.
    """
    if not isinstance(data, dict):
        raise VehicleParameterError('vehicle file must hold a mapping at top level')
    values: dict[str, float] = {}
    for field, (section, key) in _KEYS.items():
        block = data.get(section)
        if not isinstance(block, dict) or key not in block:
            raise VehicleParameterError(f'missing key {section}.{key}')
        raw = block[key]
        if isinstance(raw, bool) or not isinstance(raw, int | float):
            raise VehicleParameterError(f'{section}.{key} must be a number, got {raw!r}')
        values[field] = float(raw)
    rolling = data.get('rolling_resistance')
    if isinstance(rolling, dict) and 'regularisation_speed' in rolling:
        raw = rolling['regularisation_speed']
        if isinstance(raw, bool) or not isinstance(raw, int | float):
            raise VehicleParameterError(f'rolling_resistance.regularisation_speed: {raw!r}')
        values['rolling_regularisation_speed'] = float(raw)
    return EstimatorVehicle(**values, name=str(data.get('name', '')))


def load_estimator_vehicle(path: str | Path) -> EstimatorVehicle:
    """Read the vehicle parameter file (the simulator's YAML) for the estimators.

    Args:
        path: YAML file, e.g. vd_sim_node/config/clio_rl_1_1.yaml.

    Raises:
        VehicleParameterError: unreadable file, missing key or invalid value.
    """
    try:
        text = Path(path).read_text(encoding='utf-8')
        data = yaml.safe_load(text)
    except (OSError, yaml.YAMLError) as exc:
        # One line: a node refusing to start prints exactly this (YAML errors span lines).
        reason = ' '.join(str(exc).split())
        raise VehicleParameterError(f'cannot read vehicle file {path}: {reason}') from exc
    try:
        return vehicle_from_mapping(data)
    except VehicleParameterError as exc:
        raise VehicleParameterError(f'vehicle file {path}: {exc}') from exc
