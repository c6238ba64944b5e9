"""Start the STKF thermal-drift estimator (stkf_node, node stkf_drift_estimator).

    ros2 launch gyro_thermal_comp stkf.launch.py namespace:=robot1 imu_raw:=/vehicle/imu/data_raw \
        params_file:=/etc/robot/stkf.yaml state_file:=/var/lib/robot/stkf_state.json

Defaults: the package's config/stkf.yaml, topics relative to the namespace (REP 145 names).
"""
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare

ARGUMENTS = {   # name: (default, description)
    'namespace': ('', 'namespace of the node and its relative topics'),
    'params_file': (None, 'parameters (default: the package config/stkf.yaml)'),
    'state_file': ('', 'where the learned model is kept across restarts (empty: none)'),
    'use_sim_time': ('false', 'follow /clock (bag replay)'),
    'imu_raw': ('imu/data_raw', 'input sensor_msgs/Imu, raw rates (rad/s) and specific force (m/s^2)'),
    'mag': ('imu/mag', 'input sensor_msgs/MagneticField (T)'),
    'temperature': ('imu/temperature', 'input sensor_msgs/Temperature of the gyro (degC)'),
    'imu_out': ('imu/data', 'output sensor_msgs/Imu, drift-compensated'),
    'log_level': ('info', 'ROS log level'),
}


def generate_launch_description():
    default_params = PathJoinSubstitution([FindPackageShare('gyro_thermal_comp'), 'config', 'stkf.yaml'])
    args = [DeclareLaunchArgument(name, default_value=default_params if default is None else default,
                                  description=text) for name, (default, text) in ARGUMENTS.items()]
    arg = LaunchConfiguration
    node = Node(
        package='gyro_thermal_comp', executable='stkf_node', name='stkf_drift_estimator',
        namespace=arg('namespace'), output='screen',
        parameters=[arg('params_file'), {'use_sim_time': arg('use_sim_time'), 'state_file': arg('state_file')}],
        remappings=[('imu/data_raw', arg('imu_raw')), ('imu/mag', arg('mag')),
                    ('imu/temperature', arg('temperature')), ('imu/data', arg('imu_out'))],
        ros_arguments=['--log-level', arg('log_level')])
    return LaunchDescription([*args, node])
