"""`vd report` end to end on small bags with known answers (metrics, files, errors)."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np
import pytest
from vd_common.topics import (
    ESTIMATES_FRICTION,
    ESTIMATES_SLOPE,
    ESTIMATES_TIRE_FORCES,
    OBSERVER_WHEEL_STATES,
    SENSORS_WHEEL_TORQUES,
    TRUTH_FRICTION,
    TRUTH_NAMESPACE,
    TRUTH_SLOPE,
    TRUTH_TIRE_FORCES,
    TRUTH_WHEEL_STATES,
)
from vd_observer_node.testing.devbag import write_topic_arrays_bag
from vd_observer_node.tools.report.cli import add_report_parser, default_out_dir, run_report
from vd_observer_node.tools.report.evaluation import evaluate
from vd_observer_node.tools.report.load import load_bag_series

RATE = 100.0  # [Hz]
DURATION = 20.0  # [s]
T0_NS = 1_700_000_000_000_000_000  # an epoch-like first stamp: times are relative to it
STEP_S = 5.0  # true slope 0 -> 2 deg
SHIFT_S = (12.0, 12.25)  # gear 3 -> 0 -> 4
STATIC = np.array([3000.0, 3000.0, 2000.0, 2000.0])  # [N]
SLOPE_SETTLE_S = 0.7  # slope error 3 deg for 0.7 s after the step, then 0.1 deg


def _known_topics(t: np.ndarray, rng: np.random.Generator) -> dict[str, dict[str, np.ndarray]]:
    """Estimates = truth + known errors inside the window, wild errors outside it."""
    n = t.size
    excluded = (t < 1.0) | (np.abs(t - STEP_S) <= 0.5)
    for shift in SHIFT_S:
        excluded |= np.abs(t - shift) <= 0.5
    wild = np.where(excluded, rng.uniform(1e3, 1e4, n), 0.0)[:, None]

    omega = np.tile(40.0 + t[:, None], (1, 4))
    fx_true = np.column_stack([1000.0 * np.sin(0.3 * t)] * 2 + [np.zeros(n)] * 2)
    fz_true = np.tile(STATIC, (n, 1))
    # Rear wheels unexcited: |Fx| = 50 N < 0.05 Fz = 100 N, so their mu must not count.
    fx_true[:, 2:] = -50.0
    mu_true = fx_true / fz_true
    # mu: +0.01 where valid; the placeholder 0 of invalid samples must not count either.
    valid = np.tile(np.arange(n) % 2 == 0, (4, 1)).T
    mu_est = np.where(valid, mu_true + 0.01, 0.0)
    mu_est[:, 2:] += 0.5
    slope_true = np.radians(np.where(t < STEP_S, 0.0, 2.0))
    slope_err = np.where((t >= STEP_S) & (t < STEP_S + SLOPE_SETTLE_S), 3.0, 0.1)
    gear = np.select([t < SHIFT_S[0], t < SHIFT_S[1]], [3, 0], 4).astype(np.int8)
    return {
        SENSORS_WHEEL_TORQUES: {'gear': gear},
        TRUTH_WHEEL_STATES: {'omega': omega, 'omega_dot': np.zeros((n, 4))},
        OBSERVER_WHEEL_STATES: {
            'omega': omega * 1.001 + wild,
            'omega_dot': np.full((n, 4), 0.5) + wild,
        },
        TRUTH_TIRE_FORCES: {'fx': fx_true, 'fz': fz_true},
        ESTIMATES_TIRE_FORCES: {'fx': fx_true + 10.0 + wild, 'fz': fz_true + 30.0 + wild},
        TRUTH_FRICTION: {'mu': mu_true, 'valid': np.ones((n, 4), bool)},
        ESTIMATES_FRICTION: {'mu': mu_est + wild, 'valid': valid},
        TRUTH_SLOPE: {'angle': slope_true, 'valid': np.ones(n, bool)},
        ESTIMATES_SLOPE: {
            'angle': slope_true + np.radians(slope_err) + np.where(excluded, 1.0, 0.0),
            'valid': np.ones(n, bool),
        },
    }


@pytest.fixture(scope='module')
def known_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    t = np.arange(round(DURATION * RATE) + 1) / RATE
    stamp = T0_NS + np.round(t * 1e9).astype(np.int64)
    path = tmp_path_factory.mktemp('report') / 'known'
    topics = _known_topics(t, np.random.default_rng(7))
    # Estimates logged 30 ms late (an estimator publishes after the measurement): pairing
    # must use the header stamp, not the log time.
    late = {name: 30_000_000 for name in topics if not name.startswith(TRUTH_NAMESPACE)}
    write_topic_arrays_bag(path, stamp, topics, log_delay_ns=late)
    return path


def _vd(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog='vd')
    add_report_parser(parser.add_subparsers(dest='command', required=True))
    args = parser.parse_args(argv)
    status: int = args.run(args)
    return status


def _quantity(report: dict[str, object], key: str) -> dict[str, object]:
    for q in report['quantities']:  # type: ignore[attr-defined]
        if q['key'] == key:
            return q  # type: ignore[no-any-return]
    raise AssertionError(f'{key} missing')


def test_known_answers_through_the_command(
    known_bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / 'out'
    assert _vd(['report', str(known_bag), '--out', str(out), '--no-progress']) == 0
    data = json.loads((out / 'metrics.json').read_text())
    assert data['slope_steps_s'] == pytest.approx([STEP_S])
    assert data['gear_changes_s'] == pytest.approx(list(SHIFT_S))

    fx = _quantity(data, 'fx')
    assert fx['overall']['rms'] == pytest.approx(10.0, rel=1e-9)  # type: ignore[index]
    assert fx['overall']['max_abs'] == pytest.approx(10.0, rel=1e-9)  # type: ignore[index]
    peak = fx['extras']['max_abs_truth']  # type: ignore[index]
    assert 990.0 < peak <= 1000.0
    assert fx['extras']['rms_pct_of_max_truth'] == pytest.approx(1000.0 / peak)  # type: ignore[index]

    fz = _quantity(data, 'fz')
    assert fz['overall']['rms'] == pytest.approx(30.0, rel=1e-9)  # type: ignore[index]
    # Static loads from the median true Fz of the first second: 30 N / 3000 N and / 2000 N.
    expected_pct = 100.0 * math.sqrt((0.01**2 + 0.015**2) / 2)
    assert fz['extras']['rms_pct_of_static'] == pytest.approx(expected_pct, rel=1e-9)  # type: ignore[index]

    omega = _quantity(data, 'omega')
    assert omega['extras']['rel_rms_pct'] == pytest.approx(0.1, rel=1e-9)  # type: ignore[index]
    omega_dot = _quantity(data, 'omega_dot')
    assert omega_dot['overall']['rms'] == pytest.approx(0.5, rel=1e-9)  # type: ignore[index]
    assert omega_dot['wheels']['RR']['mean'] == pytest.approx(0.5, rel=1e-9)  # type: ignore[index]

    mu = _quantity(data, 'mu')
    assert mu['overall']['rms'] == pytest.approx(0.01, rel=1e-6)  # type: ignore[index]
    assert mu['wheels']['RL']['samples'] == 0  # type: ignore[index]
    assert mu['wheels']['RL']['rms'] is None  # type: ignore[index]

    slope = _quantity(data, 'slope')
    # Inside the window the error is 3 deg from 5.5 s to 5.7 s (20 samples), else 0.1 deg.
    t = np.arange(round(DURATION * RATE) + 1) / RATE
    window = (t >= 1.0) & (np.abs(t - STEP_S) > 0.5)
    for shift in SHIFT_S:
        window &= np.abs(t - shift) > 0.5
    err = np.where((t >= STEP_S) & (t < STEP_S + SLOPE_SETTLE_S), 3.0, 0.1)[window]
    rms = float(np.sqrt(np.mean(err**2)))
    assert slope['overall']['rms'] == pytest.approx(rms, rel=1e-6)  # type: ignore[index]
    assert slope['overall']['max_abs'] == pytest.approx(3.0, rel=1e-6)  # type: ignore[index]
    (conv,) = data['convergence']
    assert conv['step_s'] == pytest.approx(STEP_S)
    assert conv['delay_s'] == pytest.approx(SLOPE_SETTLE_S, abs=1e-6)
    assert (conv['from_deg'], conv['to_deg']) == pytest.approx((0.0, 2.0))
    assert data['targets']['Fx RMS [% of max |Fx|]']['met'] is True
    assert data['targets']['slope RMS [deg]']['met'] is False
    assert data['reference'] == 'simulator'
    assert "## Targets for the simulator's ideal sensors" in (out / 'metrics.md').read_text()

    pngs = sorted(p.name for p in out.glob('*.png'))
    assert {'summary.png', 'slope.png', 'tire_fx.png', 'friction_mu.png'} <= set(pngs)
    assert all((out / name).stat().st_size > 10_000 for name in pngs)
    markdown = (out / 'metrics.md').read_text()
    assert '| Longitudinal tyre force Fx | N | 10 | 10 |' in markdown
    assert 'max \\|err\\|' in markdown  # a literal pipe would split the table cell
    printed = capsys.readouterr().out
    assert 'Longitudinal tyre force Fx' in printed and 'step at 5.00 s' in printed


def test_default_output_dir_is_next_to_the_bag(known_bag: Path, tmp_path: Path) -> None:
    assert default_out_dir(tmp_path / 'drive') == tmp_path / 'drive_report'
    assert (
        default_out_dir(tmp_path / 'drive' / 'drive_0.mcap')
        == tmp_path / 'drive' / 'drive_0_report'
    )


def _no_reference_bag(path: Path) -> Path:
    """Estimates without any /vd/truth/* topic: a slope valid after 0.5 s, tyre forces, and a
    friction estimate never valid on the rear wheels (their panels have nothing to draw)."""
    t = np.arange(200) / RATE
    n = t.size
    slope = np.radians(np.where(t < 1.0, 0.0, 2.0))
    mu_valid = np.zeros((n, 4), bool)
    mu_valid[:, :2] = t[:, None] > 0.2
    write_topic_arrays_bag(
        path,
        T0_NS + np.round(t * 1e9).astype(np.int64),
        {
            ESTIMATES_SLOPE: {'angle': slope, 'valid': t >= 0.5},
            ESTIMATES_TIRE_FORCES: {
                'fx': np.tile([100.0, 200.0, 0.0, 0.0], (n, 1)),
                'fz': np.tile(STATIC, (n, 1)),
            },
            ESTIMATES_FRICTION: {'mu': np.full((n, 4), 0.05), 'valid': mu_valid},
        },
    )
    return path


def test_bag_without_reference_gives_an_estimates_only_report(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = _no_reference_bag(tmp_path / 'no_truth')
    out = tmp_path / 'out'
    assert _vd(['report', str(bag), '--out', str(out), '--no-progress']) == 0
    printed = capsys.readouterr().out.splitlines()
    assert 'has no reference' in printed[0] and 'estimates-only' in printed[0]
    data = json.loads((out / 'metrics.json').read_text())
    assert data['reference'] == 'none'
    assert data['quantities'] == [] and data['targets'] == {} and data['convergence'] == []
    stats = {e['key']: e for e in data['estimates']}
    assert set(stats) == {'fx', 'fz', 'mu', 'slip', 'slope'}
    assert stats['slip']['note'] == 'finite'  # the friction message's flags are mu's
    slope = stats['slope']['overall']
    assert slope['samples'] == 200 and slope['valid'] == 150
    assert slope['valid_pct'] == pytest.approx(75.0)
    assert slope['minimum'] == pytest.approx(0.0) and slope['maximum'] == pytest.approx(2.0)
    assert slope['mean'] == pytest.approx((50 * 0.0 + 100 * 2.0) / 150)
    assert stats['fx']['wheels']['FR']['mean'] == pytest.approx(200.0)
    assert (
        stats['mu']['wheels']['RL']['valid'] == 0 and stats['mu']['wheels']['RL']['mean'] is None
    )
    assert stats['mu']['wheels']['FL']['valid'] == 200 - 21  # t > 0.2 s
    md = (out / 'metrics.md').read_text()
    assert 'This bag has no reference' in md and TRUTH_SLOPE in md
    assert 'Estimate vs' not in md and 'RMS' not in md and 'Targets' not in md
    assert 'no valid samples' in md  # the rear wheels' mu
    pngs = {p.name for p in out.glob('*.png')}
    assert {'slope.png', 'tire_fx.png', 'friction_mu.png', 'summary.png'} <= pngs


def test_a_bag_with_nothing_to_report_is_a_one_line_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    t = np.arange(100) / RATE
    bag = tmp_path / 'sensors_only'
    write_topic_arrays_bag(
        bag, np.round(t * 1e9).astype(np.int64), {SENSORS_WHEEL_TORQUES: {'gear': np.ones(100)}}
    )
    assert _vd(['report', str(bag), '--out', str(tmp_path / 'out')]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith('vd: error: ') and 'nothing to report' in err[0]
    assert not (tmp_path / 'out').exists()


def test_out_replaces_only_its_own_previous_report(
    known_bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / 'out'
    assert _vd(['report', str(known_bag), '--out', str(out), '--no-progress']) == 0
    first = {p.name for p in out.iterdir()}
    assert 'tire_fz.png' in first and '.vd_report_files.json' in first
    mine = out / 'my_notes.txt'
    mine.write_text('keep me')
    # the same folder for a bag that has fewer figures: the old ones must not stay
    bag = _no_reference_bag(tmp_path / 'no_truth')
    assert _vd(['report', str(bag), '--out', str(out), '--no-progress']) == 0
    second = {p.name for p in out.iterdir()}
    assert 'replaced the previous report' in capsys.readouterr().out
    assert 'wheel_speed.png' in first and 'wheel_speed.png' not in second
    assert mine.read_text() == 'keep me'
    listed = json.loads((out / '.vd_report_files.json').read_text())['files']
    assert second == {*listed, '.vd_report_files.json', 'my_notes.txt'}


def test_out_refuses_a_folder_that_is_not_a_report(
    known_bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / 'photos'
    out.mkdir()
    (out / 'summary.png').write_bytes(b'not ours')
    assert _vd(['report', str(known_bag), '--out', str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and 'not empty and holds no vd report' in err[0]
    assert (out / 'summary.png').read_bytes() == b'not ours'


def test_missing_bag_is_a_one_line_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    args = argparse.Namespace(bag=tmp_path / 'nope', out=None, vehicle=None)
    assert run_report(args) == 2
    assert capsys.readouterr().err.count('\n') == 1


def test_partial_truth_reports_what_exists_and_says_what_is_missing(tmp_path: Path) -> None:
    t = np.arange(round(4 * RATE) + 1) / RATE
    slope = np.radians(np.where(t < 2.0, 0.0, 1.0))
    bag = tmp_path / 'partial'
    write_topic_arrays_bag(
        bag,
        np.round(t * 1e9).astype(np.int64),
        {
            TRUTH_SLOPE: {'angle': slope, 'valid': np.ones(t.size, bool)},
            ESTIMATES_SLOPE: {
                'angle': slope + np.radians(0.2),
                'valid': np.ones(t.size, bool),
            },
            ESTIMATES_TIRE_FORCES: {'fx': np.ones((t.size, 4)), 'fz': np.ones((t.size, 4))},
        },
    )
    report, comparisons = evaluate(load_bag_series(bag, progress=False))
    assert [q.key for q in report.quantities] == ['slope']
    assert report.quantities[0].overall.rms == pytest.approx(0.2, rel=1e-9)
    notes = ' '.join(report.notes)
    assert f'{TRUTH_TIRE_FORCES} missing' in notes and 'gear shifts not excluded' in notes
    forces = [c for c in comparisons if c.key == 'fx']
    assert forces and forces[0].truth is None  # still plotted, without truth


def test_truth_only_bag_says_there_is_nothing_to_compare(tmp_path: Path) -> None:
    t = np.arange(100) / RATE
    bag = tmp_path / 'truth_only'
    write_topic_arrays_bag(
        bag,
        np.round(t * 1e9).astype(np.int64),
        {TRUTH_SLOPE: {'angle': np.zeros(t.size), 'valid': np.ones(t.size, bool)}},
    )
    report, _ = evaluate(load_bag_series(bag, progress=False))
    assert report.quantities == ()
    assert any('nothing to compare' in note for note in report.notes)


def test_a_reference_on_another_clock_is_interpolated_onto_the_estimates(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # An estimator stamping with its own clock, 1.23 ms off the reference: the reference is
    # interpolated onto the estimates' stamps. Fx of the reference ramps, the estimate is the
    # ramp at its own stamps plus 5 N: the error is 5 N exactly, wherever the reference is.
    t = np.arange(300) / RATE
    stamp = np.round(t * 1e9).astype(np.int64)
    offset_ns = 1_234_567
    ramp = 100.0 * t[:, None] * np.ones(4)
    reference = {'fx': ramp, 'fz': np.full((t.size, 4), 3000.0)}
    estimate = {'fx': 100.0 * (t + offset_ns * 1e-9)[:, None] * np.ones(4) + 5.0,
                'fz': np.full((t.size, 4), 3000.0)}  # fmt: skip
    bag = tmp_path / 'foreign'
    write_topic_arrays_bag(
        bag,
        stamp,
        {TRUTH_TIRE_FORCES: reference, ESTIMATES_TIRE_FORCES: estimate},
        stamps={ESTIMATES_TIRE_FORCES: stamp + offset_ns},
    )
    out = tmp_path / 'out'
    assert _vd(['report', str(bag), '--out', str(out), '--no-progress']) == 0
    data = json.loads((out / 'metrics.json').read_text())
    fx = _quantity(data, 'fx')['overall']  # type: ignore[index]
    # from 1 s on (settle) to the last estimate inside the reference: 299 - 100 stamps
    assert fx['samples'] == 4 * 199
    assert fx['rms'] == pytest.approx(5.0, abs=1e-6)
    assert any('own clock' in note and 'interpolated' in note for note in data['notes'])
    assert 'own clock' in capsys.readouterr().out
    # a car's reference: called so, and never judged against the simulator's targets
    assert data['reference'] == 'reference' and data['targets'] == {}
    md = (out / 'metrics.md').read_text()
    assert '## Estimate vs reference' in md and 'Targets' not in md and '**no**' not in md
    assert any("not the simulator's truth" in note for note in data['notes'])


def test_a_reference_with_gaps_is_not_interpolated_across_them(tmp_path: Path) -> None:
    from vd_observer_node.tools.report.evaluation import build_comparisons
    from vd_observer_node.tools.report.results import EvaluationSettings

    t = np.arange(400) / RATE
    stamp = np.round(t * 1e9).astype(np.int64)
    keep = (t < 1.5) | (t > 2.5)  # a 1 s hole in the reference (a GNSS outage)
    slope = {'angle': np.radians(0.5 * t), 'valid': np.ones(t.size, bool)}
    # the estimate is exact at its own stamps, 2 ms after the reference's
    estimate = {'angle': np.radians(0.5 * (t + 0.002)), 'valid': np.ones(t.size, bool)}
    bag = tmp_path / 'holes'
    write_topic_arrays_bag(
        bag,
        stamp,
        {ESTIMATES_SLOPE: estimate, TRUTH_SLOPE: {k: v[keep] for k, v in slope.items()}},
        stamps={ESTIMATES_SLOPE: stamp + 2_000_000, TRUTH_SLOPE: stamp[keep]},
    )
    series = load_bag_series(bag, progress=False)
    comparisons, _, _, _ = build_comparisons(series, EvaluationSettings(reference_max_gap_s=0.5))
    c = next(c for c in comparisons if c.key == 'slope')
    assert c.truth is not None and c.estimate is not None
    assert 'reference' in c.truth_label
    hole = (c.t > 1.49) & (c.t < 2.51)  # between the reference's samples around its hole
    assert np.isnan(c.truth[hole]).all() and not c.mask[hole].any()
    inside = ~hole & (c.t < 3.98)
    np.testing.assert_allclose(c.truth[inside], c.estimate[inside], atol=1e-9)
    wide = build_comparisons(series, EvaluationSettings(reference_max_gap_s=2.0))[0]
    assert np.isfinite(next(c for c in wide if c.key == 'slope').truth[hole]).all()  # type: ignore[index]


def test_static_loads_from_the_vehicle_file(known_bag: Path, tmp_path: Path) -> None:
    from vd_observer_node.estimation.vehicle import load_estimator_vehicle

    vehicle_file = Path(__file__).resolve().parents[2] / 'vd_common/config/clio_rl_1_1.yaml'
    static = load_estimator_vehicle(vehicle_file).static_wheel_loads
    out = tmp_path / 'out'
    argv = ['report', str(known_bag), '--out', str(out), '--vehicle', str(vehicle_file)]
    assert _vd([*argv, '--no-figures', '--no-progress']) == 0
    data = json.loads((out / 'metrics.json').read_text())
    fz = _quantity(data, 'fz')['extras']
    expected = 100.0 * float(np.sqrt(np.mean((30.0 / static) ** 2)))
    assert fz['rms_pct_of_static'] == pytest.approx(expected, rel=1e-9)  # type: ignore[index]
    assert fz['static_load_RR'] == pytest.approx(float(static[3]))  # type: ignore[index]
    assert not list(out.glob('*.png'))


def test_a_mapped_topic_the_bag_lacks_is_named_with_the_bags_topics(
    known_bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import yaml
    from vd_observer_node.testing.standard_bags import STANDARD_MAPPING

    mapping = tmp_path / 'car.yaml'
    mapping.write_text(yaml.safe_dump(STANDARD_MAPPING))
    out = tmp_path / 'out'
    # the bag has estimates: no replay, the mapped inputs are only summarised
    assert _vd(['report', str(known_bag), '--mapping', str(mapping), '--out', str(out)]) == 0
    notes = json.loads((out / 'metrics.json').read_text())['notes']
    absent = [n for n in notes if n.startswith('/joint_states skipped')]
    assert len(absent) == 1 and 'the bag has no such topic' in absent[0]
    assert f'its topics: {ESTIMATES_FRICTION}, ' in absent[0]  # sorted, every one of them
    capsys.readouterr()
