"""Input hygiene and growable column buffers for the streaming carousel core (pure numpy).

Streams arrive in chunks of any size (one sample from a live node up to hour-long arrays). Bad
samples are dropped here and counted, so nothing downstream ever sees NaN or non-increasing stamps.
"""
from __future__ import annotations

from collections import Counter

import numpy as np


class StreamGate:
    """Drops non-finite rows and stamps that do not increase (repeated or out of order), with counts.

    A stamp is kept only if it is later than every finite stamp seen before on this stream, so the
    kept stamps are strictly increasing across chunks."""

    def __init__(self, name: str, counts: Counter):
        self.name = name
        self.last_t = -np.inf
        self.first_t = np.inf        # first kept stamp, s
        self._counts = counts

    def filter(self, t: np.ndarray, *required: np.ndarray) -> np.ndarray:
        """Boolean mask of the samples to keep; `required` rows must all be finite."""
        t = np.asarray(t, dtype=float)
        finite = np.isfinite(t)
        for arr in required:
            a = np.asarray(arr, dtype=float).reshape(len(t), -1)
            finite &= np.all(np.isfinite(a), axis=1)
        tf = np.where(finite, t, -np.inf)
        prev_max = np.maximum.accumulate(np.concatenate(([self.last_t], tf)))[:-1]
        keep = finite & (t > prev_max)
        n_bad = int(np.count_nonzero(~finite))
        n_order = int(np.count_nonzero(finite & ~keep))
        if n_bad:
            self._counts[f'{self.name}_nonfinite'] += n_bad
        if n_order:
            self._counts[f'{self.name}_not_increasing'] += n_order
        if len(tf):
            self.last_t = max(self.last_t, float(tf.max()))
        if np.any(keep) and not np.isfinite(self.first_t):
            self.first_t = float(t[keep][0])
        return keep


class Columns:
    """Append-only table of equally long numpy columns with a movable head (cheap front drops)."""

    def __init__(self, spec: dict):
        """spec: column name -> (trailing shape tuple, dtype)."""
        self._spec = spec
        self._cap = 256
        self._data = {k: np.empty((self._cap,) + tail, dtype=dt) for k, (tail, dt) in spec.items()}
        self._head = 0
        self._size = 0

    def __len__(self) -> int:
        return self._size - self._head

    def __getitem__(self, name: str) -> np.ndarray:
        return self._data[name][self._head:self._size]

    def append(self, **cols) -> None:
        n = len(next(iter(cols.values())))
        if n == 0:
            return
        if self._size + n > self._cap:
            live = len(self)
            if self._head and live + n <= self._cap // 2:
                new_cap = self._cap  # compacting is enough
            else:
                new_cap = max(2 * self._cap, live + n + 256)
            for k, (tail, dt) in self._spec.items():
                fresh = np.empty((new_cap,) + tail, dtype=dt)
                fresh[:live] = self._data[k][self._head:self._size]
                self._data[k] = fresh
            self._cap, self._head, self._size = new_cap, 0, live
        for k in self._spec:
            self._data[k][self._size:self._size + n] = cols[k]
        self._size += n

    def drop_front(self, n: int) -> None:
        self._head = min(self._head + max(int(n), 0), self._size)

    def clear(self) -> None:
        self._head = self._size = 0

    def take_front(self, n: int) -> dict:
        """Copy of the first n rows of every column, removed from the table."""
        out = {k: self[k][:n].copy() for k in self._spec}
        self.drop_front(n)
        return out
