"""rclpy message <-> numbers, for the nodes. Kept apart so node code reads as plumbing only.

Output messages follow REP 145: covariances filled from the noise model (never -1 where a value is
estimated), orientation in ENU (REP 103), same header (stamp, frame_id) as the input sample.
"""
from __future__ import annotations

import math

import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import QuaternionStamped
from sensor_msgs.msg import Imu

from ..angles import quat_from_euler


def stamp_s(stamp) -> float:
    return stamp.sec + stamp.nanosec * 1e-9


def time_msg(t_s: float) -> Time:
    ns = int(round(t_s * 1e9))
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def imu_row(msg: Imu) -> tuple[float, list[float]]:
    g, a = msg.angular_velocity, msg.linear_acceleration
    return stamp_s(msg.header.stamp), [g.x, g.y, g.z, a.x, a.y, a.z]


def mag_row(msg) -> tuple[float, list[float]]:
    m = msg.magnetic_field
    return stamp_s(msg.header.stamp), [m.x, m.y, m.z]


def temperature_row(msg) -> tuple[float, list[float]]:
    return stamp_s(msg.header.stamp), [msg.temperature]


def diag3(variances) -> list[float]:
    v = np.broadcast_to(np.asarray(variances, dtype=float), 3)
    return [float(v[0]), 0.0, 0.0, 0.0, float(v[1]), 0.0, 0.0, 0.0, float(v[2])]


NO_ORIENTATION = [-1.0] + [0.0] * 8  # REP 145: element 0 = -1, no orientation estimate


def imu_msg(header, gyro, accel, *, gyro_var=None, accel_var=None, orientation=None, orientation_var=None) -> Imu:
    """An Imu message; a covariance left None stays all zero ("unknown"), no `orientation` (x, y, z, w)
    marks the orientation as not provided."""
    msg = Imu(header=header)
    msg.angular_velocity.x, msg.angular_velocity.y, msg.angular_velocity.z = map(float, gyro)
    msg.linear_acceleration.x, msg.linear_acceleration.y, msg.linear_acceleration.z = map(float, accel)
    if orientation is None:
        msg.orientation_covariance = NO_ORIENTATION
    else:
        msg.orientation.x, msg.orientation.y, msg.orientation.z, msg.orientation.w = map(float, orientation)
        if orientation_var is not None:
            msg.orientation_covariance = diag3(orientation_var)
    if gyro_var is not None:
        msg.angular_velocity_covariance = diag3(gyro_var)
    if accel_var is not None:
        msg.linear_acceleration_covariance = diag3(accel_var)
    return msg


def compensated_imu(header, gyro, accel, roll, pitch, yaw, *, gyro_var, accel_var, tilt_var, heading_var) -> Imu:
    """The bias-compensated Imu: rates minus drift, orientation = roll/pitch from gravity + heading."""
    return imu_msg(header, gyro, accel, gyro_var=gyro_var, accel_var=accel_var,
                   orientation=quat_from_euler(roll, pitch, yaw), orientation_var=[tilt_var, tilt_var, heading_var])


def heading_msg(header, yaw_rad: float) -> QuaternionStamped:
    msg = QuaternionStamped(header=header)
    q = quat_from_euler(0.0, 0.0, yaw_rad)
    msg.quaternion.x, msg.quaternion.y, msg.quaternion.z, msg.quaternion.w = map(float, q)
    return msg


def _kv(key: str, value) -> KeyValue:
    if isinstance(value, float):
        value = 'nan' if not math.isfinite(value) else f'{value:.9g}'
    return KeyValue(key=key, value=str(value))


def diagnostic_array(stamp, name: str, hardware_id: str, level: int, message: str, values: dict) -> DiagnosticArray:
    level = level if isinstance(level, bytes) else bytes([level])  # the constants are bytes already
    status = DiagnosticStatus(level=level, name=name, message=message, hardware_id=hardware_id,
                              values=[_kv(k, v) for k, v in values.items()])
    return DiagnosticArray(header=_header_at(stamp), status=[status])


def _header_at(stamp):
    from std_msgs.msg import Header
    return Header(stamp=stamp)
