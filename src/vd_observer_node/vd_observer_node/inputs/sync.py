"""Put the samples of the mapped inputs together on the stamps the cascade runs on.

Two policies (`InputMapping.alignment`):

* ``'exact'``: the stamps every input has (vd's own sensors are stamped together); the last
  message of a repeated stamp wins, as a re-sent stamp replaces the buffered one live.
* ``'latest'``: the wheel sensor's stamps, each with the newest sample of every other input
  whose stamp is not later (sample and hold: what a live system has at that instant). A wheel
  stamp is dropped while another input has no sample yet or only one older than ``max_age``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from vd_observer_node.inputs.errors import MappingError

__all__ = ['Alignment', 'align_exact', 'align_latest', 'align_stamps']

IntArray = NDArray[np.int64]


class Alignment(NamedTuple):
    """Where each input's sample of each cascade stamp is.

    Attributes:
        stamp_ns: shape (M,), int64 [ns], the cascade's stamps (sorted, unique).
        indexes: per input, shape (M,), the index of its sample in its series.
        stale: wheel stamps dropped because another input was missing or too old.
    """

    stamp_ns: IntArray
    indexes: list[IntArray]
    stale: int


def _last_of_each(stamps: IntArray, wanted: IntArray) -> IntArray:
    """Index in ``stamps`` of the last sample with each stamp of ``wanted`` (all present)."""
    order = np.argsort(stamps, kind='stable')
    found: IntArray = order[np.searchsorted(stamps[order], wanted, side='right') - 1]
    return found


def align_exact(stamps: list[IntArray]) -> Alignment:
    """Stamps common to every input (sorted, unique) and each input's index of them."""
    common = stamps[0]
    for s in stamps[1:]:
        common = np.intersect1d(common, s)
    return Alignment(common, [_last_of_each(s, common) for s in stamps], 0)


def align_latest(stamps: list[IntArray], max_age_ns: int) -> Alignment:
    """The first input's stamps, each with the newest not-later sample of every other input.

    Args:
        stamps: per input, shape (N_i,), int64 [ns]; the first input drives.
        max_age_ns: a held sample older than this [ns] does not count.
    """
    drive = np.unique(stamps[0])
    keep = np.ones(drive.shape[0], dtype=bool)
    held: list[IntArray] = []
    for s in stamps[1:]:
        order = np.argsort(s, kind='stable')
        sorted_s = s[order]
        # position of the newest sample with stamp <= each drive stamp (-1: none yet)
        pos = np.searchsorted(sorted_s, drive, side='right') - 1
        ok = pos >= 0
        age = np.where(ok, drive - sorted_s[np.maximum(pos, 0)], 0)
        keep &= ok & (age <= max_age_ns)
        held.append(order[np.maximum(pos, 0)])
    first = _last_of_each(stamps[0], drive)
    stale = int(np.count_nonzero(~keep))
    return Alignment(drive[keep], [first[keep], *(h[keep] for h in held)], stale)


def align_stamps(stamps: list[IntArray], alignment: str, max_age: float) -> Alignment:
    """Dispatch by policy name (`InputMapping.alignment`); ``max_age`` in [s].

    Raises:
        MappingError: unknown policy.
    """
    if alignment == 'exact':
        return align_exact(stamps)
    if alignment == 'latest':
        return align_latest(stamps, round(max_age * 1e9))
    raise MappingError(f'alignment {alignment!r} is unknown (use exact or latest)')
