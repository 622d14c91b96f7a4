"""Many byte ranges copied in one compiled loop: how the bag writer assembles its chunks.

numpy's fancy indexing (:func:`.packed.scatter`) copies the messages of one length in one
operation, but at ~150 ns a message; this loop copies them at memory speed. Only the offline
writer (`BagWriter.write_interleaved`) uses it, importing it on first use, so reading a bag
does not load numba. It releases the GIL (``kernel._jit.jit``): the replay's other threads
run meanwhile.
"""

from __future__ import annotations

import sys

import numpy as np

from vd_observer_node.kernel._jit import jit

__all__ = ['copy_ranges']


@jit
def copy_ranges(
    out: np.ndarray, at: np.ndarray, src: np.ndarray, starts: np.ndarray, lengths: np.ndarray
) -> None:
    """Copy ``src[starts[k] : starts[k] + lengths[k]]`` to ``out[at[k]:]`` for every k.

    The same contract as :func:`.packed.scatter` (ranges of ``out`` must not overlap).

    Args:
        out: 1-D uint8 destination (writeable, C-contiguous).
        at: shape (N,) int64 destination offsets [B].
        src: 1-D uint8 source.
        starts, lengths: shape (N,) int64 source offsets and lengths [B].
    """
    for k in range(at.shape[0]):
        a = at[k]
        s = starts[k]
        n = lengths[k]
        out[a : a + n] = src[s : s + n]


def main() -> int:
    """``python -m vd_observer_node.bag.copy_kernel``: compile the copy into numba's disk
    cache (``make setup`` runs it with the step functions), for a writeable and a read-only
    source: two machine codes."""
    ones = np.ones(1, dtype=np.int64)
    for source in (np.zeros(1, dtype=np.uint8), np.frombuffer(b'\x00', dtype=np.uint8)):
        copy_ranges(np.zeros(1, dtype=np.uint8), 0 * ones, source, 0 * ones, ones)
    return 0


if __name__ == '__main__':
    sys.exit(main())
