"""Fleet replay, in one process: bag discovery, the per-bag function, the fleet report.

The engines (process pool, Dask cluster), resume and the exit code are tested across
processes in tests/test_fleet_engines.py.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from vd_common.topics import (
    ESTIMATES_SLOPE,
    SENSORS_BODY_VELOCITY,
    SENSORS_WHEEL_ANGLES,
    SENSORS_WHEEL_TORQUES,
    TRUTH_SLOPE,
    TRUTH_TIRE_FORCES,
)
from vd_observer_node.bag.writer import BagWriter
from vd_observer_node.testing.devbag import write_topic_arrays_bag
from vd_observer_node.testing.fleet_bags import TestFleet, write_test_fleet
from vd_observer_node.testing.synthetic_bags import synthetic_drive, write_synthetic_drive_bag
from vd_observer_node.tools.cli import main
from vd_observer_node.tools.fleet import (
    ROW_COLUMNS,
    FleetInputError,
    FleetSettings,
    Regression,
    compare_baseline,
    find_bags,
    process_bag,
    read_fleet_csv,
    write_fleet_report,
)
from vd_observer_node.tools.fleet.process import bag_id
from vd_observer_node.tools.fleet.report import fleet_csv, fleet_markdown, sort_worst_first
from vd_observer_node.tools.replay import replay_bag

#: The default settings (the step functions load from numba's cache, built by make setup).
PY = FleetSettings()
DURATION, RATE = 2.0, 200.0


@pytest.fixture(scope='module')
def fleet(tmp_path_factory: pytest.TempPathFactory) -> TestFleet:
    return write_test_fleet(
        tmp_path_factory.mktemp('fleet'), good=2, duration_s=DURATION, rate_hz=RATE
    )


# -- which bags ------------------------------------------------------------------------------


def test_find_bags_from_folders_files_patterns_and_lists(tmp_path: Path) -> None:
    for name in ('a/x', 'a/y', 'b/deep/z'):
        write_synthetic_drive_bag(tmp_path / name, 0.1, 100.0)
    loose = tmp_path / 'c' / 'loose.mcap'
    loose.parent.mkdir()
    loose.write_bytes(next((tmp_path / 'a/x').glob('*.mcap')).read_bytes())
    listing = tmp_path / 'lists' / 'bags.txt'
    listing.parent.mkdir()
    listing.write_text('# drives of the week\n../a/y\n\n../c/loose.mcap  # a file\n../gone\n')
    found = find_bags(
        [tmp_path / 'a', str(tmp_path / 'b' / '**' / 'z'), tmp_path / 'a' / 'x'], [listing]
    )
    # the folder of bags in sorted order, the pattern, the duplicate dropped, then the list
    # (its relative paths from the list's folder; a missing path kept, to be reported)
    assert found == [
        tmp_path / 'a/x',
        tmp_path / 'a/y',
        tmp_path / 'b/deep/z',
        loose,
        tmp_path / 'gone',
    ]
    assert find_bags([tmp_path]) == [
        tmp_path / 'a/x',
        tmp_path / 'a/y',
        tmp_path / 'b/deep/z',
        loose,
    ]
    assert find_bags([str(tmp_path / 'nothing*')]) == []


def test_find_bags_refuses_nothing_and_unreadable_lists(tmp_path: Path) -> None:
    with pytest.raises(FleetInputError, match='no bags named'):
        find_bags([])
    with pytest.raises(FleetInputError, match='cannot read the bag list'):
        find_bags([], [tmp_path / 'absent.txt'])


def test_bag_ids_differ_for_same_names_in_other_folders(tmp_path: Path) -> None:
    a, b = bag_id(tmp_path / 'x' / 'drive'), bag_id(tmp_path / 'y' / 'drive')
    assert a != b and a.startswith('drive-') and b.startswith('drive-')
    assert bag_id(tmp_path / 'x' / 'drive') == a
    assert bag_id(tmp_path / 'f.mcap').startswith('f-')


# -- the per-bag function ---------------------------------------------------------------------


def test_good_bag_row(fleet: TestFleet) -> None:
    record = process_bag(str(fleet.good[0]), PY)
    row = record['row']
    assert list(row) == list(ROW_COLUMNS)
    assert row['status'] == 'ok' and row['error'] == ''
    n = round(DURATION * RATE)
    assert row['samples'] == n and row['unmatched'] == 0
    assert row['duration_s'] == pytest.approx((n - 1) / RATE, abs=1e-9)
    # distance: the synthetic drive's true distance over the stamps, within 0.5 % (the
    # observer's filtered speed, integrated; its start-up transient is short)
    drive = synthetic_drive(DURATION, RATE, seed=0)
    t = (drive.stamp_ns - drive.stamp_ns[0]) * 1e-9
    true_distance = float(np.trapezoid(drive.speed, t))
    assert row['distance_m'] == pytest.approx(true_distance, rel=5e-3)
    assert row['has_truth'] is True
    # the synthetic drive has wheel-speed truth only: the ω target, nothing else
    assert row['omega_rel_rms_pct'] is not None and row['omega_rel_rms_pct'] < 0.1
    assert row['targets_met'] == 1 and row['targets_failed'] == 0
    assert row['slope_rms_deg'] is None and row['mu_rms'] is None
    assert all(isinstance(row[f'alerts_{k}'], int) for k in ('traction', 'lock', 'low_friction'))
    assert row['faults_total'] == 0 and row['faults'] == ''
    assert record['timing']['samples'] == n and record['timing']['wall_s'] > 0


def test_rows_are_deterministic(fleet: TestFleet) -> None:
    a, b = (process_bag(str(fleet.good[1]), PY) for _ in range(2))
    assert a['row'] == b['row'] and a['mu_max_segments'] == b['mu_max_segments']


def _failed(record: dict[str, Any]) -> str:
    row = record['row']
    assert row['status'] == 'failed'
    assert all(row[name] is None for name in ROW_COLUMNS[3:] if name != 'faults')
    assert '\n' not in row['error']
    return str(row['error'])


def test_damaged_and_missing_bags_are_rows_not_exceptions(
    fleet: TestFleet, tmp_path: Path
) -> None:
    assert fleet.corrupt is not None and fleet.truncated is not None
    assert _failed(process_bag(str(fleet.corrupt), PY)).startswith('BagCorruptError: ')
    error = _failed(process_bag(str(fleet.truncated), PY))
    assert error.startswith('BagCorruptError: ') and 'truncated' in error
    assert _failed(process_bag(str(tmp_path / 'gone'), PY)) == (
        f'FileNotFoundError: {tmp_path / "gone"}: no such bag'
    )
    not_a_bag = tmp_path / 'junk.mcap'
    not_a_bag.write_bytes(b'not an mcap file at all')
    assert _failed(process_bag(str(not_a_bag), PY)).startswith('BagFormatError: ')


def test_missing_topic_and_wrong_type(tmp_path: Path) -> None:
    drive = synthetic_drive(0.5, 100.0)
    no_speed = tmp_path / 'no_speed'
    with BagWriter(no_speed) as writer:  # wheel angles only
        writer.add_topic(SENSORS_WHEEL_ANGLES, 'vd_msgs/msg/WheelAngles')
        from vd_observer_node.bag.cdr_batch import encode_batch

        datas = encode_batch(
            'vd_msgs/msg/WheelAngles', drive.stamp_ns, 'b', {'angle': drive.angle}
        )
        writer.write_batch(SENSORS_WHEEL_ANGLES, datas, drive.stamp_ns)
    error = _failed(process_bag(str(no_speed), PY))
    assert error.startswith('ReplayInputError: ') and SENSORS_BODY_VELOCITY in error
    wrong = tmp_path / 'wrong_type'
    with BagWriter(wrong) as writer:  # the speed topic carries wheel angles
        writer.add_topic(SENSORS_WHEEL_ANGLES, 'vd_msgs/msg/WheelAngles')
        writer.write_batch(SENSORS_WHEEL_ANGLES, datas, drive.stamp_ns)
        writer.add_topic(SENSORS_BODY_VELOCITY, 'vd_msgs/msg/WheelAngles')
        writer.write_batch(SENSORS_BODY_VELOCITY, datas, drive.stamp_ns)
    error = _failed(process_bag(str(wrong), PY))
    assert 'has type vd_msgs/msg/WheelAngles' in error


def test_zero_true_force_is_a_row_without_that_figure(tmp_path: Path) -> None:
    # true Fx zero throughout (a coasting drive, or a simulator that records no force):
    # the report once divided by the largest true |Fx| and the bag failed
    drive = synthetic_drive(DURATION, RATE)
    bag = tmp_path / 'coasting'
    write_topic_arrays_bag(
        bag,
        drive.stamp_ns,
        {
            SENSORS_WHEEL_ANGLES: {'angle': drive.angle},
            SENSORS_BODY_VELOCITY: {'twist.linear.x': drive.speed},
            SENSORS_WHEEL_TORQUES: {'torque': drive.torque},
            TRUTH_TIRE_FORCES: {'fz': np.full((drive.speed.size, 4), 3000.0)},
        },
    )
    row = process_bag(str(bag), PY)['row']
    assert row['status'] == 'ok', row['error']
    assert row['fx_rms_pct'] is None and row['fz_rms_pct'] is not None


def test_no_replay_judges_the_recorded_estimates_alike(fleet: TestFleet, tmp_path: Path) -> None:
    replayed = tmp_path / 'replayed'
    replay_bag(fleet.good[0], replayed, progress=False)
    by_replay = process_bag(str(fleet.good[0]), PY)['row']
    recorded = process_bag(str(replayed), FleetSettings(replay=False))['row']
    assert recorded['status'] == 'ok'
    same = ['distance_m', 'has_truth', 'omega_rel_rms_pct', 'targets_met', 'alerts_traction']
    assert {k: recorded[k] for k in same} == {k: by_replay[k] for k in same}
    # what only the replay knows
    assert recorded['samples'] is None and recorded['faults_total'] is None


def test_kept_bags(fleet: TestFleet, tmp_path: Path) -> None:
    keep = tmp_path / 'replayed'
    record = process_bag(str(fleet.good[0]), FleetSettings(keep_dir=str(keep)))
    assert [p.name for p in keep.iterdir()] == [record['id']]  # no temporary left behind
    assert (keep / record['id'] / 'metadata.yaml').is_file()


def test_fingerprint_follows_settings_and_their_files(tmp_path: Path) -> None:
    config = tmp_path / 'replay.yaml'
    config.write_text('observer: {}\n')
    a = FleetSettings(config_file=str(config)).fingerprint()
    assert FleetSettings(config_file=str(config)).fingerprint() == a
    assert FleetSettings(config_file=str(config), replay=False).fingerprint() != a
    config.write_text('observer: {speed_lipschitz: 20.0}\n')
    assert FleetSettings(config_file=str(config), replay=False).fingerprint() != a


# -- the report -------------------------------------------------------------------------------


def _row(bag: str, **values: Any) -> dict[str, Any]:
    row: dict[str, Any] = dict.fromkeys(ROW_COLUMNS)
    row.update({'bag': bag, 'status': 'ok', 'error': '', 'faults': '', **values})
    return row


def test_worst_first_and_csv_round_trip() -> None:
    rows = [
        _row('/f/good', omega_rel_rms_pct=0.01, targets_met=1, targets_failed=0, missed=0),
        _row('/f/alerts', omega_rel_rms_pct=0.01, targets_met=1, targets_failed=0, missed=2),
        _row('/f/inaccurate', omega_rel_rms_pct=0.5, targets_met=0, targets_failed=1),
        _row('/f/broken', status='failed', error='BagCorruptError: x, "quoted"'),
        _row(
            '/f/nearly',
            omega_rel_rms_pct=0.09,
            targets_met=1,
            targets_failed=0,
            missed=0,
            has_truth=True,
            duration_s=12.5,
            samples=2500,
        ),
    ]
    ordered = sort_worst_first(rows)
    assert [r['bag'] for r in ordered] == [
        '/f/broken',
        '/f/inaccurate',
        '/f/alerts',
        '/f/nearly',
        '/f/good',
    ]
    assert ordered[3]['worst_target_ratio'] == pytest.approx(0.9)
    text = fleet_csv(ordered)
    lines = text.splitlines()
    assert lines[0].split(',')[:3] == ['bag', 'status', 'error']
    assert len(lines) == 1 + len(rows)
    md = fleet_markdown(ordered)
    assert md.index('`broken`') < md.index('`inaccurate`') < md.index('`good`')
    assert 'BagCorruptError: x, "quoted"' in md


def test_csv_reads_back_equal(tmp_path: Path) -> None:
    rows = sort_worst_first(
        [
            _row(
                '/f/a',
                omega_rel_rms_pct=0.0123456789,
                samples=400,
                has_truth=True,
                duration_s=1.995,
                faults='wheel.gap=1',
                faults_total=1,
            ),
            _row('/f/b', status='failed', error='ValueError: bad, "x"\tthing'),
        ]
    )
    (tmp_path / 'fleet.csv').write_text(fleet_csv(rows))
    back = read_fleet_csv(tmp_path)
    assert back == rows
    with pytest.raises(FleetInputError, match='not a fleet report'):
        (tmp_path / 'other.csv').write_text('a,b\n1,2\n')
        read_fleet_csv(tmp_path / 'other.csv')
    with pytest.raises(FleetInputError, match='cannot read'):
        read_fleet_csv(tmp_path / 'absent.csv')


def test_regressions_against_a_baseline() -> None:
    old = sort_worst_first(
        [
            _row(
                '/f/a',
                omega_rel_rms_pct=0.010,
                targets_met=1,
                missed=0,
                false_alarms=1,
                faults_total=0,
            ),
            _row('/f/b', omega_rel_rms_pct=0.010, targets_met=1, detected=3),
            _row('/f/c'),
            _row('/f/gone'),
            _row('/f/was_failing', status='failed', error='x'),
        ]
    )
    new = sort_worst_first(
        [
            # +10 % exactly is within the tolerance; one more false alarm and a fault are not
            _row(
                '/f/a',
                omega_rel_rms_pct=0.011,
                targets_met=1,
                missed=0,
                false_alarms=2,
                faults_total=1,
            ),
            # +20 % and a detection less
            _row('/f/b', omega_rel_rms_pct=0.012, targets_met=1, detected=2),
            _row('/f/c', status='failed', error='BagCorruptError: y'),
            _row('/f/was_failing', omega_rel_rms_pct=0.5),
            _row('/f/new'),
        ]
    )
    found = {(r.bag, r.column) for r in compare_baseline(new, old)}
    assert found == {
        ('/f/a', 'false_alarms'),
        ('/f/a', 'faults_total'),
        ('/f/b', 'omega_rel_rms_pct'),
        ('/f/b', 'detected'),
        ('/f/c', 'status'),
        ('/f/gone', 'bag'),
    }
    assert Regression('/f/c', 'status', 'ok', 'BagCorruptError: y') in compare_baseline(new, old)
    assert compare_baseline(old, old) == []


def test_baseline_of_a_fleet_that_moved() -> None:
    old = [_row('/mnt/a/drives/x/d1', mu_rms=0.01), _row('/mnt/a/drives/y/d1', mu_rms=0.01)]
    new = [_row('/data/drives/x/d1', mu_rms=0.01), _row('/data/drives/y/d1', mu_rms=0.02)]
    # no path in common: matched by their place below each fleet's folder
    assert compare_baseline(new, old) == [Regression('/data/drives/y/d1', 'mu_rms', 0.01, 0.02)]


# -- command line (setting errors; the run itself: tests/test_fleet_engines.py) ----------------


@pytest.mark.parametrize(
    ('argv', 'message'),
    [
        (['fleet', '--out', '{tmp}/o'], 'no bags named'),
        (['fleet', '{tmp}/none*', '--out', '{tmp}/o'], 'no bags found'),
        (
            ['fleet', '{tmp}', '--out', '{tmp}/o', '--baseline', '{tmp}/nothing.csv'],
            'cannot read the baseline',
        ),
        (['fleet', '{tmp}', '--out', '{tmp}/o', '--vehicle', '{tmp}/car.yaml'], '--vehicle'),
        (
            [
                'fleet',
                '{tmp}',
                '--out',
                '{tmp}/o',
                '--scheduler',
                'tcp://127.0.0.1:1',
                '--engine',
                'local',
            ],
            '--scheduler needs --engine dask',
        ),
        (['fleet', '{tmp}', '--out', '{tmp}/o', '--workers', '0'], 'workers must be'),
    ],
)
def test_setting_errors_exit_2_in_one_line(
    argv: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    write_synthetic_drive_bag(tmp_path / 'd', 0.1, 100.0)
    assert main([a.replace('{tmp}', str(tmp_path)) for a in argv]) == 2
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and err.startswith('vd: error: ') and message in err


def test_report_files(tmp_path: Path) -> None:
    records = [
        {
            'row': _row(
                '/f/a',
                omega_rel_rms_pct=0.02,
                targets_met=1,
                targets_failed=0,
                duration_s=60.0,
                alerts_traction=2,
                alerts_lock=0,
                alerts_low_friction=1,
            )
        },
        {'row': _row('/f/b', status='failed', error='BagCorruptError: z')},
    ]
    report = write_fleet_report(records, tmp_path)
    names = sorted(p.name for p in report.files)
    assert names == ['fleet.csv', 'fleet.md', 'fleet.png']
    assert (tmp_path / 'fleet.png').read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    assert [r['bag'] for r in report.rows] == ['/f/b', '/f/a'] and report.regressions is None
    assert not list(tmp_path.glob('.*'))  # no temporary file left
    again = write_fleet_report(records, tmp_path / '..' / tmp_path.name, baseline=tmp_path)
    assert again.regressions == []
    assert (tmp_path / 'regressions.csv').read_text() == 'bag,column,old,new\n'


# -- a car's reference, bags without one, symlinked folders -----------------------------------


def _car_bag(path: Path, *, reference: bool) -> Path:
    """Recorded estimates of a car (no replay) and, if asked, a grade reference on its own
    clock: 10 Hz, 3.3 ms off the estimates' 100 Hz stamps, as a GNSS/INS logs it."""
    t = np.arange(20 * 100) / 100.0
    stamp = 1_700_000_000_000_000_000 + np.round(t * 1e9).astype(np.int64)
    grade = np.radians(1.0 + 0.5 * np.sin(0.3 * t))
    rng = np.random.default_rng(3)
    topics: dict[str, dict[str, np.ndarray]] = {
        ESTIMATES_SLOPE: {
            'angle': grade + np.radians(rng.normal(0.0, 0.2, t.size)),
            'valid': t > 0.5,
        },
    }
    stamps = {}
    if reference:
        ref_t = np.arange(0.0, 20.0, 0.1) + 0.0033
        ref_stamp = 1_700_000_000_000_000_000 + np.round(ref_t * 1e9).astype(np.int64)
        topics[TRUTH_SLOPE] = {
            'angle': np.radians(1.0 + 0.5 * np.sin(0.3 * ref_t)),
            'valid': np.ones(ref_t.size, bool),
        }
        stamps[TRUTH_SLOPE] = ref_stamp
    write_topic_arrays_bag(path, stamp, topics, stamps=stamps)
    return path


def test_a_reference_on_its_own_clock_gives_vd_reports_figure(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import json

    bag = _car_bag(tmp_path / 'car', reference=True)
    row = process_bag(str(bag), FleetSettings(replay=False))['row']
    assert row['status'] == 'ok', row['error']
    assert row['has_truth'] is True
    out = tmp_path / 'report'
    assert main(['report', str(bag), '--out', str(out), '--no-figures', '--no-progress']) == 0
    capsys.readouterr()
    data = json.loads((out / 'metrics.json').read_text())
    slope = next(q for q in data['quantities'] if q['key'] == 'slope')
    assert slope['overall']['samples'] > 1500  # interpolated, not paired by stamp (none)
    assert row['slope_rms_deg'] == pytest.approx(slope['overall']['rms'], rel=1e-8)
    assert 0.15 < row['slope_rms_deg'] < 0.25  # the 0.2 deg noise put in
    # a car's reference: its figures, but never judged against the simulator's targets
    assert data['reference'] == 'reference' and data['targets'] == {}
    assert row['targets_met'] is None and row['targets_failed'] is None
    rows = sort_worst_first([row])
    assert rows[0]['worst_target_ratio'] is None
    md = fleet_markdown(rows)
    assert '| car |' in md and "1 bags with a reference (0 from the simulator, 1 a car's)" in md


def test_a_bag_without_reference_is_an_estimates_only_row(tmp_path: Path) -> None:
    bag = _car_bag(tmp_path / 'car', reference=False)
    row = process_bag(str(bag), FleetSettings(replay=False))['row']
    assert row['status'] == 'ok', row['error']
    assert row['has_truth'] is False and row['duration_s'] == pytest.approx(19.99)
    assert row['slope_rms_deg'] is None and row['targets_met'] is None
    md = fleet_markdown(sort_worst_first([row]))
    assert '| none |' in md and '1 without (estimates only: no accuracy)' in md


def test_symlinked_bag_folders_are_followed_once(tmp_path: Path) -> None:
    drives = tmp_path / 'drives'
    write_synthetic_drive_bag(drives / 'monday', 0.1, 100.0)
    write_synthetic_drive_bag(tmp_path / 'elsewhere' / 'tuesday', 0.1, 100.0)
    fleet_dir = tmp_path / 'fleet'
    fleet_dir.mkdir()
    (fleet_dir / 'monday').symlink_to(drives / 'monday', target_is_directory=True)
    (fleet_dir / 'more').symlink_to(tmp_path / 'elsewhere', target_is_directory=True)
    (fleet_dir / 'loop').symlink_to(fleet_dir, target_is_directory=True)  # must not recurse
    found = find_bags([fleet_dir])
    assert found == [fleet_dir / 'monday', fleet_dir / 'more' / 'tuesday']
