"""The reference window: e0, the heading error offset of each method and of the oracle.

The heading error is scored as e = e_raw - e0, where e0 is the mean of the continuous raw error
over the first `reference_window_s` (60 s) of scored samples (docs/design.md section 5), so that a
method is not charged for the heading it started from. Scored batches wait here until the window
is complete. A method without a finite error inside the window takes its first finite error as e0.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from .scored_rows import ScoredRows


class ReferenceWindow:
    """e0 per name (`names`: the methods and the oracle) from scored batches fed in time order."""

    def __init__(self, window_s: float, names: Sequence[str]):
        self.window_s = window_s
        self.names = list(names)
        self.t_first: float | None = None                 # time of the first scored sample, s
        self._batches: list[ScoredRows] | None = []       # held while the window fills (None: complete)
        self.e0: dict[str, float] = {}

    def add(self, rows: ScoredRows) -> list[ScoredRows]:
        """The batches that can be scored now: none while the window fills, every batch held once it
        is complete, and after that each batch as it comes."""
        t = rows.t
        if self.t_first is None:
            self.t_first = float(t[0])
        if self._batches is None:
            return [rows]
        self._batches.append(rows)
        if t[-1] >= self.t_first + self.window_s:
            return self.close()
        return []

    def close(self) -> list[ScoredRows]:
        """Complete the window with the batches it holds (the record may end inside it) and hand
        them back to be scored; nothing once it is complete."""
        batches, self._batches = self._batches, None
        if not batches:
            return []
        t = np.concatenate([b.t for b in batches])
        window = t < self.t_first + self.window_s
        for name in self.names:
            e = np.concatenate([b.error_raw[name] for b in batches])[window]
            e = e[np.isfinite(e)]
            self.e0[name] = float(np.mean(e)) if e.size else np.nan
        return batches

    def offset(self, name: str, e_raw: np.ndarray) -> float:
        """e0 of `name`, rad. A name without a finite error in the window takes the first finite one
        in e_raw (these rows' raw error); NaN while it has none."""
        if not np.isfinite(self.e0[name]):
            first = np.flatnonzero(np.isfinite(e_raw))
            if first.size:
                self.e0[name] = float(e_raw[first[0]])
        return self.e0[name]
