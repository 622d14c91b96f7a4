"""Plot helpers of vd report: the min/max envelope keeps extremes and gaps; panels without a
valid sample say so; titles say 'reference' where the bag is not the simulator's."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from matplotlib.figure import Figure
from vd_observer_node.tools.report.figures import NO_VALID_SAMPLES, _quantity_figure, envelope
from vd_observer_node.tools.report.results import AccuracyReport, Comparison, EvaluationSettings


def test_short_series_is_returned_unchanged() -> None:
    t = np.arange(100.0)
    y = np.sin(t)
    te, ye = envelope(t, y, buckets=50)
    assert te is t and ye is y


def test_a_single_sample_spike_survives_decimation() -> None:
    t = np.arange(150_001) / 1000.0
    y = np.zeros(t.size)
    y[77_777] = 5.0
    y[12_345] = -3.0
    te, ye = envelope(t, y, buckets=1500)
    assert te.size == ye.size <= 3000
    assert ye.max() == 5.0 and ye.min() == -3.0
    spike_time = te[np.argmax(ye)]
    assert abs(spike_time - t[77_777]) <= 0.101  # within one bucket (101 samples)


def test_all_nan_bucket_stays_a_gap() -> None:
    t = np.arange(10_000) / 100.0
    y = np.ones(t.size)
    y[2000:5000] = np.nan
    te, ye = envelope(t, y, buckets=100)
    gap = (te > 20.5) & (te < 49.5)
    assert gap.any() and np.isnan(ye[gap]).all()
    assert np.isfinite(ye[(te < 19.5) | (te > 50.5)]).all()


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(2, 20_000), buckets=st.integers(1, 500))
def test_envelope_keeps_global_extremes_and_time_order(seed: int, n: int, buckets: int) -> None:
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.1, 1.0, n))
    y = rng.normal(size=n)
    te, ye = envelope(t, y, buckets=buckets)
    assert ye.max() == y.max() and ye.min() == y.min()
    assert te.size == ye.size <= max(2 * buckets, n)
    assert np.all(np.diff(te) >= 0)


def _report(reference: str) -> AccuracyReport:
    return AccuracyReport(
        bag='drive',
        first_stamp_s=0.0,
        duration_s=2.0,
        settings=EvaluationSettings(),
        slope_steps_s=(),
        gear_changes_s=(),
        evaluated_fraction=0.0,
        quantities=(),
        convergence=(),
        targets={},
        notes=(),
        reference=reference,
    )


def _panel_texts(fig: Figure) -> list[str]:
    return [t.get_text() for ax in fig.axes for t in ax.texts]


def test_a_panel_without_a_valid_sample_says_so() -> None:
    t = np.arange(200) / 100.0
    valid = np.zeros((200, 4), bool)
    valid[:, :2] = True  # the rear wheels' mu is never valid (a front-wheel-drive car)
    mu = Comparison(
        'mu', 'Utilised friction μ', '-', t, np.full((200, 4), 0.1), None,
        np.ones(200, bool), 'estimated (where valid)', '', 'μ', valid,
    )  # fmt: skip
    fig = _quantity_figure(mu, _report('none'))
    try:
        titles = [ax.get_title() for ax in fig.axes]
        texts = {ax.get_title(): [x.get_text() for x in ax.texts] for ax in fig.axes}
        assert titles == ['FL', 'FR', 'RL', 'RR']
        assert texts['RL'] == [NO_VALID_SAMPLES] and texts['RR'] == [NO_VALID_SAMPLES]
        assert texts['FL'] == [] and texts['FR'] == []
        assert 'no reference' in fig.get_suptitle()
    finally:
        plt.close(fig)


def test_titles_say_reference_where_the_bag_is_not_the_simulators() -> None:
    t = np.arange(100) / 100.0
    slope = Comparison(
        'slope', 'Road slope', 'deg', t, np.ones(100), np.zeros(100), np.ones(100, bool),
        'estimated', 'reference (on its own clock)', 'slope', np.ones(100, bool),
    )  # fmt: skip
    for reference, word in (('reference', 'vs reference'), ('simulator', 'vs truth')):
        fig = _quantity_figure(slope, _report(reference))
        try:
            assert word in fig.get_suptitle()
            assert _panel_texts(fig) == []
        finally:
            plt.close(fig)
