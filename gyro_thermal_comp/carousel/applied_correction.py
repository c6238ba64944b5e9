"""The correction the encoder-free carousel angle has applied, and how it follows the filter's updates.

The angle in use is theta = raw - corr, with corr the gyro angle's modelled error

    corr(t) = off + b * (t - t0) + s * (raw(t) - raw0)

of the estimate x the angle follows (angle_reference.GravityAngleFilter's, as it stood at the last update that
took effect), plus on a wheel the axle-tilt integral (wheel_reference.AxleTilt). The origin (t0, raw0) is the
first sample: the frame is fixed there. An update made at a revolution's end takes effect at the next point of
a STEP_S grid, so results do not depend on how the data is chunked, and is slewed in over the revolution's
duration from the correction last applied (theta never jumps). What was applied is remembered over the last
few revolutions: a revolution measures the error of the angle it was demodulated with, whatever the slew.
Units: rad, s.
"""
from __future__ import annotations

import numpy as np

from .wheel_reference import AxleTilt

# Without an encoder the angle is computed in steps on this grid (s): an update made at a revolution
# end takes effect at the next grid point, so results do not depend on how the data is chunked.
STEP_S = 0.05


def grid_after(t_s: float) -> float:
    """The first step boundary after t_s: an update takes effect there, whatever the chunking."""
    return (np.floor(t_s / STEP_S) + 1.0) * STEP_S


class AppliedCorrection:
    """The model the angle in use follows, its updates waiting to take effect, and the correction applied."""

    def __init__(self, n_states: int, keep_s: float, tilt: AxleTilt | None):
        self.t0: float | None = None        # origin of the model's time and angle terms
        self.raw0 = 0.0
        self.x = np.zeros(n_states)         # the estimate the angle in use follows (updates take effect later)
        self._keep_s = keep_s               # how long the applied correction is remembered, s
        self._tilt = tilt                   # (wheel) the axle-tilt integral, a known part of the error
        self._queue: list = []              # (grid time, x or None, duration[, zeta]) updates waiting to take effect
        self._t, self._raw, self._corr = np.empty(0), np.empty(0), np.empty(0)   # applied, recent
        self._tilt_int = np.empty(0)        # the axle-tilt integral within the applied correction
        self._slew = (0.0, 0.0, 1.0)        # (t_a, pending rad at t_a, duration s)

    @property
    def last_t(self) -> float | None:
        """Time of the last sample a correction was applied to (None before any)."""
        return float(self._t[-1]) if len(self._t) else None

    def model(self, t, raw):
        x = self.x
        return x[0] + x[1] * (t - self.t0) + x[2] * (raw - self.raw0)

    def follow(self, t: np.ndarray, raw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(correction at samples (t, raw), rad; the axle-tilt integral within it): the model in effect, the
        updates due taken in first, plus what is still being slewed in."""
        tilt = np.zeros(len(t))
        # updates take effect where a grid cell starts (the previous sample lies in an earlier cell):
        # then every chunking of the data applies them to the same samples
        new_cell = not len(self._t) or np.floor(t[0] / STEP_S) > np.floor(self._t[-1] / STEP_S)
        while new_cell and self._queue and len(t) and self._queue[0][0] <= t[0]:
            self._activate(*self._queue.pop(0))
        corr = self.model(t, raw)
        if self._tilt is not None:     # the axle-tilt integral: a known part of the error
            tilt = self._tilt.at(t)
            corr = corr + tilt
        t_a, pending, dur = self._slew
        corr = corr + pending * np.clip(1.0 - (t - t_a) / dur, 0.0, 1.0)
        return corr, tilt

    def remember(self, t: np.ndarray, raw: np.ndarray, corr: np.ndarray, tilt: np.ndarray) -> None:
        """The correction applied at samples (t, raw), kept for the last `keep_s`."""
        self._t = np.concatenate((self._t, t))
        self._raw = np.concatenate((self._raw, raw))
        self._corr = np.concatenate((self._corr, corr))
        self._tilt_int = np.concatenate((self._tilt_int, tilt))
        keep = self._t >= self._t[-1] - self._keep_s
        self._t, self._raw, self._corr = self._t[keep], self._raw[keep], self._corr[keep]
        self._tilt_int = self._tilt_int[keep]

    def at(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(applied correction, the axle-tilt integral within it) at times t, rad (interpolated)."""
        return np.interp(t, self._t, self._corr), np.interp(t, self._t, self._tilt_int)

    def schedule(self, t_s: float, x: np.ndarray | None, duration: float, zeta: float | None = None) -> None:
        """An update made at t_s: follow estimate x (None: keep the model) over `duration` from the first grid
        point after t_s; (wheel) the axle-tilt rate zeta, rad/s, for as long."""
        self._queue.append((grid_after(t_s), x, duration, zeta))

    def _activate(self, t_act: float, x: np.ndarray | None, duration: float, zeta: float | None = None) -> None:
        """From the correction applied to the last sample, move to the model of x over `duration`; (wheel)
        integrate the axle-tilt rate zeta from there for as long (wheel_reference.AxleTilt)."""
        if not len(self._t):
            self.x = self.x if x is None else x
            return
        t_a, raw_a = float(self._t[-1]), float(self._raw[-1])
        if x is not None:
            applied = float(self._corr[-1]) - float(self._tilt_int[-1])
            self.x = x
            self._slew = (t_a, applied - float(self.model(t_a, raw_a)), max(duration, 1e-3))
        if zeta is not None:
            self._tilt.activate(t_a, zeta, duration)
