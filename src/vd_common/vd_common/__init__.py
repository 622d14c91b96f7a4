"""What the vd simulator (vd_sim_node) and the estimator (vd_observer_node) both need.

- `topics`: the topic contract, every ``/vd/...`` name and its message type.
- `errors`: `VdError`, the base of every vd error, and `ParameterError` (vehicle file).
- `vehicle/`: the vehicle-file parser (`vehicle.params`, with the default file,
  ``config/clio_rl_1_1.yaml``), the Magic Formula tyre (`vehicle.tire`) and its friction
  peak and road classes (`vehicle.friction`).
- `yaml_reader`: typed, range-checked reading of YAML mappings (the vehicle and scenario
  parsers).
- `params_file`, `entry`: the ROS-free half of the node plumbing (``--params-file`` check,
  the console-script guard).
- `ros`: the ROS 2 node plumbing, a module a concern (`qos`, `stamps`, `parameters`,
  `diagnostics`, `publishing`, `lifecycle` with `run_node`), the only modules here built on
  rclpy.

Nothing here imports vd_sim_node or vd_observer_node: both are built on this package.
"""

__all__: list[str] = []
