"""Angle and attitude helpers shared by every module (REP 103: ENU world, yaw CCW from east).

`wrap_angle` is the one place angles are wrapped; nothing else in the package wraps by hand.
Quaternions are (x, y, z, w), body-to-world (they rotate body vectors into ENU), as in ROS messages.
"""
from __future__ import annotations

import numpy as np


def wrap_angle(angle_rad):
    """Wrap angle(s) in rad to (-pi, pi]. Works on scalars and arrays."""
    wrapped = np.pi - np.mod(np.pi - np.asarray(angle_rad, dtype=float), 2.0 * np.pi)
    return float(wrapped) if np.ndim(wrapped) == 0 else wrapped


def quat_from_euler(roll_rad, pitch_rad, yaw_rad) -> np.ndarray:
    """ZYX (yaw, then pitch, then roll) Euler angles in rad -> quaternions (..., 4) as x, y, z, w."""
    hr, hp, hy = (0.5 * np.asarray(a, dtype=float) for a in (roll_rad, pitch_rad, yaw_rad))
    cr, sr, cp, sp, cy, sy = np.cos(hr), np.sin(hr), np.cos(hp), np.sin(hp), np.cos(hy), np.sin(hy)
    return np.stack([sr * cp * cy - cr * sp * sy,
                     cr * sp * cy + sr * cp * sy,
                     cr * cp * sy - sr * sp * cy,
                     cr * cp * cy + sr * sp * sy], axis=-1)


def euler_from_quat(quat_xyzw) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Quaternions (..., 4) x, y, z, w -> (roll, pitch, yaw) in rad, ZYX convention, yaw unwrapped
    only as far as atan2 gives (-pi, pi]."""
    q = np.asarray(quat_xyzw, dtype=float)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    roll = np.arctan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2.0 * (w * y - z * x), -1.0, 1.0))
    yaw = np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return roll, pitch, yaw


def yaw_from_quat(quat_xyzw) -> np.ndarray:
    """Heading (yaw) in rad, CCW from east, in (-pi, pi]."""
    return euler_from_quat(quat_xyzw)[2]


def rotation_matrix_from_quat(quat_xyzw) -> np.ndarray:
    """Quaternions (..., 4) -> rotation matrices (..., 3, 3) mapping body vectors into the world."""
    q = np.asarray(quat_xyzw, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], axis=-1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], axis=-1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], axis=-1),
    ], axis=-2)
