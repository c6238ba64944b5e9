"""Whether the STKF learns from a record, and if not, why: one sentence from what the estimator
already reports (no ROS here).

The filter steps only with windows that saw no closed gate, no time gap and no stale temperature
(thermal/drift_learning.py). When it has made no update, the output rows say why
(`ThermalOutput.reasons`, thermal/reasons.py): this tallies them after the still period, per row and
per window of `window_s` (one gap spoils a whole window), and names the reasons that were in at
least half of the windows: "not learning: every window crosses a time gap", "not learning: gate
shut by accel_norm for 100 % of the record". Two tallies: the whole record (for `replay` and
`evaluate` summaries and the node's log), and the time since the filter's latest update (a node
that learned once and then stopped). A live node says nothing before `LIVE_WINDOWS` windows without
an update have passed: a drive's turns and manoeuvres shut the gate for a few windows at a time by
design, ten in a row (100 s at the defaults) is no turn. A summary at the end of a record judges
after `MIN_WINDOWS`: the first update needs a whole window and its confirmation.
"""
from __future__ import annotations

import numpy as np

from .thermal.reasons import ESTIMATOR_REASONS, REASON_BIT, reasons_by_bit

_STILL = REASON_BIT['still_period']
_OWN = set(ESTIMATOR_REASONS) - {'heading_innovation'}   # the estimator's; the rest shut the compass out like the gate
MIN_WINDOWS = 2     # a first update needs a whole window after the still period and its confirmation
LIVE_WINDOWS = 10   # windows without an update before a running node says it is not learning


class _Tally:
    """Reason counts over rows and over windows of `window_s` (a reason counts for a window if any
    of its rows has it)."""

    def __init__(self, window_s: float):
        self.window_s = window_s
        # every reason known now, registered gate tests included, in bit order
        by_bit = reasons_by_bit()
        self.names = [name for name, _ in by_bit]
        self.bits = np.array([bit for _, bit in by_bit], dtype=np.int64)
        self.rows = 0
        self.row_counts = np.zeros(len(self.names), dtype=np.int64)
        self.windows = 0
        self.window_counts = np.zeros(len(self.names), dtype=np.int64)
        self._t0: float | None = None
        self._window: int | None = None      # index of the open window
        self._mask = 0                       # reasons seen in it

    def add(self, t: np.ndarray, reasons: np.ndarray) -> None:
        if t.size == 0:
            return
        self.rows += t.size
        self.row_counts += ((reasons[:, None] & self.bits[None, :]) != 0).sum(axis=0)
        if self._t0 is None:
            self._t0 = float(t[0])
        ids = np.floor((t - self._t0) / self.window_s).astype(np.int64)
        starts = np.flatnonzero(np.diff(ids, prepend=ids[0] - 1) != 0)
        for k, i0 in enumerate(starts.tolist()):
            i1 = starts[k + 1] if k + 1 < starts.size else t.size
            if self._window is not None and ids[i0] != self._window:
                self._close()
            self._window = int(ids[i0])
            self._mask |= int(np.bitwise_or.reduce(reasons[i0:i1]))

    def _close(self) -> None:
        self.windows += 1
        self.window_counts += (self._mask & self.bits) != 0
        self._mask = 0

    def main_reasons(self) -> list[str]:
        """The reasons in at least half of the closed windows, most frequent first."""
        if not self.windows:
            return []
        share_w = self.window_counts / self.windows
        return [self.names[i] for i in np.argsort(-share_w, kind='stable') if share_w[i] >= 0.5]

    def why(self, scope: str, reasons: list[str]) -> list[str]:
        """Each of `reasons` as a phrase with its share of the windows or of the rows of `scope`."""
        share_w = self.window_counts / max(self.windows, 1)
        share_r = self.row_counts / max(self.rows, 1)
        out = []
        for name in reasons:
            i = self.names.index(name)
            pw, pr = 100.0 * share_w[i], 100.0 * share_r[i]
            if name == 'time_gap':
                out.append('every window crosses a time gap (IMU stamps further apart than max_gap_s)' if pw >= 100.0
                           else f'{pw:.0f} % of the windows cross a time gap (IMU stamps further apart than max_gap_s)')
            elif name not in _OWN:
                out.append(f'gate shut by {name} for {pr:.0f} % of {scope}')
            else:
                out.append(f'{name.replace("_", " ")} for {pr:.0f} % of {scope}')
        return out


class LearningStatus:
    """Feed it every output batch (`add`); `verdict` says 'not learning: ...' or None."""

    def __init__(self, window_s: float):
        self.window_s = float(window_s)
        self.record = _Tally(self.window_s)
        self.recent = _Tally(self.window_s)      # since the latest filter update
        self._updates = 0

    def add(self, t: np.ndarray, reasons: np.ndarray, valid: np.ndarray, filter_updates: int,
            window_s: float | None = None) -> None:
        """Output rows (s, reason masks, valid) of one batch; `filter_updates`: the estimator's count
        after it (`counters()['filter_updates']`, 0 before the learner exists); `window_s`: the
        estimator's drift window in force (`drift_window_s`: sized for the compass's measured rate
        when the still period ends, before any row is tallied), so the tally's windows are the
        filter's."""
        if window_s is not None and window_s != self.window_s and self.record.rows == 0:
            self.window_s = float(window_s)
            self.record, self.recent = _Tally(self.window_s), _Tally(self.window_s)
        if filter_updates > self._updates:
            self._updates = filter_updates
            self.recent = _Tally(self.window_s)
        reasons = np.asarray(reasons, dtype=np.int64)
        use = np.asarray(valid, dtype=bool) & ((reasons & _STILL) == 0)
        t = np.asarray(t, dtype=float)[use]
        self.record.add(t, reasons[use])
        self.recent.add(t, reasons[use])

    def verdict(self, counters: dict, learn: bool = True, since_update: bool = False,
                min_windows: int = LIVE_WINDOWS, by_design=()) -> str | None:
        """None while the filter learns (or before `min_windows` windows without an update have
        passed); else 'not learning: <why>'. `since_update`: judged over the time since the latest
        update (a node that stopped learning), else over the whole record (never updated).
        `by_design`: reasons that stop learning as designed (a drive's turns): when they alone
        explain the windows without an update, None."""
        if not learn:
            return 'not learning: learning is off (learn: false)'
        updates = int(counters.get('filter_updates', 0))
        tally = self.recent if since_update else self.record
        if tally.windows < min_windows or (updates > 0 and not since_update):
            return None
        scope = f'the last {_span(tally)}' if since_update and updates else 'the record'
        reasons = tally.main_reasons()
        if reasons and set(reasons) <= set(by_design):
            return None
        why = tally.why(scope, reasons)
        if not why:
            rejected = int(counters.get('windows_rejected', 0))
            why = [f'the innovation test refused every window ({rejected})'] if rejected and not \
                counters.get('windows_used') else ['no window had a usable drift measurement']
        return 'not learning: ' + '; '.join(why)


def _span(tally: _Tally) -> str:
    s = tally.windows * tally.window_s
    return f'{s / 60.0:.0f} min' if s >= 120.0 else f'{s:.0f} s'


def learning_line(status: LearningStatus | None, counters: dict, learn: bool = True) -> str:
    """One line for a summary: the filter's updates, or why it made none."""
    verdict = status.verdict(counters, learn, min_windows=MIN_WINDOWS) if status is not None else None
    if verdict is not None:
        return verdict
    updates = int(counters.get('filter_updates', 0))
    if updates:
        return f"learning: {updates} filter updates from {int(counters.get('windows_used', 0))} windows"
    return 'not learning: the record ends before a whole window after the still period' if status is not None \
        and status.record.windows < MIN_WINDOWS else 'not learning: no filter update'


__all__ = ['LearningStatus', 'learning_line', 'LIVE_WINDOWS', 'MIN_WINDOWS']
