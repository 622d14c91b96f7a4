"""Renault Clio RL 1.1 longitudinal/pitch vehicle model on the bond-graph core.

Sub-modules, one concept each:

* :mod:`.params` -- parameter dataclasses and the validating YAML loader,
* :mod:`.tire` -- Pacejka Magic Formula (MF 5.2 style) pure longitudinal slip,
* :mod:`.powertrain` -- engine map, idle governor, launch clutch, shift logic, brakes,
* :mod:`.resistances` -- rolling resistance (paper eq. 7) and aerodynamic drag,
* :mod:`.laws` -- the same laws specialised as fast bond-graph callables,
* :mod:`.scenario` -- piecewise-in-time driver and road inputs, sensor settings,
* :mod:`.sensors` -- quantised encoders and noisy speed sensor,
* :mod:`.model` -- the assembly of all of the above as a bond graph,
* :mod:`.simulation` -- :func:`simulate` and the incremental :class:`Simulator`.
"""

from __future__ import annotations

__all__: list[str] = []
