"""Declared parameters: one `ParamSpec` per parameter (type, range, choices, description),
declared with a descriptor, checked, and the non-default ones logged at start.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.exceptions import ParameterException
from rclpy.node import Node

from vd_common.settings_log import settings_line

__all__ = [
    'InvalidParameterError',
    'ParamSpec',
    'dataclass_param_specs',
    'declare_parameters',
    'given_parameters',
    'log_settings',
]


class InvalidParameterError(Exception):
    """A parameter value was refused; the message names it and the allowed values."""


@dataclass(frozen=True)
class ParamSpec:
    """One declared parameter.

    Attributes:
        name: parameter name.
        default: default value; its Python type fixes the parameter type. None: unset by
            default and of any type (the caller checks the value, e.g. a nested setting
            that only a params file gives).
        description: shown by ``ros2 param describe``; give the unit in brackets.
        low: inclusive lower bound for numbers (None: unbounded).
        high: inclusive upper bound for numbers (None: unbounded).
        choices: allowed values for strings (empty: any).
        read_only: the node reads it once at start.
    """

    name: str
    default: Any
    description: str
    low: float | None = None
    high: float | None = None
    choices: Sequence[str] = ()
    read_only: bool = True

    def allowed(self) -> str:
        if self.default is None:
            return 'any value (unset by default)'
        if self.choices:
            return 'one of ' + ', '.join(repr(c) for c in self.choices)
        if self.low is not None or self.high is not None:
            lo = '-inf' if self.low is None else f'{self.low:g}'
            hi = 'inf' if self.high is None else f'{self.high:g}'
            return f'in [{lo}, {hi}]'
        return f'a {type(self.default).__name__}'


def _attribute_docs(cls: type) -> dict[str, str]:
    """Descriptions of the 'Attributes:' section of a Google-style class docstring."""
    doc = cls.__doc__ or ''
    section = doc.split('Attributes:', 1)[1] if 'Attributes:' in doc else ''
    docs: dict[str, str] = {}
    name = None
    for line in section.splitlines():
        match = re.match(r'^\s{4,8}(\w+):\s*(.*)$', line)
        if match and (name is None or len(line) - len(line.lstrip()) <= 8):
            name, text = match.groups()
            docs[name] = text.strip()
        elif name and line.strip():
            docs[name] += ' ' + line.strip()
    return docs


def dataclass_param_specs(
    cls: type,
    *,
    skip: Sequence[str] = (),
    choices: Mapping[str, Sequence[str]] | None = None,
) -> list[ParamSpec]:
    """One ParamSpec per field of the configuration dataclass `cls` (defaults from `cls()`).

    Descriptions come from the class docstring's 'Attributes:' section, so parameters cannot
    drift from the core's configuration; values are validated by the dataclass itself.
    """
    defaults = cls()
    docs = _attribute_docs(cls)
    return [
        ParamSpec(
            f.name,
            getattr(defaults, f.name),
            docs.get(f.name, f.name),
            choices=tuple((choices or {}).get(f.name, ())),
        )
        for f in dataclasses.fields(cls)
        if f.name not in skip
    ]


def _descriptor(spec: ParamSpec) -> ParameterDescriptor:
    desc = ParameterDescriptor(
        description=spec.description,
        read_only=spec.read_only,
        dynamic_typing=spec.default is None,
        additional_constraints=('allowed: ' + spec.allowed()) if spec.choices else '',
    )
    if spec.low is not None and spec.high is not None and not isinstance(spec.default, bool):
        if isinstance(spec.default, int):
            desc.integer_range = [
                IntegerRange(from_value=int(spec.low), to_value=int(spec.high), step=0)
            ]
        elif isinstance(spec.default, float):
            desc.floating_point_range = [
                FloatingPointRange(from_value=float(spec.low), to_value=float(spec.high), step=0.0)
            ]
    return desc


def declare_parameters(node: Node, specs: Sequence[ParamSpec]) -> dict[str, Any]:
    """Declare `specs` on `node` and return their values, checked against the specs.

    Raises:
        InvalidParameterError: a value has the wrong type or lies outside its range/choices; the
            message names the parameter, the value and what is allowed.
    """
    values: dict[str, Any] = {}
    for spec in specs:
        try:
            param = node.declare_parameter(spec.name, spec.default, _descriptor(spec))
        except ParameterException as exc:
            raise InvalidParameterError(
                f'parameter {spec.name!r} refused ({exc}); allowed: {spec.allowed()}'
            ) from None
        value = param.value
        if spec.default is None:  # unset (None) or any type: the caller checks it
            values[spec.name] = value
            continue
        if isinstance(spec.default, float) and isinstance(value, int):
            value = float(value)
        if type(value) is not type(spec.default):
            raise InvalidParameterError(
                f'parameter {spec.name!r} must be {type(spec.default).__name__}, got {value!r}'
            )
        bad_choice = spec.choices and value not in spec.choices
        below = spec.low is not None and isinstance(value, int | float) and value < spec.low
        above = spec.high is not None and isinstance(value, int | float) and value > spec.high
        if bad_choice or below or above:
            raise InvalidParameterError(
                f'parameter {spec.name!r} = {value!r} refused; allowed: {spec.allowed()}'
            )
        values[spec.name] = value
    return values


def given_parameters(specs: Sequence[ParamSpec], values: Mapping[str, Any]) -> dict[str, Any]:
    """The parameters of `values` (`declare_parameters`' result) that are not their defaults,
    by name: what a params file or ``-p`` set (a value equal to its default counts as the
    default; an unset parameter without default is left out), for the node's start-up log."""
    given: dict[str, Any] = {}
    for spec in specs:
        if spec.name not in values:
            continue
        value = values[spec.name]
        if spec.default is None:
            if value is not None:
                given[spec.name] = value
        elif value != spec.default:
            given[spec.name] = value
    return given


def log_settings(node: Node, specs: Sequence[ParamSpec], values: Mapping[str, Any]) -> None:
    """Log (INFO) the parameters that are not their defaults (`given_parameters`)."""
    line = settings_line(given_parameters(specs, values), 'parameters')
    node.get_logger().info(f'settings: {line}')
