"""The calibration's report: the fitted values as JSON and Markdown, each fit's residuals as PNG.

``calibration.json`` (machine-readable: key, value, std, samples, how; the keys not
determined with their reason; the notes; the IMU's mounting), ``calibration.md`` (the same
as tables) and one ``residuals_<fit>.png`` per fit with residuals (rolling radius, final
drive per gear, force balance, driven axle).
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from vd_observer_node.inputs.mounting import MountingFit
from vd_observer_node.tools.calibrate.calibration import Calibration
from vd_observer_node.tools.calibrate.errors import CalibrationError

__all__ = ['mounting_line', 'write_report']


def _json(calibration: Calibration, sources: str) -> dict[str, Any]:
    m = calibration.mounting
    return {
        'sources': sources,
        'drive_seconds': calibration.drive_seconds,
        'fitted': [
            {
                'key': f.key,
                'value': f.value,
                'std': f.std,
                'samples': f.samples,
                'how': f.how,
            }
            for f in calibration.fits.values()
        ],
        'not_determined': dict(calibration.not_determined),
        'notes': list(calibration.notes),
        'imu_mounting': None
        if m is None
        else {
            'mount_rpy_deg': list(m.rpy_deg),
            'std_deg': list(m.std_deg),
            'gain': m.gain,
            'samples': m.samples,
        },
    }


def mounting_line(fit: MountingFit) -> str:
    """The fitted mounting as the mapping's key, e.g. ``imu.mount_rpy_deg: [180.0, 0.8,
    -1.0] ± [0.3, 0.2, 0.4] deg (1200 samples)``."""
    values = ', '.join(f'{v:.1f}' for v in fit.rpy_deg)
    spread = ', '.join(f'{v:.1f}' for v in fit.std_deg)
    return f'imu.mount_rpy_deg: [{values}] ± [{spread}] deg ({fit.samples} samples)'


def _markdown(calibration: Calibration, sources: str, figures: list[str]) -> str:
    lines = [
        f'# Calibration from {sources}',
        '',
        f'{calibration.drive_seconds:.0f} s of drive.',
        '',
        '| key | value | std | samples | how |',
        '|---|---|---|---|---|',
    ]
    for f in calibration.fits.values():
        value = f'{f.value:.6g}' if isinstance(f.value, float) else str(f.value)
        std = f'{f.std:.3g}' if isinstance(f.std, float) else ('-' if f.std is None else 'table')
        lines.append(f'| `{f.key}` | {value} | {std} | {f.samples} | {f.how} |')
    if calibration.mounting is not None:
        lines += ['', '## IMU mounting (for the input mapping)', '']
        lines += [f'`{mounting_line(calibration.mounting)}`']
    if calibration.not_determined:
        lines += ['', '## Not determined', '']
        lines += [f'- `{k}`: {v}' for k, v in calibration.not_determined.items()]
    if calibration.notes:
        lines += ['', '## Notes', '']
        lines += [f'- {n}' for n in calibration.notes]
    if figures:
        lines += ['', '## Residuals', '']
        lines += [f'![{name}]({name})' for name in figures]
    return '\n'.join(lines) + '\n'


def _figures(calibration: Calibration, folder: Path) -> list[str]:
    import matplotlib

    matplotlib.use('Agg')  # files only, never a window
    import matplotlib.pyplot as plt

    names = []
    for title, (x, residual, xlabel, ylabel) in calibration.residuals.items():
        name = 'residuals_' + title.replace(' ', '_') + '.png'
        fig, ax = plt.subplots(figsize=(6.4, 3.6))
        ax.plot(x, residual, '.', markersize=2 if len(x) > 50 else 6)
        ax.axhline(0.0, color='k', linewidth=0.8)
        ax.set_xlabel(xlabel)
        ax.set_ylabel(ylabel)
        ax.set_title(title)
        ax.grid(True, alpha=0.3)
        fig.tight_layout()
        fig.savefig(folder / name, dpi=100)
        plt.close(fig)
        names.append(name)
    return names


def write_report(folder: str | os.PathLike[str], calibration: Calibration, sources: str) -> None:
    """Write the report into ``folder`` (created).

    Raises:
        CalibrationError: the folder cannot be written.
    """
    out = Path(folder)
    try:
        out.mkdir(parents=True, exist_ok=True)
        figures = _figures(calibration, out)
        (out / 'calibration.json').write_text(
            json.dumps(_json(calibration, sources), indent=2) + '\n', encoding='utf-8'
        )
        (out / 'calibration.md').write_text(
            _markdown(calibration, sources, figures), encoding='utf-8'
        )
    except OSError as error:
        raise CalibrationError(f'cannot write the report into {out}: {error}') from error
