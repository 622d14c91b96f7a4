"""The ROS-free core imports in a Python where rclpy cannot be imported at all."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
NODE_FILE_SUFFIXES = ('_node.py', 'ros_common.py', 'node_params.py')  # ROS side: rclpy allowed
SOURCE_DIRS = [str(ROOT / 'src' / p) for p in ('vd_sim_node', 'vd_observer_node')]


def core_modules() -> list[str]:
    mods = []
    for pkg in ('vd_sim_node', 'vd_observer_node'):
        base = ROOT / 'src' / pkg
        for path in sorted((base / pkg).rglob('*.py')):
            if path.name.endswith(NODE_FILE_SUFFIXES) or '__pycache__' in path.parts:
                continue
            rel = path.relative_to(base).with_suffix('')
            parts = rel.parts[:-1] if rel.name == '__init__' else rel.parts
            mods.append('.'.join(parts))
    return mods


def test_there_is_a_core_to_check() -> None:
    assert len(core_modules()) >= 2


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
