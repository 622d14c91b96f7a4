"""The situation monitor: traction, lock and low-friction alerts and the road's friction
potential (μ_max per axle), per stamp (`monitor.SituationMonitor`) or over a whole record
(`monitor.run_situation`). ROS-free; see docs/alerts.md.
"""

__all__: list[str] = []
