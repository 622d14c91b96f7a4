"""Make the vd_observer_node and vd_sim_node sources importable before colcon installs them."""

import sys
from pathlib import Path

_SRC = Path(__file__).resolve().parents[2]
for _package in ('vd_observer_node', 'vd_sim_node'):
    _path = str(_SRC / _package)
    if _path not in sys.path:
        sys.path.insert(0, _path)
