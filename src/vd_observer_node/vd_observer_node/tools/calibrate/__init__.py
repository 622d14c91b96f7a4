"""Vehicle calibration from recorded drives (``vd calibrate``, issue #37); ROS-free core.

Pipeline: :func:`~.drive.read_drive` (a bag on the calibration grid) -> :func:`calibrate`
(the fits, in order) -> :func:`~.vehicle_file.vehicle_file_text` and
:func:`~.vehicle_file.write_vehicle_file`, :func:`~.report.write_report`. The sub-command is
in :mod:`.cli`. The names load on first use, so ``vd --help`` imports no numpy. See
docs/calibrate.md.
"""

from typing import TYPE_CHECKING

from vd_observer_node.tools.lazy import lazy_exports

if TYPE_CHECKING:  # the names as mypy and editors see them; imported on first use
    from vd_observer_node.tools.calibrate.calibration import Calibration, Fit, calibrate
    from vd_observer_node.tools.calibrate.drive import CalibrationDrive, read_drive
    from vd_observer_node.tools.calibrate.errors import CalibrationError, NotDeterminedError
    from vd_observer_node.tools.calibrate.radius import (
        FittedValue,
        fit_proportional,
        fit_rolling_radius,
    )
    from vd_observer_node.tools.calibrate.ratios import fit_final_drive, fit_gear_ratios

__all__ = [
    'Calibration',
    'CalibrationDrive',
    'CalibrationError',
    'Fit',
    'FittedValue',
    'NotDeterminedError',
    'calibrate',
    'fit_final_drive',
    'fit_gear_ratios',
    'fit_proportional',
    'fit_rolling_radius',
    'read_drive',
]

__getattr__ = lazy_exports(
    __name__,
    {
        'Calibration': 'calibration',
        'CalibrationDrive': 'drive',
        'CalibrationError': 'errors',
        'Fit': 'calibration',
        'FittedValue': 'radius',
        'NotDeterminedError': 'errors',
        'calibrate': 'calibration',
        'fit_final_drive': 'ratios',
        'fit_gear_ratios': 'ratios',
        'fit_proportional': 'radius',
        'fit_rolling_radius': 'radius',
        'read_drive': 'drive',
    },
)
