"""The linear Kalman filter behind the encoder-free carousel angle, with its innovation gate.

Its states are those of angle_reference.GravityAngleFilter: the gyro angle's offset (rad) first, then the axial
bias (rad/s), the scale factor and the rest, each a constant or, between measurements, a random walk
(`predict`: the offset walks with the gyro's white noise, the bias with its own random walk). A measurement
whose innovation lies beyond `gate_sigma` sigma is refused: a revolution that the body's own acceleration, a
slipping wheel or a disturbed field has turned. Three refused in a row say that the model is off, not the
measurements: the offset's variance opens by the innovation^2 and the update is made. Measurements that
`agree` (the magnetometer's) re-anchor so only when MAG_REANCHOR refused in a row agree with each other to the
gate. Units: rad, rad/s, s.
"""
from __future__ import annotations

import numpy as np

from ..angles import wrap_angle

MAG_REANCHOR = 5              # magnetometer: refused measurements in a row, agreeing, that force a re-anchor


class GatedKalman:
    """Estimate `x`, its covariance `p` (initially diagonal, `p0`) and the measurements refused so far."""

    def __init__(self, p0: list, gate_sigma: float):
        self.x = np.zeros(len(p0))
        self.p = np.diag(p0)
        self.gate_sigma = gate_sigma
        self.rejected = 0
        self._t_pred: float | None = None   # time the covariance was last propagated to
        self._in_a_row = 0
        self._refused: list = []            # the innovations refused in a row, rad (newest MAG_REANCHOR)

    def predict(self, t: float, walk2: tuple) -> None:
        """Propagate the covariance to t: the first len(walk2) states walk with these densities^2 (per s)."""
        if self._t_pred is not None and t > self._t_pred:
            dt = t - self._t_pred
            q = np.zeros(len(self.x))
            q[:len(walk2)] = walk2
            self.p += np.diag(q) * dt
        self._t_pred = t if self._t_pred is None else max(self._t_pred, t)

    def update(self, h: np.ndarray, y: float, r: float, wrap: bool, agree: bool = False) -> bool:
        """Kalman update with measurement row h, value y (an angle when `wrap`) and variance r; an innovation
        beyond the gate is refused unless 3 come in a row (`agree`: MAG_REANCHOR in a row that agree with each
        other to the gate). Returns whether the update was made."""
        innov = y - h @ self.x
        if wrap:
            innov = wrap_angle(innov)
        s = float(h @ self.p @ h + r)
        gate = self.gate_sigma
        if innov ** 2 > gate ** 2 * s:
            self.rejected += 1
            self._in_a_row += 1
            self._refused = (self._refused + [innov])[-MAG_REANCHOR:]
            if self._in_a_row < 3:
                return False
            if agree and (self._in_a_row < MAG_REANCHOR or np.ptp(self._refused) > gate * np.sqrt(r)):
                return False
            self.p[0, 0] += innov ** 2        # three in a row: the model is off, not the measurements
            s = float(h @ self.p @ h + r)
        self._in_a_row = 0
        self._refused = []
        k = self.p @ h / s
        self.x = self.x + k * innov
        self.p = self.p - np.outer(k, h @ self.p)
        self.p = 0.5 * (self.p + self.p.T)
        return True

    def sigma(self, i: int) -> float:
        """1-sigma of state i."""
        return float(np.sqrt(max(self.p[i, i], 0.0)))
