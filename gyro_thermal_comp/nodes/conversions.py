"""rclpy message <-> numbers, for the nodes. Kept apart so node code reads as plumbing only.

Output messages follow REP 145: covariances filled from the noise model (never -1 where a value is
estimated), orientation in the world frame the node is set to (REP 103: ENU unless `world_frame`
is ned), same header (stamp, frame_id) as the input sample.
"""
from __future__ import annotations

import math

import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseWithCovarianceStamped, TransformStamped
from sensor_msgs.msg import Imu
from std_msgs.msg import Header

from .. import cdr
from ..stamps import NS_PER_S, TimeOrigin
from .interface import TFMessage

ABSOLUTE = TimeOrigin(0)   # seconds since 1970: for tools and tests that build stamps from small times


def stamp_s(stamp, origin: TimeOrigin = ABSOLUTE) -> float:
    """A stamp as s since `origin` (a node's: its first stamp), exact to the ns at any epoch."""
    return origin.seconds(stamp.sec * NS_PER_S + stamp.nanosec)


def time_msg(t_s: float, origin: TimeOrigin = ABSOLUTE) -> Time:
    return time_msg_ns(origin.stamp_ns(t_s))


def time_msg_ns(ns: int) -> Time:
    return Time(sec=ns // NS_PER_S, nanosec=ns % NS_PER_S)


def imu_row(msg: Imu, origin: TimeOrigin = ABSOLUTE) -> tuple[float, list[float]]:
    g, a = msg.angular_velocity, msg.linear_acceleration
    return stamp_s(msg.header.stamp, origin), [g.x, g.y, g.z, a.x, a.y, a.z]


def mag_row(msg, origin: TimeOrigin = ABSOLUTE) -> tuple[float, list[float]]:
    m = msg.magnetic_field
    return stamp_s(msg.header.stamp, origin), [m.x, m.y, m.z]


def temperature_row(msg, origin: TimeOrigin = ABSOLUTE) -> tuple[float, list[float]]:
    return stamp_s(msg.header.stamp, origin), [msg.temperature]


class InputSamples:
    """The STKF node's inputs, as a raw subscription hands them over (serialized CDR, read by
    cdr.OneMessage: rclpy's typed conversion of an Imu and its covariance arrays costs tens of us)
    or as message objects (composition, tests), as (stamp ns, frame_id, header CDR bytes, row):
    row = [gx, gy, gz rad/s, ax, ay, az m/s^2], [bx, by, bz T] or [degC]. Bytes that are no such
    message raise cdr.MalformedMessage."""

    def __init__(self):
        self._codecs = {name: cdr.OneMessage(t) for name, t in (('imu', cdr.IMU), ('mag', cdr.MAG),
                                                                 ('temperature', cdr.TEMPERATURE))}
        imu = self._codecs['imu']
        self._gyro, self._accel = imu.offset('angular_velocity'), imu.offset('linear_acceleration')
        self._field = self._codecs['mag'].offset('magnetic_field')
        self._temperature = self._codecs['temperature'].offset('temperature')

    def imu(self, msg) -> tuple[int, str, bytes, list[float]]:
        if isinstance(msg, bytes):
            ns, frame, header, v = self._codecs['imu'].decode(msg)
            return ns, frame, header, [*v[self._gyro:self._gyro + 3], *v[self._accel:self._accel + 3]]
        g, a = msg.angular_velocity, msg.linear_acceleration
        return (*_header_of(msg), [g.x, g.y, g.z, a.x, a.y, a.z])

    def mag(self, msg) -> tuple[int, str, bytes, list[float]]:
        if isinstance(msg, bytes):
            ns, frame, header, v = self._codecs['mag'].decode(msg)
            return ns, frame, header, list(v[self._field:self._field + 3])
        m = msg.magnetic_field
        return (*_header_of(msg), [m.x, m.y, m.z])

    def temperature(self, msg) -> tuple[int, str, bytes, list[float]]:
        if isinstance(msg, bytes):
            ns, frame, header, v = self._codecs['temperature'].decode(msg)
            return ns, frame, header, [v[self._temperature]]
        return (*_header_of(msg), [msg.temperature])


def _header_of(msg) -> tuple[int, str, bytes]:
    s = msg.header.stamp
    ns = s.sec * NS_PER_S + s.nanosec
    return ns, msg.header.frame_id, cdr.header_cdr(ns, msg.header.frame_id)


def header_msg(header: bytes) -> Header:
    """A std_msgs/Header from its CDR bytes (cdr.header_cdr)."""
    sec, nanosec, frame_id = cdr.header_fields(header)
    return Header(stamp=Time(sec=sec, nanosec=nanosec), frame_id=frame_id)


def diag3(variances) -> list[float]:
    """One variance or three -> a row-major 3x3 diagonal covariance."""
    a, b, c = (variances,) * 3 if np.ndim(variances) == 0 else variances
    return [float(a), 0.0, 0.0, 0.0, float(b), 0.0, 0.0, 0.0, float(c)]


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


def compensated_imu(header, gyro, accel, orientation, *, gyro_var, accel_var, orientation_var) -> Imu:
    """The bias-compensated Imu: rates minus drift, orientation (x, y, z, w: roll/pitch from gravity +
    heading) with its roll, pitch, yaw variances."""
    return imu_msg(header, gyro, accel, gyro_var=gyro_var, accel_var=accel_var, orientation=orientation,
                   orientation_var=orientation_var)


class RawOutputs:
    """imu/data and imu/heading of one sample as CDR bytes (cdr.OneMessage): `compensated_imu` and
    `heading_msg` field for field, as rclpy reads them back (padding zeroed, where rclpy leaves
    whatever its buffer held). A live node at 1 kHz publishes them raw, without building and
    converting message objects."""

    def __init__(self, fixed_frame: str):
        self._imu, self._heading = cdr.OneMessage(cdr.IMU), cdr.OneMessage(cdr.POSE_COV_STAMPED)
        self._heading_frame = cdr.header_cdr(0, fixed_frame)[12:]   # frame_id length and bytes
        self._heading_cov = tuple(heading_covariance(0.0)[:35])    # all but the yaw variance
        self._rate_cov = (None, None, ())   # gyro and accel variances -> their covariances (they rarely change)

    def imu(self, header: bytes, gyro, accel, orientation, gyro_var: float, accel_var: float,
            orientation_var) -> bytes:
        """`compensated_imu` with the header `header` (CDR, e.g. the input's)."""
        r, p, y = orientation_var
        if self._rate_cov[:2] != (gyro_var, accel_var):
            self._rate_cov = (gyro_var, accel_var, (diag3(gyro_var), diag3(accel_var)))
        g, a = self._rate_cov[2]
        return self._imu.encode(header, (*orientation, r, 0.0, 0.0, 0.0, p, 0.0, 0.0, 0.0, y, *gyro, *g, *accel, *a))

    def heading(self, header: bytes, orientation, yaw_var: float) -> bytes:
        """`heading_msg` at the stamp of `header` (CDR), in the fixed frame."""
        return self._heading.encode(header[:12] + self._heading_frame,
                                    (0.0, 0.0, 0.0, *orientation, *self._heading_cov, yaw_var))


# Variance of what imu/heading does not estimate (position, roll, pitch): large, so a consumer that
# fuses the whole pose gives them no weight (robot_localization: fuse yaw only, pose0_config).
UNKNOWN_VARIANCE = 1e6


def heading_msg(stamp, frame_id: str, orientation, yaw_var: float) -> PoseWithCovarianceStamped:
    """imu/heading: the orientation of the levelled IMU frame (yaw only) in the world frame
    `frame_id`, at the origin; of the 6x6 covariance only the yaw variance is meaningful."""
    msg = PoseWithCovarianceStamped(header=Header(stamp=stamp, frame_id=frame_id))
    o = msg.pose.pose.orientation
    o.x, o.y, o.z, o.w = map(float, orientation)
    msg.pose.covariance = heading_covariance(yaw_var)
    return msg


def heading_covariance(yaw_var: float) -> list[float]:
    """imu/heading's 6x6 covariance, row-major: x, y, z, roll, pitch unknown, then the yaw variance."""
    cov = [0.0] * 36
    for i in range(5):
        cov[7 * i] = UNKNOWN_VARIANCE
    cov[35] = float(yaw_var)
    return cov


def transform_msg(stamp, parent: str, child: str, orientation) -> TransformStamped:
    """parent -> child, rotation only (the IMU's orientation in the world frame)."""
    msg = TransformStamped(header=Header(stamp=stamp, frame_id=parent), child_frame_id=child)
    r = msg.transform.rotation
    r.x, r.y, r.z, r.w = map(float, orientation)
    return msg


def tf_message(transforms) -> 'TFMessage':
    if TFMessage is None:
        raise RuntimeError('tf2_msgs is not installed (it comes with a ROS install)')
    return TFMessage(transforms=list(transforms))


def message_stamp(msg):
    """The stamp a message is recorded at: its header's, or its first transform's (TFMessage)."""
    if hasattr(msg, 'header'):
        return msg.header.stamp
    return msg.transforms[0].header.stamp


def _kv(key: str, value) -> KeyValue:
    if isinstance(value, float):
        value = 'nan' if not math.isfinite(value) else f'{value:.9g}'
    return KeyValue(key=key, value=str(value))


def diagnostic_array(stamp, name: str, hardware_id: str, level: int, message: str, values: dict) -> DiagnosticArray:
    level = level if isinstance(level, bytes) else bytes([level])  # the constants are bytes already
    status = DiagnosticStatus(level=level, name=name, message=message, hardware_id=hardware_id,
                              values=[_kv(k, v) for k, v in values.items()])
    return DiagnosticArray(header=Header(stamp=stamp), status=[status])
