"""Vehicle calibration from recorded drives (``vd calibrate``, issue #37); ROS-free core."""

from vd_observer_node.tools.calibrate.errors import CalibrationError, NotDeterminedError
from vd_observer_node.tools.calibrate.radius import FittedValue, fit_rolling_radius

__all__ = ['CalibrationError', 'FittedValue', 'NotDeterminedError', 'fit_rolling_radius']
