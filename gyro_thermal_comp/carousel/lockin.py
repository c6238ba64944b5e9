"""Synchronous (lock-in) least-squares estimate of the in-plane sensor biases.

Platform-frame in-plane samples (complex z = x + i*y) of a turning sensor obey

    z_p(t) = beta + exp(-i*theta(t)) * sum_k c_k * tau^k,      tau = t - t_ref

beta: the constant sensor-fixed bias (what we want); c_k: the body(carousel)-frame in-plane signal
as a polynomial in time (order 0: constant body rate/gravity; order 1 also follows a slowly changing
one). This is linear in the complex unknowns x = [beta, c_0..c_p]; its real form is exactly the
two-equation model x_s = b_x + cos(th) W_x + sin(th) W_y, y_s = b_y - sin(th) W_x + cos(th) W_y.

Per revolution we keep only the normal equations (Gram matrix, right-hand side, sum |z|^2, count),
so a sliding window of K revolutions costs O(K) small matrices, not the samples. Normal equations
built about different t_ref are moved to a common reference by an exact polynomial re-basing.
Samples are equally weighted (white sensor noise per sample).
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from math import comb

import numpy as np


@dataclass(frozen=True)
class RevolutionStats:
    """Normal equations of one revolution about `t_ref_s` (complex, size m = order + 2) for q signals
    sampled together (e.g. gyro and accelerometer share theta and t, hence the Gram matrix)."""
    t_ref_s: float
    gram: np.ndarray     # (m, m) complex, sum conj(phi) phi^T
    rhs: np.ndarray      # (m, q) complex, sum conj(phi) z
    zz: np.ndarray       # (q,) sum |z|^2
    n: int               # samples

    @property
    def order(self) -> int:
        return self.gram.shape[0] - 2

    @classmethod
    def from_samples(cls, t_s, theta_rad, z, order: int, t_ref_s: float | None = None):
        """z: (N,) or (N, q) complex in-plane samples."""
        t = np.asarray(t_s, dtype=float)
        z = np.asarray(z, dtype=complex).reshape(len(t), -1)
        t_ref = float(np.mean(t)) if t_ref_s is None else float(t_ref_s)
        tau = t - t_ref
        e = np.exp(-1j * np.asarray(theta_rad, dtype=float))
        phi = np.column_stack([np.ones_like(e)] + [e * tau ** k for k in range(order + 1)])
        phi_h = phi.conj().T
        return cls(t_ref, phi_h @ phi, phi_h @ z, np.sum(np.abs(z) ** 2, axis=0), len(t))

    def truncated(self, order: int) -> 'RevolutionStats':
        m = order + 2
        return RevolutionStats(self.t_ref_s, self.gram[:m, :m], self.rhs[:m], self.zz, self.n)

    def rebased(self, t_new_s: float) -> 'RevolutionStats':
        """Same equations with tau measured from t_new_s: phi_new = S phi_old, S real."""
        p = self.order
        d = self.t_ref_s - t_new_s           # tau_new = tau_old + d
        if d == 0.0:
            return self
        s = np.zeros((p + 2, p + 2))
        s[0, 0] = 1.0
        for k in range(p + 1):
            for j in range(k + 1):
                s[1 + k, 1 + j] = comb(k, j) * d ** (k - j)
        return RevolutionStats(t_new_s, s @ self.gram @ s.T, s @ self.rhs, self.zz, self.n)


@dataclass(frozen=True)
class LockInSolution:
    bias: complex              # platform in-plane bias b_x + i b_y, unit of z
    bias_variance: float       # variance of each real component, unit(z)^2
    body_inplane: complex      # carousel-frame in-plane signal at t_ref_s (c_0)
    t_ref_s: float
    n_samples: int
    n_revolutions: int
    rms_residual: float        # per real component, unit(z)


def solve(stats: list[RevolutionStats], order: int, t_ref_s: float | None = None,
          variance_floor: float = 0.0) -> list[LockInSolution] | None:
    """Least-squares solutions (one per signal) over the given revolutions, None if not determined."""
    if not stats:
        return None
    t_ref = stats[-1].t_ref_s if t_ref_s is None else t_ref_s
    m = order + 2
    gram = np.zeros((m, m), dtype=complex)
    rhs = np.zeros((m, stats[0].rhs.shape[1]), dtype=complex)
    zz, n = np.zeros(rhs.shape[1]), 0
    for s in stats:
        r = s.truncated(order).rebased(t_ref)
        gram += r.gram
        rhs += r.rhs
        zz += r.zz
        n += r.n
    if n <= m or not np.all(np.isfinite(gram)):
        return None
    scale = np.sqrt(np.real(np.diag(gram)))
    if np.any(scale <= 0):
        return None
    g = gram / np.outer(scale, scale)       # equilibrate before judging conditioning
    try:
        g_inv = np.linalg.inv(g)
    except np.linalg.LinAlgError:
        return None
    if np.abs(g).sum(axis=0).max() * np.abs(g_inv).sum(axis=0).max() > 1e10:   # 1-norm condition
        return None
    x = (g_inv @ (rhs / scale[:, None])) / scale[:, None]
    inv00 = float(np.real(g_inv[0, 0])) / scale[0] ** 2
    out = []
    for q in range(rhs.shape[1]):
        rss = max(zz[q] - float(np.real(np.vdot(rhs[:, q], x[:, q]))), 0.0)  # |z|^2 - h^H G^-1 h
        sigma2_complex = rss / (n - m)                                    # E|r|^2 per sample
        var = max(0.5 * sigma2_complex * inv00, variance_floor)
        out.append(LockInSolution(complex(x[0, q]), var, complex(x[1, q]), t_ref, n, len(stats),
                                  float(np.sqrt(0.5 * sigma2_complex))))
    return out


class LockInEstimator:
    """Sliding window over the last `revolutions` revolutions, restarted whenever the sensor-to-
    platform arrangement changes (a flip), since the platform-frame bias then changes."""

    def __init__(self, revolutions: int, order: int, max_span_s: float, variance_floor: float = 0.0):
        self.revolutions = int(revolutions)
        self.order = int(order)
        self.max_span_s = float(max_span_s)
        self.variance_floor = variance_floor
        self._window: deque = deque()
        self._tag = None

    def add(self, stats: RevolutionStats, tag=None) -> None:
        if tag != self._tag:
            self._window.clear()
            self._tag = tag
        self._window.append(stats)
        while len(self._window) > self.revolutions:
            self._window.popleft()
        newest = stats.t_ref_s
        while self._window and newest - self._window[0].t_ref_s > self.max_span_s:
            self._window.popleft()

    def clear(self) -> None:
        self._window.clear()

    def estimate(self, t_ref_s: float | None = None) -> list[LockInSolution] | None:
        window = list(self._window)
        # Each extra body-signal term needs more than one turn to separate from the bias.
        order = min(self.order, max(len(window) - 1, 0))
        return solve(window, order, t_ref_s, self.variance_floor)
