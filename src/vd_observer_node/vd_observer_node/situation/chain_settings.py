"""The chain's settings (`ChainSettings`: the cascade's and the situation monitor's) and the
one way to build them (`chain_settings`) from node parameters (`parameter_sections`), a
settings file's sections (`tools.settings_file`) or the CLI, the vehicle file and what the
sensors are (the input mapping). Used by every node, `vd replay`, `vd report` and `vd fleet`.

It lives beside the monitor, below the chain and the tools, so that the nodes and the tools
build their settings without a new import between them."""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Final, Protocol

from vd_common.vehicle.params import load_vehicle_if_full

from vd_observer_node.errors import ConfigurationError
from vd_observer_node.estimation.body_pitch import body_pitch_of
from vd_observer_node.estimation.brakes import Brakes
from vd_observer_node.estimation.cascade import CascadeSettings
from vd_observer_node.estimation.differentiator import LevantGains
from vd_observer_node.estimation.drivetrain import Drivetrain
from vd_observer_node.estimation.estimator import EstimatorConfig
from vd_observer_node.estimation.imu_settings import imu_grade_config
from vd_observer_node.estimation.observer import ObserverConfig
from vd_observer_node.estimation.vehicle import (
    estimator_vehicle,
    load_vehicle_params,
    no_tire_note,
)
from vd_observer_node.situation.alerts import AlertConfig
from vd_observer_node.situation.friction_potential import FrictionPotentialConfig, TyreCurves
from vd_observer_node.situation.monitor import SituationConfig

__all__ = [
    'OWN_SENSORS',
    'SETTINGS_SECTIONS',
    'ChainSettings',
    'Sensors',
    'chain_settings',
    'check_settings_fit',
    'parameter_sections',
]


class Sensors(Protocol):
    """What the settings need to know of the sensors (`inputs.mapping.InputMapping` is one).

    Attributes:
        wheel_input: 'angle' or 'speed' (`ObserverConfig.wheel_input`).
        torque_source: 'measured', 'engine' or 'none'.
        brake_signal: 'switch' or 'pressure', '' without a brake input.
        imu_fusion: the IMU fusion's settings of the sensor (field, value), None without IMU.
        source: where the mapping came from (for messages).
    """

    @property
    def wheel_input(self) -> str: ...

    @property
    def torque_source(self) -> str: ...

    @property
    def brake_signal(self) -> str: ...

    @property
    def imu_fusion(self) -> tuple[tuple[str, float], ...] | None: ...

    @property
    def source(self) -> str: ...


@dataclass(frozen=True)
class _OwnSensors:
    """vd's own sensor topics (`inputs.mapping.default_mapping`)."""

    wheel_input: str = 'angle'
    torque_source: str = 'measured'
    brake_signal: str = ''
    imu_fusion: tuple[tuple[str, float], ...] | None = None
    source: str = ''


#: the sensors of vd's own topics: wheel angles, measured wheel torques, no brake, no IMU
OWN_SENSORS: Final = _OwnSensors()


@dataclass(frozen=True)
class ChainSettings(CascadeSettings):
    """Everything the chain needs: the cascade's settings (`CascadeSettings`: vehicle,
    observer, estimator, estimator speed, torque source, drivetrain, IMU, brakes) and the
    situation monitor's. `chain_settings` builds them from node parameters, a settings file
    or the CLI, and the vehicle file.

    Attributes:
        curves: the tyre's curves (friction potential); None (a vehicle file without
            ``tire``): no situation monitor, the outputs' ``situation`` is None.
        alerts: alert settings.
        friction: friction-potential settings.
        situation: fast-observer and gate settings of the monitor (its fast observer shares
            all of ``observer`` but L).
        vehicle_label: the vehicle's name and file, for logs ('' when made in code).
        situation_off: why the situation monitor is off (`vehicle.no_tire_note`), or None.
    """

    curves: TyreCurves | None = None
    alerts: AlertConfig = field(default_factory=AlertConfig)
    friction: FrictionPotentialConfig = field(default_factory=FrictionPotentialConfig)
    situation: SituationConfig = field(default_factory=SituationConfig)
    vehicle_label: str = ''
    situation_off: str | None = None


#: the sections of the settings: a settings file's top-level keys (`vd replay --config`),
#: what `parameter_sections` makes of node parameters
SETTINGS_SECTIONS: Final = (
    'observer', 'estimator', 'cascade', 'alerts', 'friction_potential', 'situation',
)  # fmt: skip
#: the settings of the ``cascade`` section
_CASCADE_KEYS: Final = ('estimator_speed',)
_OBSERVER_KEYS: Final = frozenset(
    {f for f in ObserverConfig.__dataclass_fields__ if f != 'gains'}
    | set(LevantGains.__dataclass_fields__)
)


def parameter_sections(values: Mapping[str, Any]) -> dict[str, dict[str, Any]]:
    """Node parameters (flat, each key owned by one settings class) as `SETTINGS_SECTIONS`.

    ``speed_source`` is the cascade's ``estimator_speed``; a key of no other section is an
    alert setting (`AlertConfig.from_mapping` refuses one it does not know).

    Args:
        values: the declared parameters' values, without the ones that are not settings
            (``vehicle_file``, the input mapping, queue sizes).
    """
    owners = {
        'observer': _OBSERVER_KEYS,
        'estimator': set(EstimatorConfig.setting_keys()),
        'situation': set(SituationConfig.__dataclass_fields__),
        'friction_potential': set(FrictionPotentialConfig.__dataclass_fields__),
    }
    sections: dict[str, dict[str, Any]] = {name: {} for name in SETTINGS_SECTIONS}
    for key, value in values.items():
        if key == 'speed_source':
            sections['cascade']['estimator_speed'] = value
            continue
        owner = next((name for name, keys in owners.items() if key in keys), 'alerts')
        sections[owner][key] = value
    return sections


def chain_settings(
    mapping: Sensors | None = None,
    vehicle_file: str | os.PathLike[str] | None = None,
    sections: Mapping[str, Mapping[str, Any] | None] | None = None,
) -> ChainSettings:
    """The chain's settings, built one way for every node, `vd replay`, `vd report` and
    `vd fleet`.

    What the sensors are comes from the input mapping: angles or ABS wheel speeds (the
    observers' ``wheel_input``, whatever the observer section says), the torque source (the
    engine path takes the file's drivetrain), the brake input (with the file's gains) and the
    IMU fusion (the mapping's ``imu.fusion`` and the body's pitch on the file's springs).

    Args:
        mapping: what the sensors are: the input mapping (`inputs.mapping.InputMapping`);
            None: vd's own topics (wheel angles, measured wheel torques, no brake, no IMU).
        vehicle_file: the vehicle YAML (estimator vehicle, tyre, drivetrain, brakes, body
            pitch, read once); None: the shipped Clio.
        sections: settings by `SETTINGS_SECTIONS` name, each flat (the keys of
            ``ObserverConfig.from_mapping``, ``EstimatorConfig.from_mapping``,
            ``estimator_speed``, ``AlertConfig``, ``FrictionPotentialConfig``,
            ``SituationConfig``); a section absent or None: its defaults.

    Raises:
        ConfigurationError: an unknown section or key, or a value out of range.
        VehicleParameterError: the vehicle file is unreadable or invalid.
    """
    mapping = mapping or OWN_SENSORS
    given = {name: dict(value) for name, value in (sections or {}).items() if value is not None}
    unknown = sorted(set(given) - set(SETTINGS_SECTIONS))
    if unknown:
        raise ConfigurationError(
            f'unknown settings section {unknown[0]!r} (sections: {", ".join(SETTINGS_SECTIONS)})'
        )
    cascade = given.get('cascade', {})
    extra = sorted(set(cascade) - set(_CASCADE_KEYS))
    if extra:
        raise ConfigurationError(
            f'unknown cascade setting {extra[0]!r} (settings: {", ".join(_CASCADE_KEYS)})'
        )
    params = load_vehicle_params(vehicle_file)
    # the simulator's reading of the same file, once: the chassis's springs, if it has any
    full = load_vehicle_if_full(vehicle_file)
    source = mapping.torque_source
    return ChainSettings(
        vehicle=estimator_vehicle(params, full),
        observer=ObserverConfig.from_mapping(
            {**given.get('observer', {}), 'wheel_input': mapping.wheel_input}
        ),
        estimator=EstimatorConfig.from_mapping(given.get('estimator', {})),
        estimator_speed=cascade.get('estimator_speed', 'measured'),
        torque_source=source,
        drivetrain=Drivetrain.from_params(params) if source == 'engine' else None,
        imu=(
            imu_grade_config(body_pitch_of(full), mapping.imu_fusion)
            if mapping.imu_fusion is not None
            else None
        ),
        brakes=(
            Brakes.from_params(_brake_in_use(mapping), params, mapping.source)
            if _brake_in_use(mapping)
            else None
        ),
        curves=None if params.tire is None else TyreCurves.from_tire(params.tire),
        alerts=AlertConfig.from_mapping(given.get('alerts', {})),
        friction=FrictionPotentialConfig.from_mapping(given.get('friction_potential', {})),
        situation=SituationConfig.from_mapping(given.get('situation', {})),
        vehicle_label=f'{params.name} ({params.source})',
        situation_off=no_tire_note(params),
    )


def _brake_in_use(mapping: Sensors) -> str:
    """The brake input's signal the cascade uses, '' for none: without a torque there is
    nothing to take a brake torque from."""
    return mapping.brake_signal if mapping.torque_source != 'none' else ''


def check_settings_fit(settings: CascadeSettings, mapping: Sensors) -> None:
    """Refuse settings made for other sensors than the mapping's (`chain_settings` makes
    them fit).

    Raises:
        ConfigurationError: the wheel input, the torque source, the IMU or the brake input
            of the settings is not the mapping's.
    """
    wants = {
        'observer.wheel_input': (settings.observer.wheel_input, mapping.wheel_input),
        'torque_source': (settings.torque_source, mapping.torque_source),
        'imu (fused)': (settings.imu is not None or mapping.imu_fusion is None, True),
        'brakes': (
            settings.brakes.kind if settings.brakes is not None else 'none',
            _brake_in_use(mapping) or 'none',
        ),
    }
    for name, (have, need) in wants.items():
        if have != need:
            raise ConfigurationError(
                f'settings do not fit the input mapping: {name} is {have!r}, the mapping '
                f'needs {need!r} (build them with chain_settings(mapping, ...))'
            )
