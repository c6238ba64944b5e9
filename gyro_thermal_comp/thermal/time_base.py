"""`TimeBase`: one increasing internal time for a clock that may jump back.

A bag played in a loop, a simulator reset or a driver re-syncing its clock makes the stamps jump back.
The stream guards (input_guard.py) accept such a jump once enough samples continue it; here each
accepted backward jump of the IMU adds to an offset so that internal time = stamp + offset keeps
increasing and the jump reads as a time gap of `gap_s` (nothing is integrated across it, the heading
uncertainty grows, the drift window is discarded: the estimator's gap handling). The learned model is
untouched. Other streams follow the IMU's offsets in order: a stream whose own stamps step back by
more than `max_jump_s` moves on to the next offset the IMU has taken. Output rows keep the input stamps.
"""
from __future__ import annotations

import math

import numpy as np


_SMALL = 8   # up to this many stamps, `_no_step_back` works on Python floats


class TimeBase:
    def __init__(self, gap_s: float, max_jump_s: float):
        self.gap_s = float(gap_s)
        self.max_jump_s = float(max_jump_s)
        self.offsets = [0.0]        # one per IMU time base, s
        self._last_imu = -math.inf  # newest kept IMU stamp, s (input clock)
        self._epoch: dict[str, int] = {}       # per other stream: index into offsets
        self._pending: dict[str, bool] = {}    # stepped back, waiting for the IMU's next time base
        self._last: dict[str, float] = {}      # newest finite stamp in arrival order, s

    @property
    def changes(self) -> int:
        return len(self.offsets) - 1

    def imu(self, t: np.ndarray) -> np.ndarray:
        """Internal times (s) of kept IMU stamps `t` (increasing but across accepted backward jumps)."""
        if t.size == 0:
            return t
        if t[0] > self._last_imu and (t.size == 1 or (t[1:] > t[:-1]).all()):   # the usual case: no jump back
            self._last_imu = float(t[-1])
            return t + self.offsets[-1]
        step = np.diff(np.concatenate(([self._last_imu], t)))
        back = np.flatnonzero(step <= 0)
        offset = np.full(t.size, self.offsets[-1])
        for k in back.tolist():   # rare: one per accepted jump
            end = t[k - 1] if k > 0 else self._last_imu
            self.offsets.append(self.offsets[-1] + (end - t[k]) + self.gap_s)
            offset[k:] = self.offsets[-1]
        self._last_imu = float(t[-1])
        return t + offset

    def other(self, stream: str, t: np.ndarray) -> np.ndarray:
        """Internal times (s) of another stream's stamps `t`, in arrival order. A step back of more
        than `max_jump_s` moves the stream to the IMU's next time base, at once if the IMU has taken
        it, else as soon as it does (until then its samples read as old and are dropped)."""
        if t.size == 0:
            return t
        epoch = self._epoch.get(stream, 0)
        pending = self._pending.get(stream, False)
        last = self._last.get(stream, -math.inf)
        if not pending and t.size and _no_step_back(t, last, self.max_jump_s):
            # the usual case, without the loop: every stamp on the current time base
            self._epoch[stream], self._pending[stream], self._last[stream] = epoch, False, float(t[-1])
            return t + self.offsets[epoch]
        offset = np.empty(t.size)
        for k, tk in enumerate(t.tolist()):   # cheap: compass and temperature run at 1-100 Hz
            if tk < last - self.max_jump_s:
                pending = True
            if pending and epoch + 1 < len(self.offsets):
                epoch, pending = epoch + 1, False
            offset[k] = self.offsets[epoch]
            if math.isfinite(tk):
                last = tk
        self._epoch[stream], self._pending[stream], self._last[stream] = epoch, pending, last
        return t + offset


def _no_step_back(t: np.ndarray, last: float, max_jump_s: float) -> bool:
    """All stamps finite and none more than `max_jump_s` before its predecessor (`last` before the
    first): `other`'s loop would then keep every stamp on the current time base."""
    if t.size <= _SMALL:   # a live node's few stamps: cheaper as Python floats than any numpy call
        ts = t.tolist()
        return all(map(math.isfinite, ts)) and ts[0] >= last - max_jump_s and \
            all(b - a >= -max_jump_s for a, b in zip(ts, ts[1:]))
    lo, hi = float(t.min()), float(t.max())
    if not (math.isfinite(lo) and math.isfinite(hi)) or t[0] < last - max_jump_s:
        return False
    return t.size < 2 or not float(np.diff(t).min()) < -max_jump_s
