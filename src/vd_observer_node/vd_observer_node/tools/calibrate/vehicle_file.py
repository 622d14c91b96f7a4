"""The calibrated vehicle file: the estimation keys, each with where its value comes from.

The file has the layout of the estimation-only files (docs/vehicle_file.md): the sections and
keys `vd_common.vehicle.estimation` reads, in their order. Each key's comment says whether it
was fitted (with its standard deviation and sample count), not determined by the drive (and
why) and so taken from the base file, or taken from the base file because a drive never
determines it (wheelbase, inertias). The text is checked by the estimators' own parser before
it is written, and written whole or not at all.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml
from vd_common.vehicle.estimation import parse_estimation_vehicle

from vd_observer_node.tools.calibrate.calibration import Calibration, Fit
from vd_observer_node.tools.calibrate.errors import CalibrationError

__all__ = ['ESTIMATION_KEYS', 'vehicle_file_text', 'write_vehicle_file']

#: The estimation file's sections and keys, in the file's order (None: the whole section).
ESTIMATION_KEYS: dict[str, tuple[str, ...] | None] = {
    'chassis': ('mass', 'wheelbase', 'cg_to_front_axle', 'cg_height'),
    'wheel': ('inertia_front', 'inertia_rear', 'effective_radius'),
    'aero': ('drag_coefficient', 'frontal_area', 'air_density'),
    'rolling_resistance': None,
    'environment': None,
    'gearbox': ('ratios', 'reverse_ratio', 'final_drive', 'efficiency'),
    'engine': ('inertia',),
    'driveline': ('layout', 'front_share'),
    'torque_converter': ('speed_ratio', 'torque_ratio', 'capacity_factor'),
    'brakes': ('gain_front', 'gain_rear'),
    'tire': None,
}


def _number(value: float) -> str:
    return f'{value:.6g}'


def _scalar(value: Any) -> str:
    if isinstance(value, bool) or value is None or isinstance(value, str):
        return str(yaml.safe_dump(value, default_flow_style=True)).split('\n')[0]
    if isinstance(value, int | float):
        return _number(float(value)) if isinstance(value, float) else str(value)
    if isinstance(value, list | tuple):
        return '[' + ', '.join(_scalar(v) for v in value) + ']'
    raise CalibrationError(f'cannot write {value!r} into the vehicle file')


def _fitted_comment(fit: Fit) -> str:
    if fit.std is None:
        spread = ''
    elif isinstance(fit.std, tuple):
        spread = ' ± [' + ', '.join('-' if s != s else _number(s) for s in fit.std) + ']'
    else:
        spread = f' ± {_number(fit.std)}'
    return f'fitted{spread} ({fit.samples} samples): {fit.how}'


def _key_lines(
    calibration: Calibration, given: Mapping[str, Any], section: str, key: str
) -> list[str]:
    """The file's lines of one key: fitted, or the base's value with why."""
    dotted = f'{section}.{key}'
    fit = calibration.fits.get(dotted)
    if fit is not None:
        return [f'  {key}: {_scalar(fit.value)}  # {_fitted_comment(fit)}']
    if key not in given:
        return []
    why = calibration.not_determined.get(dotted)
    origin = f'base; not determined: {why}' if why else 'base'
    value = given[key]
    if isinstance(value, Mapping):
        dumped = yaml.safe_dump(dict(value), default_flow_style=None, sort_keys=False)
        return [f'  {key}:  # {origin}', *('    ' + row for row in dumped.splitlines())]
    return [f'  {key}: {_scalar(value)}  # {origin}']


def vehicle_file_text(
    calibration: Calibration, base: Mapping[str, Any], base_name: str, sources: str
) -> str:
    """The calibrated file's text.

    Args:
        calibration: the fits.
        base: the base vehicle file as parsed YAML (its values fill what was not fitted).
        base_name: how the comments name the base ('the base file x.yaml', 'vd's default').
        sources: the bags, for the header.

    Raises:
        CalibrationError: the base lacks a section the estimators need.
    """
    lines = [
        f'# Written by vd calibrate from {sources}: an estimation-only vehicle file',
        '# (docs/calibrate.md). Each key says whether the drive determined it ("fitted", with',
        '# its standard deviation and the samples of the 20 Hz calibration grid it rests on) or',
        f'# not ("base": from {base_name}).',
        f'name: {_scalar(str(base.get("name", "vehicle")) + " (calibrated)")}',
    ]
    for section, keys in ESTIMATION_KEYS.items():
        given = base.get(section)
        if not isinstance(given, Mapping):
            given = {}
        if keys is None:
            keys = tuple(given)
        layout = calibration.fits.get('driveline.layout')
        if section == 'driveline' and layout is not None and layout.value != 'AWD':
            keys = ('layout',)
        body = [row for key in keys for row in _key_lines(calibration, given, section, key)]
        if body:
            lines += ['', f'{section}:', *body]
    return '\n'.join(lines) + '\n'


def write_vehicle_file(path: str | os.PathLike[str], text: str) -> None:
    """Check ``text`` with the estimators' parser, then write it whole (a temporary file
    renamed into place: an interrupted write leaves no partial file).

    Raises:
        CalibrationError: the text is not a valid estimation file, or cannot be written.
    """
    target = Path(path)
    try:
        parse_estimation_vehicle(yaml.safe_load(text), source=str(target))
    except Exception as error:
        raise CalibrationError(f'the calibrated file would not load: {error}') from error
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(
            'w', encoding='utf-8', dir=target.parent, prefix=f'.{target.name}.', delete=False
        ) as handle:
            handle.write(text)
        os.replace(handle.name, target)
    except OSError as error:
        raise CalibrationError(f'cannot write {target}: {error}') from error
