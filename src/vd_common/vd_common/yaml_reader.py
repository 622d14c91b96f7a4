"""Small helpers that read typed, range-checked values out of nested YAML mappings.

Every failure raises the error class given by the caller with a message that names the
offending key by its dotted path, so a user sees exactly one clear message such as
``chassis.mass must be > 0 kg, got -3``.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any, TypeAlias

import yaml

__all__ = ['KeySchema', 'MappingReader', 'check_known_keys', 'load_yaml_mapping']

#: The keys a YAML mapping may hold: each key maps to the schema of its nested mapping, or
#: to None for a value that is not checked further (a number, a list, a string).
KeySchema: TypeAlias = Mapping[str, 'KeySchema | None']


def check_known_keys(data: Any, schema: KeySchema, error: type[Exception], path: str = '') -> None:
    """Refuse the first key of ``data`` (depth first, in file order) that ``schema`` lacks.

    A misspelt key would otherwise be ignored (an optional one: its default is used
    silently) or be reported as the key it should have been being missing. Values that are
    not mappings where the schema expects one are left to the typed readers, which name them.

    Args:
        data: the parsed YAML mapping (anything else is not checked).
        schema: the known keys, nested.
        error: exception class raised.
        path: dotted path of ``data`` in the document ('' for the top level).

    Raises:
        error: ``brakes.gain_frnt is not a known key; did you mean brakes.gain_front?`` (the
            closest known key when one is close, else the known keys of that mapping).
    """
    if not isinstance(data, Mapping):
        return
    prefix = f'{path}.' if path else ''
    for key, value in data.items():
        name = f'{prefix}{key}'
        if not isinstance(key, str) or key not in schema:
            close = difflib.get_close_matches(str(key), list(schema), n=1, cutoff=0.6)
            hint = (
                f'did you mean {prefix}{close[0]}?'
                if close
                else f'known keys{" of " + path if path else ""}: {", ".join(schema)}'
            )
            raise error(f'{name} is not a known key; {hint}')
        nested = schema[key]
        if nested is not None:
            check_known_keys(value, nested, error, name)


def load_yaml_mapping(path: str | Path, error: type[Exception], what: str = '') -> dict[str, Any]:
    """Read a YAML file whose top level must be a mapping.

    Every message is one line (PyYAML's own span several), because a node refusing to start
    prints exactly this message as its single ``error:`` line.

    Args:
        path: file to read.
        error: exception class raised on any failure.
        what: what the file is, named before its path in messages (e.g. ``'vehicle file'``
            gives ``cannot read vehicle file x.yaml: ...``); empty: the path alone.

    Returns:
        The parsed top-level mapping.
    """
    p = Path(path)
    label = f'{what} {p}' if what else str(p)
    try:
        text = p.read_text(encoding='utf-8')
    except OSError as exc:
        raise error(f'cannot read {label}: {exc}') from exc
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        reason = ' '.join(str(exc).split())
        raise error(f'{label} is not valid YAML: {reason}') from exc
    if not isinstance(data, dict):
        raise error(f'{label}: top level must be a mapping, got {type(data).__name__}')
    return data


class MappingReader:
    """Typed access to one YAML mapping, remembering its dotted path for error messages."""

    def __init__(self, data: Any, path: str, error: type[Exception]) -> None:
        """Wrap ``data`` (must be a mapping) found at dotted ``path``."""
        if not isinstance(data, Mapping):
            where = path or 'document'
            raise error(f'{where} must be a mapping, got {type(data).__name__}')
        self._data = data
        self._path = path
        self._error = error

    def _key(self, key: str) -> str:
        return f'{self._path}.{key}' if self._path else key

    def has(self, key: str) -> bool:
        """Whether ``key`` is present (even if null)."""
        return key in self._data

    def raw(self, key: str) -> Any:
        """The raw value of a required key."""
        if key not in self._data or self._data[key] is None:
            raise self._error(f'{self._key(key)} is missing')
        return self._data[key]

    def section(self, key: str) -> MappingReader:
        """A reader for the required nested mapping ``key``."""
        return MappingReader(self.raw(key), self._key(key), self._error)

    def optional_section(self, key: str) -> MappingReader | None:
        """A reader for nested mapping ``key`` or None if absent."""
        if key not in self._data or self._data[key] is None:
            return None
        return self.section(key)

    def number(
        self,
        key: str,
        unit: str = '',
        *,
        gt: float | None = None,
        ge: float | None = None,
        lt: float | None = None,
        le: float | None = None,
        default: float | None = None,
    ) -> float:
        """A finite real number with optional bounds.

        Args:
            key: key inside this mapping.
            unit: unit named in error messages, e.g. ``'kg'``.
            gt, ge, lt, le: strict/non-strict lower and upper bounds.
            default: value used when the key is absent (None: the key is required).

        Returns:
            The value as float.
        """
        if default is not None and (key not in self._data or self._data[key] is None):
            return float(default)
        return self._check_number(self._key(key), self.raw(key), unit, gt, ge, lt, le)

    def _check_number(
        self,
        name: str,
        value: Any,
        unit: str,
        gt: float | None,
        ge: float | None,
        lt: float | None,
        le: float | None,
    ) -> float:
        u = f' {unit}' if unit else ''
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self._error(f'{name} must be a number{u}, got {value!r}')
        x = float(value)
        if not math.isfinite(x):
            raise self._error(f'{name} must be finite, got {value!r}')
        if gt is not None and not x > gt:
            raise self._error(f'{name} must be > {gt:g}{u}, got {value!r}')
        if ge is not None and not x >= ge:
            raise self._error(f'{name} must be >= {ge:g}{u}, got {value!r}')
        if lt is not None and not x < lt:
            raise self._error(f'{name} must be < {lt:g}{u}, got {value!r}')
        if le is not None and not x <= le:
            raise self._error(f'{name} must be <= {le:g}{u}, got {value!r}')
        return x

    def number_list(
        self,
        key: str,
        unit: str = '',
        *,
        min_len: int = 1,
        gt: float | None = None,
        ge: float | None = None,
        increasing: bool = False,
        decreasing: bool = False,
    ) -> tuple[float, ...]:
        """A list of finite numbers with optional element bounds and monotonicity."""
        name = self._key(key)
        value = self.raw(key)
        if not isinstance(value, list):
            raise self._error(f'{name} must be a list of numbers, got {value!r}')
        if len(value) < min_len:
            raise self._error(f'{name} needs at least {min_len} entries, got {len(value)}')
        out = tuple(
            self._check_number(f'{name}[{i}]', v, unit, gt, ge, None, None)
            for i, v in enumerate(value)
        )
        for i in range(1, len(out)):
            if increasing and not out[i] > out[i - 1]:
                raise self._error(f'{name} must be strictly increasing, got {list(out)}')
            if decreasing and not out[i] < out[i - 1]:
                raise self._error(f'{name} must be strictly decreasing, got {list(out)}')
        return out

    def string(self, key: str, default: str | None = None) -> str:
        """A string value (``default`` when absent, if given)."""
        if default is not None and (key not in self._data or self._data[key] is None):
            return default
        value = self.raw(key)
        if not isinstance(value, str):
            raise self._error(f'{self._key(key)} must be a string, got {value!r}')
        return value

    def boolean(self, key: str, default: bool | None = None) -> bool:
        """A boolean value (``default`` when absent, if given)."""
        if default is not None and (key not in self._data or self._data[key] is None):
            return default
        value = self.raw(key)
        if not isinstance(value, bool):
            raise self._error(f'{self._key(key)} must be true or false, got {value!r}')
        return value

    def integer(self, key: str, *, ge: int | None = None, default: int | None = None) -> int:
        """An integer value with optional lower bound."""
        if default is not None and (key not in self._data or self._data[key] is None):
            return default
        value = self.raw(key)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self._error(f'{self._key(key)} must be an integer, got {value!r}')
        if ge is not None and value < ge:
            raise self._error(f'{self._key(key)} must be >= {ge}, got {value!r}')
        return value
