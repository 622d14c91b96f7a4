"""The settings file of the offline tools (`vd replay --config`, `vd report`, `vd fleet`): the
chain's settings by section (`situation.chain_settings.SETTINGS_SECTIONS`), and what the file
set, for the log of where each setting came from. `situation.chain_settings` builds the
settings from it."""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from vd_observer_node.errors import ConfigurationError
from vd_observer_node.situation.chain_settings import (
    SETTINGS_SECTIONS,
    ChainSettings,
    Sensors,
    chain_settings,
)

__all__ = ['SettingsFile', 'load_settings_file']


@dataclass(frozen=True)
class SettingsFile:
    """A settings file's sections (none: every default).

    Attributes:
        sections: the settings by section name (`chain_settings.SETTINGS_SECTIONS`), each
            flat.
        given: what the file set, by ``section.key`` (nested sections flattened, e.g.
            ``'estimator.mass.mass_tau'``), for the log of where each setting came from.
        source: the file's path ('' when not read from a file).
    """

    sections: dict[str, dict[str, Any]] = field(default_factory=dict)
    given: dict[str, Any] = field(default_factory=dict)
    source: str = ''

    def settings(
        self,
        mapping: Sensors | None = None,
        vehicle_file: str | os.PathLike[str] | None = None,
    ) -> ChainSettings:
        """The chain's settings of these sections, for a mapping and a vehicle file
        (`situation.chain_settings`).

        Raises:
            ConfigurationError: a key of no settings class, or a value out of range.
            VehicleParameterError: the vehicle file is unreadable or invalid.
        """
        try:
            return chain_settings(mapping, vehicle_file, self.sections)
        except ConfigurationError as exc:
            where = f'{self.source}: ' if self.source else ''
            raise ConfigurationError(f'{where}{exc}') from exc


def _flat(prefix: str, section: Mapping[str, Any]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in section.items():
        if isinstance(value, dict):
            out.update(_flat(f'{prefix}{key}.', value))
        else:
            out[f'{prefix}{key}'] = value
    return out


def load_settings_file(path: str | os.PathLike[str]) -> SettingsFile:
    """Read settings from YAML: optional ``observer``, ``estimator``, ``cascade``,
    ``alerts``, ``friction_potential`` and ``situation`` mappings (flat, the keys of
    ``ObserverConfig.from_mapping`` / ``EstimatorConfig.from_mapping`` / ``estimator_speed``
    / ``AlertConfig`` / ``FrictionPotentialConfig`` / ``SituationConfig``).

    The values are checked here, with the defaults' mapping and vehicle, so that a typo
    is refused before a bag is opened.

    Raises:
        ConfigurationError: unreadable file, not a mapping, or unknown keys.
    """
    try:
        data = yaml.safe_load(Path(path).read_text(encoding='utf-8')) or {}
    except (OSError, yaml.YAMLError, UnicodeDecodeError) as exc:
        raise ConfigurationError(f'{path}: cannot read settings: {exc}') from exc
    if not isinstance(data, dict) or set(data) - set(SETTINGS_SECTIONS):
        raise ConfigurationError(
            f'{path}: expected a mapping with sections among {" / ".join(SETTINGS_SECTIONS)}'
        )
    sections: dict[str, dict[str, Any]] = {}
    for key in SETTINGS_SECTIONS:
        value = data.get(key)
        if value is not None and not isinstance(value, dict):
            raise ConfigurationError(f'{path}: {key} must be a mapping')
        if value is not None:
            sections[key] = value
    loaded = SettingsFile(
        sections=sections,
        given={
            k: v for key, section in sections.items() for k, v in _flat(f'{key}.', section).items()
        },
        source=str(path),
    )
    loaded.settings()  # refuses a bad key or value now
    return loaded
