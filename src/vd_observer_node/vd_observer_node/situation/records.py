"""Named-field records: the typed state and settings the situation's step functions take.

A record is one element of a numpy structured dtype (``np.record``): its fields are read and
written by name, as attributes, in plain Python and in numba-compiled code alike, so the step
functions need no positional slot tables. Array fields (``('count', 'f8', (2,))``) are views
into the record and can be written in place.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ['new_record', 'record_of']


def new_record(dtype: np.dtype[Any]) -> Any:
    """A zeroed record of `dtype` (an ``np.record``)."""
    return np.zeros(1, dtype).view(np.recarray)[0]


def record_of(dtype: np.dtype[Any], source: object) -> Any:
    """A record of `dtype` whose every field is the same-named attribute of `source` (a
    settings dataclass)."""
    rec = new_record(dtype)
    for name in dtype.names or ():
        setattr(rec, name, getattr(source, name))
    return rec
