"""Estimation: wheel and speed observers (Levant differentiators) and the force, friction,
resistance and slope estimator, with their pure formulas, filters, stamp alignment and fault
counting; `cascade.run_cascade` runs them over a whole record. ROS-free (numpy; numba
compiles the per-sample step functions, e.g. `levant_step`, `torque_offset`).
"""

__all__: list[str] = []
