"""Shared fixtures of the cross-package tests (graph, bag and layout tests).

These tests run inside the environment of ``env.sh`` (``make test`` sources it), so the
colcon-installed packages, rclpy and the vd_msgs Python bindings are importable, and
processes they start find them too.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))

from rosproc import RosProcessGroup  # noqa: E402


@pytest.fixture
def ros_env(worker_domain_id: int) -> dict[str, str]:
    """Environment for ROS processes of one test: an isolated DDS domain on loopback."""
    env = dict(os.environ)
    env['ROS_DOMAIN_ID'] = str(worker_domain_id)
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    env['PYTHONUNBUFFERED'] = '1'
    return env


_domain_counter = iter(range(40, 100))


@pytest.fixture
def worker_domain_id() -> int:
    """A fresh ROS domain id per test, so tests never hear each other's topics."""
    return next(_domain_counter)


@pytest.fixture
def procs(ros_env: dict[str, str], tmp_path: Path) -> Iterator[RosProcessGroup]:
    """Processes started by a test; all are stopped (SIGINT, then SIGKILL) at its end."""
    group = RosProcessGroup(ros_env, tmp_path)
    try:
        yield group
    finally:
        group.stop_all()


@pytest.fixture(scope='session')
def install_dir() -> Path:
    """The colcon install folder of the workspace."""
    path = ROOT / 'install'
    if not (path / 'local_setup.bash').exists():
        pytest.fail('install/ is missing: run `make setup` (make test does it) first')
    return path
