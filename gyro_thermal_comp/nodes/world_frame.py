"""Orientation of the IMU frame in the world frame the node publishes in (REP 103), pure numpy.

The estimator works in ENU (yaw counter-clockwise from east). `ned` is offered as
imu_filter_madgwick offers it: the same IMU frame (imu_link, x forward, y left, z up) seen from a
north-east-down world, so a level unit has roll pi there and its yaw is the compass heading,
clockwise from north. With R_ned_enu = Rz(pi/2) Rx(pi):

    R_ned_imu = Rz(pi/2 - yaw) Ry(-pitch) Rx(roll + pi)

Each angle is wrapped once, by angles.wrap_angle.
"""
from __future__ import annotations

import math

import numpy as np

from ..angles import quat_from_euler, wrap_angle

WORLD_FRAMES = ('enu', 'ned')


def world_euler(roll_rad, pitch_rad, yaw_rad, world_frame: str):
    """ENU roll, pitch, yaw (rad) -> the same attitude's ZYX angles in `world_frame`."""
    if world_frame == 'enu':
        return roll_rad, pitch_rad, yaw_rad
    if world_frame == 'ned':
        return (wrap_angle(np.asarray(roll_rad) + np.pi), -np.asarray(pitch_rad),
                wrap_angle(np.pi / 2 - np.asarray(yaw_rad)))
    raise ValueError(f'world_frame must be one of {WORLD_FRAMES}, not {world_frame!r}')


def world_quat(roll_rad, pitch_rad, yaw_rad, world_frame: str) -> np.ndarray:
    """Quaternion(s) (x, y, z, w) of the IMU frame in `world_frame`, from ENU roll, pitch, yaw."""
    return quat_from_euler(*world_euler(roll_rad, pitch_rad, yaw_rad, world_frame))


def world_yaw(yaw_rad, world_frame: str):
    """ENU yaw (rad) -> the yaw of a level IMU frame in `world_frame` (NED: clockwise from north)."""
    return world_euler(0.0, 0.0, yaw_rad, world_frame)[2]


def world_quat_one(roll_rad: float, pitch_rad: float, yaw_rad: float, world_frame: str) -> tuple:
    """`world_quat` for one attitude in Python floats (a node's per-sample path)."""
    if world_frame == 'ned':
        roll_rad, pitch_rad, yaw_rad = (wrap_angle(roll_rad + math.pi), -pitch_rad, wrap_angle(math.pi / 2 - yaw_rad))
    elif world_frame != 'enu':
        raise ValueError(f'world_frame must be one of {WORLD_FRAMES}, not {world_frame!r}')
    hr, hp, hy = 0.5 * roll_rad, 0.5 * pitch_rad, 0.5 * yaw_rad
    cr, sr, cp, sp, cy, sy = math.cos(hr), math.sin(hr), math.cos(hp), math.sin(hp), math.cos(hy), math.sin(hy)
    return (sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy,
            cr * cp * cy + sr * sp * sy)
