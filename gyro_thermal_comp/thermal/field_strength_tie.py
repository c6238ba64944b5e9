"""The heading filter's second measurement of the compass deviation: the horizontal field strength.

The horizontal field strength ties the deviation down before the headings repeat (`norm_tie`).
The hard and soft iron that turn the measured horizontal field by delta(psi) also stretch it; to
first order, with the same coefficients,
    |B_h| / B_h0 - 1 = beta + sum_n d_cn sin n psi_c - d_sn cos n psi_c
(a hard iron h in body x, y: d_c1 = h_x / B_h, d_s1 = -h_y / B_h; a symmetric soft iron E: d_c2 =
E_xy, d_s2 = (E_xx - E_yy) / 2; this compass's atan2(m_x, m_y) convention). The horizontal
strength, not the total: soft iron that couples the vertical field into the horizontal (E_xz B_z)
looks like hard iron to the heading and to |B_h| alike, but enters |B| twice over (through E_zx
too); on a simulated drive the total strength put the map 1.5 deg off and the scale factor's sign
wrong. |B_h| is levelled with the same tilt as the heading and shares its errors: tan(dip) x the
tilt error, 1 % in 20 s within one straight of the simulated drives as the speed changes. So beta,
a random walk, takes that (and the magnetometer's gain, -0.3 %/K for the simulated one, and the
local field), and what the tie learns is the step in |B_h| across a turn. Taken as white noise it
was averaged down and over-trusted: a slow random walk (1e-7 /s) let one of ten family-A drives
diverge (78 deg), and with a 0.5 % white floor added another learned a map that then refused the
compass until the lap closed (7.6 deg). Without the tie a vehicle with an uncalibrated compass
(6-9 deg of hard iron in the simulated drives) cannot tell a scale-factor error from the deviation
until enough headings have been seen: the first lap's error grows as k x the angle turned (5 deg
per lap at k = 1.5 %). The radial noise of an isotropic magnetometer is independent of the
tangential: the same variance as the heading's, and no noise shared with the heading measurement.
Used where the heading measurement is (the gate open, its innovation test passed), with its own
innovation test.
"""
from __future__ import annotations

import math

import numpy as np


class FieldStrengthTie:
    """r = |B_h| / B_h0 - 1 as a measurement of a heading filter's state of size `n`: beta at index
    `i_b`, the deviation harmonics n = 1..`harmonics` as (d_cn, d_sn) pairs from index `i_d`."""

    def __init__(self, n: int, i_b: int, i_d: int, harmonics: int):
        self.n, self.i_b, self.i_d, self.harmonics = n, i_b, i_d, harmonics
        self.b_ref_t = math.nan      # horizontal field strength B_h0 at the first sample, T

    def start(self, b_h_t: float) -> None:
        """B_h0 from the first compass sample's horizontal field strength, T (NaN or not positive: no
        field-strength updates)."""
        self.b_ref_t = float(b_h_t) if math.isfinite(b_h_t) and b_h_t > 0 else math.nan

    def rows(self, psi_c: np.ndarray, b_h_t):
        """For the field-strength updates: (per block r = |B_h| / B_h0 - 1 as a list, finite?, the
        rows g (m, n) of r = g . x at the compass headings psi_c, rad), or None without a strength."""
        if b_h_t is None or not math.isfinite(self.b_ref_t):
            return None
        r = np.broadcast_to(np.asarray(b_h_t, dtype=float), psi_c.shape) / self.b_ref_t - 1.0
        g = np.zeros((psi_c.size, self.n))
        g[:, self.i_b] = 1.0
        for k in range(1, self.harmonics + 1):
            j = self.i_d + 2 * k - 2
            g[:, j] = np.sin(k * psi_c)
            g[:, j + 1] = -np.cos(k * psi_c)
        return r.tolist(), np.isfinite(r).tolist(), g

    @staticmethod
    def update(x: np.ndarray, P: np.ndarray, g: np.ndarray, r: float, r_var: float, reject2: float) -> None:
        """One measurement r = g . x + noise of variance r_var into the state x and covariance P (in
        place), refused where its innovation exceeds sqrt(reject2) standard deviations (0: no test)."""
        nu = r - float(g.dot(x))
        pg = P.dot(g)
        s = float(g.dot(pg)) + r_var
        if reject2 > 0 and nu * nu > reject2 * s:
            return
        x += pg * (nu / s)
        P -= pg.reshape(-1, 1).dot((pg / s).reshape(1, -1))
