"""Spin coupling of the in-plane gyro biases, learnt so the output at rest is clean.

A turning table adds k * Omega to the in-plane biases (gyro cross-axis, sensor z tilted against the
spin axis), so the lock-in bias measured while turning is wrong at rest by k * Omega. Per platform
in-plane axis (x + i y, complex; both axes share H, hence one real covariance):

    bias(Omega) = b0(t) + k * Omega,      x = [b0 rad/s, k rad/s per rad/s]

b0 walks (thermal drift, bias instability); k is constant. Measurements: every clean revolution's own
bias at its time-mean spin (H = [1, Omega]; record_assembly fits the spin ramp inside the revolution), and
the start-up still stretch if the body was at rest (H = [1, 0]: raw in-plane mean less the body's (Earth's)
in-plane rate, as the demodulated revolutions after it measure it over EARTH_AVERAGE_S; the revolutions
meanwhile wait and follow it in time order). Later stops are not used: at
rest the in-plane gyro cannot tell a bias from the body's own rate. Different spin rates (start-up
still, rate steps, a stop) separate k from b0; at one rate alone k stays at its prior and nothing
changes. `bias_at(Omega)` is what to remove at rest once b0 is known to `spin_coupling_rest_sigma_rad_s`
(a wobble of a few % alone does not get there; a still start or a rate step does).
"""
from __future__ import annotations

import numpy as np

from ..constants import EARTH_RATE_RAD_S
from .config import CarouselConfig

# The still start's Earth-rate correction is the mean demodulated body rate over this much spinning (or
# the still's length if longer, or what there is at the first stop), s: over the still's own 60 s its
# noise equalled the still mean's and dominated the error of k * Omega at rest.
EARTH_AVERAGE_S = 600.0


class SpinCoupling:
    def __init__(self, config: CarouselConfig):
        self.config = config
        self.x = np.zeros(2, dtype=complex)
        self.p = np.diag([config.angle_ref_bias_sigma_rad_s ** 2, config.spin_coupling_sigma ** 2])
        self._t: float | None = None
        self.revolutions = 0
        self.still_intervals = 0
        self._still = None          # still-start measurement waiting for the body rate of the revolutions after it
        self._pending = []          # revolution measurements held back meanwhile (applied in time order)
        self.rejected = 0

    @property
    def known(self) -> bool:
        """b0 known well enough to use at rest (spin rates far enough apart), after at least one revolution.
        No side effects: diagnostics read it at wall-clock moments."""
        return bool(self.config.spin_coupling and self.revolutions > 0
                    and np.sqrt(self.p[0, 0]) < self.config.spin_coupling_rest_sigma_rad_s)

    @property
    def waiting_s(self) -> float | None:
        """Seconds of the still start's Earth-rate average gathered while it waits (None: not waiting)."""
        return None if self._still is None else float(self._still['seconds'])

    def for_rest(self) -> bool:
        """Called where a record at rest needs b0 + k * Omega: a still-start measurement still waiting
        for its Earth-rate average is applied with what there is. Then `known`."""
        if self._still is not None and self.revolutions:
            self._apply_still()
        return self.known

    def bias_at(self, omega_rad_s: float) -> complex:
        """Platform in-plane gyro bias (x + i y, rad/s) at spin rate omega."""
        return complex(self.x[0] + self.x[1] * omega_rad_s)

    def on_still(self, still) -> None:
        """The start-up still stretch (still_start.StillStart), if the body was at rest: the raw
        in-plane gyro mean is b0 at zero spin plus the body's rate (the Earth's, up to 7.3e-5 rad/s, in
        the platform frame at the initial angle). The body's rate is taken from the demodulated
        revolutions that follow (as long again as the still stretch), so the measurement and the
        revolutions are applied once those are in."""
        if not (self.config.spin_coupling and not self.config.flip.enabled and still.accepted):
            return
        g = still.gyro_mean
        self._still = {'t': still.t1, 'duration': still.duration_s, 'raw': complex(g[0], g[1]),
                       'var': 0.5 * float(still.gyro_var[0] + still.gyro_var[1]) / still.n,
                       'turn': np.exp(-1j * self.config.initial_angle_rad), 'rate_sum': 0j, 'seconds': 0.0,
                       'var_sum': 0.0}

    def add_revolution(self, t_s: float, omega_rad_s: float, bias: complex, variance: float,
                       body_rate: complex) -> None:
        """One clean revolution: its own in-plane bias (variance per component, (rad/s)^2) and its
        demodulated in-plane body rate (carousel frame, rad/s)."""
        self.revolutions += 1
        st = self._still
        if st is None:
            self._update(t_s, omega_rad_s, bias, variance)
            return
        self._pending.append((t_s, omega_rad_s, bias, variance))
        duration = t_s - (st['t'] if not st['seconds'] else st['last'])
        st['rate_sum'] += body_rate * duration
        st['var_sum'] += variance * duration ** 2      # the body rate is a mean of the same samples
        st['seconds'] += duration
        st['last'] = t_s
        if st['seconds'] >= max(st['duration'], EARTH_AVERAGE_S):
            self._apply_still()

    def _apply_still(self) -> None:
        st, self._still = self._still, None
        if st is None:
            return
        body = st['rate_sum'] / st['seconds'] if st['seconds'] > 0 else 0j
        r = st['var'] + (st['var_sum'] / st['seconds'] ** 2 if st['seconds'] > 0 else EARTH_RATE_RAD_S ** 2)
        if self._update(st['t'], 0.0, st['raw'] - st['turn'] * body, r):
            self.still_intervals += 1
        for m in self._pending:
            self._update(*m)
        self._pending = []

    def _update(self, t_s: float, omega: float, y: complex, r: float) -> bool:
        """One measurement y = b0 + k * omega (complex, variance r per component)."""
        cfg = self.config
        if self._t is not None and t_s > self._t:
            self.p[0, 0] += cfg.spin_coupling_bias_walk_rad_s_rts ** 2 * (t_s - self._t)
        self._t = t_s if self._t is None else max(self._t, t_s)
        h = np.array([1.0, omega])
        innov = y - h @ self.x
        s = float(h @ self.p @ h + r)
        if abs(innov) ** 2 > 2 * cfg.angle_ref_gate_sigma ** 2 * s:     # |complex|^2: two components
            self.rejected += 1
            return False
        k = self.p @ h / s
        self.x = self.x + k * innov
        self.p = self.p - np.outer(k, h @ self.p)
        self.p = 0.5 * (self.p + self.p.T)
        return True
