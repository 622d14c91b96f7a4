"""`lifecycle.TeardownWatchdog`: a hung middleware teardown ends the process with the exit
code it was going to have: 0 after a stop, 2 after a refusal."""

from __future__ import annotations

import subprocess
import sys
import time

import pytest

_HANGS = """
import time
from vd_common.ros.lifecycle import TeardownWatchdog
print('outputs closed', flush=True)
with TeardownWatchdog({timeout}):
    time.sleep({sleep})  # stands for an executor shutdown that does not return
print('teardown finished', flush=True)
"""


def _run(timeout: float, sleep: float) -> tuple[subprocess.CompletedProcess[str], float]:
    started = time.monotonic()
    code = _HANGS.format(timeout=timeout, sleep=sleep)
    result = subprocess.run(
        [sys.executable, '-c', code], capture_output=True, text=True, timeout=60
    )
    return result, time.monotonic() - started


@pytest.mark.ros
def test_a_hung_teardown_is_cut_short_with_exit_0_and_one_line() -> None:
    result, elapsed = _run(timeout=0.5, sleep=30.0)
    assert result.returncode == 0
    assert result.stdout == 'outputs closed\n'  # flushed before the exit, nothing after
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith('teardown still running after 0 s, in <module>')
    assert 'Traceback' not in result.stderr
    assert elapsed < 25.0  # not the 30 s sleep


@pytest.mark.ros
def test_a_teardown_in_time_is_left_alone() -> None:
    result, _ = _run(timeout=10.0, sleep=0.05)
    assert result.returncode == 0
    assert result.stdout == 'outputs closed\nteardown finished\n'
    assert result.stderr == ''


# A node refused while being built: the line is out, then the half-built node is released with
# the exception, and its middleware teardown hangs. The process must still end, with code 2.
_REFUSED_THEN_HANGS = """
import time
import rclpy.node
from vd_common.ros import lifecycle, parameters

class MiddlewareTeardown:
    def __del__(self):  # runs when the half-built node is released
        print('teardown entered', flush=True)
        time.sleep(30)  # stands for a teardown that does not return

class Refused(rclpy.node.Node):
    def __init__(self):
        super().__init__('refused')
        self.middleware = MiddlewareTeardown()
        raise parameters.InvalidParameterError('max_gap must be > 0, got -1.0')

lifecycle.TEARDOWN_TIMEOUT_S = 0.5
raise SystemExit(lifecycle.run_node(Refused, []))
"""


@pytest.mark.ros
def test_a_refused_node_whose_teardown_hangs_exits_with_code_2(ros_env: dict[str, str]) -> None:
    env = {**ros_env, 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'OFF'}  # alone (tests/rosproc.py)
    result = subprocess.run(
        [sys.executable, '-c', _REFUSED_THEN_HANGS],
        capture_output=True,
        text=True,
        timeout=20,  # the hang lasts 30 s
        env=env,
    )
    assert result.stdout == 'teardown entered\n', result
    assert result.returncode == 2, result
    lines = result.stderr.strip().splitlines()
    assert lines[0] == 'error: max_gap must be > 0, got -1.0', result.stderr
    assert len(lines) == 2, result.stderr
    assert lines[1].startswith('teardown still running after 0 s, in __del__'), result.stderr


# rclpy's C++ calls hold the GIL: a teardown stuck in one leaves the watchdog's Python thread
# waiting; the backstop (faulthandler, a C thread) ends the process, code 1, with the stacks.
_HANGS_HOLDING_THE_GIL = """
import ctypes
from vd_common.ros import lifecycle, parameters
print('outputs closed', flush=True)
lifecycle.TEARDOWN_BACKSTOP_GRACE_S = 0.5
with lifecycle.TeardownWatchdog(0.5):
    ctypes.PyDLL(None).sleep(30)  # libc sleep, GIL held: a Fast DDS deadlock in rclpy
print('teardown finished', flush=True)
"""


@pytest.mark.ros
def test_a_teardown_stuck_holding_the_gil_is_ended_by_the_backstop() -> None:
    result = subprocess.run(
        [sys.executable, '-c', _HANGS_HOLDING_THE_GIL],
        capture_output=True,
        text=True,
        timeout=20,  # the hang lasts 30 s
    )
    assert result.returncode == 1, result
    assert result.stdout == 'outputs closed\n', result
    assert result.stderr.startswith('Timeout (0:00:01)!'), result.stderr
    assert 'in <module>' in result.stderr, result.stderr  # where the main thread was stuck
