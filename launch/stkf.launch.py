"""Start the STKF thermal-drift estimator (stkf_node, node stkf_drift_estimator).

    ros2 launch gyro_thermal_comp stkf.launch.py namespace:=robot1 imu_raw:=/vehicle/imu/data_raw \
        params_file:=/etc/robot/stkf.yaml state_file:=/var/lib/robot/stkf_state.json

Defaults: the package's config/stkf.yaml, topics relative to the namespace (REP 145 names). Only the
arguments given on the command line reach the node: `state_file` and `use_sim_time` left out keep
the params file's values, and a remap left out keeps the topic's own name.
"""
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare

ARGUMENTS = {   # name: (default, description); '' = not given: the params file (or the node) decides
    'namespace': ('', 'namespace of the node and its relative topics'),
    'params_file': (None, 'parameters (default: the package config/stkf.yaml)'),
    'state_file': ('', "where the learned model is kept across restarts (not given: the params file's)"),
    'use_sim_time': ('', "follow /clock (bag replay): true or false (not given: the params file's, else false)"),
    'imu_raw': ('', 'input sensor_msgs/Imu, raw rates (rad/s) and specific force (m/s^2) (default imu/data_raw)'),
    'mag': ('', 'input sensor_msgs/MagneticField (T) (default imu/mag)'),
    'temperature': ('', 'input sensor_msgs/Temperature of the gyro (degC) (default imu/temperature)'),
    'imu_out': ('', 'output sensor_msgs/Imu, drift-compensated (default imu/data)'),
    'log_level': ('', 'ROS log level (default info)'),
}
PARAMETERS = ('state_file', 'use_sim_time')   # launch arguments that set a parameter of the same name
REMAPS = {'imu_raw': 'imu/data_raw', 'mag': 'imu/mag', 'temperature': 'imu/temperature', 'imu_out': 'imu/data'}


def _node(context):
    given = {name: value for name, value in context.launch_configurations.items() if name in ARGUMENTS and value != ''}
    overrides = {name: given[name] for name in PARAMETERS if name in given}
    if 'use_sim_time' in overrides:
        overrides['use_sim_time'] = overrides['use_sim_time'].lower() in ('true', '1', 'yes')
    return [Node(
        package='gyro_thermal_comp', executable='stkf_node', name='stkf_drift_estimator',
        namespace=given.get('namespace', ''), output='screen',
        parameters=[given['params_file']] + ([overrides] if overrides else []),
        remappings=[(topic, given[arg]) for arg, topic in REMAPS.items() if arg in given],
        ros_arguments=['--log-level', given['log_level']] if 'log_level' in given else [])]


def generate_launch_description():
    default_params = PathJoinSubstitution([FindPackageShare('gyro_thermal_comp'), 'config', 'stkf.yaml'])
    args = [DeclareLaunchArgument(name, default_value=default_params if default is None else default,
                                  description=text) for name, (default, text) in ARGUMENTS.items()]
    return LaunchDescription([*args, OpaqueFunction(function=_node)])
