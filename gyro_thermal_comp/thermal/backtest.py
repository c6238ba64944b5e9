"""`DriftBacktest`: what past drift predictions of a given age missed beyond their own variance.

Between learner updates, and through an outage, D_hat is a prediction from parameters learned `age`
seconds ago. The learner's P gives that prediction's variance as the model sees it, not what the
model lacks (an effect it has no term for, a lag or hysteresis of another shape, a bias that
wanders). The accepted windows show it. A coast integrates the drift error over minutes, where one
10-s window's white noise hides an error that matters (0.01 deg/s: 3 deg in 300 s), so consecutive
accepted windows are averaged in blocks of `BLOCK_WINDOWS` (y, h and R / n: the noise averages,
a slow error does not) and block k is compared with the parameters (x, P) in force `H` s before
its middle (never inside the block),

    e_k(H) = y_k - h_k . x(t_k - H),     E[e_k^2] = R_k + h_k P(t_k - H) h_k' + m(H)^2,

so the mean of e^2 - R - h P h' over recent blocks estimates m(H)^2, the error variance of a
prediction H s old beyond what the model accounts for, whatever its cause (R with the adaptive-R
scale the windows were weighed with). Predictions from parameters still being learned had a wide P
and are not counted against a coast that starts from a settled one. m^2 is taken only where
significant, as adaptive R is (mean e^2 / mean (R + h P h') beyond 1 + 3.5 x its scatter for that
many blocks; a filter as good as P says passes it about 1 % of the time), else 0. Between horizons
m is interpolated linearly in age, from 0 at age 0; beyond the longest horizon it grows in
proportion to the age (a slope error carried on). It says nothing about a regime the windows never
saw (the first cooling after heating): that is coasting.py's extrapolation term, added on top.

"""
from __future__ import annotations

import bisect
import math
from collections import deque

import numpy as np

HORIZONS_S = (40.0, 80.0, 160.0, 320.0, 640.0, 1280.0)   # >= half a block: the snapshot precedes it
BLOCK_WINDOWS = 6          # windows averaged per block (60 s at 10 s)
MEMORY_BLOCKS = 30.0       # exponential memory of the means, blocks (30 min at 60 s)
SIGNIFICANCE_SIGMA = 3.5   # mean e^2 / mean R must exceed 1 + this x its scatter sqrt(2 / n)
MIN_BLOCKS = 5             # blocks before a horizon says anything
KEEP_MARGIN_S = 600.0      # updates kept beyond the longest horizon, s


class DriftBacktest:
    """Per horizon: exponentially weighted means of e^2 and of R + h P h' over blocks of accepted
    windows."""

    def __init__(self, horizons_s=HORIZONS_S, block_windows: int = BLOCK_WINDOWS, memory_blocks: float = MEMORY_BLOCKS):
        self.horizons_s = np.asarray(horizons_s, dtype=float)
        self.block_windows = int(block_windows)
        self._alpha = 1.0 / memory_blocks
        self._block: list[tuple[float, float, float, np.ndarray, float]] = []   # (t0, t1, y, h, R) waiting
        n = self.horizons_s.size
        self._e2 = np.zeros(n)          # weighted mean of e^2, (rad/s)^2
        self._r = np.zeros(n)           # weighted mean of R + h P h', (rad/s)^2
        self._n = np.zeros(n)           # blocks seen per horizon
        self._t: deque[float] = deque()           # update times, s (increasing)
        self._x: deque[np.ndarray] = deque()      # parameters after each update
        self._p: deque[np.ndarray] = deque()      # and their covariance
        self.t_update = -math.inf                 # the latest update, s

    def add_window(self, t0: float, t1: float, y: float, h: np.ndarray, r: float) -> None:
        """An accepted window ([t0, t1] s, y rad/s, h, R (rad/s)^2), before the update it makes.
        Windows join the waiting block while they follow each other (an outage starts a new one)."""
        if not (math.isfinite(y) and math.isfinite(r) and r > 0):
            return
        if self._block and t0 > self._block[-1][1] + 1e-6:
            self._block = []
        self._block.append((t0, t1, y, np.asarray(h, dtype=float), r))
        if len(self._block) == self.block_windows:
            self._add_block()
            self._block = []

    def _add_block(self) -> None:
        n = len(self._block)
        t_mid = 0.5 * (self._block[0][0] + self._block[-1][1])
        y = sum(w[2] for w in self._block) / n
        h = sum(w[3] for w in self._block) / n
        r = sum(w[4] for w in self._block) / (n * n)     # independent window noise averaged
        times = list(self._t)
        for j, horizon in enumerate(self.horizons_s):
            i = bisect.bisect_right(times, t_mid - horizon) - 1   # the parameters in force then
            if i < 0:
                continue
            e = y - float(h @ self._x[i])
            expected = r + max(float(h @ self._p[i] @ h), 0.0)
            a = max(self._alpha, 1.0 / (self._n[j] + 1.0))       # a plain mean until the memory fills
            self._e2[j] += a * (e * e - self._e2[j])
            self._r[j] += a * (expected - self._r[j])
            self._n[j] += 1.0

    def add_update(self, t: float, x: np.ndarray, P: np.ndarray) -> None:
        """The parameters and covariance an update at `t` (s) put in force."""
        self._t.append(float(t))
        self._x.append(np.array(x, dtype=float))
        self._p.append(np.array(P, dtype=float))
        self.t_update = float(t)
        # keep what the longest horizon can still reach from a block ending later (a block's middle
        # may lie half a block and its confirmation before its last update)
        cut = t - self.horizons_s[-1] - KEEP_MARGIN_S
        while len(self._t) > 1 and self._t[1] <= cut:
            self._t.popleft()
            self._x.popleft()
            self._p.popleft()

    def variances(self) -> np.ndarray:
        """m^2 at each horizon, (rad/s)^2; 0 where not significant."""
        n_eff = np.minimum(self._n, 2.0 / self._alpha)
        scatter = np.sqrt(2.0 / np.maximum(n_eff, 1.0))
        significant = (self._n >= MIN_BLOCKS) & (self._e2 > self._r * (1.0 + SIGNIFICANCE_SIGMA * scatter))
        return np.where(significant, self._e2 - self._r, 0.0)

    def variance_at(self, age_s: float) -> float:
        """m^2 for a prediction `age_s` s old, (rad/s)^2 (0 before any evidence)."""
        return float(self.variances_at(np.array([age_s]))[0])

    def variances_at(self, age_s: np.ndarray) -> np.ndarray:
        """`variance_at` for an array of ages, s."""
        age = np.where(np.isfinite(age_s), np.asarray(age_s, dtype=float), 0.0)
        sigma = np.sqrt(self.variances())
        if not sigma.any():
            return np.zeros(age.shape)
        hz = self.horizons_s
        inside = np.interp(age, np.concatenate(([0.0], hz)), np.concatenate(([0.0], sigma)))
        return np.where(age > hz[-1], sigma[-1] * age / hz[-1], np.where(age > 0, inside, 0.0)) ** 2
