"""The whole vd graph on a scenario, recorded to an MCAP bag (system ROS 2 with ros2 launch).

    ros2 launch vd_observer_node demo.launch.py scenario:=paper_table1 rate_hz:=100.0 \
        real_time_factor:=1.0 bag:=vd_demo

The same graph as `make demo` (scripts/demo.py), which does not need ros2 launch. The launch
ends when the simulator finishes the scenario; the recorder then closes the bag. The simulator
runs in lockstep with the estimator, the alerts node and the recorder (nothing is lost on a
slow machine); ``lockstep_topics:=''`` paces it by the wall clock alone.
"""

from launch import LaunchDescription
from launch.actions import (
    DeclareLaunchArgument,
    EmitEvent,
    RegisterEventHandler,
    SetEnvironmentVariable,
    TimerAction,
)
from launch.event_handlers import OnProcessExit
from launch.events import Shutdown
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare
from vd_common.topics import ESTIMATES_ALERTS, ESTIMATES_SLOPE, STATUS_RECORDER_PROGRESS

LOCKSTEP_TOPICS = f'{ESTIMATES_SLOPE},{ESTIMATES_ALERTS},{STATUS_RECORDER_PROGRESS}'


def generate_launch_description() -> LaunchDescription:
    scenario = LaunchConfiguration('scenario')
    rate_hz = LaunchConfiguration('rate_hz')
    rtf = LaunchConfiguration('real_time_factor')
    bag = LaunchConfiguration('bag')
    lockstep = LaunchConfiguration('lockstep_topics')
    sim = Node(
        package='vd_sim_node',
        executable='sim_node',
        parameters=[
            {
                'scenario_file': scenario,
                'rate_hz': rate_hz,
                'real_time_factor': rtf,
                'lockstep_topics': lockstep,
            }
        ],
        output='screen',
    )
    return LaunchDescription(
        [
            DeclareLaunchArgument('scenario', default_value='paper_table1'),
            DeclareLaunchArgument('rate_hz', default_value='100.0'),
            DeclareLaunchArgument('real_time_factor', default_value='1.0'),
            DeclareLaunchArgument('bag', default_value='vd_demo'),
            DeclareLaunchArgument('lockstep_topics', default_value=LOCKSTEP_TOPICS),
            # a 50 ms heartbeat: lost messages are repaired within a lockstep pause
            # (config/fastdds_lockstep.xml says why)
            SetEnvironmentVariable(
                'FASTDDS_DEFAULT_PROFILES_FILE',
                PathJoinSubstitution(
                    [FindPackageShare('vd_observer_node'), 'config', 'fastdds_lockstep.xml']
                ),
            ),
            Node(
                package='vd_observer_node',
                executable='recorder_node',
                parameters=[{'output': bag}],
                output='screen',
            ),
            Node(package='vd_observer_node', executable='observer_node', output='screen'),
            Node(package='vd_observer_node', executable='estimator_node', output='screen'),
            Node(package='vd_observer_node', executable='alerts_node', output='screen'),
            # give the subscribers time to be discovered before the first sample
            TimerAction(period=2.0, actions=[sim]),
            RegisterEventHandler(
                OnProcessExit(
                    target_action=sim,
                    on_exit=[TimerAction(period=2.0, actions=[EmitEvent(event=Shutdown())])],
                )
            ),
        ]
    )
