"""Body (base_link) trajectories as pure functions of time: static poses and smooth segment paths.

Everything is analytic (position by Gauss-Legendre quadrature inside a segment), so any stream can be
evaluated at its own stamps and chunking cannot change a value. The sensor's motion relative to the
body (turntable, wheel, a later flip stage) lives in mounts.py.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..angles import quat_from_euler, rotation_matrix_from_quat
from .earth import specific_force_at_rest_enu

_GL_X, _GL_W = np.polynomial.legendre.leggauss(24)


@dataclass(frozen=True)
class BodyState:
    """Body state at N times (ENU world, body x forward, y left, z up)."""
    quat: np.ndarray                 # (N, 4) x, y, z, w, body -> ENU
    rot: np.ndarray                  # (N, 3, 3) body -> ENU
    position: np.ndarray             # (N, 3) m, ENU
    velocity_body: np.ndarray        # (N, 3) m/s
    rate_body: np.ndarray            # (N, 3) rad/s, w.r.t. ENU
    specific_force_body: np.ndarray  # (N, 3) m/s^2 (what an ideal accelerometer at the origin reads)
    yaw_rad: np.ndarray              # (N,) unwrapped heading, CCW from east
    yaw_rate: np.ndarray             # (N,) d yaw/dt, rad/s
    speed: np.ndarray                # (N,) m/s along the path
    distance: np.ndarray             # (N,) m travelled since t = 0


def _body_state(roll, pitch, yaw, droll, dpitch, dyaw, position, speed, accel_enu, distance) -> BodyState:
    quat = quat_from_euler(roll, pitch, yaw)
    rot = rotation_matrix_from_quat(quat)
    sr, cr, sp, cp = np.sin(roll), np.cos(roll), np.sin(pitch), np.cos(pitch)
    # ZYX Euler-rate kinematics: the body rate that exactly differentiates this quaternion.
    rate = np.stack([droll - dyaw * sp, dpitch * cr + dyaw * sr * cp, -dpitch * sr + dyaw * cr * cp], axis=-1)
    vel_enu = speed[:, None] * np.stack([np.cos(yaw), np.sin(yaw), np.zeros_like(yaw)], axis=-1)
    to_body = np.swapaxes(rot, -1, -2)
    f_enu = accel_enu + specific_force_at_rest_enu()
    return BodyState(quat=quat, rot=rot, position=position,
                     velocity_body=np.einsum('nij,nj->ni', to_body, vel_enu), rate_body=rate,
                     specific_force_body=np.einsum('nij,nj->ni', to_body, f_enu),
                     yaw_rad=yaw, yaw_rate=dyaw, speed=speed, distance=distance)


class StaticPose:
    """A motionless body at fixed roll, pitch, yaw (rad)."""

    def __init__(self, roll_rad: float = 0.0, pitch_rad: float = 0.0, yaw_rad: float = 0.0):
        self.rpy = (roll_rad, pitch_rad, yaw_rad)

    def state(self, t_s) -> BodyState:
        n = len(np.atleast_1d(t_s))
        zero = np.zeros(n)
        roll, pitch, yaw = (np.full(n, float(a)) for a in self.rpy)
        return _body_state(roll, pitch, yaw, zero, zero, zero, np.zeros((n, 3)), zero,
                           np.zeros((n, 3)), zero)


class Segment(NamedTuple):
    """duration_s; speed blends v0 -> v1 as sin^2 (C1); heading turns by dpsi_rad with a raised-cosine
    yaw rate (zero rate and rate derivative at both ends)."""
    duration_s: float
    v0: float
    v1: float
    dpsi_rad: float = 0.0


def _speed(tau, dur, v0, dv):
    x = np.pi * tau / dur
    v = v0 + dv * np.sin(0.5 * x) ** 2
    return v, dv * np.pi / (2 * dur) * np.sin(x), dv * np.pi ** 2 / (2 * dur ** 2) * np.cos(x)


def _yaw(tau, dur, dpsi):
    y = 2 * np.pi * tau / dur
    return (dpsi * (tau / dur - np.sin(y) / (2 * np.pi)), dpsi / dur * (1 - np.cos(y)),
            dpsi * 2 * np.pi / dur ** 2 * np.sin(y))


def _distance(tau, dur, v0, dv):
    return v0 * tau + dv * (0.5 * tau - dur / (2 * np.pi) * np.sin(np.pi * tau / dur))


def _displacement(tau, dur, v0, dv, dpsi):
    """Planar displacement (N, 2) from a segment's start, in the frame of its start heading."""
    tau = np.asarray(tau, dtype=float)
    s = tau[..., None] * 0.5 * (_GL_X + 1.0)
    d, v0b, dvb, dpb = (np.asarray(a, dtype=float)[..., None] for a in (dur, v0, dv, dpsi))
    v = _speed(s, d, v0b, dvb)[0]
    psi = _yaw(s, d, dpb)[0]
    w = 0.5 * tau[..., None] * _GL_W
    return np.stack([np.sum(w * v * np.cos(psi), -1), np.sum(w * v * np.sin(psi), -1)], axis=-1)


class SegmentPath:
    """A planar drive: `prefix` segments once, then `lap` segments repeated forever.

    Body roll and pitch follow the accelerations (roll = roll_gain*lateral accel, outward in turns;
    pitch = -pitch_gain*longitudinal accel, nose down when braking), rad per m/s^2.
    """

    def __init__(self, prefix, lap, heading_rad=0.0, roll_gain=0.0, pitch_gain=0.0):
        segs = [Segment(*s) for s in list(prefix) + list(lap)]
        if not lap or any(s.duration_s <= 0 for s in segs):
            raise ValueError('segment durations must be > 0 and the lap non-empty')
        self.n_prefix = len(prefix)
        self.heading_rad, self.roll_gain, self.pitch_gain = heading_rad, roll_gain, pitch_gain
        self.dur = np.array([s.duration_s for s in segs])
        self.v0 = np.array([s.v0 for s in segs])
        self.dv = np.array([s.v1 - s.v0 for s in segs])
        self.dpsi = np.array([s.dpsi_rad for s in segs])
        # state at each segment start; the lap part relative to the lap start
        self.t0, self.yaw0, self.dist0 = (np.zeros(len(segs)) for _ in range(3))
        self.pos0 = np.zeros((len(segs), 2))
        t = yaw = dist = 0.0
        pos = np.zeros(2)
        for i in range(len(segs)):
            if i == self.n_prefix:
                self.lap_start_s, yaw_lap0, dist_lap0, pos_lap0 = t, yaw, dist, pos.copy()
                t = 0.0
            self.t0[i], self.yaw0[i], self.dist0[i], self.pos0[i] = t, yaw, dist, pos
            h = heading_rad + yaw
            d = _displacement(self.dur[i], self.dur[i], self.v0[i], self.dv[i], self.dpsi[i])
            pos = pos + np.array([[np.cos(h), -np.sin(h)], [np.sin(h), np.cos(h)]]) @ d
            t, yaw = t + self.dur[i], yaw + self.dpsi[i]
            dist += _distance(self.dur[i], self.dur[i], self.v0[i], self.dv[i])
        self.lap_period_s = t
        self.lap_dpsi, self.lap_distance = yaw - yaw_lap0, dist - dist_lap0
        self.lap_displacement = pos - pos_lap0

    def _locate(self, t):
        t = np.maximum(np.asarray(t, dtype=float), 0.0)
        in_lap = t >= self.lap_start_s
        n = np.where(in_lap, np.floor((t - self.lap_start_s) / self.lap_period_s), 0.0)
        local = np.where(in_lap, t - self.lap_start_s - n * self.lap_period_s, t)
        idx_pre = np.searchsorted(self.t0[:self.n_prefix], local, side='right') - 1
        idx_lap = self.n_prefix + np.clip(
            np.searchsorted(self.t0[self.n_prefix:], local, side='right') - 1, 0, None)
        idx = np.where(in_lap, idx_lap, np.clip(idx_pre, 0, None))
        idx = np.clip(idx, 0, len(self.dur) - 1)
        tau = np.clip(local - self.t0[idx], 0.0, self.dur[idx])
        return idx, tau, n

    def state(self, t_s) -> BodyState:
        idx, tau, n = self._locate(t_s)
        dur, v0, dv, dpsi = self.dur[idx], self.v0[idx], self.dv[idx], self.dpsi[idx]
        v, dv_dt, dv_dt2 = _speed(tau, dur, v0, dv)
        psi_l, r, dr = _yaw(tau, dur, dpsi)
        h0 = self.heading_rad + self.yaw0[idx] + n * self.lap_dpsi
        yaw = h0 + psi_l
        c0, s0 = np.cos(h0), np.sin(h0)
        d = _displacement(tau, dur, v0, dv, dpsi)
        base = self.pos0[idx] + n[:, None] * self.lap_displacement
        xy = base + np.stack([c0 * d[:, 0] - s0 * d[:, 1], s0 * d[:, 0] + c0 * d[:, 1]], axis=-1)
        position = np.column_stack([xy, np.zeros(len(tau))])
        distance = self.dist0[idx] + n * self.lap_distance + _distance(tau, dur, v0, dv)
        roll = self.roll_gain * v * r
        droll = self.roll_gain * (dv_dt * r + v * dr)
        pitch = -self.pitch_gain * dv_dt
        dpitch = -self.pitch_gain * dv_dt2
        cy, sy = np.cos(yaw), np.sin(yaw)
        accel = np.stack([dv_dt * cy - v * r * sy, dv_dt * sy + v * r * cy, np.zeros_like(v)], axis=-1)
        return _body_state(roll, pitch, yaw, droll, dpitch, r, position, v, accel, distance)


def rectangle_laps(*, heading_rad, still_s, speed, turn_speed, straight_s, short_straight_s, turn_s,
                   roll_gain, pitch_gain, launch_s=10.0) -> SegmentPath:
    """Still, pull away, then counter-clockwise laps of a rectangle: each straight speeds up to `speed`
    and slows back to `turn_speed` for a 90 deg left turn. The lap closes (yaw +2*pi, zero shift)."""
    def straight(d):
        return [(d / 2, turn_speed, speed), (d / 2, speed, turn_speed)]
    turn = [(turn_s, turn_speed, turn_speed, np.pi / 2)]
    lap = (straight(straight_s) + turn + straight(short_straight_s) + turn) * 2
    prefix = [(still_s, 0.0, 0.0), (launch_s, 0.0, turn_speed)]
    return SegmentPath(prefix, lap, heading_rad, roll_gain, pitch_gain)


def stop_and_go(*, heading_rad, still_s, speed, turn_speed, roll_gain, pitch_gain) -> SegmentPath:
    """A town drive for the wheel-mounted IMU: pull away, cruise, a left turn, stop; again with a right
    turn; repeat. The wheel stops with the car."""
    def leg(dpsi):
        return [(10.0, 0.0, speed), (25.0, speed, speed), (6.0, speed, turn_speed),
                (8.0, turn_speed, turn_speed, dpsi), (8.0, turn_speed, speed), (20.0, speed, speed),
                (10.0, speed, 0.0), (15.0, 0.0, 0.0)]
    return SegmentPath([(still_s, 0.0, 0.0)], leg(np.pi / 2) + leg(-np.pi / 2), heading_rad,
                       roll_gain, pitch_gain)


def drive_and_reverse(*, heading_rad, still_s, speed, reverse_speed, brake_s, roll_gain, pitch_gain) -> SegmentPath:
    """A wheel's hard lap: pull away, cruise, a 90 deg left turn, brake hard (in brake_s) to a stop, stand,
    back up at reverse_speed, stop, stand; repeat. The wheel accelerates, brakes, stops and reverses."""
    lap = [(8.0, 0.0, speed), (12.0, speed, speed), (10.0, speed, speed, np.pi / 2), (brake_s, speed, 0.0),
           (8.0, 0.0, 0.0), (6.0, 0.0, -reverse_speed), (6.0, -reverse_speed, 0.0), (8.0, 0.0, 0.0)]
    return SegmentPath([(still_s, 0.0, 0.0)], lap, heading_rad, roll_gain, pitch_gain)
