"""The settings file of an offline replay (`vd replay --config`): cascade, alert and situation
settings by section, and what the file set, for the log of where each setting came from."""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from vd_observer_node.errors import ConfigurationError
from vd_observer_node.estimation.estimator import EstimatorConfig
from vd_observer_node.estimation.observer import ObserverConfig
from vd_observer_node.situation.alerts import AlertConfig
from vd_observer_node.situation.friction_potential import FrictionPotentialConfig
from vd_observer_node.situation.monitor import SituationConfig

__all__ = ['ReplayConfig', 'load_replay_config']


@dataclass(frozen=True)
class ReplayConfig:
    """Cascade and alert settings of an offline replay (None: the defaults).

    Attributes:
        given: what the file set, by ``section.key`` (nested sections flattened, e.g.
            ``'estimator.mass.mass_tau'``), for the log of where each setting came from.
        source: the file's path ('' when not read from a file).
    """

    observer: ObserverConfig | None = None
    estimator: EstimatorConfig | None = None
    cascade_kwargs: dict[str, Any] | None = None
    alerts: AlertConfig | None = None
    friction: FrictionPotentialConfig | None = None
    situation: SituationConfig | None = None
    given: dict[str, Any] = field(default_factory=dict)
    source: str = ''

    def replay_kwargs(self) -> dict[str, Any]:
        """These settings as `replay_bag`'s keyword arguments."""
        return {
            'observer_config': self.observer,
            'estimator_config': self.estimator,
            'cascade_kwargs': self.cascade_kwargs,
            'alert_config': self.alerts,
            'friction_config': self.friction,
            'situation_config': self.situation,
        }


def _flat(prefix: str, section: Mapping[str, Any]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in section.items():
        if isinstance(value, dict):
            out.update(_flat(f'{prefix}{key}.', value))
        else:
            out[f'{prefix}{key}'] = value
    return out


_SECTIONS = ('observer', 'estimator', 'cascade', 'alerts', 'friction_potential', 'situation')


def load_replay_config(path: str | os.PathLike[str]) -> ReplayConfig:
    """Read replay settings from YAML: optional ``observer``, ``estimator``, ``cascade``,
    ``alerts``, ``friction_potential`` and ``situation`` mappings (flat, the keys of
    ``ObserverConfig.from_mapping`` / ``EstimatorConfig.from_mapping`` / extra ``run_cascade``
    keyword arguments / ``AlertConfig`` / ``FrictionPotentialConfig`` / ``SituationConfig``).

    Raises:
        ConfigurationError: unreadable file, not a mapping, or unknown keys.
    """
    try:
        data = yaml.safe_load(Path(path).read_text(encoding='utf-8')) or {}
    except (OSError, yaml.YAMLError, UnicodeDecodeError) as exc:
        raise ConfigurationError(f'{path}: cannot read replay settings: {exc}') from exc
    if not isinstance(data, dict) or set(data) - set(_SECTIONS):
        raise ConfigurationError(
            f'{path}: expected a mapping with sections among {" / ".join(_SECTIONS)}'
        )
    sections = {}
    for key in _SECTIONS:
        value = data.get(key)
        if value is not None and not isinstance(value, dict):
            raise ConfigurationError(f'{path}: {key} must be a mapping')
        sections[key] = value
    return ReplayConfig(
        observer=ObserverConfig.from_mapping(sections['observer'])
        if sections['observer'] is not None
        else None,
        estimator=EstimatorConfig.from_mapping(sections['estimator'])
        if sections['estimator'] is not None
        else None,
        cascade_kwargs=sections['cascade'],
        alerts=AlertConfig.from_mapping(sections['alerts'])
        if sections['alerts'] is not None
        else None,
        friction=FrictionPotentialConfig.from_mapping(sections['friction_potential'])
        if sections['friction_potential'] is not None
        else None,
        situation=SituationConfig.from_mapping(sections['situation'])
        if sections['situation'] is not None
        else None,
        given={
            k: v
            for key, section in sections.items()
            if section is not None
            for k, v in _flat(f'{key}.', section).items()
        },
        source=str(path),
    )
