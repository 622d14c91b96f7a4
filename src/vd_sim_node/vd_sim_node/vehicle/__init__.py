"""Renault Clio RL 1.1 longitudinal/pitch vehicle model on the bond-graph core.

The parameters (``vd_common.vehicle.params``) and the Magic Formula tyre
(``vd_common.vehicle.tire``) are shared with the estimator and live in vd_common. Sub-modules,
one concept each:

* :mod:`.powertrain` -- engine map, idle governor, launch clutch, shift logic, brakes,
* :mod:`.resistances` -- rolling resistance (paper eq. 7) and aerodynamic drag,
* :mod:`.laws` -- the same laws specialised as fast bond-graph callables,
* :mod:`.scenario` -- piecewise-in-time driver and road inputs, sensor settings,
* :mod:`.sensors` -- quantised encoders and noisy speed sensor,
* :mod:`.model` -- the assembly of all of the above as a bond graph,
* :mod:`.friction_truth` -- the true friction potential of the simulated tyre,
* :mod:`.variants` -- the true vehicle of a scenario (load, tyre radius, torque offset),
* :mod:`.simulation` -- :func:`simulate` and the incremental :class:`Simulator`.
"""

from __future__ import annotations

__all__: list[str] = []
