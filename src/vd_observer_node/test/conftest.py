"""Make the vd_observer_node and vd_common sources importable before colcon installs them.

vd_sim_node too: the tests use the simulator as their oracle (a test dependency only; the
package itself never imports it, tests/test_standalone_estimator.py checks that).
"""

import sys
from pathlib import Path

_SRC = Path(__file__).resolve().parents[2]
for _package in ('vd_observer_node', 'vd_sim_node', 'vd_common'):
    _path = str(_SRC / _package)
    if _path not in sys.path:
        sys.path.insert(0, _path)
