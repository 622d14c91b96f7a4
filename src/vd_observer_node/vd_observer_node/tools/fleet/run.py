"""Run the per-bag function over a fleet: a local process pool, or a Dask cluster.

Results are stored one JSON file per bag, ``<out>/bags/<bag id>.json``, written by the
coordinating process as each bag finishes: first to a temporary file, then renamed, so a file
is there whole or not at all. A run that is interrupted (Ctrl-C, a killed job, a reboot) and
started again with the same output folder loads those files and processes only the bags
without one (or whose file no longer matches: the bag changed, or the settings did).

Engines:

* ``local`` (default): :class:`concurrent.futures.ProcessPoolExecutor` with ``workers``
  processes (default: the machine's cores), started with ``spawn`` (no forked copies of a
  parent's threads or numba state).
* ``dask``: a :mod:`distributed` client, either of the cluster at ``scheduler`` (an address
  such as ``tcp://10.0.0.5:8786``; the workers must have vd installed and see the bags under
  the same paths) or of a :class:`distributed.LocalCluster` of ``workers`` single-threaded
  processes on the loopback interface. Dask is the optional extra ``fleet``.

The per-bag function is :func:`~.process.process_bag` in both, so the rows are identical.
"""

from __future__ import annotations

import multiprocessing
import os
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tqdm import tqdm

from vd_observer_node.tools.fleet.errors import FleetEngineError, FleetInputError
from vd_observer_node.tools.fleet.process import (
    RECORD_VERSION,
    ROW_COLUMNS,
    TEXT_COLUMNS,
    FleetSettings,
    bag_id,
    bag_stat,
    dumps_record,
    process_bag,
)

__all__ = [
    'ENGINES',
    'WORKER_DIED',
    'FleetEngine',
    'FleetRun',
    'load_records',
    'run_fleet',
    'write_atomic',
]

ENGINES = ('local', 'dask')
RESULTS_DIR = 'bags'


@dataclass
class FleetRun:
    """What a fleet run did.

    Attributes:
        records: one record per bag (:func:`~.process.process_bag`), in the order the bags
            were given; bags the engine lost (a worker process died) have none.
        processed: bags processed in this run.
        skipped: bags whose stored result was reused (resume).
        failed: bags whose row says 'failed' (this run's and reused ones).
        lost: bags without a result because the cluster lost them (not a bag that kills
            its worker: that one is a failed row); not stored, so the next run retries them.
        wall_time_s: [s] of this run.
        engine: 'local' or 'dask'.
        workers: worker processes used.
    """

    records: list[dict[str, Any]] = field(default_factory=list)
    processed: int = 0
    skipped: int = 0
    failed: int = 0
    lost: list[str] = field(default_factory=list)
    wall_time_s: float = 0.0
    engine: str = 'local'
    workers: int = 1

    @property
    def samples_processed(self) -> int:
        """Aligned samples of the bags processed in this run."""
        return sum(int(r['timing'].get('samples', 0)) for r in self._this_run())

    @property
    def hours_processed(self) -> float:
        """[h] of drive in the bags processed in this run."""
        return sum((r['row']['duration_s'] or 0.0) for r in self._this_run()) / 3600.0

    def _this_run(self) -> list[dict[str, Any]]:
        return [r for r in self.records if not r.get('reused')]


def write_atomic(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` via a temporary file in the same folder and a rename."""
    tmp = path.with_name(f'.{path.name}.{os.getpid()}.tmp')
    with open(tmp, 'w', encoding='utf-8') as handle:
        handle.write(text)
        handle.flush()
        os.fsync(handle.fileno())
    os.replace(tmp, path)


def load_records(out_dir: Path) -> dict[str, dict[str, Any]]:
    """Stored per-bag records of an output folder by bag id (unreadable files ignored)."""
    import json

    found: dict[str, dict[str, Any]] = {}
    folder = Path(out_dir) / RESULTS_DIR
    if not folder.is_dir():
        return found
    for path in sorted(folder.glob('*.json')):
        try:
            record = json.loads(path.read_text(encoding='utf-8'))
        except (OSError, ValueError):
            continue  # a damaged file: the bag is simply processed again
        if isinstance(record, dict) and isinstance(record.get('id'), str):
            found[record['id']] = record
    return found


def _reusable(
    record: dict[str, Any] | None, bag: str, fingerprint: str, retry_failed: bool
) -> bool:
    if record is None or record.get('version') != RECORD_VERSION:
        return False
    if record.get('fingerprint') != fingerprint or record.get('bag') != bag:
        return False
    if record.get('stat') != bag_stat(bag):
        return False
    return not (retry_failed and record['row']['status'] != 'ok')


#: The row error of a bag whose worker process died (twice: alone, the second time).
WORKER_DIED = (
    'WorkerDied: the worker process died while processing this bag (killed, or out of '
    'memory: a replay holds the whole bag in memory, see docs/fleet.md)'
)

BagFunction = Callable[[str, FleetSettings], dict[str, Any]]


def _died(bag: str, settings: FleetSettings) -> dict[str, Any]:
    """The record of a bag that killed its worker: a failed row, like any bad bag."""
    row: dict[str, Any] = {name: '' if name in TEXT_COLUMNS else None for name in ROW_COLUMNS}
    row.update(bag=bag, status='failed', error=WORKER_DIED)
    return {
        'version': RECORD_VERSION,
        'fingerprint': settings.fingerprint(),
        'bag': bag,
        'id': bag_id(bag),
        'stat': bag_stat(bag),
        'row': row,
        'mu_max_segments': [],
        'timing': {'samples': 0},
    }


def _local_results(
    bags: Sequence[str], settings: FleetSettings, workers: int, function: BagFunction
) -> Iterator[tuple[str, dict[str, Any] | None]]:
    """Results of the process pool, as they come.

    At most ``workers`` bags are in flight, so when a worker dies (the pool breaks) the bags
    it may have held are known: each runs again alone in a fresh pool, and one that kills
    its worker alone too gets the :data:`WORKER_DIED` row. The others go on.
    """
    context = multiprocessing.get_context('spawn')
    queue = list(reversed(bags))  # pop() takes them in order
    suspects: list[str] = []
    while queue or suspects:
        alone = bool(suspects)
        limit = 1 if alone else workers
        source = suspects if alone else queue
        with ProcessPoolExecutor(max_workers=limit, mp_context=context) as pool:
            pending: dict[Future[dict[str, Any]], str] = {}
            broken = False
            try:
                while (source or pending) and not broken:
                    while source and len(pending) < limit:
                        bag = source.pop()
                        try:
                            pending[pool.submit(function, bag, settings)] = bag
                        except BrokenProcessPool:
                            # a worker died since the last wait: this bag never started
                            source.append(bag)
                            broken = True
                            break
                    if not pending:
                        break
                    done, _ = wait(pending, return_when=FIRST_COMPLETED)
                    for future in done:
                        bag = pending.pop(future)
                        try:
                            record = future.result()
                        except BrokenProcessPool:
                            broken = True
                            if alone:
                                yield bag, _died(bag, settings)
                            else:
                                suspects.append(bag)
                            continue
                        yield bag, record
            finally:
                for future in pending:
                    future.cancel()
            if broken:
                # the bags in flight at the break: suspects (or, run alone, innocent: requeue)
                for bag in pending.values():
                    (queue if alone else suspects).append(bag)


def _dask_results(
    bags: Sequence[str],
    settings: FleetSettings,
    workers: int,
    scheduler: str | None,
    function: BagFunction,
) -> Iterator[tuple[str, dict[str, Any] | None]]:
    try:
        from distributed import Client, LocalCluster, as_completed
        from distributed.scheduler import KilledWorker
    except ImportError as exc:
        raise FleetEngineError(
            "engine 'dask' needs Dask distributed: pip install 'vd_observer_node[fleet]' "
            '(or: pip install distributed)'
        ) from exc
    import dask

    cluster = None
    try:
        if scheduler is None:
            # One bag per worker at a time, none queued behind it: when a bag kills its worker
            # (out of memory), Dask counts every bag assigned to that worker as suspect and
            # gives up on one after three deaths; with the default saturation (1.1, i.e. two
            # bags per one-thread worker) an innocent bag queued behind the killer could be
            # failed with it.
            with dask.config.set({'distributed.scheduler.worker-saturation': 1.0}):
                cluster = LocalCluster(
                    n_workers=workers,
                    threads_per_worker=1,  # the replay holds the GIL: one bag per process
                    processes=True,
                    host='127.0.0.1',
                    dashboard_address=None,
                )
        client = Client(cluster if cluster is not None else scheduler, timeout='30s')
    except (OSError, TimeoutError) as exc:
        if cluster is not None:
            cluster.close()
        raise FleetEngineError(f'cannot reach the Dask scheduler {scheduler}: {exc}') from exc
    try:
        # pure=False: a bag processed again (resume) must run again, not come from a cache
        futures = {client.submit(function, bag, settings, pure=False): bag for bag in bags}
        for future in as_completed(futures):
            bag = futures[future]
            try:
                yield bag, future.result()
            except KilledWorker:  # Dask retried it on other workers; each one died
                yield bag, _died(bag, settings)
            except Exception:  # the cluster lost it otherwise: retried in the next run
                yield bag, None
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


@dataclass(frozen=True)
class FleetEngine:
    """Where the bags are processed.

    Attributes:
        kind: 'local' (process pool) or 'dask' (`ENGINES`).
        workers: worker processes (default: ``os.cpu_count()``); with ``scheduler``, unused.
        scheduler: address of a running Dask scheduler (kind 'dask').
    """

    kind: str = 'local'
    workers: int | None = None
    scheduler: str | None = None


def run_fleet(
    bags: Sequence[str | os.PathLike[str]],
    out_dir: str | os.PathLike[str],
    settings: FleetSettings | None = None,
    *,
    engine: FleetEngine = FleetEngine(),
    retry_failed: bool = False,
    progress: bool = True,
    on_record: Callable[[dict[str, Any]], None] | None = None,
    function: BagFunction = process_bag,
) -> FleetRun:
    """Process every bag (resuming a previous run in ``out_dir``) and store one result each.

    Args:
        bags: bag paths (:func:`~.bags.find_bags`).
        out_dir: output folder; ``bags/<bag id>.json`` per bag.
        settings: how the bags are processed; default :class:`FleetSettings`.
        engine: the process pool or the Dask cluster, and its workers.
        retry_failed: process again the bags whose stored result is a failure.
        progress: tqdm bars on stderr: bags (failures so far in its postfix), and samples
            done with their rate.
        on_record: called with each new record after it is stored (tests, tools).
        function: the per-bag function (tests inject failures with it); it must be
            importable by the workers and return :func:`~.process.process_bag`'s records.

    Returns:
        The run's :class:`FleetRun`.

    Raises:
        FleetInputError: unknown engine, or workers < 1.
        FleetEngineError: Dask missing or its scheduler unreachable.
    """
    started = time.perf_counter()
    cfg = settings or FleetSettings()
    kind, workers, scheduler = engine.kind, engine.workers, engine.scheduler
    if kind not in ENGINES:
        raise FleetInputError(f'engine must be one of {", ".join(ENGINES)}, got {kind!r}')
    count = workers if workers is not None else (os.cpu_count() or 1)
    if count < 1:
        raise FleetInputError(f'workers must be at least 1, got {count}')
    out = Path(out_dir)
    results = out / RESULTS_DIR
    results.mkdir(parents=True, exist_ok=True)
    fingerprint = cfg.fingerprint()
    names = [os.fspath(b) for b in bags]
    stored = load_records(out)
    by_bag: dict[str, dict[str, Any]] = {}
    todo: list[str] = []
    for bag in names:
        record = stored.get(bag_id(bag))
        if _reusable(record, bag, fingerprint, retry_failed):
            assert record is not None
            by_bag[bag] = {**record, 'reused': True}
        else:
            todo.append(bag)
    run = FleetRun(engine=kind, workers=count, skipped=len(names) - len(todo))
    bar = tqdm(
        total=len(names),
        initial=run.skipped,
        unit='bag',
        desc='fleet',
        disable=not progress,
        file=sys.stderr,
    )
    # the sample count of a bag is known only once it is done: a counter with its rate
    samples_bar = tqdm(
        unit='sample',
        unit_scale=True,
        desc='samples',
        disable=not progress,
        file=sys.stderr,
        position=1,
    )
    with bar, samples_bar:
        if todo:
            stream = (
                _local_results(todo, cfg, count, function)
                if kind == 'local'
                else _dask_results(todo, cfg, count, scheduler, function)
            )
            for bag, record in stream:
                bar.update(1)
                if record is None:
                    run.lost.append(bag)
                    continue
                write_atomic(results / f'{record["id"]}.json', dumps_record(record))
                by_bag[bag] = record
                run.processed += 1
                samples_bar.update(int(record['timing'].get('samples', 0)))
                failed = sum(1 for r in by_bag.values() if r['row']['status'] != 'ok')
                bar.set_postfix_str(f'{failed} failed', refresh=False)
                if on_record is not None:
                    on_record(record)
    run.records = [by_bag[b] for b in names if b in by_bag]
    run.failed = sum(1 for r in run.records if r['row']['status'] != 'ok')
    run.wall_time_s = time.perf_counter() - started
    return run
