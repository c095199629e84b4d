"""Start the simulator and the actuator (full ROS 2 install: ``ros2 launch micro_feeder micro_feeder.launch.py``).

Arguments: ``params_file`` (default: the package's config/feeder.yaml), ``real_time_factor`` (1.0),
``start_paused`` (false), ``auto_start`` (true), ``namespace`` ('' = root; give each feeder of a graph its
own, docs/interface.md). Both nodes read the same parameters file.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue

from launch import LaunchDescription


def generate_launch_description() -> LaunchDescription:
    default_params = os.path.join(get_package_share_directory('micro_feeder'), 'config', 'feeder.yaml')
    params_file = LaunchConfiguration('params_file')
    return LaunchDescription([
        DeclareLaunchArgument('params_file', default_value=default_params,
                              description='ROS 2 parameters file for both nodes'),
        DeclareLaunchArgument('real_time_factor', default_value='1.0',
                              description='sim seconds per wall second; 0 = as fast as possible'),
        DeclareLaunchArgument('start_paused', default_value='false',
                              description='start paused (simulator/step, simulator/pause)'),
        DeclareLaunchArgument('auto_start', default_value='true',
                              description='actuator sends the burst once the simulator is connected'),
        DeclareLaunchArgument('namespace', default_value='',
                              description='namespace of this feeder (only the root one publishes /clock)'),
        Node(package='micro_feeder', executable='simulator', name='simulator', output='screen',
             namespace=LaunchConfiguration('namespace'),
             parameters=[params_file, {
                 'real_time_factor': ParameterValue(LaunchConfiguration('real_time_factor'), value_type=float),
                 'start_paused': ParameterValue(LaunchConfiguration('start_paused'), value_type=bool)}]),
        Node(package='micro_feeder', executable='actuator', name='actuator', output='screen',
             namespace=LaunchConfiguration('namespace'),
             parameters=[params_file, {
                 'auto_start': ParameterValue(LaunchConfiguration('auto_start'), value_type=bool)}]),
    ])
