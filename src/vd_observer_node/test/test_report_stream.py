"""The streamed evaluation (tools/report/stream.py) against the whole-bag reference.

``evaluate(load_bag_series(bag))`` is the reference. The streamed :func:`evaluate_bag` must
give the same report on bags that exercise every figure (slope steps, gear shifts, alert
episodes, false alarms, road segments, estimates logged late, repeated and missing stamps),
with blocks so small that their boundaries fall inside episodes, segments, stretches and
the pairs' waiting rows. Counts, times, maxima and decisions are compared exactly; means and
RMS values (summed in another order) to 1e-12 relative.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from vd_common.topics import (
    ESTIMATES_ALERTS,
    ESTIMATES_FRICTION,
    ESTIMATES_FRICTION_POTENTIAL,
    ESTIMATES_SLOPE,
    ESTIMATES_TIRE_FORCES,
    OBSERVER_WHEEL_STATES,
    TRUTH_NAMESPACE,
    TRUTH_WHEEL_STATES,
)
from vd_observer_node.bag.writer import BagWriter
from vd_observer_node.testing.devbag import (
    alerts_topics,
    cascade_topics,
    sim_topics,
    write_topic_arrays_bag,
)
from vd_observer_node.testing.fleet_bags import write_test_fleet
from vd_observer_node.tools.fleet.process import (
    FleetSettings,
    _replay,
    bag_figures,
    bag_figures_whole,
    process_bag,
)
from vd_observer_node.tools.report.alerts import AlertSettings, truth_conditions
from vd_observer_node.tools.report.errors import ReportInputError, StampOrderError
from vd_observer_node.tools.report.evaluation import evaluate
from vd_observer_node.tools.report.load import load_bag_series
from vd_observer_node.tools.report.results import AccuracyReport
from vd_observer_node.tools.report.stream import evaluate_bag
from vd_observer_node.tools.report.stream_join import iter_topic_blocks

ROOT = Path(__file__).resolve().parents[3]
CONFIG = ROOT / 'src' / 'vd_sim_node' / 'config'
RATE = 200.0  # [Hz] short runs; the figures do not depend on the rate
REL = 1e-12  # relative tolerance of sums taken in another order
BLOCKS = (7, 1000, 200_000)  # messages per block: tiny (boundaries everywhere) to one


def _differences(a: Any, b: Any, path: str = 'report') -> list[str]:
    """Where two reports differ: exact for everything but floats (REL, nan equals nan)."""
    if dataclasses.is_dataclass(a) and not isinstance(a, type):
        if type(a) is not type(b):
            return [f'{path}: {type(a).__name__} != {type(b).__name__}']
        out = []
        for f in dataclasses.fields(a):
            out += _differences(getattr(a, f.name), getattr(b, f.name), f'{path}.{f.name}')
        return out
    if isinstance(a, dict):
        if not isinstance(b, dict) or list(a) != list(b):
            return [f'{path}: keys {list(a)} != {b if not isinstance(b, dict) else list(b)}']
        return [d for k in a for d in _differences(a[k], b[k], f'{path}[{k!r}]')]
    if isinstance(a, tuple | list):
        if not isinstance(b, tuple | list) or len(a) != len(b):
            return [f'{path}: {a!r} != {b!r}']
        return [
            d
            for i, (x, y) in enumerate(zip(a, b, strict=True))
            for d in _differences(x, y, f'{path}[{i}]')
        ]
    if isinstance(a, float) and isinstance(b, float):
        same = (math.isnan(a) and math.isnan(b)) or math.isclose(a, b, rel_tol=REL, abs_tol=0.0)
        return [] if same else [f'{path}: {a!r} != {b!r}']
    if type(a) is not type(b) or a != b:
        return [f'{path}: {a!r} != {b!r}']
    return []


def _reference(bag: Path) -> AccuracyReport:
    report, _ = evaluate(load_bag_series(bag, progress=False))
    return report


def _assert_streamed_equal(bag: Path, blocks: tuple[int, ...] = BLOCKS) -> AccuracyReport:
    ref = _reference(bag)
    for block in blocks:
        found = evaluate_bag(bag, block_messages=block)
        assert found.report is not None
        assert _differences(ref, found.report) == [], f'block_messages={block}'
    return ref


def _late_detector(sim: Any, rng: np.random.Generator) -> dict[str, dict[str, np.ndarray]]:
    """Alerts = the true condition 40 ms late with seeded spurious activations; μ_max
    estimate = the truth + a seeded error (some samples outside the 0.1 goal)."""
    truth = truth_conditions(sim.slip, sim.mu, sim.peak_slip, sim.peak_mu)
    n = truth.shape[0]
    level = np.zeros(truth.shape, np.int64)
    level[8:] = truth[:-8] * 2
    for start in rng.integers(0, n - 40, 12).tolist():  # 12 short spurious activations
        level[start : start + 30, rng.integers(0, 3), rng.integers(0, 4)] = 1
    onset = np.where(level > 0, sim.t[:, None, None] - 0.01, np.nan)
    axle_peak = sim.peak_mu[:, ::2]
    mu_max = axle_peak + rng.normal(0.0, 0.06, axle_peak.shape)
    return alerts_topics(
        0,
        level,
        onset,
        onset,
        mu_max=mu_max,
        confidence=rng.uniform(0.0, 1.0, axle_peak.shape),
        road_class=rng.integers(0, 5, axle_peak.shape),
    )


def _simulated_topics(scenario: str, duration: float | None = None) -> tuple[Any, dict]:
    from vd_common.vehicle.params import load_vehicle
    from vd_observer_node.estimation.cascade import CascadeSeries, CascadeSettings, run_cascade
    from vd_observer_node.estimation.vehicle import load_estimator_vehicle
    from vd_sim_node.vehicle.scenario import load_scenario
    from vd_sim_node.vehicle.simulation import simulate

    vehicle = ROOT / 'src' / 'vd_common' / 'config' / 'clio_rl_1_1.yaml'
    loaded = load_scenario(CONFIG / 'scenarios' / scenario)
    if duration is not None:
        loaded = dataclasses.replace(loaded, duration=duration)
    sim = simulate(load_vehicle(vehicle), loaded, rate_hz=RATE)
    est = run_cascade(
        CascadeSeries(sim.t, sim.wheel_angle, sim.body_speed, sim.wheel_torque),
        CascadeSettings(load_estimator_vehicle(vehicle)),
    )
    topics = {**sim_topics(sim), **cascade_topics(est, sim.wheel_angle)}
    topics.update(_late_detector(sim, np.random.default_rng(3)))
    return sim, topics


@pytest.fixture(scope='module')
def paper(tmp_path_factory: pytest.TempPathFactory) -> tuple[Any, dict, Path]:
    """Paper scenario, 12 s: launch, 1->2 upshift, slope step at 10 s; estimates and alerts."""
    sim, topics = _simulated_topics('paper_table1.yaml', 12.0)
    bag = tmp_path_factory.mktemp('stream') / 'paper'
    write_topic_arrays_bag(bag, np.round(sim.t * 1e9).astype(np.int64), topics)
    return sim, topics, bag


@pytest.fixture(scope='module')
def low_mu(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Launch onto a low-μ patch: traction and low-friction episodes, road segments."""
    sim, topics = _simulated_topics('launch_low_mu.yaml')
    bag = tmp_path_factory.mktemp('stream') / 'low_mu'
    write_topic_arrays_bag(bag, np.round(sim.t * 1e9).astype(np.int64), topics)
    return bag


@pytest.mark.slow
def test_paper_scenario_equal_to_the_reference(paper: tuple[Any, dict, Path]) -> None:
    ref = _assert_streamed_equal(paper[2])
    # the bag exercises what the streaming must carry across blocks
    assert ref.slope_steps_s and len(ref.gear_changes_s) >= 2 and ref.convergence
    assert ref.alerts is not None and ref.alerts.episodes and ref.alerts.false_alarms
    assert {q.key for q in ref.quantities} >= {'omega', 'fx', 'fz', 'mu', 'slope'}


@pytest.mark.slow
def test_low_mu_launch_equal_to_the_reference(low_mu: Path) -> None:
    ref = _assert_streamed_equal(low_mu)
    assert ref.alerts is not None
    # the μ_max segment begins at the road step (a block boundary falls inside it)
    assert ref.alerts.mu_max and all(m.start_index > 0 for m in ref.alerts.mu_max)
    assert {e.status for e in ref.alerts.episodes} >= {'met', 'missed'}


@pytest.mark.slow
def test_late_logged_repeated_and_missing_stamps(
    paper: tuple[Any, dict, Path], tmp_path: Path
) -> None:
    """Estimates logged 0.3 s after their stamp (they wait for their truth across blocks),
    with stamps dropped and repeated (the first of a repeated stamp counts)."""
    sim, topics, _ = paper
    stamps = np.round(sim.t * 1e9).astype(np.int64)
    rng = np.random.default_rng(11)
    n = stamps.size
    rows = np.sort(np.concatenate([rng.choice(n, n - 150, replace=False), rng.choice(n, 40)]))
    changed = (ESTIMATES_TIRE_FORCES, ESTIMATES_FRICTION, OBSERVER_WHEEL_STATES)
    shuffled = {
        name: {k: v[rows] for k, v in values.items()} if name in changed else values
        for name, values in topics.items()
    }
    late = {name: 300_000_000 for name in topics if not name.startswith(TRUTH_NAMESPACE)}
    bag = tmp_path / 'late'
    write_topic_arrays_bag(
        bag,
        stamps,
        shuffled,
        stamps={name: stamps[rows] for name in changed},
        log_delay_ns=late,
    )
    _assert_streamed_equal(bag, (13, 997, 200_000))


@pytest.mark.slow
def test_partial_bags_equal_the_reference_notes_and_all(
    paper: tuple[Any, dict, Path], tmp_path: Path
) -> None:
    """Truth without some estimates, estimates without their truth, no alerts topic, no
    friction-potential estimate, no slope truth: the same notes and the same skipped parts."""
    sim, topics, _ = paper
    stamps = np.round(sim.t * 1e9).astype(np.int64)
    cases = {
        'no_slope_truth_no_alerts': [
            name
            for name in topics
            if name.endswith(('/slope', '/alerts')) and name != ESTIMATES_SLOPE
        ],
        'no_wheel_truth_no_potential': [TRUTH_WHEEL_STATES, ESTIMATES_FRICTION_POTENTIAL],
        'no_estimate_of_forces': [ESTIMATES_TIRE_FORCES, ESTIMATES_ALERTS],
    }
    for name, dropped in cases.items():
        bag = tmp_path / name
        kept = {k: v for k, v in topics.items() if k not in dropped}
        write_topic_arrays_bag(bag, stamps, kept)
        _assert_streamed_equal(bag, (29, 200_000))


def test_bag_without_truth_or_topics(tmp_path: Path) -> None:
    t = np.arange(100) / RATE
    stamps = np.round(t * 1e9).astype(np.int64)
    bag = tmp_path / 'no_truth'
    write_topic_arrays_bag(bag, stamps, {OBSERVER_WHEEL_STATES: {'omega': np.ones((100, 4))}})
    with pytest.raises(ReportInputError, match='no truth topics') as whole:
        _reference(bag)
    found = evaluate_bag(bag, block_messages=50)
    assert found.report is None and found.no_report == str(whole.value)
    assert found.topics == (OBSERVER_WHEEL_STATES,) and found.last_stamp_ns == stamps[-1]
    empty = tmp_path / 'empty'
    with BagWriter(empty) as writer:  # a vd topic of a foreign type, no message
        writer.add_topic(TRUTH_WHEEL_STATES, 'geometry_msgs/msg/TwistStamped')
    with pytest.raises(ReportInputError, match='none of the vd topics'):
        evaluate_bag(empty)


def test_stamps_going_backwards_are_refused_and_the_fleet_falls_back(tmp_path: Path) -> None:
    from vd_observer_node.bag.cdr_batch import encode_batch
    from vd_observer_node.tools.report.topics import ESTIMATE_TOPICS, TRUTH_TOPICS

    n = 300
    t = np.arange(n) / RATE
    stamps = np.round(t * 1e9).astype(np.int64)
    omega = np.tile(50.0 + t[:, None], (1, 4))
    order = np.arange(n)
    order[100:110] = order[100:110][::-1]  # ten estimates logged in reverse stamp order
    names = [TRUTH_WHEEL_STATES, OBSERVER_WHEEL_STATES]
    types = {**TRUTH_TOPICS, **ESTIMATE_TOPICS}
    zeros = np.zeros((n, 4))
    datas = [
        encode_batch(types[name], s, 'base_link', {'angle': zeros, 'omega': w, 'omega_dot': zeros})
        for name, s, w in zip(
            names, (stamps, stamps[order]), (omega, omega[order] + 0.01), strict=True
        )
    ]
    bag = tmp_path / 'backwards'
    with BagWriter(bag) as writer:
        for name in names:
            writer.add_topic(name, types[name])
        which = np.tile([0, 1], n)
        interleaved = [datas[k][i] for i in range(n) for k in (0, 1)]
        writer.write_interleaved(names, which, interleaved, np.repeat(stamps, 2))
    with pytest.raises(StampOrderError, match=OBSERVER_WHEEL_STATES):
        evaluate_bag(bag)
    row = process_bag(str(bag), FleetSettings(replay=False))['row']
    assert row['status'] == 'ok' and row['has_truth'] is True
    whole = bag_figures_whole(bag, str(bag))[0]
    assert row['omega_rel_rms_pct'] == whole['omega_rel_rms_pct'] is not None


def test_blocks_hold_at_most_the_asked_messages(paper: tuple[Any, dict, Path]) -> None:
    from vd_observer_node.bag.reader import BagReader

    reader = BagReader(paper[2])
    topics = list(reader.topics)
    sizes = [
        sum(s.stamp_ns.size for s in b.values()) for b in iter_topic_blocks(reader, topics, 61)
    ]
    assert max(sizes) == 61 and sum(sizes) == sum(i.message_count for i in reader.topics.values())
    with pytest.raises(ValueError, match='block_messages'):
        evaluate_bag(paper[2], block_messages=0)


def test_fleet_row_figures_equal_the_whole_bag_path(tmp_path: Path) -> None:
    """The fleet's per-bag figures (streamed) and the reference path give the same row on a
    replayed bag of the test fleet, whatever the block size."""
    fleet = write_test_fleet(tmp_path / 'fleet', 2, corrupt=False, truncated=False)
    for k, bag in enumerate(fleet.good):
        replayed = tmp_path / f'replayed_{k}'
        _replay(str(bag), replayed, FleetSettings())
        whole = bag_figures_whole(replayed, str(bag))
        for block in (17, 200_000):
            assert bag_figures(replayed, str(bag), block) == whole
        assert whole[0]['has_truth'] is True and whole[0]['distance_m'] is not None


def test_state_held_between_blocks_is_bounded_not_the_bag(
    paper: tuple[Any, dict, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    """While the 12 s bag streams in blocks of 1000 messages (~50 stamps), the alert rows
    kept (the 2 s windows either side of the rows scored, plus a block), the rows waiting in
    a stamp join (at most a block) and the paired rows held for the events (0.5 s, 1 s at the
    start, plus a block) stay far below the bag's 2401 stamps."""
    from vd_observer_node.tools.report import stream
    from vd_observer_node.tools.report.stream_alerts import AlertStream
    from vd_observer_node.tools.report.stream_join import StampJoin

    kept: list[int] = []
    waiting: list[int] = []
    feed, pop = AlertStream.feed, StampJoin.pop

    def feed_and_count(self: Any, data: Any) -> None:
        feed(self, data)
        kept.append(0 if self.buffer is None else int(self.buffer.t.size))

    def pop_and_count(self: Any, final: bool) -> Any:
        out = pop(self, final)
        waiting.append(
            max(sum(c.stamp_ns.size for c in chunks) for chunks in self._chunks.values())
        )
        return out

    held: list[int] = []
    delayed = stream._delayed_rows

    def delayed_and_count(queue: Any, horizon: int) -> Any:
        out = delayed(queue, horizon)
        held.append(sum(stamps.size for stamps, _, _ in queue))
        return out

    monkeypatch.setattr(stream, '_delayed_rows', delayed_and_count)
    monkeypatch.setattr(AlertStream, 'feed', feed_and_count)
    monkeypatch.setattr(StampJoin, 'pop', pop_and_count)
    evaluate_bag(paper[2], block_messages=1000)
    probe = AlertStream(AlertSettings(), judged=True, mu_max=True)
    window = round((probe.lookback + probe.lookahead) * RATE)  # rows either side of those scored
    block_stamps = 1000 // 16  # messages per block over the bag's topics per stamp (>= 16)
    assert len(kept) > 20 and window < max(kept) <= window + block_stamps < 2401
    assert len(waiting) > 20 and max(waiting) <= block_stamps
    # rows held until the slope truth and the gear are 0.5 s (+1 ms) past them, and at the
    # start until the first second of true forces (the static loads) is read; plus a block
    assert len(held) > 20 and 0 < max(held) <= round(1.0 * RATE) + block_stamps
    assert max(held[len(held) // 2 :]) <= round(0.501 * RATE) + block_stamps


def test_omega_relative_rms_is_the_rms_error_over_the_rms_truth(tmp_path: Path) -> None:
    # A constant error of 0.05 rad/s on wheels turning 10 to 110 rad/s: the RMS error over the
    # RMS truth (closed form below) is 1.5x smaller than the RMS of per-sample ratios, which
    # the report gave before; whole and streamed evaluations must both give the closed form.
    n = 2001
    t = np.arange(n) / RATE
    stamps = np.round(t * 1e9).astype(np.int64)
    omega = np.tile(10.0 + 10.0 * t[:, None], (1, 4))
    zeros = np.zeros((n, 4))
    bag = tmp_path / 'omega'
    write_topic_arrays_bag(
        bag,
        stamps,
        {
            TRUTH_WHEEL_STATES: {'angle': zeros, 'omega': omega, 'omega_dot': zeros},
            OBSERVER_WHEEL_STATES: {'angle': zeros, 'omega': omega + 0.05, 'omega_dot': zeros},
        },
    )
    window = t >= 1.0  # EvaluationSettings.settle_s; every wheel spins above omega_min
    expected = 100.0 * 0.05 / math.sqrt(np.mean(np.square(omega[window, 0])))
    per_sample = 100.0 * math.sqrt(np.mean(np.square(0.05 / omega[window, 0])))
    assert per_sample > 1.4 * expected  # the two definitions differ on this drive

    def rel_rms(report: AccuracyReport | None) -> float:
        assert report is not None
        (q,) = [q for q in report.quantities if q.key == 'omega']
        return float(q.extras['rel_rms_pct'])

    whole, _ = evaluate(load_bag_series(bag, progress=False))
    assert rel_rms(whole) == pytest.approx(expected, rel=1e-9)
    assert rel_rms(evaluate_bag(bag).report) == pytest.approx(expected, rel=1e-9)
