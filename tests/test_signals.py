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
from rosproc import RosProcess, RosProcessGroup, catches_signal
from vd_observer_node.bag import BagReader
from vd_observer_node.testing.synthetic_bags import write_synthetic_drive_bag

SCENARIO = Path(__file__).parent / 'data' / 'short_launch.yaml'
ROUNDS = int(os.environ.get('VD_SIGNAL_ROUNDS', '2'))
LATEST_S = 4.0  # [s] latest moment after the guard is in place


def catches_sigterm(pid: int) -> bool:
    """True once the process has a handler for SIGTERM."""
    return catches_signal(pid, signal.SIGTERM)


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
    """Wait until every entry point's guard is in place; returns name -> monotonic time.

    The random moments start there. That the guard precedes rclpy's import (so that the
    moments cover the imports) is checked deterministically by
    `test_the_guard_is_in_place_before_rclpy_is_imported`: polling /proc for it raced the
    imports on a busy machine (the poller was descheduled past them).
    """
    deadline = time.monotonic() + timeout
    guarded: dict[str, float] = {}
    while len(guarded) < len(procs) and time.monotonic() < deadline:
        for name, proc in procs.items():
            if name in guarded:
                continue
            pid = proc.popen.pid
            if catches_sigterm(pid) or proc.popen.poll() is not None:
                guarded[name] = time.monotonic()
        time.sleep(0.001)
    missing = sorted(set(procs) - set(guarded))
    assert not missing, f'no SIGTERM handler within {timeout} s: {missing}'
    return guarded


@pytest.mark.slow
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


#: Runs a console script with an import hook: at the first import of rclpy it reports
#: whether SIGTERM already has a handler (the entry point's guard) and ends the process.
_GUARD_PROBE = """
import os, runpy, signal, sys
class Probe:
    def find_spec(self, name, path=None, target=None):
        if name == 'rclpy':
            handler = signal.getsignal(signal.SIGTERM)
            print('guarded' if callable(handler) else 'unguarded', flush=True)
            os._exit(0)
        return None
sys.meta_path.insert(0, Probe())
sys.argv = [sys.argv[1]]
runpy.run_path(sys.argv[0], run_name='__main__')
"""

_EXECUTABLES = [
    ('vd_sim_node', 'sim_node'),
    ('vd_observer_node', 'observer_node'),
    ('vd_observer_node', 'estimator_node'),
    ('vd_observer_node', 'alerts_node'),
    ('vd_observer_node', 'pipeline_node'),
    ('vd_observer_node', 'recorder_node'),
    ('vd_observer_node', 'player_node'),
]


@pytest.mark.ros
@pytest.mark.parametrize(('package', 'executable'), _EXECUTABLES, ids=[e for _, e in _EXECUTABLES])
def test_the_guard_is_in_place_before_rclpy_is_imported(package: str, executable: str) -> None:
    import subprocess
    import sys

    from vd_observer_node.testing.launcher import find_executable

    script = find_executable(package, executable)
    result = subprocess.run(
        [sys.executable, '-c', _GUARD_PROBE, str(script)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.stdout.strip() == 'guarded', result.stdout + result.stderr
