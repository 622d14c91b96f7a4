"""Test and demo helpers that ship with the package: synthetic drives (`synthetic`) and bags
(`synthetic_bags`), the report's development bag (`devbag`) and the graph launcher that
starts nodes through the ament index as `ros2 run` does (`launcher`, used by `make demo`).
"""

__all__: list[str] = []
