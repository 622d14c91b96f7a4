"""Fleet replay across processes: the local process pool and a real Dask LocalCluster on
loopback give identical results; an interrupted run resumes without processing a bag twice
and ends with the same report; the exit code says when bags failed.

The bags are short synthetic drives made here (one corrupt, one truncated); the workers load
the compiled step functions from numba's cache (``make setup`` builds it).
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
from vd_observer_node.testing.fleet_bags import (
    DIE_MARKER,
    TestFleet,
    process_or_die,
    write_test_fleet,
)
from vd_observer_node.tools.fleet import (
    ENGINES,
    FleetEngine,
    FleetSettings,
    find_bags,
    load_records,
    run_fleet,
    write_fleet_report,
)

SETTINGS = FleetSettings()
GOOD = 8  # + 1 corrupt + 1 truncated


@pytest.fixture(scope='module')
def fleet(tmp_path_factory: pytest.TempPathFactory) -> TestFleet:
    return write_test_fleet(tmp_path_factory.mktemp('fleet') / 'bags', good=GOOD)


@pytest.fixture(scope='module')
def local_run(fleet: TestFleet, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One uninterrupted run with the local pool of 2 processes: the reference."""
    out = tmp_path_factory.mktemp('local')
    run = run_fleet(
        [str(b) for b in find_bags([fleet.folder])],
        out,
        SETTINGS,
        engine=FleetEngine(workers=2),
        progress=False,
    )
    assert (run.processed, run.skipped, run.failed, run.lost) == (GOOD + 2, 0, 2, [])
    write_fleet_report(run.records, out, figures=False)
    return out


def _rows(out: Path) -> dict[str, Any]:
    return {r['bag']: (r['row'], r['mu_max_segments']) for r in load_records(out).values()}


def test_local_pool_reports_every_bag(fleet: TestFleet, local_run: Path) -> None:
    rows = _rows(local_run)
    assert sorted(rows) == [str(b) for b in fleet.bags]
    failed = {bag: row['error'] for bag, (row, _) in rows.items() if row['status'] != 'ok'}
    assert set(failed) == {str(fleet.corrupt), str(fleet.truncated)}
    assert all(error.startswith('BagCorruptError: ') for error in failed.values())
    ok = [row for row, _ in rows.values() if row['status'] == 'ok']
    assert len(ok) == GOOD and all(row['samples'] == 400 for row in ok)
    # the worst bags first: the two failures lead the CSV
    lines = (local_run / 'fleet.csv').read_text().splitlines()
    assert len(lines) == 1 + GOOD + 2
    assert {line.split(',')[0] for line in lines[1:3]} == set(failed)


def test_dask_cluster_gives_identical_results(
    fleet: TestFleet, local_run: Path, tmp_path: Path
) -> None:
    pytest.importorskip('distributed')
    run = run_fleet(
        [str(b) for b in find_bags([fleet.folder])],
        tmp_path,
        SETTINGS,
        engine=FleetEngine('dask', workers=2),
        progress=False,
    )
    assert (run.processed, run.failed, run.engine) == (GOOD + 2, 2, 'dask')
    write_fleet_report(run.records, tmp_path, figures=False)
    assert _rows(tmp_path) == _rows(local_run)
    assert (tmp_path / 'fleet.csv').read_bytes() == (local_run / 'fleet.csv').read_bytes()
    assert (tmp_path / 'fleet.md').read_bytes() == (local_run / 'fleet.md').read_bytes()


class _InterruptError(Exception):
    pass


def test_interrupted_run_resumes_without_processing_a_bag_twice(
    fleet: TestFleet, local_run: Path, tmp_path: Path
) -> None:
    bags = [str(b) for b in find_bags([fleet.folder])]
    first: list[str] = []

    def stop_after_three(record: dict[str, Any]) -> None:
        first.append(record['bag'])
        if len(first) == 3:
            raise _InterruptError  # as a Ctrl-C in the coordinating process would

    with pytest.raises(_InterruptError):
        run_fleet(
            bags,
            tmp_path,
            SETTINGS,
            engine=FleetEngine(workers=2),
            progress=False,
            on_record=stop_after_three,
        )
    assert len(load_records(tmp_path)) == 3
    # leftovers of a crash: a temporary file and a damaged result, both ignored
    (tmp_path / 'bags' / '.x.json.123.tmp').write_text('{"id": "half')
    damaged = next((tmp_path / 'bags').glob('*.json'))
    damaged_bag = json.loads(damaged.read_text())['bag']
    damaged.write_text('{"id": "cut sh')
    second: list[str] = []
    run = run_fleet(
        bags,
        tmp_path,
        SETTINGS,
        engine=FleetEngine(workers=2),
        progress=False,
        on_record=lambda r: second.append(r['bag']),
    )
    assert run.skipped == 2 and run.processed == len(bags) - 2
    assert sorted(second) == sorted(set(bags) - set(first) | {damaged_bag})
    assert not set(second) & (set(first) - {damaged_bag})
    write_fleet_report(run.records, tmp_path, figures=False)
    assert (tmp_path / 'fleet.csv').read_bytes() == (local_run / 'fleet.csv').read_bytes()
    assert (tmp_path / 'fleet.md').read_bytes() == (local_run / 'fleet.md').read_bytes()
    # a third run has nothing left to do
    third = run_fleet(bags, tmp_path, SETTINGS, engine=FleetEngine(workers=2), progress=False)
    assert (third.processed, third.skipped) == (0, len(bags))


def test_changed_bag_or_settings_are_processed_again(fleet: TestFleet, tmp_path: Path) -> None:
    bags = [str(fleet.good[0]), str(fleet.corrupt)]
    run_fleet(bags, tmp_path, SETTINGS, engine=FleetEngine(workers=1), progress=False)
    again = run_fleet(bags, tmp_path, SETTINGS, engine=FleetEngine(workers=1), progress=False)
    assert (again.processed, again.skipped) == (0, 2)
    retried = run_fleet(
        bags, tmp_path, SETTINGS, engine=FleetEngine(workers=1), progress=False, retry_failed=True
    )
    assert (retried.processed, retried.skipped) == (1, 1)
    other = FleetSettings(replay=False)  # another fingerprint
    assert (
        run_fleet(bags, tmp_path, other, engine=FleetEngine(workers=1), progress=False).processed
        == 2
    )


@pytest.mark.parametrize('engine', ENGINES)
def test_a_bag_that_kills_its_worker_is_a_failed_row(
    engine: str, fleet: TestFleet, tmp_path: Path
) -> None:
    if engine == 'dask':
        pytest.importorskip('distributed')
    killer = tmp_path / 'killer'
    shutil.copytree(fleet.good[0], killer)
    (killer / DIE_MARKER).touch()  # process_or_die: SIGKILL, as the OOM killer would
    bags = [str(b) for b in [*fleet.good[:3], killer, *fleet.good[3:5]]]
    run = run_fleet(
        bags,
        tmp_path / 'out',
        SETTINGS,
        engine=FleetEngine(engine, workers=2),
        progress=False,
        function=process_or_die,
    )
    rows = {r['bag']: r['row'] for r in run.records}
    assert run.lost == [] and sorted(rows) == sorted(bags)
    assert rows[str(killer)]['status'] == 'failed'
    assert rows[str(killer)]['error'].startswith('WorkerDied: ')
    others = {b: (rows[b]['status'], rows[b].get('error')) for b in bags if b != str(killer)}
    assert all(status == 'ok' for status, _ in others.values()), others
    assert run.failed == 1


def _wait_for_results(out: Path, count: int, process: subprocess.Popen[str]) -> None:
    deadline = time.monotonic() + 120.0
    while len(list((out / 'bags').glob('*.json'))) < count:
        assert process.poll() is None, 'the run ended before it could be interrupted'
        assert time.monotonic() < deadline, 'no result came'
        time.sleep(0.05)


@pytest.mark.parametrize('signal_number', [signal.SIGINT, signal.SIGKILL], ids=['int', 'kill'])
def test_killed_command_resumes(
    signal_number: int, fleet: TestFleet, local_run: Path, tmp_path: Path
) -> None:
    """Ctrl-C (exit 130), or the whole job killed: the next run does only the rest."""
    out = tmp_path / 'out'
    argv = [
        sys.executable,
        '-m',
        'vd_observer_node.tools.cli',
        'fleet',
        str(fleet.folder),
        '--out',
        str(out),
        '--workers',
        '2',
        '--no-figures',
    ]
    first = subprocess.Popen(
        argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True
    )  # a process group: the job and its workers
    try:
        _wait_for_results(out, 2, first)
        os.killpg(first.pid, signal_number)
        first.communicate(timeout=60)
    finally:
        if first.poll() is None:
            os.killpg(first.pid, signal.SIGKILL)
            first.wait()
    assert first.returncode == (130 if signal_number == signal.SIGINT else -signal.SIGKILL)
    done = {p.name: p.read_bytes() for p in (out / 'bags').glob('*.json')}
    assert 2 <= len(done) < GOOD + 2
    if signal_number == signal.SIGINT:  # stopped cleanly: no temporary file left behind
        assert not list((out / 'bags').glob('.*'))
    second = _vd(*argv[3:])
    assert second.returncode == 1, second.stderr  # the corrupt and the truncated bag
    assert (
        f'fleet: {GOOD + 2} bags, {GOOD + 2 - len(done)} processed now, {len(done)} done before'
        in second.stdout
    )
    # the results of the first run were kept as they were: no bag processed twice
    assert {name: (out / 'bags' / name).read_bytes() for name in done} == done
    assert (out / 'fleet.csv').read_bytes() == (local_run / 'fleet.csv').read_bytes()
    assert (out / 'fleet.md').read_bytes() == (local_run / 'fleet.md').read_bytes()


def _vd(*argv: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, '-m', 'vd_observer_node.tools.cli', *argv],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )


def test_command_exit_codes_and_baseline(
    fleet: TestFleet, local_run: Path, tmp_path: Path
) -> None:
    common = ['--workers', '2', '--no-progress', '--no-figures']
    good = _vd('fleet', *map(str, fleet.good[:2]), '--out', str(tmp_path / 'good'), *common)
    assert good.returncode == 0, good.stderr
    assert 'fleet: 2 bags, 2 processed now, 0 done before, 0 failed' in good.stdout
    listing = tmp_path / 'bags.txt'
    listing.write_text(''.join(f'{b}\n' for b in fleet.bags))
    failing = _vd(
        'fleet',
        '--list',
        str(listing),
        '--out',
        str(tmp_path / 'all'),
        *common,
        '--baseline',
        str(tmp_path / 'good'),
    )
    assert failing.returncode == 1, failing.stderr
    assert f'vd: failed: {fleet.corrupt}: BagCorruptError: ' in failing.stderr
    assert f'vd: failed: {fleet.truncated}: BagCorruptError: ' in failing.stderr
    # the baseline's two bags did not regress
    assert 'regressions against' not in failing.stdout
    assert (tmp_path / 'all' / 'regressions.csv').read_text() == 'bag,column,old,new\n'
    assert (tmp_path / 'all' / 'fleet.csv').read_bytes() == (local_run / 'fleet.csv').read_bytes()
    # a baseline where drive 0 was fine and now it is missing from the run: a regression
    regress = _vd(
        'fleet',
        str(fleet.good[1]),
        '--out',
        str(tmp_path / 'one'),
        *common,
        '--baseline',
        str(tmp_path / 'good'),
        '--fail-on-regression',
    )
    assert regress.returncode == 1
    assert '1 regressions against' in regress.stdout
    assert (
        f'- `{fleet.good[0]}`: bag present → absent from this run'
        in (tmp_path / 'one' / 'fleet.md').read_text()
    )


def test_output_folder_among_the_bags(fleet: TestFleet, tmp_path: Path) -> None:
    """`vd fleet . --out ./fleet --keep-bags` twice: the kept replays are not new input."""
    bags = tmp_path / 'bags'
    shutil.copytree(fleet.good[0], bags / 'd0')
    argv = [
        'fleet',
        str(bags),
        '--out',
        str(bags / 'fleet'),
        '--keep-bags',
        '--workers',
        '1',
        '--no-progress',
        '--no-figures',
    ]
    first = _vd(*argv)
    assert first.returncode == 0, first.stderr
    assert len(list((bags / 'fleet' / 'replayed').iterdir())) == 1
    second = _vd(*argv)
    assert second.returncode == 0, second.stderr
    assert 'fleet: 1 bags, 0 processed now, 1 done before' in second.stdout
