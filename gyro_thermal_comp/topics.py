"""Topic names and frame ids shared by bags, nodes and the CLI (docs/design.md section 4).

Node topics are relative (remappable); bags record them under the root namespace. Diagnostics are
absolute, as diagnostic_updater publishes them: the aggregator reads `/diagnostics` whatever the
node's namespace.
"""
IMU_RAW = 'imu/data_raw'
MAG = 'imu/mag'
TEMPERATURE = 'imu/temperature'
JOINT_STATES = 'carousel/joint_states'
IMU_AUX_RAW = 'imu_aux/data_raw'
IMU_COMPENSATED = 'imu/data'
HEADING = 'imu/heading'
IMU_DEMODULATED = 'imu/demodulated'
CAROUSEL_GYRO_BIAS = 'carousel/gyro_bias'
CAROUSEL_GYRO_BIAS_SIGMA = 'carousel/gyro_bias_sigma'
DIAGNOSTICS = '/diagnostics'
TF = '/tf'
GROUND_TRUTH_ODOM = '/ground_truth/odom'
GROUND_TRUTH_GYRO_BIAS = '/ground_truth/gyro_bias'
GROUND_TRUTH_MAG_DISTURBANCE = '/ground_truth/mag_disturbance'
SIM_CONFIG = '/sim/config'
IMPORT_SOURCE = '/import/source'   # an imported record's provenance (JSON), sources/importer.py

# SensorChunk field -> (bag topic, ROS message type)
BAG_STREAMS = {
    'imu': ('/' + IMU_RAW, 'sensor_msgs/msg/Imu'),
    'mag': ('/' + MAG, 'sensor_msgs/msg/MagneticField'),
    'temperature': ('/' + TEMPERATURE, 'sensor_msgs/msg/Temperature'),
    'joint': ('/' + JOINT_STATES, 'sensor_msgs/msg/JointState'),
    'imu_aux': ('/' + IMU_AUX_RAW, 'sensor_msgs/msg/Imu'),
    'odom': (GROUND_TRUTH_ODOM, 'nav_msgs/msg/Odometry'),
    'gyro_bias': (GROUND_TRUTH_GYRO_BIAS, 'geometry_msgs/msg/Vector3Stamped'),
    'mag_disturbance': (GROUND_TRUTH_MAG_DISTURBANCE, 'geometry_msgs/msg/Vector3Stamped'),
}

IMU_FRAME = 'imu_link'
BODY_FRAME = 'base_link'
ODOM_FRAME = 'odom'
CAROUSEL_JOINT = 'carousel_joint'
