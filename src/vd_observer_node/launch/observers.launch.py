"""Observer and estimator nodes, e.g. beside your own sensor drivers or `ros2 bag play`.

    ros2 launch vd_observer_node observers.launch.py use_sim_time:=true

Parameters come from this package's config/observer_node.yaml and estimator_node.yaml.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description() -> LaunchDescription:
    config = os.path.join(get_package_share_directory('vd_observer_node'), 'config')
    use_sim_time = LaunchConfiguration('use_sim_time')
    return LaunchDescription(
        [
            DeclareLaunchArgument('use_sim_time', default_value='false'),
            Node(
                package='vd_observer_node',
                executable='observer_node',
                parameters=[
                    os.path.join(config, 'observer_node.yaml'),
                    {'use_sim_time': use_sim_time},
                ],
                output='screen',
            ),
            Node(
                package='vd_observer_node',
                executable='estimator_node',
                parameters=[
                    os.path.join(config, 'estimator_node.yaml'),
                    {'use_sim_time': use_sim_time},
                ],
                output='screen',
            ),
        ]
    )
