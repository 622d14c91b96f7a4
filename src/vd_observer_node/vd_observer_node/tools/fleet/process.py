"""The per-bag function of the fleet: one bag in, one result row out, never an exception.

:func:`process_bag` runs the offline replay (:func:`vd_observer_node.tools.replay.replay_bag`)
into a temporary bag, then computes the row of the fleet report with the report's metrics,
streamed over that bag in bounded memory (:func:`bag_figures`, via
:func:`vd_observer_node.tools.report.stream.evaluate_bag`; the whole-bag reference
:func:`bag_figures_whole` gives the same figures and takes bags whose stamps go backwards). The
local process pool and the Dask workers call this same function, so their results are the
same bit for bit. Any failure of a bag (missing, corrupt, truncated, missing topics, wrong
types, a bug) becomes the row's ``error``; the run goes on with the next bag.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import re
import shutil
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
from vd_common.topics import ESTIMATES_ALERTS, OBSERVER_BODY_VELOCITY, SENSORS_BODY_VELOCITY

from vd_observer_node.tools.report.alerts import ALERT_KINDS, activation_indices
from vd_observer_node.tools.report.errors import (
    ReferenceClockError,
    ReportInputError,
    StampOrderError,
)
from vd_observer_node.tools.report.evaluation import target_values
from vd_observer_node.tools.report.results import AccuracyReport
from vd_observer_node.tools.report.stream import evaluate_bag
from vd_observer_node.tools.report.stream_join import DEFAULT_BLOCK_MESSAGES

__all__ = [
    'RECORD_VERSION',
    'ROW_COLUMNS',
    'TARGET_COLUMNS',
    'TEXT_COLUMNS',
    'FleetSettings',
    'bag_figures',
    'bag_figures_whole',
    'bag_id',
    'bag_stat',
    'dumps_record',
    'process_bag',
    'settings_dict',
]

#: Bumped when the row's meaning changes: older per-bag results are then recomputed.
RECORD_VERSION = 2  # 2: a car's reference interpolated, its targets not judged

#: Accuracy targets of the report (``evaluate.TARGETS`` names) -> fleet column.
TARGET_COLUMNS: dict[str, str] = {
    'slope RMS [deg]': 'slope_rms_deg',
    'mu RMS [-]': 'mu_rms',
    'Fx RMS [% of max |Fx|]': 'fx_rms_pct',
    'Fz RMS [% of static load]': 'fz_rms_pct',
    'omega relative RMS [%]': 'omega_rel_rms_pct',
}

#: Columns of a row, in report order. Missing figures are None (empty in CSV); the text
#: columns (bag, status, error, faults) are strings, '' when empty.
ROW_COLUMNS: tuple[str, ...] = (
    'bag',
    'status',
    'error',
    'duration_s',
    'distance_m',
    'samples',
    'unmatched',
    'has_truth',
    *TARGET_COLUMNS.values(),
    'targets_met',
    'targets_failed',
    *(f'alerts_{kind}' for kind in ALERT_KINDS),
    'episodes',
    'detected',
    'missed',
    'false_alarms',
    'mu_max_segments',
    'mu_max_rms_worst',
    'mu_max_max_abs_worst',
    'faults_total',
    'faults',
)


#: Columns holding text (never None).
TEXT_COLUMNS = frozenset({'bag', 'status', 'error', 'faults'})


@dataclass(frozen=True)
class FleetSettings:
    """How every bag of a run is processed (picklable: it travels to the workers).

    Attributes:
        replay: run the replay first (False: judge the estimates recorded in the bag, as
            ``vd report`` does).
        vehicle_file: vehicle YAML of the replay (None: the Clio file).
        config_file: replay settings YAML (``vd replay --config``), or None.
        mapping_file: input mapping YAML (``vd replay --mapping``), or None.
        keep_dir: folder where the replayed bags are kept (as ``<bag id>``), or None to
            delete them once evaluated. Must be shared with the workers on a cluster.
    """

    replay: bool = True
    vehicle_file: str | None = None
    config_file: str | None = None
    mapping_file: str | None = None
    keep_dir: str | None = None

    def fingerprint(self) -> str:
        """Hash of everything that changes a row: the settings and their files' contents.

        A stored result with another fingerprint is stale and recomputed on resume.
        """
        h = hashlib.sha256(f'vd-fleet {RECORD_VERSION} {self.replay}'.encode())
        for name in (self.vehicle_file, self.config_file, self.mapping_file):
            h.update(b'\0')
            if name is not None:
                try:
                    h.update(Path(name).read_bytes())
                except OSError:
                    h.update(f'unreadable {name}'.encode())
        return h.hexdigest()[:16]


def bag_id(bag: str | os.PathLike[str]) -> str:
    """File-name-safe identity of a bag: its name plus a hash of its absolute path.

    Two drives named alike in different folders get different ids.
    """
    path = Path(bag).absolute()
    name = (
        re.sub(
            r'[^A-Za-z0-9._-]+',
            '_',
            path.with_suffix('').name if path.suffix == '.mcap' else path.name,
        )[:60]
        or 'bag'
    )
    digest = hashlib.sha1(str(path).encode()).hexdigest()[:10]
    return f'{name}-{digest}'


def bag_stat(bag: str | os.PathLike[str]) -> list[int]:
    """[total bytes, newest mtime ns] of a bag's files ([-1, -1] when missing).

    A bag re-recorded under the same path no longer matches its stored result.
    """
    path = Path(bag)
    try:
        files = [path] if path.is_file() else sorted(p for p in path.iterdir() if p.is_file())
        stats = [p.stat() for p in files]
    except OSError:
        return [-1, -1]
    return [sum(s.st_size for s in stats), max((s.st_mtime_ns for s in stats), default=0)]


def _finite(value: float | None, digits: int = 9) -> float | None:
    """A float rounded to ``digits`` significant digits, None for nan/inf/None.

    Rounding makes the CSV the same however the float was printed; 9 digits are far
    below any metric's meaning.
    """
    if value is None:
        return None
    v = float(value)
    if not math.isfinite(v):
        return None
    return float(f'{v:.{digits}g}')


def _empty_row(bag: str) -> dict[str, Any]:
    row: dict[str, Any] = {name: None for name in ROW_COLUMNS}
    row.update(bag=bag, status='ok', error='', faults='')
    return row


def _distance(series: Any) -> float | None:
    """[m] integral of the body speed over the stamps (observer's, else the sensor's)."""
    topic = series.topics.get(OBSERVER_BODY_VELOCITY) or series.topics.get(SENSORS_BODY_VELOCITY)
    if topic is None or topic.stamp_ns.size < 2:
        return None
    t = (topic.stamp_ns - topic.stamp_ns[0]) * 1e-9
    v = topic.values['twist.linear.x'].astype(np.float64)
    ok = np.isfinite(v)
    return float(np.trapezoid(np.abs(v[ok]), t[ok])) if ok.sum() > 1 else None


def _alert_counts(series: Any) -> dict[str, int | None]:
    """Activations (OK -> active) per alert kind, summed over the four wheels."""
    topic = series.topics.get(ESTIMATES_ALERTS)
    if topic is None:
        return {f'alerts_{kind}': None for kind in ALERT_KINDS}
    level = topic.values['level']
    return {
        f'alerts_{kind}': int(sum(activation_indices(level[:, k, w]).size for w in range(4)))
        for k, kind in enumerate(ALERT_KINDS)
    }


def _truth_figures(report: AccuracyReport | None, row: dict[str, Any]) -> list[dict[str, Any]]:
    """Fill the accuracy and alert-scoring columns; return the μ_max segments.

    The accuracy figures are filled for any reference; ``targets_met`` / ``targets_failed``
    only where the report judged the simulator's ideal-sensor targets (a simulator bag), else
    they stay None: a real car is not marked against them.

    Args:
        report: the bag's accuracy report, None when the bag has no reference.
        row: the row to fill.
    """
    if report is None or report.reference == 'none':
        row['has_truth'] = False
        return []
    row['has_truth'] = True
    values = target_values(report.quantities)
    for name, column in TARGET_COLUMNS.items():
        row[column] = _finite(values.get(name))
    if report.reference == 'simulator':
        row['targets_met'] = sum(1 for _, _, met in report.targets.values() if met)
        row['targets_failed'] = sum(1 for _, _, met in report.targets.values() if not met)
    segments: list[dict[str, Any]] = []
    section = report.alerts
    if section is not None:
        counts = section.counts
        row['episodes'] = counts.get('episodes', 0)
        row['detected'] = counts.get('met', 0) + counts.get('late', 0)
        row['missed'] = counts.get('missed', 0)
        row['false_alarms'] = counts.get('false_alarms', 0)
        for m in section.mu_max:
            segments.append(
                {
                    'axle': 'front' if m.axle == 0 else 'rear',
                    'start_s': _finite(m.start_s),
                    'end_s': _finite(m.end_s),
                    'true_mu_max': _finite(m.true_mu_max),
                    'estimate_mean': _finite(m.estimate_mean),
                    'rms': _finite(m.rms),
                    'max_abs': _finite(m.max_abs),
                }
            )
        row['mu_max_segments'] = len(segments)
        rms = [s['rms'] for s in segments if s['rms'] is not None]
        worst = [s['max_abs'] for s in segments if s['max_abs'] is not None]
        row['mu_max_rms_worst'] = max(rms) if rms else None
        row['mu_max_max_abs_worst'] = max(worst) if worst else None
    return segments


def bag_figures(
    path: str | os.PathLike[str], bag: str, block_messages: int = DEFAULT_BLOCK_MESSAGES
) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """The row's figures of an evaluated (replayed) bag, streamed in bounded memory.

    Args:
        path: the bag to evaluate.
        bag: the bag's name in the fleet (for errors).
        block_messages: messages decoded at a time (see :func:`evaluate_bag`).

    Returns:
        (row columns from ``duration_s`` on, μ_max segments).

    Raises:
        ReportInputError: none of the vd topics in the bag.
        StampOrderError: stamps go backwards: use :func:`bag_figures_whole`.
        ReferenceClockError: the reference runs on its own clock: use
            :func:`bag_figures_whole`, which interpolates it as ``vd report`` does.
        BagError: the bag cannot be read.
    """
    try:
        found = evaluate_bag(path, block_messages=block_messages)
    except ReportInputError as exc:
        raise ReportInputError(f'{bag}: none of the vd topics found in the bag') from exc
    row: dict[str, Any] = {
        'duration_s': _finite((found.last_stamp_ns - found.first_stamp_ns) * 1e-9),
        'distance_m': _finite(found.distance_m),
    }
    for kind in ALERT_KINDS:
        row[f'alerts_{kind}'] = None if found.activations is None else found.activations[kind]
    segments = _truth_figures(found.report, row)
    return row, segments


def bag_figures_whole(
    path: str | os.PathLike[str], bag: str
) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """:func:`bag_figures` from the whole decoded bag (``load_bag_series``): the reference,
    and the path for bags whose stamps go backwards or whose reference runs on its own clock
    (interpolated by ``evaluate``, the code of ``vd report``). Memory grows with the bag's
    length."""
    from vd_observer_node.tools.report.evaluation import evaluate
    from vd_observer_node.tools.report.load import load_bag_series

    series = load_bag_series(path, progress=False)
    if not series.topics:
        raise ReportInputError(f'{bag}: none of the vd topics found in the bag')
    first = min(int(s.stamp_ns[0]) for s in series.topics.values())
    last = max(int(s.stamp_ns[-1]) for s in series.topics.values())
    row: dict[str, Any] = {
        'duration_s': _finite((last - first) * 1e-9),
        'distance_m': _finite(_distance(series)),
    }
    row.update(_alert_counts(series))
    try:
        report: AccuracyReport | None = evaluate(series)[0]
    except ReportInputError:
        report = None
    return row, _truth_figures(report, row)


def _replay(bag: str, target: Path, settings: FleetSettings) -> Any:
    from vd_observer_node.inputs.mapping import default_mapping, load_input_mapping
    from vd_observer_node.tools.replay import replay_bag
    from vd_observer_node.tools.settings_file import SettingsFile, load_settings_file

    config = load_settings_file(settings.config_file) if settings.config_file else SettingsFile()
    mapping = (
        load_input_mapping(settings.mapping_file) if settings.mapping_file else default_mapping()
    )
    chain = config.settings(mapping, settings.vehicle_file)
    return replay_bag(bag, target, chain, mapping=mapping, progress=False)


def _one_line(exc: BaseException) -> str:
    text = ' '.join(str(exc).split()) or '(no message)'
    return f'{type(exc).__name__}: {text}'


def process_bag(bag: str, settings: FleetSettings) -> dict[str, Any]:
    """Replay and evaluate one bag; the fleet's unit of work (local pool and Dask alike).

    Args:
        bag: bag folder or ``.mcap`` file (as listed by :func:`~.bags.find_bags`).
        settings: the run's settings.

    Returns:
        A JSON-ready record: ``version``, ``fingerprint``, ``bag``, ``id``, ``stat``
        (:func:`bag_stat`), ``row`` (:data:`ROW_COLUMNS`; ``status`` 'ok' or 'failed' with a
        one-line ``error``), ``mu_max_segments`` (per axle and constant-road segment) and
        ``timing`` (wall times [s], ``samples``; never part of the report, which must not
        depend on the machine). Never raises for a bad bag.
    """
    started = time.perf_counter()
    row = _empty_row(bag)
    record: dict[str, Any] = {
        'version': RECORD_VERSION,
        'fingerprint': settings.fingerprint(),
        'bag': bag,
        'id': bag_id(bag),
        'stat': bag_stat(bag),
        'row': row,
        'mu_max_segments': [],
        'timing': {},
    }
    timing: dict[str, float] = {}
    work: Path | None = None
    try:
        if not Path(bag).exists():
            raise FileNotFoundError(f'{bag}: no such bag')
        evaluated = Path(bag)
        if settings.replay:
            if settings.keep_dir is not None:
                keep = Path(settings.keep_dir)
                keep.mkdir(parents=True, exist_ok=True)
                work = Path(tempfile.mkdtemp(prefix=f'.{record["id"]}.', dir=keep))
            else:
                work = Path(tempfile.mkdtemp(prefix='vd-fleet-'))
            evaluated = work / 'replayed'
            replay_start = time.perf_counter()
            replayed = _replay(bag, evaluated, settings)
            timing['replay_s'] = time.perf_counter() - replay_start
            row['duration_s'] = _finite(replayed.bag_duration_s)
            row['samples'] = replayed.samples
            row['unmatched'] = replayed.unmatched
            faults = {k: int(v) for k, v in sorted(replayed.faults.items()) if v}
            row['faults_total'] = sum(faults.values())
            row['faults'] = ' '.join(f'{k}={v}' for k, v in faults.items())
        report_start = time.perf_counter()
        try:
            figures, segments = bag_figures(evaluated, bag)
        except (StampOrderError, ReferenceClockError):
            # stamps out of order (the whole-bag path sorts them), or a car's reference on its
            # own clock (it interpolates it, as vd report does)
            figures, segments = bag_figures_whole(evaluated, bag)
        if settings.mapping_file is not None:  # a car's own topics: its reference is a car's
            figures.pop('targets_met', None)
            figures.pop('targets_failed', None)
        if row['duration_s'] is not None:  # the replay's own duration
            del figures['duration_s']
        row.update(figures)
        record['mu_max_segments'] = segments
        timing['report_s'] = time.perf_counter() - report_start
        if settings.keep_dir is not None and work is not None:
            final = Path(settings.keep_dir) / record['id']
            if final.exists():
                shutil.rmtree(final)
            os.replace(evaluated, final)  # whole or not at all
    except Exception as exc:  # every failure of this bag is its row's error; the fleet goes on
        for name in ROW_COLUMNS[3:]:
            row[name] = '' if name in TEXT_COLUMNS else None
        row['status'] = 'failed'
        row['error'] = _one_line(exc)
    finally:
        if work is not None:
            shutil.rmtree(work, ignore_errors=True)
    timing['wall_s'] = time.perf_counter() - started
    record['timing'] = {k: round(v, 4) for k, v in timing.items()}
    record['timing']['samples'] = row['samples'] or 0
    return record


def settings_dict(settings: FleetSettings) -> dict[str, Any]:
    """The settings as a JSON-ready mapping (for the run's summary)."""
    return asdict(settings)


def dumps_record(record: dict[str, Any]) -> str:
    """The record as stable JSON text (sorted keys, one trailing newline)."""
    return json.dumps(record, indent=1, sort_keys=True) + '\n'
