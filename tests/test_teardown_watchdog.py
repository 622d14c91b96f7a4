"""`ros_common.TeardownWatchdog`: a hung middleware teardown ends the process with exit 0."""

from __future__ import annotations

import subprocess
import sys
import time

import pytest

_HANGS = """
import time
from vd_sim_node.ros_common import TeardownWatchdog
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
