"""Two-position flip: the main IMU turns 90 deg about an in-plane platform axis so that each of its
axes is, in one position or the other, in the plane of rotation and hence modulated (the paper's
answer to the unobservable axial bias). An auxiliary IMU fixed to the platform stands in while the
main one moves.

Position k means the main IMU is turned k quarter turns about the flip axis: v_platform =
flip_rotation(axis, k) @ v_imu. The flip axis is the same in both frames, so the main IMU's rate
about it minus the auxiliary IMU's is the flip motion alone; integrating that over a detected flip
gives the quarter turns moved. No extra sensor or schedule is needed.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

AXIS_INDEX = {'x': 0, 'y': 1}


def flip_rotation(axis: str, k: int) -> np.ndarray:
    """Exact rotation by k*90 deg about platform axis 'x' or 'y' (maps imu vectors to platform)."""
    c, s = [(1, 0), (0, 1), (-1, 0), (0, -1)][int(k) % 4]
    if axis == 'x':
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]], dtype=float)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]], dtype=float)


def platform_axis_to_imu(axis: str, k: int, platform_axis: int) -> tuple[int, float]:
    """Which imu axis (index, sign) lies along a platform axis in position k."""
    col = flip_rotation(axis, k)[platform_axis]      # row of R: e_p^T R = (R^T e_p)^T
    j = int(np.argmax(np.abs(col)))
    return j, float(col[j])


@dataclass(frozen=True)
class FlipEvent:
    t_start_s: float
    t_end_s: float
    angle_rad: float        # integrated main-minus-aux rate about the flip axis over the flip
    position_before: int
    position_after: int
    ambiguous: bool         # angle far from a multiple of 90 deg (position still rounded)


@dataclass(frozen=True)
class FlipRelease:
    """Decided samples of a `FlipTracker.release`: the n oldest pushed ones."""
    flipping: np.ndarray    # (n,) bool: part of a flip (or within guard_s of one)
    position: np.ndarray    # (n,) int: main IMU quarter turns about the flip axis


class FlipTracker:
    """Streaming flip detector with a look-ahead of `guard_s` (samples are held that long).

    push() relative rates r = main - aux about the flip axis, rad/s; release() returns, for the
    oldest samples whose +-guard neighbourhood is known, whether they belong to a flip and the
    position the main IMU is in."""

    def __init__(self, threshold_rad_s: float, guard_s: float, initial_position: int = 0,
                 max_angle_error_rad: float = 0.35):
        self.threshold = float(threshold_rad_s)
        self.guard = float(guard_s)
        self.position = int(initial_position) % 4
        self.max_angle_error = float(max_angle_error_rad)
        self._t = np.empty(0)
        self._r = np.empty(0)
        self._last_active_released = -np.inf
        # last released sample: the flip angle integral continues from it
        self._prev_t: float | None = None
        self._prev_rate = 0.0
        self._prev_flipping = False
        self._phi = 0.0
        self._flip_start = np.nan
        self.events: list[FlipEvent] = []

    @property
    def pending(self) -> int:
        return len(self._t)

    def push(self, t: np.ndarray, r: np.ndarray) -> None:
        self._t = np.concatenate((self._t, np.asarray(t, dtype=float)))
        self._r = np.concatenate((self._r, np.asarray(r, dtype=float)))

    def release(self, final: bool = False) -> FlipRelease:
        """Flip membership and position of the oldest pushed samples now decidable."""
        if len(self._t) == 0:
            return FlipRelease(np.zeros(0, bool), np.zeros(0, int))
        t_lim = np.inf if final else self._t[-1] - self.guard
        n = int(np.searchsorted(self._t, t_lim, side='right'))
        t, r = self._t[:n], self._r[:n]
        active_t = self._t[np.abs(self._r) > self.threshold]
        if np.isfinite(self._last_active_released):
            active_t = np.concatenate(([self._last_active_released], active_t))
        flipping = np.zeros(n, bool)
        if len(active_t) and n:
            j = np.searchsorted(active_t, t)
            before = np.where(j > 0, t - active_t[np.maximum(j - 1, 0)], np.inf)
            after = np.where(j < len(active_t), active_t[np.minimum(j, len(active_t) - 1)] - t, np.inf)
            flipping = np.minimum(before, after) <= self.guard
        position = np.full(n, self.position, dtype=int)
        if n:
            self._integrate(t, r, flipping, position)
            act = np.abs(r) > self.threshold
            if np.any(act):
                self._last_active_released = float(t[act][-1])
        self._t, self._r = self._t[n:], self._r[n:]
        return FlipRelease(flipping, position)

    def _integrate(self, t, r, flipping, position) -> None:
        """Integrate r over each flip; at its end, move `position` by the rounded quarter turns."""
        if self._prev_t is not None:
            times = np.concatenate(([self._prev_t], t))
            rates = np.concatenate(([self._prev_rate], r))
            moving = np.concatenate(([self._prev_flipping], flipping))
        else:
            times, rates, moving = t, r, flipping
        off = len(times) - len(t)
        seg = 0.5 * (rates[1:] + rates[:-1]) * np.diff(times) * (moving[1:] & moving[:-1])
        cum = np.concatenate(([0.0], np.cumsum(seg)))
        starts = np.flatnonzero(moving[1:] & ~moving[:-1]) + 1
        ends = np.flatnonzero(~moving[1:] & moving[:-1]) + 1       # first non-flipping index after a run
        in_flip = bool(moving[0])
        if in_flip and self._prev_t is None:       # data starts mid-flip
            self._phi, self._flip_start = 0.0, float(times[0])
        cursor = 0
        for idx in np.sort(np.concatenate((starts, ends))):
            if not in_flip:                                 # a flip begins at idx
                self._phi, self._flip_start = 0.0, float(times[idx])
                cursor, in_flip = idx, True
            else:                                           # the flip ended just before idx
                self._phi += cum[idx - 1] - cum[cursor]
                quarter = np.pi / 2
                steps = int(np.round(self._phi / quarter))
                before = self.position
                self.position = (self.position + steps) % 4
                self.events.append(FlipEvent(
                    self._flip_start, float(times[idx - 1]), self._phi, before, self.position,
                    abs(self._phi - steps * quarter) > self.max_angle_error))
                position[max(idx - off, 0):] = self.position
                in_flip, cursor = False, idx
        if in_flip:
            self._phi += cum[-1] - cum[cursor]
        self._prev_t, self._prev_rate, self._prev_flipping = float(t[-1]), float(r[-1]), bool(flipping[-1])
