"""`kernel._jit.FixedCall`: the machine code looked up once, never run on other types."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import pytest
from vd_observer_node.kernel._jit import JIT_ENABLED, FixedCall, jit


class Parts(NamedTuple):
    gain: np.ndarray
    total: np.ndarray


@jit
def _accumulate(parts: Parts, x: np.ndarray, out: np.ndarray) -> float:
    for k in range(x.shape[0]):
        parts.total[0] += parts.gain[0] * x[k]
        out[k] = parts.total[0]
    return float(parts.total[0])


def test_the_same_results_as_the_plain_function_and_state_carried() -> None:
    parts = Parts(np.array([2.0]), np.zeros(1))
    call = FixedCall(_accumulate, (parts,), (np.zeros(3), np.zeros(3)))
    assert parts.total[0] == 0.0  # compiling ran on copies
    out = np.zeros(3)
    assert call(np.array([1.0, 2.0, 3.0]), out) == 12.0
    np.testing.assert_array_equal(out, [2.0, 6.0, 12.0])  # closed form: 2 * cumsum
    assert call(np.array([0.5]), out[:1]) == 13.0


@pytest.mark.skipif(not JIT_ENABLED, reason='VD_JIT=0 calls the plain function anyway')
def test_other_layouts_go_through_the_dispatcher() -> None:
    parts = Parts(np.array([1.0]), np.zeros(1))
    call = FixedCall(_accumulate, (parts,), (np.zeros(3), np.zeros(3)))
    strided = np.arange(6.0)[::2]  # not C-contiguous: other machine code
    out = np.zeros(3)
    assert call(strided, out) == 6.0  # 0 + 2 + 4
    np.testing.assert_array_equal(out, [0.0, 2.0, 6.0])
    ints = np.array([1, 2], dtype=np.int64)  # another dtype: compiled anew by numba
    assert call(ints, np.zeros(2)) == 9.0
