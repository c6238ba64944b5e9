"""The carousel angle and spin rate per sample: from the encoder, or from the integrated axial gyro.

Without an encoder the gyro cannot separate spin from body yaw, so the per-sample spin rate is the
axial mean over `gyro_spin_window_s`, and a rate too slow to complete a revolution counts as
stopped (docs/carousel.md, "Limitations").
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .config import CarouselConfig


@dataclass(frozen=True)
class AngleTrack:
    theta: np.ndarray     # (N,) carousel angle, rad, unwrapped
    spin: np.ndarray      # (N,) spin rate, rad/s
    raw: np.ndarray | None = None   # (N,) gyro mode: the uncorrected integral, rad


class CarouselAngle:
    """Continues the angle across runs; `reset()` where the gyro integral cannot be bridged (a data
    gap or a change of angle source), after which it continues from the last angle."""

    def __init__(self, config: CarouselConfig):
        self.config = config
        self._min_spin = 2.0 * np.pi / config.max_revolution_period_s
        self._last_theta = float(config.initial_angle_rad)
        self._last_raw = float(config.initial_angle_rad)   # the uncorrected gyro integral
        self._last_t = 0.0                  # last gyro-integrated sample, when _history_t is not empty
        self._last_axial = 0.0
        self._history_t = np.empty(0)       # recent gyro-mode (t, theta) for the spin-rate window
        self._history_theta = np.empty(0)

    def reset(self) -> None:
        self._history_t, self._history_theta = np.empty(0), np.empty(0)

    def from_encoder(self, angle: np.ndarray, rate: np.ndarray) -> AngleTrack:
        self._last_theta = self._last_raw = float(angle[-1])
        return AngleTrack(angle, rate)

    def from_gyro(self, t: np.ndarray, axial_rate: np.ndarray, correction=None) -> AngleTrack:
        """Trapezoid integral of the axial rate (bias removed) continuing the last angle, minus
        `correction(t, raw)` (rad; angle_reference.GravityAngleFilter) when given."""
        cfg = self.config
        if len(self._history_t):        # bridge the integral from the previous run's last sample
            times = np.concatenate(([self._last_t], t))
            rates = np.concatenate(([self._last_axial], axial_rate))
            raw = self._last_raw + np.cumsum(0.5 * (rates[1:] + rates[:-1]) * np.diff(times))
        else:       # start, or after a reset: cannot integrate across, continue from the last angle
            steps = 0.5 * (axial_rate[1:] + axial_rate[:-1]) * np.diff(t)
            raw = self._last_raw + np.concatenate(([0.0], np.cumsum(steps)))
        theta = raw if correction is None else raw - correction(t, raw)
        self._last_t, self._last_axial, self._last_raw = float(t[-1]), float(axial_rate[-1]), float(raw[-1])
        self._last_theta = float(theta[-1])
        history_t = np.concatenate((self._history_t, t))
        history_theta = np.concatenate((self._history_theta, theta))
        t_back = np.maximum(t - cfg.gyro_spin_window_s, history_t[0])
        span = t - t_back
        with np.errstate(invalid='ignore', divide='ignore'):
            spin = np.where(span > 0, (theta - np.interp(t_back, history_t, history_theta)) / span, 0.0)
        spin = np.where(np.abs(spin) >= self._min_spin, spin, 0.0)
        if cfg.nominal_spin_rate_rad_s is not None:
            spin = np.where(spin != 0.0, cfg.nominal_spin_rate_rad_s, 0.0)
        keep = history_t >= history_t[-1] - cfg.gyro_spin_window_s - 1.0
        self._history_t, self._history_theta = history_t[keep], history_theta[keep]
        return AngleTrack(theta, spin, raw)
