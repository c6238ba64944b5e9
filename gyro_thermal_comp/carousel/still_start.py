"""The start-up still stretch: platform not yet turning, body at rest (the node's "still start").

It lasts from the first sample to the first whose axial rate exceeds `still_rate_rad_s`. Accepted
only if the body did not move either: the specific force of the first and the last second agree to
`still_accel_tol_m_s2` (a body turning about a horizontal axis turns gravity in the sensor frame).
Then it tells the gravity angle filter where gravity (and the magnetometer reference where the field)
lies at the known initial angle, and the spin coupling the in-plane gyro bias at zero spin. Raw
platform-frame samples; units rad/s, m/s^2, T, s.

The platform starts turning before its rate passes the threshold: a spin-up whose rate grows as the square of
the time (a sin^2 ramp) has turned by threshold x time / 3 when it gets there (0.5 Hz in 2 s: 2.7e-3 rad; in
5 s: 6.7e-3 rad), which the gyro integral over the stretch would count as axial bias (a 60 s still and a 5 s
spin-up: 1.1e-4 rad/s, 7 sigma of that measurement on the simulated MTi-1). `rest_end` is therefore where the rate left the noise band of the stretch's mean before
that: the start of the last 0.2 s whose mean axial rate is within 3 sigma of it (by its end a spin-up growing as
the time squared may be most of the way to the threshold), looking back from the end over the last `_TAIL_S`.
"""
from __future__ import annotations

import numpy as np

from .config import CarouselConfig

_EDGE_S = 1.0       # length of the first and last pieces compared for the body-at-rest check, s
_TAIL_S = 5.0       # the end of the stretch searched for the spin-up's onset, s
_ONSET_S = 0.2      # the spin-up's onset: windows of this length whose mean rate leaves the noise band, s
_ONSET_SIGMA = 3.0


class StillStart:
    def __init__(self, config: CarouselConfig):
        self.config = config
        self.open = True
        self.accepted = False
        self.reason = 'not seen yet'
        self.t0 = self.t1 = None
        self.n = 0
        self.gyro_sum = np.zeros(3)
        self.accel_sum = np.zeros(3)
        self.gyro_sq = np.zeros(3)       # for the per-sample variance
        self._first = (np.zeros(3), 0)   # accel sum, count over the first _EDGE_S
        self._last = []                  # recent (t, accel) for the last _EDGE_S
        self.raw_angle = (0.0, 0.0)      # integrated axial gyro at t0, t1 (for the angle filter)
        self.rest_end = (None, 0.0)      # (time s, integrated axial gyro) where the spin-up began (close)
        self._tail = []                  # recent (t, axial rate, integrated axial gyro), the last _TAIL_S
        self._head = np.zeros(3)         # count, sum and sum of squares of the axial rate before the tail
        self.mag_sum = np.zeros(3)       # raw magnetometer (samples with mag_ok), T
        self.mag_n = 0
        self._listeners = []

    def on_close(self, callback) -> None:
        """callback(still) when the stretch ends (accepted or not)."""
        self._listeners.append(callback)

    @property
    def duration_s(self) -> float:
        return 0.0 if self.t0 is None else self.t1 - self.t0

    @property
    def gyro_mean(self) -> np.ndarray:
        return self.gyro_sum / max(self.n, 1)

    @property
    def accel_mean(self) -> np.ndarray:
        return self.accel_sum / max(self.n, 1)

    @property
    def gyro_var(self) -> np.ndarray:
        """Per-sample variance of the gyro, (rad/s)^2 per axis."""
        return np.maximum(self.gyro_sq / max(self.n, 1) - self.gyro_mean ** 2, 0.0)

    @property
    def mag_mean(self) -> np.ndarray | None:
        """Mean raw magnetometer over the stretch, T (None without magnetometer samples)."""
        return self.mag_sum / self.mag_n if self.mag_n else None

    def add(self, t: np.ndarray, gyro: np.ndarray, accel: np.ndarray, raw_angle: np.ndarray | None = None,
            mag: np.ndarray | None = None, mag_ok: np.ndarray | None = None) -> None:
        if not self.open or not len(t):
            return
        moving = np.flatnonzero(np.abs(gyro[:, 2]) > self.config.still_rate_rad_s)
        n = int(moving[0]) if len(moving) else len(t)
        if n:
            if self.t0 is None:
                self.t0 = float(t[0])
                self.raw_angle = (0.0 if raw_angle is None else float(raw_angle[0]), 0.0)
            g, a = gyro[:n], accel[:n]
            self.n += n
            self.gyro_sum += g.sum(axis=0)
            self.gyro_sq += (g ** 2).sum(axis=0)
            self.accel_sum += a.sum(axis=0)
            if mag is not None:
                ok = mag_ok[:n]
                self.mag_sum += mag[:n][ok].sum(axis=0)
                self.mag_n += int(ok.sum())
            first = t[:n] < self.t0 + _EDGE_S
            s, c = self._first
            self._first = (s + a[first].sum(axis=0), c + int(first.sum()))
            self._last.append((t[:n], a))
            while len(self._last) > 1 and self._last[1][0][0] < t[n - 1] - _EDGE_S:
                self._last.pop(0)
            raw = np.zeros(n) if raw_angle is None else np.asarray(raw_angle[:n], dtype=float)
            self._tail.append((t[:n], g[:, 2], raw))
            while len(self._tail) > 1 and self._tail[1][0][0] < t[n - 1] - _TAIL_S:
                old = self._tail.pop(0)[1]
                self._head += (len(old), old.sum(), (old ** 2).sum())
            self.t1 = float(t[n - 1])
            self.raw_angle = (self.raw_angle[0], 0.0 if raw_angle is None else float(raw_angle[n - 1]))
        if len(moving):
            self.close(turning=True)

    def close(self, turning: bool = False) -> None:
        """The stretch ends: the platform starts `turning`, or a data gap (then it never did)."""
        if not self.open:
            return
        self.open = False
        cfg = self.config
        self.rest_end = self._onset() if turning else (self.t1, self.raw_angle[1])
        if self.t0 is None or self.duration_s < 2 * _EDGE_S:
            self.reason = 'no still start (under 2 s before the platform turned)'
        else:
            ts = np.concatenate([p[0] for p in self._last])
            acc = np.concatenate([p[1] for p in self._last])
            last = acc[ts >= self.t1 - _EDGE_S].mean(axis=0)
            first = self._first[0] / max(self._first[1], 1)
            moved = float(np.linalg.norm(last - first))
            if moved > cfg.still_accel_tol_m_s2:
                self.reason = (f'body moved during the still start: specific force changed {moved:.3g} m/s^2 > '
                               f'{cfg.still_accel_tol_m_s2:g}')
            else:
                self.accepted = True
                self.reason = f'still start of {self.duration_s:.1f} s'
        self._last, self._tail = [], []
        for callback in self._listeners:
            callback(self)

    def _onset(self) -> tuple:
        """(time s, integrated axial gyro) where the spin-up left the stretch's noise band (module docstring);
        the tail's start if it never was inside it (a spin-up longer than _TAIL_S)."""
        if not self._tail:
            return self.t1, self.raw_angle[1]
        t, rate, raw = (np.concatenate([p[i] for p in self._tail]) for i in range(3))
        count, total, squares = self._head
        if count < 2:               # a stretch no longer than the tail: its own mean, no onset to find
            return self.t1, self.raw_angle[1]
        mean = total / count
        sigma = np.sqrt(max(squares / count - mean ** 2, 0.0))
        m = max(int(round(_ONSET_S / max((t[-1] - t[0]) / max(len(t) - 1, 1), 1e-9))), 1)
        if len(t) < m:
            return self.t1, self.raw_angle[1]
        window = np.convolve(rate, np.ones(m) / m, mode='valid')      # window k: samples k .. k + m - 1
        inside = np.flatnonzero(np.abs(window - mean) <= _ONSET_SIGMA * sigma / np.sqrt(m))
        if not len(inside):
            return float(t[0]), float(raw[0])
        k = int(inside[-1])         # the last window at rest: its start (by its end the spin-up may be under way)
        return float(t[k]), float(raw[k])
