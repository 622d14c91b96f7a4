"""Shared fixtures of the cross-package tests (graph, bag and layout tests).

These tests run inside the environment of ``env.sh`` (``make test`` sources it), so the
colcon-installed packages, rclpy and the vd_msgs Python bindings are importable, and
processes they start find them too.
"""

from __future__ import annotations

import fcntl
import os
import sys
import tempfile
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


#: Domain ids the tests use: ROS 2's portable range (1..101), one per test.
_DOMAINS = range(1, 102)
_next_domain = [0]
_LOCKS = Path(tempfile.gettempdir()) / 'vd-test-ros-domains'


@pytest.fixture
def worker_domain_id() -> Iterator[int]:
    """A ROS domain id that no other running test uses, on this machine: held by a lock file.

    Fresh per test within a session (the search goes on where the last test's ended), so a
    test never hears the topics of an earlier one; and locked for the test's duration, so two
    test sessions at once (a developer's beside scripts/stress_suite.sh) never share a
    domain: when they did, one graph test received the other's simulator.
    """
    _LOCKS.mkdir(exist_ok=True)
    for _ in range(len(_DOMAINS)):
        domain = _DOMAINS[_next_domain[0] % len(_DOMAINS)]
        _next_domain[0] += 1
        lock = (_LOCKS / f'{domain}.lock').open('w')
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            lock.close()
            continue
        try:
            yield domain
        finally:
            lock.close()  # releases the lock
        return
    pytest.fail(f'every ROS domain id in {_DOMAINS} is in use by other test sessions')


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
