"""ROS 2 sensor messages <-> samples: what the bag reader and writer build, encode and decode.

Samples -> messages: per SensorChunk stream a builder of rosbags message objects (`BUILDERS`), and
for the fixed-layout types Imu, MagneticField and Temperature an encoder straight to CDR bytes as
arrays (`ENCODERS`, cdr.py) that gives the same bytes as the builders. Messages -> samples: per
stream a row extractor and the message types it accepts (`READERS`), the fields cdr.decode gives for
the fixed-layout types (`FAST`), and the conversion of rows to the stream's samples. Message types
come from rosbags' ROS 2 Jazzy typestore.

Time: float times are seconds since a time origin (stamps.py), never since 1970; builders take the
origin in integer ns since 1970 and rows carry header stamps as seconds since the origin they are
given.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import cdr, topics
from .cdr import TYPESTORE
from .samples import ImuSamples, JointSamples, MagSamples, PoseSamples, TemperatureSamples, VectorSamples
from .stamps import NS_PER_S, ns_at, seconds_since

_T = TYPESTORE.types
_Time, _Header = _T['builtin_interfaces/msg/Time'], _T['std_msgs/msg/Header']
_Vec3, _Quat = _T['geometry_msgs/msg/Vector3'], _T['geometry_msgs/msg/Quaternion']
_Point = _T['geometry_msgs/msg/Point']

NO_ORIENTATION_COV = np.array([-1.0] + [0.0] * 8)  # REP 145 / sensor_msgs: orientation not provided
_ZERO9, _ZERO36 = np.zeros(9), np.zeros(36)


def stamp_to_ns(t_s: float, origin_ns: int = 0) -> int:
    """Seconds since `origin_ns` -> integer nanoseconds since 1970, rounded so k/rate stamps round-trip."""
    return ns_at(t_s, origin_ns)


def _header(t_ns: int, frame_id: str):
    return _Header(stamp=_Time(sec=t_ns // NS_PER_S, nanosec=t_ns % NS_PER_S), frame_id=frame_id)


def header_stamp_s(header, origin_ns: int) -> float:
    """A message header's stamp in s since `origin_ns` (ns since 1970)."""
    return seconds_since(header.stamp.sec * NS_PER_S + header.stamp.nanosec, origin_ns)


def _diag_cov(variances) -> np.ndarray:
    """Per-axis variances -> row-major 3x3 covariance; None means unknown (all zeros, per sensor_msgs)."""
    return _ZERO9 if variances is None else np.diag(np.broadcast_to(np.asarray(variances, float), 3)).ravel()


@dataclass
class Covariances:
    """Noise variances written into raw sensor messages (None = unknown: zeros, as sensor_msgs says)."""
    gyro_rad2_s2: object = None       # per-axis variance of one gyro sample, (rad/s)^2
    accel_m2_s4: object = None        # per-axis variance of one accel sample, (m/s^2)^2
    mag_t2: object = None             # per-axis variance of one magnetometer sample, T^2
    temperature_c2: float = 0.0       # variance of one temperature reading, degC^2


# ---------------------------------------------------------------- samples -> messages
# Builders: (samples, frame id, covariances, origin ns) -> (log time ns, message) per sample, stamp = log time.
def imu_msgs(s: ImuSamples, frame_id: str, cov: Covariances, origin_ns: int = 0):
    gcov, acov = _diag_cov(cov.gyro_rad2_s2), _diag_cov(cov.accel_m2_s4)
    Imu, quat0 = _T['sensor_msgs/msg/Imu'], _Quat(x=0.0, y=0.0, z=0.0, w=1.0)
    for t_ns, g, a in zip(_ns(s.t, origin_ns), s.gyro.tolist(), s.accel.tolist()):
        yield t_ns, Imu(header=_header(t_ns, frame_id), orientation=quat0, orientation_covariance=NO_ORIENTATION_COV,
                        angular_velocity=_Vec3(x=g[0], y=g[1], z=g[2]), angular_velocity_covariance=gcov,
                        linear_acceleration=_Vec3(x=a[0], y=a[1], z=a[2]), linear_acceleration_covariance=acov)


def mag_msgs(s: MagSamples, frame_id: str, cov: Covariances, origin_ns: int = 0):
    Mag, mcov = _T['sensor_msgs/msg/MagneticField'], _diag_cov(cov.mag_t2)
    for t_ns, m in zip(_ns(s.t, origin_ns), s.field.tolist()):
        yield t_ns, Mag(header=_header(t_ns, frame_id), magnetic_field=_Vec3(x=m[0], y=m[1], z=m[2]),
                        magnetic_field_covariance=mcov)


def temperature_msgs(s: TemperatureSamples, frame_id: str, cov: Covariances, origin_ns: int = 0):
    Temp = _T['sensor_msgs/msg/Temperature']
    for t_ns, temp in zip(_ns(s.t, origin_ns), s.temp_c.tolist()):
        yield t_ns, Temp(header=_header(t_ns, frame_id), temperature=temp, variance=float(cov.temperature_c2))


def odom_msgs(s: PoseSamples, frame_id: str, cov: Covariances, origin_ns: int = 0):
    T = _T
    Odom = T['nav_msgs/msg/Odometry']
    PwC, TwC = T['geometry_msgs/msg/PoseWithCovariance'], T['geometry_msgs/msg/TwistWithCovariance']
    Pose, Twist = T['geometry_msgs/msg/Pose'], T['geometry_msgs/msg/Twist']
    for t_ns, q, p, v, w in zip(_ns(s.t, origin_ns), s.quat.tolist(), s.position.tolist(),
                                s.velocity_body.tolist(), s.rate_body.tolist()):
        pose = Pose(position=_Point(x=p[0], y=p[1], z=p[2]), orientation=_Quat(x=q[0], y=q[1], z=q[2], w=q[3]))
        twist = Twist(linear=_Vec3(x=v[0], y=v[1], z=v[2]), angular=_Vec3(x=w[0], y=w[1], z=w[2]))
        yield t_ns, Odom(header=_header(t_ns, topics.ODOM_FRAME), child_frame_id=topics.BODY_FRAME,
                         pose=PwC(pose=pose, covariance=_ZERO36), twist=TwC(twist=twist, covariance=_ZERO36))


def vector_msgs(s: VectorSamples, frame_id: str, cov: Covariances, origin_ns: int = 0):
    V3S = _T['geometry_msgs/msg/Vector3Stamped']
    for t_ns, v in zip(_ns(s.t, origin_ns), s.vec.tolist()):
        yield t_ns, V3S(header=_header(t_ns, frame_id), vector=_Vec3(x=v[0], y=v[1], z=v[2]))


def joint_msgs(s: JointSamples, frame_id: str, cov: Covariances, origin_ns: int = 0):
    JS, empty = _T['sensor_msgs/msg/JointState'], np.zeros(0)
    for t_ns, pos, vel in zip(_ns(s.t, origin_ns), s.position.tolist(), s.velocity.tolist()):
        yield t_ns, JS(header=_header(t_ns, frame_id), name=[topics.CAROUSEL_JOINT],
                       position=np.array([pos]), velocity=np.array([vel]), effort=empty)


def _ns(t_s: np.ndarray, origin_ns: int) -> list[int]:
    return ns_at(np.asarray(t_s), origin_ns).tolist()


# Fixed-layout streams are encoded in bulk (cdr.py): the same bytes as the builders above would give.
def _imu_cdr(s: ImuSamples, frame_id: str, cov: Covariances, t_ns: np.ndarray) -> list[bytes]:
    return cdr.encode_imu(t_ns, frame_id, orientation_covariance=NO_ORIENTATION_COV, angular_velocity=s.gyro,
                          angular_velocity_covariance=_diag_cov(cov.gyro_rad2_s2), linear_acceleration=s.accel,
                          linear_acceleration_covariance=_diag_cov(cov.accel_m2_s4))


def _mag_cdr(s: MagSamples, frame_id: str, cov: Covariances, t_ns: np.ndarray) -> list[bytes]:
    return cdr.encode_mag(t_ns, frame_id, s.field, _diag_cov(cov.mag_t2))


def _temperature_cdr(s: TemperatureSamples, frame_id: str, cov: Covariances, t_ns: np.ndarray) -> list[bytes]:
    return cdr.encode_temperature(t_ns, frame_id, s.temp_c, float(cov.temperature_c2))


ENCODERS = {'imu': _imu_cdr, 'imu_aux': _imu_cdr, 'mag': _mag_cdr, 'temperature': _temperature_cdr}


# SensorChunk field -> (message builder, frame id)
BUILDERS = {
    'imu': (imu_msgs, topics.IMU_FRAME),
    'imu_aux': (imu_msgs, topics.IMU_FRAME + '_aux'),
    'mag': (mag_msgs, topics.IMU_FRAME),
    'temperature': (temperature_msgs, topics.IMU_FRAME),
    'odom': (odom_msgs, topics.ODOM_FRAME),
    'gyro_bias': (vector_msgs, topics.IMU_FRAME),
    'mag_disturbance': (vector_msgs, topics.IMU_FRAME),
    'joint': (joint_msgs, topics.BODY_FRAME),
}


# ---------------------------------------------------------------- messages -> samples
def _imu_row(msg, origin_ns: int):
    g, a = msg.angular_velocity, msg.linear_acceleration
    return header_stamp_s(msg.header, origin_ns), g.x, g.y, g.z, a.x, a.y, a.z


def _mag_row(msg, origin_ns: int):
    m = msg.magnetic_field
    return header_stamp_s(msg.header, origin_ns), m.x, m.y, m.z


def _temperature_row(msg, origin_ns: int):
    return header_stamp_s(msg.header, origin_ns), msg.temperature


def _odom_row(msg, origin_ns: int):
    p, q = msg.pose.pose.position, msg.pose.pose.orientation
    v, w = msg.twist.twist.linear, msg.twist.twist.angular
    return header_stamp_s(msg.header, origin_ns), q.x, q.y, q.z, q.w, p.x, p.y, p.z, v.x, v.y, v.z, w.x, w.y, w.z


def _vector_row(msg, origin_ns: int):
    v = msg.vector
    return header_stamp_s(msg.header, origin_ns), v.x, v.y, v.z


def _joint_row(msg, origin_ns: int):
    if len(msg.position) == 0:
        return None
    vel = msg.velocity[0] if len(msg.velocity) else math.nan
    return header_stamp_s(msg.header, origin_ns), msg.position[0], vel


def _to_imu(a): return ImuSamples(a[:, 0], a[:, 1:4], a[:, 4:7])
def _to_mag(a): return MagSamples(a[:, 0], a[:, 1:4])
def _to_temperature(a): return TemperatureSamples(a[:, 0], a[:, 1])
def _to_odom(a): return PoseSamples(a[:, 0], a[:, 1:5], a[:, 5:8], a[:, 8:11], a[:, 11:14])
def _to_vector(a): return VectorSamples(a[:, 0], a[:, 1:4])
def _to_joint(a): return JointSamples(a[:, 0], a[:, 1], a[:, 2])


# stream -> (row extractor, accepted message types, row width, array -> samples)
READERS = {
    'imu': (_imu_row, {'sensor_msgs/msg/Imu'}, 7, _to_imu),
    'imu_aux': (_imu_row, {'sensor_msgs/msg/Imu'}, 7, _to_imu),
    'mag': (_mag_row, {'sensor_msgs/msg/MagneticField'}, 4, _to_mag),
    'temperature': (_temperature_row, {'sensor_msgs/msg/Temperature'}, 2, _to_temperature),
    'odom': (_odom_row, {'nav_msgs/msg/Odometry'}, 14, _to_odom),
    'gyro_bias': (_vector_row, {'geometry_msgs/msg/Vector3Stamped'}, 4, _to_vector),
    'mag_disturbance': (_vector_row, {'geometry_msgs/msg/Vector3Stamped'}, 4, _to_vector),
    'joint': (_joint_row, {'sensor_msgs/msg/JointState'}, 3, _to_joint),
}


def stream_msgtypes(stream: str) -> set[str]:
    """The ROS message types a stream is read from (ROS 1 and ROS 2 name them alike in rosbags)."""
    return set(READERS[stream][1])


def message_row(stream: str, msg, origin_ns: int):
    """One decoded message of `stream` as a row [t, values...] (t in s since origin_ns), or None for
    a message without a value (a JointState with no position): for readers of other bag formats."""
    return READERS[stream][0](msg, origin_ns)


def samples_from_rows(stream: str, rows) -> object:
    """Rows of `message_row` -> the stream's samples (ImuSamples, MagSamples, ...)."""
    return READERS[stream][3](np.asarray(rows, np.float64).reshape(-1, READERS[stream][2]))


# stream -> (fixed-layout type decoded in bulk by cdr.decode, its fields after the stamp, as READERS' rows)
FAST = {
    'imu': (cdr.IMU, ('angular_velocity', 'linear_acceleration')),
    'imu_aux': (cdr.IMU, ('angular_velocity', 'linear_acceleration')),
    'mag': (cdr.MAG, ('magnetic_field',)),
    'temperature': (cdr.TEMPERATURE, ('temperature',)),
}


def seconds_since_many(stamp_ns: np.ndarray, origin_ns: int) -> np.ndarray:
    """stamps.seconds_since over an array, float for float the same (whole seconds + fraction)."""
    sec, nanosec = np.divmod(np.asarray(stamp_ns, np.int64) - np.int64(origin_ns), NS_PER_S)
    return sec.astype(np.float64) + nanosec.astype(np.float64) * 1e-9

