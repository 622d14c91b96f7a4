"""One recorder for the offline runs of a stateful estimator (`mass_grade.run_mass_grade`,
`rolling_radius.run_rolling_radius`): its estimate after each stamp, every field an array.

The fields are those of the estimate's dataclass, written once there; `Track` reads them
from it, so a field added to an estimate is recorded without a second list.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ['Track', 'record_track']


@dataclasses.dataclass(frozen=True)
class Track:
    """A stateful estimator's estimates over a record (N stamps).

    Attributes:
        t: shape (N,), [s].
        series: each field of the estimate (`dataclasses.fields`) as an array of N rows
            (bool, int and float fields as bool, int64 and float64 arrays).
        faults: the estimator's fault counts per kind at the end.
    """

    t: NDArray[np.float64]
    series: Mapping[str, NDArray[Any]]
    faults: dict[str, int]

    def __getitem__(self, name: str) -> NDArray[Any]:
        """The series of the estimate's field `name` (e.g. ``track['mass']``)."""
        return self.series[name]


def record_track(
    t: NDArray[np.float64], kind: type, rows: Sequence[Any], faults: Mapping[str, int]
) -> Track:
    """The `Track` of `rows`, the estimates (dataclasses of type `kind`) at the stamps `t`."""
    names = [f.name for f in dataclasses.fields(kind)]
    series = {name: np.asarray([getattr(row, name) for row in rows]) for name in names}
    if not rows:  # no stamp: empty arrays of the fields' kinds
        series = {name: np.zeros(0) for name in names}
    return Track(t, series, dict(faults))
