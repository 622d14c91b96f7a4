"""The ROS-free core imports in a Python where rclpy cannot be imported at all.

Every module of the three Python packages but the ROS side (the nodes, their parameter lists
and `vd_common.ros`): the simulator's and the estimator's cores, and what vd_common
shares with them (topics, errors, the vehicle-file parser, the tyre, the entry guard, the
``--params-file`` check).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
NODE_FILE_SUFFIXES = ('_node.py', 'node_params.py')  # ROS side: rclpy allowed
#: the folder of vd_common's ROS plumbing (ROS side too)
ROS_FOLDER = ('vd_common', 'vd_common', 'ros')
PACKAGES = ('vd_common', 'vd_sim_node', 'vd_observer_node')
SOURCE_DIRS = [str(ROOT / 'src' / p) for p in PACKAGES]


def core_modules() -> list[str]:
    mods = []
    for pkg in PACKAGES:
        base = ROOT / 'src' / pkg
        for path in sorted((base / pkg).rglob('*.py')):
            if path.name.endswith(NODE_FILE_SUFFIXES) or '__pycache__' in path.parts:
                continue
            if path.relative_to(ROOT / 'src').parts[:3] == ROS_FOLDER:
                continue
            rel = path.relative_to(base).with_suffix('')
            parts = rel.parts[:-1] if rel.name == '__init__' else rel.parts
            mods.append('.'.join(parts))
    return mods


def test_there_is_a_core_to_check() -> None:
    modules = core_modules()
    assert len(modules) >= 2
    for shared in ('topics', 'errors', 'params_file', 'entry', 'yaml_reader'):
        assert f'vd_common.{shared}' in modules
    for shared in ('params', 'tire', 'friction'):
        assert f'vd_common.vehicle.{shared}' in modules
    assert not [m for m in modules if m.startswith('vd_common.ros')]  # the ROS side


def test_core_modules_import_without_rclpy() -> None:
    code = (
        'import sys\n'
        "for name in ('rclpy', 'rclpy.node', 'rosidl_runtime_py'):\n"
        '    sys.modules[name] = None  # any import of them now raises ImportError\n'
        f'sys.path[:0] = {SOURCE_DIRS!r}\n'
        'import importlib\n'
        f'for mod in {core_modules()!r}:\n'
        '    importlib.import_module(mod)\n'
        "print('CORE OK')\n"
    )
    result = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert 'CORE OK' in result.stdout
