"""Vehicle calibration from recorded drives (``vd calibrate``, issue #37); ROS-free core."""

from vd_observer_node.tools.calibrate.errors import CalibrationError, NotDeterminedError
from vd_observer_node.tools.calibrate.radius import (
    FittedValue,
    fit_proportional,
    fit_rolling_radius,
)
from vd_observer_node.tools.calibrate.ratios import fit_final_drive, fit_gear_ratios

__all__ = [
    'CalibrationError',
    'FittedValue',
    'NotDeterminedError',
    'fit_final_drive',
    'fit_gear_ratios',
    'fit_proportional',
    'fit_rolling_radius',
]
