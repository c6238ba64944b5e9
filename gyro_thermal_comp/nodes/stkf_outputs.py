"""What the STKF node publishes, as numbers (no ROS here): `OneOutput` for a sample published the
moment it arrives, `OutputArrays` for a batch (live: samples that waited for the estimator; replay:
a whole chunk, encoded in bulk by output_arrays.BulkRecorder). Both carry REP 145 variances (rad^2,
(rad/s)^2, (m/s^2)^2) and orientations (x, y, z, w) in the node's world frame.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np


class OneOutput(NamedTuple):
    """One published sample in Python floats (the live per-sample path)."""
    header: bytes                 # the input's std_msgs/Header as CDR
    gyro: tuple                   # compensated rates, rad/s
    accel: list                   # specific force as measured, m/s^2
    q_imu: tuple                  # the IMU in the world frame
    orientation_var: tuple        # roll, pitch, yaw
    gyro_var: float
    accel_var: float
    q_heading: tuple | None       # the levelled IMU frame (yaw only); None when not asked for


@dataclass(frozen=True)
class OutputArrays:
    """n published samples."""
    ns: np.ndarray                # (n,) int64 header stamps
    frame_id: str                 # of imu/data (the input's)
    headers: np.ndarray           # (n,) the inputs' headers as CDR bytes; None where a chunk had none (replay)
    gyro: np.ndarray              # (n, 3) compensated rates, rad/s
    accel: np.ndarray             # (n, 3) specific force as measured, m/s^2
    q_imu: np.ndarray             # (n, 4) x, y, z, w: the IMU in the world frame
    q_heading: np.ndarray         # (n, 4) the levelled IMU frame (yaw only)
    orientation_var: np.ndarray   # (n, 3) roll, pitch, yaw
    gyro_var: float
    accel_var: float
