"""Online observers and estimators of wheel states, tire forces, friction and road slope.

One folder per job, imported top-down (nothing imports upwards):

- `estimation/`: Levant differentiators, wheel and speed observers, the estimator of Fx, Fz,
  μ, slip, rolling resistance, aero drag and slope (pure formulas in `formulas`), filters,
  stamp alignment, fault counting, the offline cascade, the estimator's vehicle parameters.
- `situation/`: the situation monitor (alerts and the road's friction potential).
- `chain`: estimation and situation per stamp (what `pipeline_node` runs).
- `kernel/`: the compiled (numba) twins of estimation, situation and chain.
- `bag/`: rosbag2 MCAP files and CDR encoding (a leaf: it imports none of the above).
- `tools/`: offline replay, the report and the `vd` command line.
- `testing/`: synthetic drives and bags, the development bag, the graph launcher.
- `nodes/`: the thin ROS 2 nodes (with `raw_io`, `node_params`, `entry_points`), the only
  modules that import rclpy.

What the simulator shares (topic names, the vehicle file and its parser, the tyre model, the
node plumbing) comes from vd_common; this package never imports the simulator.
"""

__all__: list[str] = []
