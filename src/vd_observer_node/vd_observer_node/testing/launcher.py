"""Start a graph of vd nodes as separate processes, without ``ros2 launch``.

``ros2 launch`` is not available everywhere (the PyPI ROS 2 wheels do not ship it), but the
demo and the graph tests must still run every node as its own process over the real
middleware. This module finds node executables the way ``ros2 run`` does (the ament index:
``<prefix>/lib/<package>/<executable>``), starts them with ``--ros-args``, keeps their
output in log files, and stops them in order with SIGINT, escalating to SIGKILL.
It is ROS-free (no rclpy): it only starts processes.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from vd_observer_node.errors import ConfigurationError

__all__ = ['GraphLauncher', 'NodeProcess', 'NodeSpec', 'find_executable']


def find_executable(package: str, executable: str) -> Path:
    """Path of `executable` of `package`, looked up as ``ros2 run`` does.

    Raises:
        ConfigurationError: the package is not in the ament index or has no such executable.
    """
    from ament_index_python.packages import PackageNotFoundError, get_package_prefix

    try:
        prefix = Path(get_package_prefix(package))
    except PackageNotFoundError:
        raise ConfigurationError(
            f'package {package!r} not found in AMENT_PREFIX_PATH; source env.sh '
            '(or install/setup.bash) first'
        ) from None
    path = prefix / 'lib' / package / executable
    if not (path.is_file() and os.access(path, os.X_OK)):
        raise ConfigurationError(f'{package} has no executable {executable!r} ({path})')
    return path


def _param_arg(value: object) -> str:
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, float):
        return repr(value)
    return str(value)


@dataclass(frozen=True)
class NodeSpec:
    """One node to start.

    Attributes:
        package: ROS package name.
        executable: executable name (as for ``ros2 run``).
        name: label for logs; also the node name (``__node``) if `rename` is set.
        parameters: ``-p name:=value`` overrides.
        rename: pass ``-r __node:=<name>``.
    """

    package: str
    executable: str
    name: str
    parameters: Mapping[str, object] = field(default_factory=dict)
    rename: bool = False

    def argv(self) -> list[str]:
        args = [str(find_executable(self.package, self.executable)), '--ros-args']
        if self.rename:
            args += ['-r', f'__node:={self.name}']
        for key, value in self.parameters.items():
            args += ['-p', f'{key}:={_param_arg(value)}']
        return args


class NodeProcess:
    """A started node; its stdout and stderr go to ``<log_dir>/<name>.log``."""

    def __init__(self, spec: NodeSpec, log_dir: Path, env: Mapping[str, str]) -> None:
        self.spec = spec
        self.log_path = log_dir / f'{spec.name}.log'
        self._log = self.log_path.open('wb')
        self.popen = subprocess.Popen(
            spec.argv(),
            stdout=self._log,
            stderr=subprocess.STDOUT,
            env=dict(env),
            start_new_session=True,
        )

    @property
    def running(self) -> bool:
        return self.popen.poll() is None

    def log_tail(self, n_bytes: int = 2000) -> str:
        data = self.log_path.read_bytes()
        return data[-n_bytes:].decode(errors='replace')

    def stop(self, timeout_s: float = 10.0) -> int:
        """SIGINT, wait up to `timeout_s`, then SIGKILL; return the exit code."""
        if self.running:
            self._signal(signal.SIGINT)
            try:
                self.popen.wait(timeout_s)
            except subprocess.TimeoutExpired:
                self._signal(signal.SIGKILL)
                self.popen.wait(5.0)
        self._log.close()
        return int(self.popen.returncode)

    def _signal(self, sig: int) -> None:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(self.popen.pid, sig)


class GraphLauncher:
    """Start nodes in order and stop them in reverse order.

    Use as a context manager so every process is stopped whatever happens.
    """

    def __init__(self, log_dir: Path, env: Mapping[str, str] | None = None) -> None:
        self.log_dir = log_dir
        self.log_dir.mkdir(parents=True, exist_ok=True)
        self.env = dict(os.environ if env is None else env)
        self.env.setdefault('PYTHONUNBUFFERED', '1')
        self.nodes: list[NodeProcess] = []

    def start(self, spec: NodeSpec) -> NodeProcess:
        proc = NodeProcess(spec, self.log_dir, self.env)
        self.nodes.append(proc)
        return proc

    def start_all(self, specs: Sequence[NodeSpec], settle_s: float = 0.0) -> None:
        for spec in specs:
            self.start(spec)
        if settle_s > 0:
            time.sleep(settle_s)

    def dead(self) -> list[NodeProcess]:
        """Nodes that have exited."""
        return [n for n in self.nodes if not n.running]

    def stop_all(self, timeout_s: float = 10.0) -> dict[str, int]:
        """Stop every node, newest first; return exit codes by node name."""
        return {n.spec.name: n.stop(timeout_s) for n in reversed(self.nodes)}

    def __enter__(self) -> GraphLauncher:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop_all()
