"""`BulkRecorder`: replay writes the STKF node's outputs (`OutputArrays`, stkf_outputs.py) in bulk.

A batch of outputs becomes CDR built from the arrays at once (`cdr.py`), byte for byte what
serialising the rclpy messages one by one gives (test/test_replay_bulk.py), at a fraction of the cost.
"""
from __future__ import annotations

import numpy as np

from .. import cdr
from . import conversions as conv
from .stkf_outputs import OutputArrays


def _diag3(v) -> np.ndarray:
    """(n, 3) or scalar variances -> (n, 9) or (9,) row-major diagonal covariances."""
    v = np.asarray(v, dtype=float)
    out = np.zeros(v.shape[:-1] + (9,) if v.ndim else (9,))
    out[..., [0, 4, 8]] = v if v.ndim else [v, v, v]
    return out


def heading_covariance(yaw_var: np.ndarray) -> np.ndarray:
    """(n,) yaw variances -> (n, 36) imu/heading covariances (conversions.heading_covariance's layout)."""
    cov = np.tile(conv.heading_covariance(0.0), (np.size(yaw_var), 1))
    cov[:, 35] = yaw_var
    return cov


class BulkRecorder:
    """Replay's sink for a node's imu/data and imu/heading: encodes a batch and writes it to the bag."""

    def __init__(self, writer, imu_port, heading_port, fixed_frame: str):
        self.writer, self.fixed_frame = writer, fixed_frame
        self.imu = ('/' + imu_port.topic.lstrip('/'), imu_port.type_name)
        self.heading = ('/' + heading_port.topic.lstrip('/'), heading_port.type_name)
        self.count = 0

    def write(self, o: OutputArrays) -> None:
        imu = cdr.encode_imu(o.ns, o.frame_id, orientation=o.q_imu, orientation_covariance=_diag3(o.orientation_var),
                             angular_velocity=o.gyro, angular_velocity_covariance=_diag3(o.gyro_var),
                             linear_acceleration=o.accel, linear_acceleration_covariance=_diag3(o.accel_var))
        heading = cdr.encode_pose_with_covariance_stamped(o.ns, self.fixed_frame, o.q_heading,
                                                          covariance=heading_covariance(o.orientation_var[:, 2]))
        for t, a, b in zip(o.ns.tolist(), imu, heading):
            self.writer.write_raw(*self.imu, t, a)
            self.writer.write_raw(*self.heading, t, b)
        self.count += o.ns.size
