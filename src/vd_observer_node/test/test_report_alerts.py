"""Alerts section of `vd report`: metric functions on synthetic arrays with known answers,
Alerts CDR coding, and the section end to end on small bags (and skipped without truth)."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from vd_common.topics import ESTIMATES_ALERTS, TRUTH_FRICTION, TRUTH_FRICTION_POTENTIAL
from vd_observer_node.bag import BagReader
from vd_observer_node.bag.alerts_cdr import decode_alerts
from vd_observer_node.bag.errors import BagFormatError
from vd_observer_node.bag.typestore import deserialize, message_class, serialize
from vd_observer_node.testing.devbag import (
    alerts_topics,
    encode_alerts,
    sim_topics,
    write_topic_arrays_bag,
)
from vd_observer_node.tools.report.alerts import (
    AlertSettings,
    activation_indices,
    already_active,
    evaluate_alerts,
    false_alarms,
    score_episodes,
    truth_conditions,
    truth_episodes,
)
from vd_observer_node.tools.report.cli import add_report_parser
from vd_observer_node.tools.report.evaluation import evaluate
from vd_observer_node.tools.report.load import load_bag_series
from vd_observer_node.tools.report.mu_max import (
    axle_utilisation,
    mu_max_errors,
    segments_from_peaks,
    segments_from_road,
)

RATE = 100.0  # [Hz]
CFG = AlertSettings()
REFERENCE_BAG = Path(__file__).resolve().parents[3] / 'bags' / 'paper_table1_100hz'


def _t(duration: float, rate: float = RATE) -> np.ndarray:
    return np.arange(round(duration * rate) + 1) / rate


# -- truth conditions ---------------------------------------------------------------------


def test_truth_conditions_per_kind_and_relaxed() -> None:
    peak_slip = np.full((1, 4), 0.1)
    peak_mu = np.full((1, 4), 0.5)
    slip = np.array([[0.1, 0.09, -0.1, 0.0]])
    mu = np.array([[0.0, 0.0, 0.0, -0.4]])
    truth = truth_conditions(slip, mu, peak_slip, peak_mu)
    assert truth.shape == (1, 3, 4)
    np.testing.assert_array_equal(truth[0, 0], [True, False, False, False])  # traction
    np.testing.assert_array_equal(truth[0, 1], [False, False, True, False])  # lock
    # |mu| >= 0.4 on RR; FL and RL past their peak slip with mu 0: all friction used
    np.testing.assert_array_equal(truth[0, 2], [True, False, True, True])
    relaxed = truth_conditions(slip, mu, peak_slip, peak_mu, scale=0.8)
    np.testing.assert_array_equal(relaxed[0, 0], [True, True, False, False])  # 0.09 >= 0.08
    np.testing.assert_array_equal(relaxed[0, 2], [True, True, True, True])


def test_spinning_wheel_past_its_peak_is_low_friction() -> None:
    """At slip 0.95 the MF tyre gives ~0.65 of its peak: below the 0.8 ratio, yet past the
    peak all available friction is used."""
    peak_slip, peak_mu = np.full((1, 4), 0.12), np.full((1, 4), 0.3)
    slip = np.array([[0.95, -0.95, 0.05, 0.95]])
    mu = np.array([[0.65 * 0.3, -0.65 * 0.3, 0.65 * 0.3, 0.0]])
    truth = truth_conditions(slip, mu, peak_slip, peak_mu)
    np.testing.assert_array_equal(truth[0, 2], [True, True, False, True])
    # RL, before its peak at the same mu: not low friction (0.65 < 0.8) but relaxed
    relaxed = truth_conditions(slip, mu, peak_slip, peak_mu, scale=0.8)
    np.testing.assert_array_equal(relaxed[0, 2], [True, True, True, True])  # 0.65 >= 0.64


@given(
    st.floats(-1.0, 1.0),
    st.floats(-1.5, 1.5),
    st.floats(0.01, 0.3),
    st.floats(0.05, 1.2),
    st.floats(0.1, 1.0),
)
def test_truth_implies_relaxed(
    slip: float, mu: float, peak_slip: float, peak_mu: float, scale: float
) -> None:
    args = (np.full((1, 4), slip), np.full((1, 4), mu))
    peaks = (np.full((1, 4), peak_slip), np.full((1, 4), peak_mu))
    truth = truth_conditions(*args, *peaks)
    relaxed = truth_conditions(*args, *peaks, scale=scale)
    assert np.all(relaxed | ~truth)
    assert not np.any(truth[:, 0] & truth[:, 1])  # a wheel cannot spin and lock at once
    for cond in (truth, relaxed):  # past the peak is low friction, at every scale
        assert np.all(cond[:, 2] | ~(cond[:, 0] | cond[:, 1]))


# -- episodes, delays, false alarms ---------------------------------------------------------


def test_episodes_start_after_settle_and_merge_within_a_second() -> None:
    t = _t(10.0)
    cond = np.zeros(t.size, bool)
    cond[(t >= 0.2) & (t < 0.7)] = True  # from before settle_s: scored from 0.5 s
    cond[(t >= 3.0) & (t < 3.2)] = True
    cond[(t >= 3.5) & (t < 3.6)] = True  # 0.5 s after the previous start: same event
    cond[(t >= 6.0) & (t < 6.1)] = True
    np.testing.assert_allclose(truth_episodes(t, cond, CFG), [0.5, 3.0, 6.0], atol=1e-12)


def test_known_onset_gives_known_delay() -> None:
    onsets = np.array([2.0, 5.0, 8.0, 11.0])
    # 40 ms late; 300 ms late; 200 ms early; the only activation for 11 s is 1.5 s late
    activations = np.array([2.04, 5.3, 7.8, 12.5])
    scored = score_episodes(onsets, activations, CFG)
    assert [s[3] for s in scored] == ['met', 'late', 'met', 'missed']
    assert scored[0][1] == pytest.approx(2.04) and scored[0][2] == pytest.approx(0.04)
    assert scored[1][2] == pytest.approx(0.3)
    assert scored[2][2] == pytest.approx(-0.2)
    assert scored[3][1] is None and scored[3][2] is None


def test_episode_beginning_while_already_active_is_detected_with_no_delay() -> None:
    onsets = np.array([3.0, 6.0, 9.0])
    # 3.0: active since 1.0 (2 s before, beyond early_s) -> already active;
    # 6.0: active since 5.5 (within early_s) -> the early activation, delay -0.5;
    # 9.0: the channel went OK at 8.0 and activates 1.5 s late -> missed
    activations = np.array([1.0, 5.5, 10.5])
    active_at = np.array([True, True, False])
    scored = score_episodes(onsets, activations, CFG, active_at_onset=active_at)
    assert scored[0] == (3.0, 3.0, 0.0, 'met')
    assert scored[1][2] == pytest.approx(-0.5) and scored[1][3] == 'met'
    assert scored[2][3] == 'missed'
    np.testing.assert_array_equal(
        already_active(onsets, activations, active_at, CFG), [True, False, False]
    )
    # without the level at the onsets: as before, the long-active episode is missed
    assert score_episodes(onsets, activations, CFG)[0][3] == 'missed'


def test_evaluate_alerts_reports_already_active() -> None:
    """low_friction FL active from 1.0 s (a wet road, say) when the wheel spins at 4.0 s."""
    t = _t(8.0)
    n = t.size
    truth = np.zeros((n, 3, 4), bool)
    truth[(t >= 4.0) & (t < 5.0), 2, 0] = True
    level = np.zeros((n, 3, 4), np.int64)
    level[(t >= 1.0 - 1e-9) & (t < 6.0), 2, 0] = 1
    onset = np.where(level > 0, 0.98, np.nan)
    episodes, alarms = evaluate_alerts(t, truth, truth, level, onset, CFG)
    (episode,) = episodes
    assert episode.already_active and episode.status == 'met'
    assert episode.detected_s == pytest.approx(4.0) and episode.delay_s == 0.0
    assert episode.reported_onset_s == pytest.approx(0.98)
    (alarm,) = alarms  # the activation at 1.0 s itself had no truth near it
    assert alarm.t_s == pytest.approx(1.0)


def test_one_spurious_activation_is_one_false_alarm() -> None:
    t = _t(10.0)
    relaxed = np.zeros(t.size, bool)
    relaxed[(t >= 2.0) & (t < 2.5)] = True
    # 2.3: inside relaxed; 2.9: relaxed 0.4 s before (within 0.5 s); 1.85: relaxed 0.15 s
    # after (beyond +0.1 s) -> false; 6.0: nothing near -> false
    found = false_alarms(t, np.array([1.85, 2.3, 2.9, 6.0]), relaxed, CFG)
    np.testing.assert_allclose(found, [1.85, 6.0])


def test_evaluate_alerts_on_channels() -> None:
    t = _t(10.0)
    n = t.size
    truth = np.zeros((n, 3, 4), bool)
    relaxed = np.zeros((n, 3, 4), bool)
    level = np.zeros((n, 3, 4), np.int64)
    onset = np.full((n, 3, 4), np.nan)
    # lock RL: true from 4.0 s, the alert warns from 4.05 s (onset stamp 4.03 s), critical
    # from 4.2 s (no new activation), off at 6 s
    truth[(t >= 4.0) & (t < 6.0), 1, 2] = True
    relaxed[(t >= 3.9) & (t < 6.0), 1, 2] = True
    level[(t >= 4.05 - 1e-9) & (t < 6.0), 1, 2] = 1
    level[(t >= 4.2 - 1e-9) & (t < 6.0), 1, 2] = 2
    onset[(t >= 4.05 - 1e-9) & (t < 6.0), 1, 2] = 4.03
    # traction FR: a spurious activation at 8 s, no truth at all
    level[(t >= 8.0 - 1e-9) & (t < 8.5), 0, 1] = 1
    assert activation_indices(level[:, 1, 2]).tolist() == [405]
    episodes, alarms = evaluate_alerts(t, truth, relaxed, level, onset, CFG)
    (episode,) = episodes
    assert (episode.kind, episode.wheel, episode.status) == ('lock', 2, 'met')
    assert episode.true_onset_s == pytest.approx(4.0)
    assert episode.delay_s == pytest.approx(0.05)
    assert episode.reported_onset_s == pytest.approx(4.03)
    (alarm,) = alarms
    assert (alarm.kind, alarm.wheel) == ('traction', 1)
    assert alarm.t_s == pytest.approx(8.0)


# -- friction potential ---------------------------------------------------------------------


def test_axle_utilisation_takes_the_more_used_wheel() -> None:
    util = axle_utilisation(np.array([[0.2, -0.4, 0.0, 0.1]]), np.array([[1.0, 0.5, 1.0, 0.0]]))
    np.testing.assert_allclose(util, [[0.8, 0.1 / 1e-6]])


def test_segments_from_a_road_step_not_from_load_steps() -> None:
    peaks = np.tile([1.05, 1.08], (10, 1))
    peaks[4:] *= 0.25  # road 1.0 -> 0.25 at sample 4
    peaks[7:, 0] *= 1.03  # braking: front load up, its peak changes a few per cent...
    peaks[7:, 1] *= 0.97  # ...the rear one the other way
    np.testing.assert_array_equal(segments_from_peaks(peaks, CFG.road_jump), [0, 4])
    np.testing.assert_array_equal(segments_from_road([1.0, 1.0, 0.3, 0.3, 1.0]), [0, 2, 4])


def test_mu_max_error_after_excitation() -> None:
    t = _t(10.0)
    n = t.size
    truth = np.tile([1.0, 1.0], (n, 1))
    truth[t >= 5.0] = 0.3
    util = np.zeros((n, 2))
    util[(t >= 2.0) & (t < 3.0), 0] = 0.9  # front excited on the dry road 2..3 s
    util[(t >= 6.0) & (t < 6.5), 0] = 0.6  # and on the slippery one 6..6.5 s
    est = np.tile([1.0, 1.0], (n, 1))
    est[:, 0] = np.where(t < 5.0, 1.05, 0.5)  # +0.05 on dry, +0.2 on the slippery road
    est[(t >= 2.0) & (t < 2.5), 0] = 1.3  # a bad estimate early in the excitation
    starts = segments_from_peaks(truth, CFG.road_jump)
    segs = mu_max_errors(t, util, truth, est, starts, confidence=np.ones((n, 2)), settings=CFG)
    assert [(s.axle, s.start_index) for s in segs] == [(0, 0), (0, 500)]  # rear never excited
    dry, slippery = segs
    assert dry.excited_s == pytest.approx(2.0)
    # (a): 2.1 .. 3.49 s (excited within the last 0.5 s): 40 samples at +0.3, 100 at +0.05
    assert dry.recent_samples == 140
    assert dry.recent_rms == pytest.approx(np.sqrt((40 * 0.3**2 + 100 * 0.05**2) / 140))
    assert dry.recent_within_pct == pytest.approx(100 * 100 / 140)
    # (b): 2.0 .. 4.99 s: 50 samples at +0.3, 250 at +0.05; last miss at 2.49 s
    assert dry.within_pct == pytest.approx(100 * 250 / 300)
    assert dry.last_miss_s == pytest.approx(0.49)
    assert dry.true_mu_max == pytest.approx(1.0)
    assert slippery.rms == pytest.approx(0.2)
    assert slippery.within_pct == 0.0
    assert slippery.confidence_mean == pytest.approx(1.0)


# -- Alerts CDR -----------------------------------------------------------------------------


@pytest.mark.parametrize('frame_id', ['', 'a', 'base_link', 'abc'])
def test_alerts_coding_agrees_with_rosbags(frame_id: str) -> None:
    rng = np.random.default_rng(3)
    n = 5
    stamps = 1_700_000_000_123_456_789 + np.arange(n) * 10_000_000
    level = rng.integers(0, 3, (n, 3, 4))
    onset = np.where(level > 0, stamps[:, None, None] - 5_000_000, 0)
    datas = encode_alerts(stamps, frame_id, {'level': level, 'onset_ns': onset})
    msg = deserialize(datas[2], 'vd_msgs/msg/Alerts')
    assert msg.header.frame_id == frame_id and len(msg.alerts) == 12
    a = msg.alerts[7]  # lock RR
    assert (a.kind, a.wheel, a.level, a.active) == (1, 3, level[2, 1, 3], level[2, 1, 3] > 0)
    decoded = decode_alerts(datas)
    np.testing.assert_array_equal(decoded.stamp_ns, stamps)
    np.testing.assert_array_equal(decoded.values['level'], level)
    np.testing.assert_array_equal(decoded.values['onset_ns'], onset)
    np.testing.assert_array_equal(decoded.values['detected_ns'], 0)


def test_decoding_a_message_with_only_the_active_alerts() -> None:
    alerts_cls = message_class('vd_msgs/msg/Alerts')
    alert_cls = message_class('vd_msgs/msg/Alert')
    header_cls = message_class('std_msgs/msg/Header')
    time_cls = message_class('builtin_interfaces/msg/Time')
    active = alert_cls(
        kind=2, wheel=1, level=2, active=True, onset=time_cls(7, 5), detected=time_cls(7, 9)
    )
    msg = alerts_cls(header=header_cls(stamp=time_cls(8, 0), frame_id='x'), alerts=[active])
    decoded = decode_alerts([serialize(msg, 'vd_msgs/msg/Alerts')])
    assert decoded.values['level'].sum() == 2 and decoded.values['level'][0, 2, 1] == 2
    assert decoded.values['onset_ns'][0, 2, 1] == 7_000_000_005
    assert decoded.values['detected_ns'][0, 2, 1] == 7_000_000_009
    assert decoded.stamp_ns[0] == 8_000_000_000
    with pytest.raises(BagFormatError):
        decode_alerts([serialize(msg, 'vd_msgs/msg/Alerts')[:-4]])


# -- the section from bags ------------------------------------------------------------------


def _vd(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog='vd')
    add_report_parser(parser.add_subparsers(dest='command', required=True))
    args = parser.parse_args(argv)
    status: int = args.run(args)
    return status


def _synthetic_topics(t: np.ndarray, with_truth_potential: bool = True) -> dict[str, dict]:
    """Front wheels spin from 3.0 s to 4.0 s; the traction alert is active from 3.05 s;
    a spurious lock RR activation at 7.0 s; mu_max estimate 0.05 too high."""
    n = t.size
    slip = np.zeros((n, 4))
    spin = (t >= 3.0) & (t < 4.0)
    slip[spin, :2] = 0.3
    mu = np.zeros((n, 4))
    mu[spin, :2] = 0.7  # excited (> 0.5 peak), short of 0.8 peak; low_friction by the slip
    level = np.zeros((n, 3, 4), np.int64)
    level[(t >= 3.05 - 1e-9) & (t < 4.2), 0, :2] = 2
    level[(t >= 7.0 - 1e-9) & (t < 7.5), 1, 3] = 1
    onset = np.where(level > 0, 3.04, np.nan)
    mu_max = np.tile([1.0, 1.05], (n, 1))
    topics: dict[str, dict] = {
        TRUTH_FRICTION: {'slip': slip, 'mu': mu, 'valid': np.ones((n, 4), bool)},
        **alerts_topics(
            0,
            level,
            onset,
            onset,
            mu_max=mu_max + 0.05,
            confidence=np.ones((n, 2)),
            road_class=np.full((n, 2), 4),
        ),
    }
    if with_truth_potential:
        topics[TRUTH_FRICTION_POTENTIAL] = {
            'mu_max': mu_max,
            'slip_peak': np.full((n, 2), 0.15),
            'confidence': np.ones((n, 2)),
            'road_class': np.full((n, 2), 4, np.uint8),
        }
    return topics


def test_section_end_to_end_through_the_command(tmp_path: Path) -> None:
    t = _t(10.0)
    bag = tmp_path / 'bag'
    write_topic_arrays_bag(bag, np.round(t * 1e9).astype(np.int64), _synthetic_topics(t))
    out = tmp_path / 'out'
    assert _vd(['report', str(bag), '--out', str(out), '--no-progress']) == 0
    data = json.loads((out / 'metrics.json').read_text())['alerts']
    episodes = data['episodes']
    assert [(e['kind'], e['wheel'], e['status']) for e in episodes] == [
        ('traction', 'FL', 'met'),
        ('traction', 'FR', 'met'),
        ('low_friction', 'FL', 'missed'),  # past the peak slip, no low_friction alert
        ('low_friction', 'FR', 'missed'),
    ]
    assert episodes[0]['delay_s'] == pytest.approx(0.05)
    assert episodes[0]['reported_onset_s'] == pytest.approx(3.04)
    assert [(a['kind'], a['wheel'], a['t_s']) for a in data['false_alarms']] == [
        ('lock', 'RR', pytest.approx(7.0))
    ]
    (front,) = data['mu_max']  # the rear axle is never excited
    assert front['axle'] == 'front' and front['road_class'] == 'dry'
    assert front['rms'] == pytest.approx(0.05) and front['within_pct'] == 100.0
    assert data['targets']['false alarms [-]'] == {'value': 1.0, 'limit': 0.0, 'met': False}
    assert (out / 'alerts.png').stat().st_size > 10_000
    assert (out / 'friction_potential.png').stat().st_size > 10_000
    md = (out / 'metrics.md').read_text()
    assert '## Alerts: detection delay and false alarms' in md and '| lock | RR | 7.000 |' in md


def test_section_skipped_with_a_note_without_the_true_potential(tmp_path: Path) -> None:
    t = _t(5.0)
    bag = tmp_path / 'bag'
    stamps = np.round(t * 1e9).astype(np.int64)
    write_topic_arrays_bag(bag, stamps, _synthetic_topics(t, with_truth_potential=False))
    report, _ = evaluate(load_bag_series(bag, progress=False))
    assert report.alerts is None
    assert any('alerts section skipped' in note for note in report.notes)


def test_only_the_friction_potential_estimate_gives_mu_max_only(tmp_path: Path) -> None:
    t = _t(5.0)
    topics = _synthetic_topics(t)
    del topics[ESTIMATES_ALERTS]
    bag = tmp_path / 'bag'
    write_topic_arrays_bag(bag, np.round(t * 1e9).astype(np.int64), topics)
    report, _ = evaluate(load_bag_series(bag, progress=False))
    assert report.alerts is not None
    assert report.alerts.episodes == () and len(report.alerts.mu_max) == 1
    assert any(f'{ESTIMATES_ALERTS} missing' in note for note in report.alerts.notes)


def test_reference_bag_has_alerts_but_no_true_potential() -> None:
    """Recorded before the simulator published /vd/truth/friction_potential: skipped."""
    assert ESTIMATES_ALERTS in BagReader(REFERENCE_BAG).topics
    report, _ = evaluate(load_bag_series(REFERENCE_BAG, progress=False))
    assert report.alerts is None
    assert any(
        'alerts section skipped' in note and TRUTH_FRICTION_POTENTIAL in note
        for note in report.notes
    )


def test_simulated_run_with_a_perfect_late_detector(tmp_path: Path) -> None:
    """launch_low_mu at 200 Hz; alert levels = the true condition 20 ms late: every episode
    is detected within 20 ms, no false alarm, and the truth comes through the bag intact."""
    from vd_common.vehicle.params import load_vehicle
    from vd_sim_node.vehicle.scenario import load_scenario
    from vd_sim_node.vehicle.simulation import simulate

    config = Path(__file__).resolve().parents[2] / 'vd_sim_node' / 'config'
    sim = simulate(
        load_vehicle(config.parents[1] / 'vd_common' / 'config' / 'clio_rl_1_1.yaml'),
        load_scenario(config / 'scenarios' / 'launch_low_mu.yaml'),
        rate_hz=200.0,
    )
    truth = truth_conditions(sim.slip, sim.mu, sim.peak_slip, sim.peak_mu)
    lag = 4  # samples = 20 ms
    level = np.zeros(truth.shape, np.int64)
    level[lag:] = truth[:-lag]
    stamps = np.round(sim.t * 1e9).astype(np.int64)
    topics = {**sim_topics(sim), **alerts_topics(0, level)}
    bag = tmp_path / 'sim'
    write_topic_arrays_bag(bag, stamps, topics)
    report, _ = evaluate(load_bag_series(bag, progress=False))
    section = report.alerts
    assert section is not None
    kinds = {e.kind for e in section.episodes}
    assert {'traction', 'low_friction'} <= kinds  # the launch on the patch is exercised
    assert section.false_alarms == ()
    for e in section.episodes:
        if e.true_onset_s > sim.t[-1] - 0.02:
            # the run ends before the late detector could react: honestly missed
            assert e.status == 'missed'
            continue
        assert e.delay_s is not None and e.delay_s <= 0.02 + 1e-9, e
    # the first traction episode is the spin-up at 6.1 s, exactly 20 ms before detection
    first = next(e for e in section.episodes if e.kind == 'traction')
    assert 6.0 < first.true_onset_s < 6.3 and first.delay_s == pytest.approx(0.02)


def test_mu_max_says_how_often_the_class_was_unknown_or_confidently_wrong() -> None:
    """While excited (2.1 .. 3.49 s, 140 samples): the first 40 off by 0.3 and class unknown
    for 30 of them; 100 within 0.1, 20 of those unknown. Unknown 50 of 140; known and wrong
    the 10 off by 0.3 with a class."""
    t = _t(10.0)
    n = t.size
    truth = np.ones((n, 2))
    util = np.zeros((n, 2))
    util[(t >= 2.0) & (t < 3.0), 0] = 0.9
    est = np.ones((n, 2))
    est[(t >= 2.0) & (t < 2.5), 0] = 1.3
    klass = np.full((n, 2), 4)  # dry
    first = int(np.searchsorted(t, 2.1))
    klass[first : first + 30, 0] = 0  # unknown while wrong
    klass[first + 40 : first + 60, 0] = 0  # unknown while right
    (dry,) = mu_max_errors(
        t, util, truth, est, np.array([0]), road_classes=(klass, None), settings=CFG
    )
    assert dry.recent_samples == 140
    assert dry.recent_unknown_pct == pytest.approx(100 * 50 / 140)
    assert dry.recent_known_wrong_pct == pytest.approx(100 * 10 / 140)
    (bare,) = mu_max_errors(t, util, truth, est, np.array([0]), settings=CFG)
    assert math.isnan(bare.recent_unknown_pct) and math.isnan(bare.recent_known_wrong_pct)
