"""Every node stops on SIGINT and SIGTERM at any moment: exit 0, no traceback, outputs closed.

Each node is started as `ros2 run` would and sent the signal at a seeded random moment from
the instant its entry point has installed its guard (read from /proc: the process catches
SIGTERM) to a few seconds later: during imports, parameter declaration, discovery waits,
spinning, writing a bag, the end of a scenario. The recorder's bag, when it was created, must
be readable. ``VD_SIGNAL_ROUNDS`` (default 2) sets the number of random moments per node and
signal, for soak runs.
"""

from __future__ import annotations

import os
import random
import signal
import time
from pathlib import Path
from typing import Any

import pytest
from rosproc import RosProcess, RosProcessGroup
from vd_observer_node.bag import BagReader
from vd_observer_node.testing.synthetic_bags import write_synthetic_drive_bag

SCENARIO = Path(__file__).parent / 'data' / 'short_launch.yaml'
ROUNDS = int(os.environ.get('VD_SIGNAL_ROUNDS', '2'))
LATEST_S = 4.0  # [s] latest moment after the guard is in place


def catches_sigterm(pid: int) -> bool:
    """True once the process has a handler for SIGTERM (SigCgt in /proc/<pid>/status)."""
    try:
        status = Path(f'/proc/{pid}/status').read_text()
    except OSError:
        return False
    for line in status.splitlines():
        if line.startswith('SigCgt:'):
            return bool(int(line.split()[1], 16) & (1 << (signal.SIGTERM - 1)))
    return False


def start_nodes(procs: RosProcessGroup, tag: str, folder: Path, played: Path) -> dict[str, Any]:
    """One process of every node; returns name -> (process, recorder bag or None)."""
    bag = folder / f'rec_{tag}'
    specs: dict[str, tuple[str, str, dict[str, object]]] = {
        'sim': ('vd_sim_node', 'sim_node', {'scenario_file': str(SCENARIO), 'rate_hz': 200.0}),
        'observer': ('vd_observer_node', 'observer_node', {}),
        'estimator': ('vd_observer_node', 'estimator_node', {}),
        'alerts': ('vd_observer_node', 'alerts_node', {}),
        'pipeline': ('vd_observer_node', 'pipeline_node', {}),
        'recorder': ('vd_observer_node', 'recorder_node', {'output': str(bag)}),
        'player': ('vd_observer_node', 'player_node', {'bag': str(played), 'rate': 1.0}),
    }
    return {
        name: (procs.node(f'{name}_{tag}', package, executable, **params), bag)
        for name, (package, executable, params) in specs.items()
    }


def wait_guarded(procs: dict[str, RosProcess], timeout: float = 60.0) -> dict[str, float]:
    """Wait until every entry point's guard is in place; check it came before rclpy.

    The random moments start there, so they cover the imports only if the guard precedes
    them: when a process is first seen catching SIGTERM (all are polled together, every
    millisecond), rclpy's extension must not be loaded yet. Returns name -> monotonic time.
    """
    deadline = time.monotonic() + timeout
    guarded: dict[str, float] = {}
    while len(guarded) < len(procs) and time.monotonic() < deadline:
        for name, proc in procs.items():
            if name in guarded:
                continue
            pid = proc.popen.pid
            if catches_sigterm(pid):
                maps = Path(f'/proc/{pid}/maps').read_text(errors='replace')
                assert '_rclpy_pybind11' not in maps, f'{proc.name}: no guard before rclpy'
                guarded[name] = time.monotonic()
            elif proc.popen.poll() is not None:
                guarded[name] = time.monotonic()
        time.sleep(0.001)
    missing = sorted(set(procs) - set(guarded))
    assert not missing, f'no SIGTERM handler within {timeout} s: {missing}'
    return guarded


@pytest.mark.ros
@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM], ids=['SIGINT', 'SIGTERM'])
def test_every_node_stops_cleanly_at_random_moments(
    procs: RosProcessGroup, tmp_path: Path, sig: signal.Signals
) -> None:
    played = tmp_path / 'played'
    write_synthetic_drive_bag(played, duration_s=6.0, rate_hz=100.0)
    rng = random.Random(20261124 + int(sig))
    for round_ in range(ROUNDS):
        nodes = start_nodes(procs, f'{sig.name}_{round_}', tmp_path, played)
        moments = {name: rng.uniform(0.0, LATEST_S) for name in nodes}
        started = wait_guarded({name: proc for name, (proc, _) in nodes.items()})
        pending = dict(nodes)
        while pending:
            now = time.monotonic()
            for name in [n for n in pending if now - started[n] >= moments[n]]:
                proc, bag = pending.pop(name)
                code = proc.stop(sig, timeout=30.0)
                out = proc.output()
                where = f'{name} stopped {moments[name]:.2f} s after its guard by {sig.name}'
                assert code == 0, f'{where}: exit code {code}\n{out[-3000:]}'
                assert 'Traceback' not in out, f'{where}:\n{out[-3000:]}'
                if name == 'recorder' and bag.exists() and any(bag.iterdir()):
                    BagReader(bag).topics  # noqa: B018 (readable: metadata and summary)
            time.sleep(0.01)
