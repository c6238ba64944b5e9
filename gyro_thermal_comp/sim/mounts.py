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
    """Spin at spin_hz about mount z from start_s on, reached smoothly (sin^2 rate ramp) in spinup_s;
    with stop_s, the same ramp mirrored brings it to rest from stop_s on (rate = up(t) - up(t - stop))."""

    def __init__(self, spin_hz: float, start_s: float, spinup_s: float, stop_s: float | None = None):
        self.omega = 2 * np.pi * spin_hz
        self.start_s, self.spinup_s = start_s, spinup_s
        self.stop_s = None if stop_s is None else max(float(stop_s), start_s)

    def _ramp(self, t0: float, t_s):
        """(angle, rate) / omega of a sin^2 ramp up starting at t0."""
        tau = np.maximum(np.asarray(t_s, dtype=float) - t0, 0.0)
        ramp = tau < self.spinup_s
        tu = self.spinup_s
        angle = np.where(ramp, 0.5 * tau - tu / (2 * np.pi) * np.sin(np.pi * np.minimum(tau, tu) / tu),
                         0.5 * tu + (tau - tu))
        rate = np.where(ramp, np.sin(0.5 * np.pi * np.minimum(tau, tu) / tu) ** 2, 1.0)
        return angle, rate

    def angle_rate(self, t_s, body: BodyState):
        angle, rate = self._ramp(self.start_s, t_s)
        if self.stop_s is not None:   # (no stop: the original expressions, bit for bit)
            a_down, r_down = self._ramp(self.stop_s, t_s)
            angle, rate = angle - a_down, rate - r_down
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


def rot_x(angle_rad) -> np.ndarray:
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    z, o = np.zeros_like(c), np.ones_like(c)
    return np.stack([np.stack([o, z, z], -1), np.stack([z, c, -s], -1), np.stack([z, s, c], -1)], -2)


class FlipSchedule:
    """The carousel paper's two-position mechanism: quarter turns of the IMU about platform x.

    Flip i starts at first_s + i * period_s (i < n_flips), lasts duration_s and turns +1 quarter
    (i even) or -1 (i odd), with a raised-cosine angle profile (zero rate at both ends), so the IMU
    alternates between positions 0 and 1 with equal time in each. Position k means
    v_platform = Rx(k * 90 deg) v_imu, as in carousel.flip.flip_rotation('x', k). Closed form in t."""

    def __init__(self, first_s: float, period_s: float, duration_s: float, n_flips: int):
        if duration_s >= period_s:
            raise ValueError('a flip must be shorter than the flip period')
        self.first_s, self.period_s, self.duration_s = float(first_s), float(period_s), float(duration_s)
        self.n_flips = max(0, int(n_flips))

    @classmethod
    def alternating(cls, first_s: float, period_s: float, duration_s: float, end_s: float) -> 'FlipSchedule':
        """Flips from first_s on every period_s, the last one starting at or before end_s."""
        n = int(np.floor((end_s - first_s) / period_s)) + 1 if end_s >= first_s else 0
        return cls(first_s, period_s, duration_s, n)

    def angle_rate(self, t_s):
        """(phi rad, dphi/dt rad/s) about platform x at times t_s."""
        t = np.asarray(t_s, dtype=float)
        if self.n_flips == 0:
            return np.zeros_like(t), np.zeros_like(t)
        i = np.clip(np.floor((t - self.first_s) / self.period_s), 0, self.n_flips - 1)
        u = np.clip((t - self.first_s - i * self.period_s) / self.duration_s, 0.0, 1.0)
        odd = (i % 2) == 1
        step = np.where(odd, -1.0, 1.0)
        quarter = 0.5 * np.pi
        phi = quarter * (odd + step * 0.5 * (1 - np.cos(np.pi * u)))
        rate = np.where((u > 0) & (u < 1), step * quarter * 0.5 * np.pi * np.sin(np.pi * u) / self.duration_s, 0.0)
        return phi, rate


class FlipJointMount(JointMount):
    """Joint with the flip stage between it and the sensor: R_bs = R_bm Rz(joint) Rx(phi(t)).
    The joint angle (encoder) is the platform's; the sensor's rate relative to the body, in sensor
    axes, is Rx(phi)^T [0, 0, joint rate] + [phi rate, 0, 0]."""

    def __init__(self, rot_bm: np.ndarray, joint, schedule: FlipSchedule):
        super().__init__(rot_bm, joint)
        self.schedule = schedule

    def state(self, t_s, body: BodyState) -> MountState:
        angle, rate = self.joint.angle_rate(t_s, body)
        phi, phi_rate = self.schedule.angle_rate(t_s)
        c, s = np.cos(phi), np.sin(phi)
        rate_s = np.column_stack((phi_rate, s * rate, c * rate))   # Rx(phi)^T e_z * rate
        return MountState(self.rot_bm @ rot_z(angle) @ rot_x(phi), rate_s, angle, rate)
