"""`Truth`: the body truth of a simulator run at any time, for scoring the demodulator.

Rebuilt from the run's SimConfig (every bag records it as /sim/config), so the demodulator itself
never sees it: the simulator's motion and mount are pure functions of time. Imports the simulator
lazily; no ROS.
"""
from __future__ import annotations

import numpy as np


class Truth:
    """Body truth of a run at arbitrary times (pure functions of time in the simulator)."""

    def __init__(self, cfg):
        from ..sim.engine import build_world
        self.cfg, self.world = cfg, build_world(cfg)

    def body(self, t):
        """(rate w.r.t. inertial space (N, 3) rad/s, specific force (N, 3) m/s^2), body frame."""
        body = self.world.motion.state(np.atleast_1d(np.asarray(t, dtype=float)))
        earth_b = np.einsum('nji,j->ni', body.rot, self.world.earth_rate_enu)
        return body.rate_body + earth_b, body.specific_force_body

    def sensor_earth_rate(self, t):
        """Earth rate in the main IMU's axes (N, 3), rad/s."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        body = self.world.motion.state(t)
        rot_es = body.rot @ self.world.mount.state(t, body).rot_bs
        return np.einsum('nji,j->ni', rot_es, self.world.earth_rate_enu)

    def joint_angle(self, t):
        t = np.atleast_1d(np.asarray(t, dtype=float))
        return self.world.mount.joint.angle_rate(t, self.world.motion.state(t))[0]

    def interval_means(self, t0, t1, n: int = 64):
        """Mean body truth over each [t0_i, t1_i] (midpoint rule on n points): rate, specific force."""
        t0, t1 = np.asarray(t0, dtype=float), np.asarray(t1, dtype=float)
        u = (np.arange(n) + 0.5) / n
        grid = (t0[:, None] + (t1 - t0)[:, None] * u[None, :]).ravel()
        w, f = self.body(grid)
        return w.reshape(len(t0), n, 3).mean(axis=1), f.reshape(len(t0), n, 3).mean(axis=1)
