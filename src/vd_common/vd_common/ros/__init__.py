"""ROS 2 plumbing shared by every vd node, one module a concern: `qos`, `stamps`,
`parameters`, `diagnostics`, `publishing`, `lifecycle`.

vd_common is the base package of the stack: the simulator's node and the estimator's nodes
import these modules rather than repeating them. Nothing here computes anything physical: that
stays in the ROS-free cores. These are the only modules of vd_common that import rclpy.
"""
