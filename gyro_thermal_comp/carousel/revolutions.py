"""Revolution boundaries from an unwrapped carousel angle (encoder or integrated axial gyro).

A revolution ends where theta crosses `phase + 2*pi*n`. After a boundary at level L the next one is
L + 1 or L - 1 (full turn forwards or backwards): this ladder is a Schmitt trigger with a full turn
of hysteresis, so encoder dither or gyro noise around a level (a stopped wheel) never produces
spurious revolutions, and reversing rotation (a wheel backing up) still yields whole turns.
Angles stay unwrapped; nothing here wraps (angles.wrap_angle is the only wrapping helper).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

TWO_PI = 2.0 * np.pi


@dataclass(frozen=True)
class Crossing:
    t_s: float          # interpolated crossing time, s
    level_rad: float    # the boundary angle phase + 2*pi*n, rad (unwrapped)
    direction: int      # +1 forwards (CCW about +z), -1 backwards


class RevolutionLadder:
    """Streaming boundary detector. Feed consecutive (t, theta) runs; `reset()` after a break."""

    def __init__(self, phase_rad: float = 0.0):
        self.phase_rad = float(phase_rad)
        self.level_index: int | None = None   # index n of the last boundary passed
        self._prev_t: float | None = None      # last sample of the previous run: the next one continues it
        self._prev_theta = 0.0

    def reset(self) -> None:
        self.level_index = None
        self._prev_t = None

    def _level(self, n: int) -> float:
        return self.phase_rad + TWO_PI * n

    def process(self, t: np.ndarray, theta: np.ndarray) -> list[Crossing]:
        """Boundaries crossed within this run (continuing from the previous run's last sample)."""
        t = np.asarray(t, dtype=float)
        theta = np.asarray(theta, dtype=float)
        if len(t) == 0:
            return []
        if self._prev_t is not None:
            t = np.concatenate(([self._prev_t], t))
            theta = np.concatenate(([self._prev_theta], theta))
        self._prev_t, self._prev_theta = float(t[-1]), float(theta[-1])
        m = np.floor((theta - self.phase_rad) / TWO_PI).astype(np.int64)
        out: list[Crossing] = []
        # Loop only over samples where the floor index changes: about once per revolution.
        for i in np.flatnonzero(np.diff(m)) + 1:
            m_prev, m_now = int(m[i - 1]), int(m[i])
            if self.level_index is None:
                # First boundary: the first level crossed in either direction.
                first = m_prev + 1 if m_now > m_prev else m_prev
                self.level_index = first
                out.append(self._crossing(t, theta, i, first, 1 if m_now > m_prev else -1))
            while m_now >= self.level_index + 1:            # theta >= next level up
                self.level_index += 1
                out.append(self._crossing(t, theta, i, self.level_index, 1))
            while m_now <= self.level_index - 2:            # theta < next level down
                self.level_index -= 1
                out.append(self._crossing(t, theta, i, self.level_index, -1))
        return out

    def _crossing(self, t, theta, i, n, direction) -> Crossing:
        level = self._level(n)
        d = theta[i] - theta[i - 1]
        frac = 0.0 if d == 0.0 else float(np.clip((level - theta[i - 1]) / d, 0.0, 1.0))
        return Crossing(float(t[i - 1] + frac * (t[i] - t[i - 1])), level, direction)


def rate_deviation(t: np.ndarray, theta: np.ndarray, min_dt_s: float = 1e-6) -> float:
    """Largest |segment rate / mean rate - 1| over a window, a measure of spin irregularity.

    Segments shorter than `min_dt_s` (interpolated end points) are skipped: their rate is noise."""
    dt = np.diff(t)
    dth = np.diff(theta)
    total_t = t[-1] - t[0]
    if total_t <= 0:
        return np.inf
    mean = (theta[-1] - theta[0]) / total_t
    ok = dt > min_dt_s
    if mean == 0.0 or not np.any(ok):
        return np.inf
    return float(np.max(np.abs(dth[ok] / dt[ok] / mean - 1.0)))
