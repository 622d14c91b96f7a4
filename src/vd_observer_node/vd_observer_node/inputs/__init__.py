"""Inputs: a user's topics and message types mapped to the cascade's three inputs.

`mapping` reads and checks an input mapping (YAML or a dict); `decode` turns one mapped
topic's raw CDR messages into stamped SI arrays. ROS-free; see docs/input_mapping.md.
"""

__all__: list[str] = []
