"""The thin ROS 2 nodes: the only modules of vd_observer_node that import rclpy.

One module per node (``observer_node``, ``estimator_node``, ``alerts_node``,
``pipeline_node``, ``recorder_node``, ``player_node``), each mapping parameters to the core's
configuration and messages to arrays, and their helpers: `node_params` (the declared
parameters), `raw_io` (CDR bytes in, stamp matching, bytes out; ROS-free) and `entry_points`
(the console scripts: ``ros2 run vd_observer_node observer_node`` and so on). The ROS
plumbing they share with the simulator's node is ``vd_common.ros``.
"""

__all__: list[str] = []
