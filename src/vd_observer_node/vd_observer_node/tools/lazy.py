"""A package's names imported on first use (PEP 562), so a command that only needs a package's
command-line parser (``vd --help``, ``vd bag info``) does not import all of its modules."""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping

__all__ = ['lazy_exports']


def lazy_exports(package: str, exports: Mapping[str, str]) -> Callable[[str], object]:
    """A module ``__getattr__`` for `package` that imports each exported name from its module.

    Args:
        package: the package's ``__name__``.
        exports: exported name -> the submodule (relative to `package`) that defines it. A name
            must not be a submodule's too: importing that submodule would set the package's
            attribute to the module.

    Returns:
        The ``__getattr__``: the name's value (kept in the package's namespace after the
        first use); AttributeError for a name it does not export.
    """

    def lookup(name: str) -> object:
        module = exports.get(name)
        if module is None:
            raise AttributeError(f'module {package!r} has no attribute {name!r}')
        value = getattr(importlib.import_module(f'{package}.{module}'), name)
        setattr(importlib.import_module(package), name, value)
        return value

    return lookup
