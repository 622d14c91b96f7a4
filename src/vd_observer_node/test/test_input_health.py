"""`StreamHealth`: the share of expected stamps, lag and losses of one input stream."""

from __future__ import annotations

import math

import numpy as np
import pytest
from vd_observer_node.inputs.health import HealthLimits, StreamHealth, health_notes

MS = 1_000_000


def _feed(health: StreamHealth, stamps: np.ndarray, lag_ns: int | None = None) -> None:
    for stamp in stamps.tolist():
        health.add(int(stamp), lag_ns)


def test_a_lossless_stream_has_share_one_and_its_period() -> None:
    health = StreamHealth()
    _feed(health, np.arange(0, 1000) * MS, lag_ns=3 * MS)
    w = health.window()
    assert (w.received, w.expected, w.share, w.lost_total) == (999, 999, 1.0, 0)
    assert w.period == pytest.approx(1e-3)
    assert w.lag_mean == pytest.approx(3e-3) and w.lag_max == pytest.approx(3e-3)


@pytest.mark.parametrize('loss', [0.05, 0.3, 0.45])
def test_random_loss_is_counted_to_within_a_message(loss: float) -> None:
    rng = np.random.default_rng(3)
    stamps = np.arange(0, 10_000) * MS
    kept = stamps[np.concatenate(([True], rng.random(stamps.size - 1) >= loss))]
    health = StreamHealth()
    lost = 0
    for window in np.array_split(kept, 10):  # ten diagnostics periods
        _feed(health, window)
        w = health.window()
        lost = w.lost_total
    last = int(kept[-1] // MS)  # stamps 0..last expected, all but the kept ones lost
    assert lost == last + 1 - kept.size
    assert health.received_total / health.expected_total == pytest.approx(1 - loss, abs=0.02)


def test_a_burst_gap_is_counted_across_windows() -> None:
    health = StreamHealth()
    _feed(health, np.arange(0, 500) * MS)
    assert health.window().share == 1.0
    _feed(health, np.arange(700, 1000) * MS)  # 200 ms lost between the windows
    w = health.window()
    assert (w.received, w.expected) == (300, 500)
    assert w.share == pytest.approx(0.6) and w.lost_total == 200


def test_a_jump_back_and_repeats_are_not_losses() -> None:
    health = StreamHealth()
    _feed(health, np.arange(0, 100) * MS)
    _feed(health, np.arange(0, 100) * MS)  # the bag loops
    _feed(health, np.array([99, 99]) * MS)  # repeated stamps
    w = health.window()
    assert w.lost_total == 0 and w.share == 1.0


def test_an_empty_window_expects_nothing_and_reports_no_lag() -> None:
    health = StreamHealth()
    w = health.window()
    assert (w.received, w.expected, w.share) == (0, 0, 1.0)
    assert math.isnan(w.lag_mean) and math.isnan(w.period)


def test_notes_warn_on_loss_lag_and_a_full_queue_only() -> None:
    health = StreamHealth()
    _feed(health, np.arange(0, 100) * MS)  # the nominal period, from a lossless start
    health.window()
    _feed(health, np.arange(100, 200, 2) * MS, lag_ns=900 * MS)  # every second one lost
    w = health.window()
    notes, values = health_notes('/in', w, HealthLimits(max_lag=0.5), queue=90, capacity=100)
    assert any('% of the expected stamps arrived' in n for n in notes)
    assert any('lags 0.90 s' in n for n in notes)
    assert any('90 of 100 messages queued' in n for n in notes)
    assert values['/in share_of_expected'] == pytest.approx(0.5, abs=0.01)
    assert values['/in lost_total'] == 49  # 101, 103, ..., 197
    assert values['/in queue'] == 90
    healthy = StreamHealth()
    _feed(healthy, np.arange(0, 100) * MS, lag_ns=1 * MS)
    notes, _ = health_notes('/in', healthy.window(), HealthLimits(), queue=1, capacity=100)
    assert notes == []
    lagging = StreamHealth()
    _feed(lagging, np.arange(0, 100) * MS, lag_ns=5_000 * MS)
    notes, values = health_notes('/in', lagging.window(), HealthLimits())
    assert notes == [] and values['/in lag_s'] == pytest.approx(5.0)  # reported, no WARN


def test_the_recording_summary_states_the_stamps_lost_of_inputs_with_a_header() -> None:
    from test_inputs import USER_MAPPING
    from vd_observer_node.inputs.decode import InputSeries, input_stats
    from vd_observer_node.inputs.mapping import mapping_from_dict

    mapping = mapping_from_dict(USER_MAPPING)
    rng = np.random.default_rng(11)
    stamps = np.arange(0, 2000) * 10 * MS  # 100 Hz, 20 s
    kept = stamps[np.concatenate(([True], rng.random(stamps.size - 1) >= 0.3))]
    series = InputSeries(kept, np.zeros((kept.size, 4)), np.full(kept.size, b''))
    stats = input_stats(mapping.wheels, series, 0.5)  # JointState: header stamps
    last = int(kept[-1] // (10 * MS))
    assert (stats.expected, stats.lost) == (last, last + 1 - kept.size)
    assert f'{stats.lost} of {stats.expected} expected stamps lost (' in stats.text()
    torques = next(spec for spec in mapping.specs if spec.name == 'wheel_torques')
    headerless = input_stats(torques, series, 0.5)  # Float64MultiArray: log times
    assert (headerless.expected, headerless.lost) == (None, None)
    assert 'lost' not in headerless.text()
