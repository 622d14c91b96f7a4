"""numba's njit with the project's settings, typed so mypy --strict keeps the signatures."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar, cast

import numba

__all__ = ['jit']

F = TypeVar('F', bound=Callable[..., Any])


def jit(fn: F) -> F:
    """Compile `fn` in nopython mode, cached on disk (numba's cache=True), no fastmath.

    No fastmath: it would change NaN handling and the last bits the equality tests against
    the Python reference rely on. nogil: offline tools may run kernels in threads.
    """
    return cast(F, numba.njit(cache=True, nogil=True)(fn))
