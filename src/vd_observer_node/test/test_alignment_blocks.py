"""`BlockAligner`: alignment of inputs given in blocks equals `align_stamps` on the whole record.

Inputs on their own clocks (rates, offsets, jitter, repeated stamps, dropouts), split into
blocks at random points per input; the sets, the payload at each set, the stale count and the
samples used are those of one call on everything.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from vd_observer_node.errors import ConfigurationError
from vd_observer_node.estimation.alignment import BlockAligner, align_stamps


def _clock(rng: np.random.Generator, n: int, period: int, offset: int) -> np.ndarray:
    """Non-decreasing stamps [ns]: jitter, repeats and a dropout."""
    stamps = offset + np.arange(n, dtype=np.int64) * period
    stamps += rng.integers(0, period // 3 + 1, n)
    stamps = np.maximum.accumulate(stamps)
    repeat = rng.random(n) < 0.05
    stamps[1:][repeat[1:]] = stamps[:-1][repeat[1:]]
    cut = int(rng.integers(0, n))
    return np.delete(stamps, np.s_[cut : cut + n // 10])


def _inputs(seed: int, alignment: str) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    if alignment == 'exact':  # a common clock, each input missing some stamps
        base = np.arange(300, dtype=np.int64) * 10
        return [base[rng.random(base.size) < 0.9] for _ in range(3)]
    return [_clock(rng, 300, 10, 0), _clock(rng, 100, 30, 7), _clock(rng, 40, 70, 100)]


def _split(rng: np.random.Generator, n: int, blocks: int) -> list[int]:
    return [0, *sorted(rng.integers(0, n + 1, blocks - 1).tolist()), n]


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 10_000), blocks=st.integers(1, 40), alignment=st.sampled_from(
    ['exact', 'latest']))  # fmt: skip
def test_blocks_give_the_sets_of_the_whole_record(seed: int, blocks: int, alignment: str) -> None:
    stamps = _inputs(seed, alignment)
    whole = align_stamps(stamps, alignment, max_age=0.00005)
    rng = np.random.default_rng(seed + 1)
    # the same number of blocks per input, cut at independent points (a block of the bag
    # holds different shares of each topic)
    cuts = [_split(rng, len(s), blocks) for s in stamps]
    aligner = BlockAligner(len(stamps), alignment, max_age=0.00005)
    got_stamps: list[np.ndarray] = []
    got_index: list[list[np.ndarray]] = [[] for _ in stamps]
    for b in range(blocks):
        parts = [s[c[b] : c[b + 1]] for s, c in zip(stamps, cuts, strict=True)]
        columns = [{'i': np.arange(c[b], c[b + 1])} for c in cuts]
        common, out = aligner.push(parts, columns, final=b == blocks - 1)
        got_stamps.append(common)
        for k, o in enumerate(out):
            assert len(o['i']) == len(common)
            got_index[k].append(o['i'])
    np.testing.assert_array_equal(np.concatenate(got_stamps), whole.stamp_ns)
    for k in range(len(stamps)):
        np.testing.assert_array_equal(np.concatenate(got_index[k]), whole.indexes[k])
        assert aligner.used[k] == len(np.unique(whole.indexes[k]))
    assert aligner.stale == whole.stale
    assert aligner.carried == 0
    if alignment == 'latest':
        assert whole.stale > 0 and len(whole.stamp_ns) > 0  # the record exercises both


def test_samples_wait_for_the_other_inputs() -> None:
    aligner = BlockAligner(2, 'exact', 0.1)
    none = np.zeros(0, dtype=np.int64)
    common, out = aligner.push(
        [np.array([1, 2, 3]), none], [{'v': np.array([10, 20, 30])}, {'v': none}]
    )
    assert len(common) == 0 and aligner.carried == 3
    common, out = aligner.push([none, np.array([2, 3])], [{'v': none}, {'v': np.array([5, 6])}])
    # 2 is final (both inputs are at 3 or later); 3 may still get a repeat
    np.testing.assert_array_equal(common, [2])
    np.testing.assert_array_equal(out[0]['v'], [20])
    common, out = aligner.push([none, none], [{}, {}], final=True)
    np.testing.assert_array_equal(common, [3])
    assert aligner.used == [2, 2] and aligner.carried == 0


@pytest.mark.parametrize('alignment', ['exact', 'latest'])
def test_a_stopped_input_holds_the_others_no_longer_than_max_wait(alignment: str) -> None:
    """The second input stops for most of the record: with max_wait the carry stays small
    and the sets are still those of the whole record (blocks cut at common stamps)."""
    drive = np.arange(0, 30_000, 10, dtype=np.int64)
    other = np.arange(0, 30_000, 30, dtype=np.int64) + (3 if alignment == 'latest' else 0)
    other = other[(other < 5_000) | (other >= 25_000)]  # stopped from 5 to 25 us
    stamps = [drive, other]
    whole = align_stamps(stamps, alignment, max_age=5e-8)
    carried: dict[float | None, int] = {}
    for wait in (2e-6, None):
        aligner = BlockAligner(2, alignment, 5e-8, max_wait=wait)
        got: list[np.ndarray] = []
        index: list[list[np.ndarray]] = [[], []]
        most = 0
        edges = np.arange(0, 30_500, 500)
        for b, (lo, hi) in enumerate(itertools.pairwise(edges)):
            parts = [s[(s >= lo) & (s < hi)] for s in stamps]
            columns = [{'i': np.flatnonzero((s >= lo) & (s < hi))} for s in stamps]
            common, out = aligner.push(parts, columns, final=b == len(edges) - 2)
            got.append(common)
            for k in range(2):
                index[k].append(out[k]['i'])
            most = max(most, aligner.carried)
        np.testing.assert_array_equal(np.concatenate(got), whole.stamp_ns)
        for k in range(2):
            np.testing.assert_array_equal(np.concatenate(index[k]), whole.indexes[k])
        assert aligner.stale == whole.stale
        carried[wait] = most
    # 2 us + one block of 0.5 us: at most ~250 + 85 samples; without limit the 20 us gap's
    assert carried[2e-6] < 400 < 1500 < carried[None]


def test_configuration_errors() -> None:
    with pytest.raises(ConfigurationError, match='alignment'):
        BlockAligner(2, 'nearest', 0.1)
    with pytest.raises(ConfigurationError, match='inputs'):
        BlockAligner(0, 'exact', 0.1)
    with pytest.raises(ConfigurationError, match='max_wait'):
        BlockAligner(2, 'exact', 0.1, max_wait=0.0)
