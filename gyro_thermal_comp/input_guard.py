"""`StreamGuard`: the one input-hygiene rule of the package, with one set of counter names.

Every stream (IMU, magnetometer, temperature, encoder, auxiliary IMU; in the cores and in the nodes'
stamp merger) keeps a sample only if its stamp and values are all finite and its stamp is strictly
after the last kept stamp of that stream. Everything downstream may then assume finite values and
strictly increasing stamps, in any chunking: the rule depends only on the samples kept before.
"""
from __future__ import annotations

import math

import numpy as np


class StreamGuard:
    """Keeps finite samples with increasing stamps; counts what it drops.

    Counters (`counters()`): `<name>_dropped_nonfinite` (NaN or inf in the stamp or any value) and
    `<name>_dropped_order` (stamp repeated or not after the last kept one)."""

    def __init__(self, name: str):
        self.name = name
        self.last_t = -math.inf       # newest kept stamp, s
        self.first_t = math.inf       # first kept stamp, s
        self.dropped_nonfinite = 0
        self.dropped_order = 0

    def keep(self, t: np.ndarray, *values: np.ndarray) -> np.ndarray:
        """Boolean mask over the rows of `t` (s) to keep; each of `values` has one row per stamp."""
        t = np.asarray(t, dtype=float).reshape(-1)
        if t.size == 0:
            return np.zeros(0, dtype=bool)
        if t.size == 1:       # the live path: one sample per call, no array machinery
            return np.array([self.keep_one(float(t[0]), *values)])
        finite = np.isfinite(t)
        for v in values:
            finite &= np.all(np.isfinite(np.asarray(v, dtype=float).reshape(t.size, -1)), axis=1)
        # kept stamps increase, so "after the last kept one" is "after every earlier finite row"
        tf = np.where(finite, t, -np.inf)
        prev_max = np.maximum.accumulate(np.concatenate(([self.last_t], tf)))[:-1]
        ok = finite & (t > prev_max)
        self.dropped_nonfinite += int(t.size - np.count_nonzero(finite))
        self.dropped_order += int(np.count_nonzero(finite & ~ok))
        if np.any(ok):
            self._kept(float(t[ok][0]), float(t[ok][-1]))
        return ok

    def keep_one(self, t: float, *values) -> bool:
        """`keep` for one sample: True if (t, values) is finite and t is after the last kept stamp."""
        if not (math.isfinite(t) and all(bool(np.all(np.isfinite(v))) for v in values)):
            self.dropped_nonfinite += 1
            return False
        if t <= self.last_t:
            self.dropped_order += 1
            return False
        self._kept(t, t)
        return True

    def _kept(self, first: float, last: float) -> None:
        if self.first_t == math.inf:
            self.first_t = first
        self.last_t = last

    @property
    def dropped(self) -> int:
        return self.dropped_nonfinite + self.dropped_order

    def counters(self) -> dict[str, int]:
        return {f'{self.name}_dropped_nonfinite': self.dropped_nonfinite,
                f'{self.name}_dropped_order': self.dropped_order}
