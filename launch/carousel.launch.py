"""Start the carousel demodulator (carousel_node, node carousel_demodulator).

    ros2 launch gyro_thermal_comp carousel.launch.py config:=carousel_wheel.yaml namespace:=wheel_fl

`config` picks a file of the package's config/ (carousel.yaml: turntable with encoder;
carousel_wheel.yaml: non-steered wheel); `params_file` overrides it with a path of your own. Only
the arguments given on the command line reach the node: `use_sim_time` left out keeps the params
file's value, and a remap left out keeps the topic's own name.
"""
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare

ARGUMENTS = {   # name: (default, description); '' = not given: the params file (or the node) decides
    'namespace': ('', 'namespace of the node and its relative topics'),
    'config': ('carousel.yaml', 'a parameters file of the package config/ (carousel.yaml, carousel_wheel.yaml)'),
    'params_file': (None, 'parameters file path (default: the package config/<config>)'),
    'use_sim_time': ('', "follow /clock (bag replay): true or false (not given: the params file's, else false)"),
    'imu_raw': ('', 'input sensor_msgs/Imu of the spinning IMU (default imu/data_raw)'),
    'joint_states': ('', 'input sensor_msgs/JointState, the platform angle (encoder) (default carousel/joint_states)'),
    'imu_out': ('', 'output sensor_msgs/Imu, body-frame rates at the revolution rate (default imu/demodulated)'),
    'log_level': ('', 'ROS log level (default info)'),
}
REMAPS = {'imu_raw': 'imu/data_raw', 'joint_states': 'carousel/joint_states', 'imu_out': 'imu/demodulated'}


def _node(context):
    given = {name: value for name, value in context.launch_configurations.items() if name in ARGUMENTS and value != ''}
    overrides = {}
    if 'use_sim_time' in given:
        overrides['use_sim_time'] = given['use_sim_time'].lower() in ('true', '1', 'yes')
    return [Node(
        package='gyro_thermal_comp', executable='carousel_node', name='carousel_demodulator',
        namespace=given.get('namespace', ''), output='screen',
        parameters=[given['params_file']] + ([overrides] if overrides else []),
        remappings=[(topic, given[arg]) for arg, topic in REMAPS.items() if arg in given],
        ros_arguments=['--log-level', given['log_level']] if 'log_level' in given else [])]


def generate_launch_description():
    share = FindPackageShare('gyro_thermal_comp')
    default_params = PathJoinSubstitution([share, 'config', LaunchConfiguration('config')])
    args = [DeclareLaunchArgument(name, default_value=default_params if default is None else default,
                                  description=text) for name, (default, text) in ARGUMENTS.items()]
    return LaunchDescription([*args, OpaqueFunction(function=_node)])
