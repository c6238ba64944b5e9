"""Tilt-compensated compass: heading, field norm and dip angle from magnetometer + accelerometer.

Conventions (docs/design.md section 1): body x forward, y left, z up; yaw psi counter-clockwise from east (ENU).
At rest the accelerometer measures +g along body "up", so roll = atan2(f_y, f_z) and
pitch = atan2(-f_x, hypot(f_y, f_z)). The magnetometer is levelled with Ry(pitch) Rx(roll); the
Earth's horizontal field points to magnetic north, so in the levelled frame it reads
(B_h sin psi_m, B_h cos psi_m) and psi_m = atan2(m_x, m_y). Magnetic north lies `declination_rad`
east of (clockwise from) true north, so the true ENU heading is psi_m - declination.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..angles import wrap_angle


def roll_pitch_from_accel(accel_m_s2) -> tuple[np.ndarray, np.ndarray]:
    """Roll and pitch (rad, ZYX) from specific force (N, 3) in m/s^2, body frame, assuming no
    acceleration other than gravity."""
    f = np.asarray(accel_m_s2, dtype=float)
    roll = np.arctan2(f[..., 1], f[..., 2])
    pitch = np.arctan2(-f[..., 0], np.hypot(f[..., 1], f[..., 2]))
    return roll, pitch


def level(vec_body, roll_rad, pitch_rad) -> np.ndarray:
    """Rotate body vectors (N, 3) into the heading-aligned level frame: Ry(pitch) Rx(roll) v."""
    return np.stack(_level_xyz(np.asarray(vec_body, dtype=float), roll_rad, pitch_rad), axis=-1)


def _level_xyz(v: np.ndarray, roll_rad, pitch_rad) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`level` as its three components (no stacking: the compass needs them apart)."""
    cr, sr, cp, sp = np.cos(roll_rad), np.sin(roll_rad), np.cos(pitch_rad), np.sin(pitch_rad)
    y1 = cr * v[..., 1] - sr * v[..., 2]
    z1 = sr * v[..., 1] + cr * v[..., 2]
    x2 = cp * v[..., 0] + sp * z1
    z2 = -sp * v[..., 0] + cp * z1
    return x2, y1, z2


@dataclass(frozen=True)
class CompassReading:
    heading_rad: np.ndarray   # (N,) true ENU yaw, CCW from east, wrapped to (-pi, pi]
    field_norm_t: np.ndarray  # (N,) |B|, tesla
    dip_rad: np.ndarray       # (N,) inclination, positive when the field points below the horizon


def compass_heading(mag_t, accel_m_s2=None, declination_rad: float = 0.0,
                    roll_pitch=None) -> CompassReading:
    """Tilt-compensated heading, field norm and dip for mag (N,3) T with either paired accel (N,3)
    m/s^2 or already known (roll, pitch) in rad (e.g. from averaged accelerometer samples)."""
    roll, pitch = roll_pitch if roll_pitch is not None else roll_pitch_from_accel(accel_m_s2)
    mag = np.asarray(mag_t, dtype=float)
    mx, my, mz = _level_xyz(mag, roll, pitch)
    heading = wrap_angle(np.arctan2(mx, my) - declination_rad)
    norm = np.linalg.norm(mag, axis=-1)
    dip = np.arctan2(-mz, np.hypot(mx, my))
    return CompassReading(np.atleast_1d(heading), norm, dip)
