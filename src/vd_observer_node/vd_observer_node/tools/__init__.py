"""Offline tools built on the core: `replay` (the cascade and monitor over a bag), `report`
(metrics and figures against the truth) and `cli` (the `vd` command).
"""

__all__: list[str] = []
