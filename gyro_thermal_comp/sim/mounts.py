"""How the sensor (imu_link) sits on the body: fixed, or turning on a revolute joint (carousel, wheel).

A mount returns, at N times, the sensor-to-body rotation and the sensor's rate relative to the body.
Stages compose by matrix product, so a later flip mechanism (the IMU turned 90 deg about an in-plane
axis, Kolesnyk & Chernyak 2023) is one more stage between the mount frame and the joint, and an
auxiliary IMU is simply a second FixedMount.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .motion import BodyState

# Mount frames (columns: mount x, y, z in body axes). The joint always turns about mount z, so the
# sensor z axis is the spin axis.
VERTICAL_AXIS = np.eye(3)                                        # spin about body z (up)
HORIZONTAL_AXIS = np.array([[0.0, 0, 1], [1, 0, 0], [0, 1, 0]])  # spin about body x (forward)
AXLE_AXIS = np.array([[0.0, 1, 0], [0, 0, 1], [1, 0, 0]])        # spin about body y (the axle, left)


@dataclass(frozen=True)
class MountState:
    rot_bs: np.ndarray                      # (N, 3, 3) sensor -> body
    rate_bs_s: np.ndarray                   # (N, 3) rad/s, sensor rate relative to the body, sensor frame
    joint_angle: np.ndarray | None = None   # (N,) rad, unwrapped
    joint_rate: np.ndarray | None = None    # (N,) rad/s


def rot_z(angle_rad) -> np.ndarray:
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    z, o = np.zeros_like(c), np.ones_like(c)
    return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1), np.stack([z, z, o], -1)], -2)


class FixedMount:
    has_joint = False

    def __init__(self, rot_bm: np.ndarray = VERTICAL_AXIS):
        self.rot_bm = np.asarray(rot_bm, dtype=float)

    def state(self, t_s, body: BodyState) -> MountState:
        n = len(np.atleast_1d(t_s))
        return MountState(np.broadcast_to(self.rot_bm, (n, 3, 3)), np.zeros((n, 3)))


class TurntableJoint:
    """Spin at spin_hz about mount z from start_s on, reached smoothly (sin^2 rate ramp) in spinup_s."""

    def __init__(self, spin_hz: float, start_s: float, spinup_s: float):
        self.omega = 2 * np.pi * spin_hz
        self.start_s, self.spinup_s = start_s, spinup_s

    def angle_rate(self, t_s, body: BodyState):
        tau = np.maximum(np.asarray(t_s, dtype=float) - self.start_s, 0.0)
        ramp = tau < self.spinup_s
        tu = self.spinup_s
        angle = np.where(ramp, 0.5 * tau - tu / (2 * np.pi) * np.sin(np.pi * np.minimum(tau, tu) / tu),
                         0.5 * tu + (tau - tu))
        rate = np.where(ramp, np.sin(0.5 * np.pi * np.minimum(tau, tu) / tu) ** 2, 1.0)
        return self.omega * angle, self.omega * rate


class WheelJoint:
    """Right rear (non-steered) wheel of the body: turns with the distance its contact point rolls.

    The right wheel runs at lateral offset -track/2, so it travels distance + yaw*track/2; forward
    rolling is a positive turn about the axle (body +y), angle = that distance / radius.
    """

    def __init__(self, radius_m: float, track_m: float, yaw0_rad: float):
        self.radius_m, self.track_m, self.yaw0_rad = radius_m, track_m, yaw0_rad

    def angle_rate(self, t_s, body: BodyState):
        half = 0.5 * self.track_m
        angle = (body.distance + (body.yaw_rad - self.yaw0_rad) * half) / self.radius_m
        rate = (body.speed + body.yaw_rate * half) / self.radius_m
        return angle, rate


class JointMount:
    """Sensor turned by a joint angle about mount z: R_bs = R_bm @ Rz(angle)."""
    has_joint = True

    def __init__(self, rot_bm: np.ndarray, joint):
        self.rot_bm, self.joint = np.asarray(rot_bm, dtype=float), joint

    def state(self, t_s, body: BodyState) -> MountState:
        angle, rate = self.joint.angle_rate(t_s, body)
        rate_s = np.zeros((len(angle), 3))
        rate_s[:, 2] = rate
        return MountState(self.rot_bm @ rot_z(angle), rate_s, angle, rate)
