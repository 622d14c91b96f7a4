"""The simulator alone: sensors, truth and /clock of a scenario.

ros2 launch vd_sim_node sim.launch.py scenario:=braking_low_mu real_time_factor:=1.0
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description() -> LaunchDescription:
    config = os.path.join(get_package_share_directory('vd_sim_node'), 'config', 'sim_node.yaml')
    return LaunchDescription(
        [
            DeclareLaunchArgument('scenario', default_value='paper_table1'),
            DeclareLaunchArgument('real_time_factor', default_value='1.0'),
            DeclareLaunchArgument('rate_hz', default_value='1000.0'),
            Node(
                package='vd_sim_node',
                executable='sim_node',
                parameters=[
                    config,
                    {
                        'scenario_file': LaunchConfiguration('scenario'),
                        'real_time_factor': LaunchConfiguration('real_time_factor'),
                        'rate_hz': LaunchConfiguration('rate_hz'),
                    },
                ],
                output='screen',
            ),
        ]
    )
