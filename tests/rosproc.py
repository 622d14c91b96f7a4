"""Start ROS 2 processes from tests and talk to them through their output (no launch_testing)."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterable
from pathlib import Path

__all__ = ['RosProcess', 'RosProcessGroup']


class RosProcess:
    """One child process whose stdout+stderr go to a log file that tests can poll."""

    def __init__(self, name: str, argv: list[str], env: dict[str, str], log_dir: Path) -> None:
        self.name = name
        self.log_path = log_dir / f'{name}.log'
        self._log = self.log_path.open('wb')
        self.popen = subprocess.Popen(
            argv, env=env, stdout=self._log, stderr=subprocess.STDOUT, start_new_session=True
        )

    def output(self) -> str:
        return self.log_path.read_text(errors='replace')

    def stacks(self) -> str:
        """The output, after asking the process for its threads' Python stacks if it runs.

        vd's node entry points dump them on SIGUSR1 (vd_common.entry); other processes are
        left alone (SIGUSR1 would end them). For failure messages: where a hung node is.
        """
        if self.popen.poll() is None and catches_signal(self.popen.pid, signal.SIGUSR1):
            size = self.log_path.stat().st_size
            with contextlib.suppress(ProcessLookupError):
                os.kill(self.popen.pid, signal.SIGUSR1)
            deadline = time.monotonic() + 5.0
            while time.monotonic() < deadline and self.log_path.stat().st_size == size:
                time.sleep(0.05)
            time.sleep(0.2)  # the rest of the dump
        return self.output()

    def wait_for(self, text: str, timeout: float = 20.0) -> str:
        """Wait until `text` appears in the output; fail with the output if it does not."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            out = self.output()
            if text in out:
                return out
            if self.popen.poll() is not None:
                break
            time.sleep(0.05)
        out = self.output()
        if text in out:
            return out
        out = self.stacks()
        raise AssertionError(
            f'{self.name}: {text!r} not seen within {timeout} s '
            f'(exit code {self.popen.poll()}); output:\n{out[-4000:]}'
        )

    def stop(self, sig: int = signal.SIGINT, timeout: float = 30.0) -> int:
        """Send `sig` to the process group, wait, escalate to SIGKILL; return the exit code."""
        if self.popen.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self.popen.pid, sig)
            try:
                self.popen.wait(timeout)
            except subprocess.TimeoutExpired:
                os.killpg(self.popen.pid, signal.SIGKILL)
                self.popen.wait(5)
        self._log.close()
        return self.popen.returncode


def catches_signal(pid: int, sig: int) -> bool:
    """True if process `pid` has a handler for `sig` (SigCgt in /proc/<pid>/status)."""
    try:
        status = Path(f'/proc/{pid}/status').read_text()
    except OSError:
        return False
    for line in status.splitlines():
        if line.startswith('SigCgt:'):
            return bool(int(line.split()[1], 16) & (1 << (sig - 1)))
    return False


def wait_recording(recorder: RosProcess, topics: Iterable[str], timeout: float = 60.0) -> None:
    """Wait until the recorder is connected to a publisher of each topic.

    The recorder logs 'recording TOPIC (TYPE)' when its subscription matches the topic's first
    publisher. Messages published before that are not in the bag (volatile QoS), so a test
    that compares a bag with everything a node published waits on this, after starting the
    node and before the data flows.
    """
    for topic in topics:
        recorder.wait_for(f'recording {topic} (', timeout=timeout)


class RosProcessGroup:
    """The processes of one test."""

    def __init__(self, env: dict[str, str], log_dir: Path) -> None:
        self.env = env
        self.log_dir = log_dir
        self.procs: list[RosProcess] = []

    def start(self, name: str, argv: list[str], **env: str) -> RosProcess:
        proc = RosProcess(name, argv, {**self.env, **env}, self.log_dir)
        self.procs.append(proc)
        return proc

    def node(
        self,
        name: str,
        package: str,
        executable: str,
        env: dict[str, str] | None = None,
        **params: object,
    ) -> RosProcess:
        """Start a node as `ros2 run` would, with `-p key:=value` for each parameter.

        `env` adds to (or overrides) the group's environment for this process.
        """
        from vd_observer_node.testing.launcher import NodeSpec

        return self.start(name, NodeSpec(package, executable, name, params).argv(), **(env or {}))

    def python(self, name: str, script: Path | str, *args: str, **env: str) -> RosProcess:
        return self.start(name, [sys.executable, str(script), *args], **env)

    def without_discovery(self) -> RosProcessGroup:
        """This group, for processes that must not discover any other participant.

        For processes that are checked one by one and never talk (e.g. nodes refused at
        start): ``ROS_AUTOMATIC_DISCOVERY_RANGE=OFF``, with which rmw_fastrtps admits no remote
        participant. Started in one domain, such processes would see each other come and go,
        and Fast DDS 3.2 can deadlock a participant that receives the endpoint removals of
        another one in its first seconds (a discovery thread holding the PDP mutex waits for
        the event thread, whose participant announcement waits for that mutex; the main thread
        then blocks in its next endpoint creation): twelve refused nodes started together hung
        one of them inside ``Node()`` before it printed its line. The processes are still
        stopped with this group's.
        """
        view = RosProcessGroup({**self.env, 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'OFF'}, self.log_dir)
        view.procs = self.procs
        return view

    def stop_all(self) -> None:
        for proc in reversed(self.procs):
            proc.stop()
