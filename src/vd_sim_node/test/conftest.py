"""Make vd_sim_node and vd_common importable from the source before colcon installs them."""

import sys
from pathlib import Path

_SRC = Path(__file__).resolve().parents[2]
for _package in ('vd_sim_node', 'vd_common'):
    _path = str(_SRC / _package)
    if _path not in sys.path:
        sys.path.insert(0, _path)
