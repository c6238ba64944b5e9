"""Gravity's in-plane specific force in the carousel frame: the reference of the encoder-free carousel angle.

With the spin axis tilted, specific force has an in-plane component w (g sin(tilt)) fixed in the carousel
frame; a revolution demodulated with the angle in use is compared with its direction there, w_ref
(angle_reference.GravityAngleFilter). From the still start: its raw platform mean at `initial_angle_rad`, less
the platform in-plane accelerometer bias. The lock-in bias in use averages a few revolutions only (~4e-4 m/s^2
of noise on an MTi-1 at 0.5 Hz, 0.05 deg at 0.5 m/s^2 in-plane): the reference takes a long average of it
(ACCEL_BIAS_MEMORY_S). Without a still start: the first revolution's, on a wheel less that revolution's road
acceleration a (wheel_reference: across gravity, c = w_ref (|w_ref| + i a) / |w_ref|); such a reference is turned
by the gyro angle's error over that revolution, so the filter learns its direction. Units: m/s^2, rad, s.
"""
from __future__ import annotations

import numpy as np

ACCEL_BIAS_MEMORY_S = 600.0   # memory of the accelerometer bias average behind the reference, s


class GravityReference:
    """The still start's or the first revolution's in-plane specific force; `reference()` is w_ref."""

    def __init__(self, initial_angle_rad: float):
        self.initial_angle_rad = initial_angle_rad
        self.from_still = False             # the still start gave the reference
        self._still_accel = 0j              # raw platform in-plane specific force of the still start
        self.first: complex | None = None   # reference from the first revolution, carousel frame (no still start)
        self.accel_bias = 0j                # platform in-plane accel bias (long average of the lock-in's), m/s^2
        self._bias_sum, self._bias_weight = 0j, 0.0

    def on_still(self, still) -> None:
        """The body was at rest over the still start (still_start.StillStart, accepted): its mean is the reference."""
        self.from_still = True
        self._still_accel = complex(still.accel_mean[0], still.accel_mean[1])

    def average_bias(self, accel_bias: complex, duration: float) -> None:
        """A revolution of `duration` s with the lock-in's platform in-plane accel bias in use."""
        keep = np.exp(-duration / ACCEL_BIAS_MEMORY_S)
        self._bias_sum = keep * self._bias_sum + duration * accel_bias
        self._bias_weight = keep * self._bias_weight + duration
        self.accel_bias = self._bias_sum / self._bias_weight

    @property
    def wanted(self) -> bool:
        """No reference yet: the next revolution gives it."""
        return self.first is None and not self.from_still

    def take_first(self, accel_carousel: complex, road_accel_m_s2: float | None) -> None:
        """The first revolution's demodulated in-plane specific force (carousel frame) as the reference; on a wheel
        less its road acceleration, m/s^2 (None: not on a wheel)."""
        self.first = accel_carousel
        if road_accel_m_s2 is None:
            return
        a = road_accel_m_s2
        g2 = abs(accel_carousel) ** 2 - a ** 2         # |w_ref|^2: the road acceleration is across it
        if g2 <= 0.0:
            return
        self.first = complex(accel_carousel * np.sqrt(g2) / (np.sqrt(g2) + 1j * a))

    def reference(self) -> complex:
        """w_ref, carousel frame, m/s^2."""
        if self.from_still:      # the still start at initial_angle_rad, lock-in accel bias removed
            return complex(np.exp(1j * self.initial_angle_rad) * (self._still_accel - self.accel_bias))
        return self.first
