"""The vehicle as both packages see it: its parameter file and its tyre.

* :mod:`.params` -- parameter dataclasses and the validating YAML loader,
* :mod:`.tire` -- Pacejka Magic Formula (MF 5.2 style) pure longitudinal slip,
* :mod:`.friction` -- the tyre's friction peak per load and the road classes.
"""

from __future__ import annotations

__all__: list[str] = []
