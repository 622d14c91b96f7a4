"""Online observers and estimators of wheel states, tire forces, friction and road slope.

The core modules are ROS-free (numpy only): `differentiator`, `vehicle`, `estimators`,
`cascade`, `alignment`. Only the `*_node.py` files import rclpy.
"""

__all__: list[str] = []
