"""A stream's sampling period, as measured, and the durations that must follow it.

The estimator's durations have defaults for sensors at 5 Hz-1 kHz. A logger that keeps 1 Hz point
samples (an animal tag, a slow data logger) makes every IMU interval longer than a 0.5 s gap limit
and leaves one compass sample at each 1 s window edge. So each duration is a floor that the
stream's own period can raise:
- an interval is a time gap only beyond `GAP_PERIODS` periods (two samples missed) as well as
  beyond `max_gap_s`: between samples the rate is as unknown as the sampling leaves it, no more;
- no compass for `TIMEOUT_PERIODS` periods (two samples missed) as well as `mag_timeout_s` is no
  compass;
- each averaging span holds at least a few samples of the stream it averages (`at_least`): a drift
  window's edges `EDGE_SAMPLES`, the window `WINDOW_SAMPLES`, the gate's smoothing of the
  compass-gyro disagreement `SMOOTH_SAMPLES`. With white compass noise sigma_c and n samples per
  edge, a window of L s measures the drift to sigma_c sqrt(2 / n) / L: one sample per 1 s edge of a
  10 s window leaves 0.2 deg/s at 1.4 deg of compass noise, five per 5 s edge of a 50 s window 0.018.
Rates at or above 5 Hz (a 10 Hz compass, a 100 Hz IMU) change nothing.

The period is the running median of the last `PERIOD_INTERVALS` intervals, the newest included:
robust to jitter and to a missed sample, and it follows a stream that changes its rate.
"""
from __future__ import annotations

import math
from collections import deque

import numpy as np

PERIOD_INTERVALS = 16      # intervals in the running median
GAP_PERIODS = 3.0          # an IMU interval beyond this many periods is a time gap
TIMEOUT_PERIODS = 2.5      # no compass sample for this many periods: no compass
EDGE_SAMPLES = 5           # compass samples at each drift-window edge, at least
WINDOW_SAMPLES = 50        # compass samples in a drift window, at least
SMOOTH_SAMPLES = 5         # compass samples in the gate's mismatch smoothing, at least


def at_least(duration_s: float, period_s: float | None, samples: float) -> float:
    """`duration_s`, raised to hold `samples` sample periods, in whole multiples of itself (so grids
    built on it stay aligned); as it is when the period is unknown or the duration is 0."""
    if period_s is None or not period_s > 0 or duration_s <= 0:
        return duration_s
    return duration_s * max(1, math.ceil(samples * period_s / duration_s - 1e-9))


class SamplePeriod:
    """A stream's period: the running median of its last `PERIOD_INTERVALS` sample intervals."""

    def __init__(self):
        self._recent: deque = deque(maxlen=PERIOD_INTERVALS)

    @property
    def period_s(self) -> float | None:
        """The period in force now, s (None before two samples)."""
        return float(np.median(self._recent)) if self._recent else None

    def periods(self, dt: np.ndarray, where: np.ndarray | None = None) -> np.ndarray:
        """The period in force at each new interval `dt` (s), the newest included: at every one, or
        only where `where` is True (NaN elsewhere, cheaper). Takes the intervals in."""
        dt = np.asarray(dt, dtype=float)
        hist = np.concatenate((np.fromiter(self._recent, float, len(self._recent)), dt))
        pos = np.arange(len(self._recent), hist.size) if where is None else len(self._recent) + np.flatnonzero(where)
        out = np.full(dt.size, np.nan)
        if pos.size:
            k = PERIOD_INTERVALS
            full = pos >= k - 1
            if np.any(full):
                idx = pos[full][:, None] + np.arange(1 - k, 1)
                out[pos[full] - len(self._recent)] = np.median(hist[idx], axis=1)
            for p in pos[~full]:
                out[p - len(self._recent)] = np.median(hist[:p + 1])
        self._recent.extend(dt[-PERIOD_INTERVALS:].tolist())
        return out

    def gaps(self, dt: np.ndarray, min_gap_s: float) -> np.ndarray:
        """Time-gap flags for new intervals `dt` (s): beyond `min_gap_s` and `GAP_PERIODS` periods."""
        dt = np.asarray(dt, dtype=float)
        long = dt > min_gap_s
        per = self.periods(dt, long)
        return long & (dt > GAP_PERIODS * np.nan_to_num(per, nan=np.inf))

    def gap_one(self, dt: float, min_gap_s: float) -> bool:
        """`gaps` for one interval, in Python floats (a live node's per-sample cost)."""
        self._recent.append(dt)
        return dt > min_gap_s and dt > GAP_PERIODS * float(np.median(self._recent))

    def state(self) -> list[float]:
        return list(self._recent)
