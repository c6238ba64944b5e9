"""Start the carousel demodulator (carousel_node, node carousel_demodulator).

    ros2 launch gyro_thermal_comp carousel.launch.py config:=carousel_wheel.yaml namespace:=wheel_fl

`config` picks a file of the package's config/ (carousel.yaml: turntable with encoder;
carousel_wheel.yaml: non-steered wheel); `params_file` overrides it with a path of your own.
"""
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare

ARGUMENTS = {   # name: (default, description)
    'namespace': ('', 'namespace of the node and its relative topics'),
    'config': ('carousel.yaml', 'a parameters file of the package config/ (carousel.yaml, carousel_wheel.yaml)'),
    'params_file': (None, 'parameters file path (default: the package config/<config>)'),
    'use_sim_time': ('false', 'follow /clock (bag replay)'),
    'imu_raw': ('imu/data_raw', 'input sensor_msgs/Imu of the spinning IMU'),
    'joint_states': ('carousel/joint_states', 'input sensor_msgs/JointState, the platform angle (encoder)'),
    'imu_out': ('imu/demodulated', 'output sensor_msgs/Imu, body-frame rates at the revolution rate'),
    'log_level': ('info', 'ROS log level'),
}


def generate_launch_description():
    share = FindPackageShare('gyro_thermal_comp')
    default_params = PathJoinSubstitution([share, 'config', LaunchConfiguration('config')])
    args = [DeclareLaunchArgument(name, default_value=default_params if default is None else default,
                                  description=text) for name, (default, text) in ARGUMENTS.items()]
    arg = LaunchConfiguration
    node = Node(
        package='gyro_thermal_comp', executable='carousel_node', name='carousel_demodulator',
        namespace=arg('namespace'), output='screen',
        parameters=[arg('params_file'), {'use_sim_time': arg('use_sim_time')}],
        remappings=[('imu/data_raw', arg('imu_raw')), ('carousel/joint_states', arg('joint_states')),
                    ('imu/demodulated', arg('imu_out'))],
        ros_arguments=['--log-level', arg('log_level')])
    return LaunchDescription([*args, node])
