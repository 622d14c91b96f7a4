"""Plot helpers of vd report: the min/max envelope keeps extremes and gaps."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from vd_observer_node.tools.report.figures import envelope


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
