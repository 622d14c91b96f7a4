"""Named-field records: the typed state and settings the situation's step functions take.

A record is one element of a numpy structured dtype (``np.record``): its fields are read and
written by name, as attributes, in plain Python and in numba-compiled code alike, so the step
functions need no positional slot tables. Array fields (``('count', 'f8', (2,))``) are views
into the record and can be written in place.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from vd_observer_node.kernel._jit import new_record

__all__ = ['record_of']


def record_of(dtype: np.dtype[Any], source: object) -> Any:
    """A record of `dtype` whose every field is the same-named attribute of `source` (a
    settings dataclass)."""
    rec = new_record(dtype)
    for name in dtype.names or ():
        setattr(rec, name, getattr(source, name))
    return rec
