"""Bond-graph simulator of a Renault Clio RL 1.1 (ROS-free core plus a thin ROS 2 node)."""

__all__: list[str] = []
