"""`StreamGuard`: the one input-hygiene rule of the package, with one set of counter names.

Every stream (IMU, magnetometer, temperature, encoder, auxiliary IMU; in the cores and in the nodes'
stamp merger) keeps a sample only if

- its stamp and values are all finite;
- its values lie inside the sensor's declared range (`limits`, one (lo, hi) or (lo, hi, min_norm)
  per value array): a value outside what the sensor can measure, or a vector shorter than any real
  one (an all-zero magnetometer), is a driver or bus fault, not a measurement;
- its stamp is strictly after the last kept stamp of that stream;
- its stamp is not a jump of more than `max_jump_s` from the last kept one. A jump is taken as a new
  time base only once `confirm_samples` samples in a row continue it (a clock that really jumped);
  until then the samples of the jump are dropped, so a few messages stamped an hour ahead cannot
  make every later sample look out of order. A stream that follows another's clock
  (`allow_back=False`) takes no jump back of its own.

Everything downstream may then assume finite, plausible values and strictly increasing stamps, in
any chunking: the rule depends only on the samples seen before. Samples at 99 % of a declared
range or beyond it are counted as `<name>_saturated` (kept when inside the range).
"""
from __future__ import annotations

import math

import numpy as np

_SATURATION_FRACTION = 0.99
# Defaults for the time-jump rule: longer than any data gap worth bridging, and enough samples that
# a burst of bad stamps cannot pass for a new clock.
MAX_JUMP_S = 60.0
CONFIRM_SAMPLES = 10
_SMALL_ROWS = 8   # up to this many rows, `_all_clean` works on Python floats


class StreamGuard:
    """Keeps finite, in-range samples with increasing stamps; counts what it drops.

    Counters (`counters()`): `<name>_dropped_nonfinite` (NaN or inf in the stamp or any value),
    `<name>_dropped_range` (a value outside `limits`), `<name>_dropped_order` (stamp repeated or not
    after the last kept one), `<name>_dropped_jump` (a jump not (yet) confirmed), `<name>_saturated`
    and `<name>_time_base_changes` (confirmed jumps: forward ones look like a gap downstream)."""

    def __init__(self, name: str, limits: tuple | None = None, max_jump_s: float = math.inf,
                 confirm_samples: int = CONFIRM_SAMPLES, allow_back: bool = True):
        self.name = name
        self.limits = tuple(limits or ())     # per value array: (lo, hi) or None
        self.max_jump_s = float(max_jump_s)
        self.confirm_samples = int(confirm_samples)
        self.allow_back = allow_back          # False: a stream that follows another's time base
        self.last_t = -math.inf       # newest kept stamp, s
        self.first_t = math.inf       # first kept stamp, s
        self.dropped_nonfinite = 0
        self.dropped_range = 0
        self.dropped_order = 0
        self.dropped_jump = 0
        self.saturated = 0
        self.time_base_changes = 0
        self._jump_last_t = math.nan  # the newest sample of an unconfirmed jump, s
        self._jump_count = 0

    def keep(self, t: np.ndarray, *values: np.ndarray) -> np.ndarray:
        """Boolean mask over the rows of `t` (s) to keep; each of `values` has one row per stamp."""
        t = np.asarray(t, dtype=float).reshape(-1)
        if t.size == 0:
            return np.zeros(0, dtype=bool)
        rows = [np.asarray(v, dtype=float).reshape(t.size, -1) for v in values]
        if not self._jump_count and self._all_clean(t, rows):   # the usual chunk: a few reductions
            self._kept(float(t[0]), float(t[-1]))
            return np.ones(t.size, dtype=bool)
        finite = np.isfinite(t)
        for v in rows:
            finite &= np.all(np.isfinite(v), axis=1)
        plausible = finite & self._in_range(rows, finite)
        self.dropped_nonfinite += int(t.size - np.count_nonzero(finite))
        self.dropped_range += int(np.count_nonzero(finite & ~plausible))
        # kept stamps increase, so "after the last kept one" is "after every earlier plausible row"
        tp = np.where(plausible, t, -np.inf)
        prev_max = np.maximum.accumulate(np.concatenate(([self.last_t], tp)))[:-1]
        ok = plausible & (t > prev_max)
        with np.errstate(invalid='ignore'):   # non-finite stamps are not kept anyway
            jumps = ok & (t - prev_max > self.max_jump_s) & np.isfinite(prev_max)
        if np.any(jumps) or self._jump_count or (np.isfinite(self.max_jump_s) and np.any(plausible & ~ok)):
            ok = np.array([self._step(ti) if p else False for ti, p in zip(t.tolist(), plausible.tolist())])
        else:
            self.dropped_order += int(np.count_nonzero(plausible & ~ok))
            if np.any(ok):
                self._kept(float(t[ok][0]), float(t[ok][-1]))
        return ok

    def _all_clean(self, t: np.ndarray, rows: list[np.ndarray]) -> bool:
        """True when `keep` would keep every row without counting anything: stamps finite, strictly
        increasing from `last_t` with no jump; values finite, inside their ranges, none near an end.
        Whole-array min/max instead of per-row masks (NaN fails every comparison); a live node's
        chunks of a few rows are checked as Python floats, cheaper than any numpy call."""
        small = t.size <= _SMALL_ROWS
        if small:
            ts = t.tolist()
            if not all(map(math.isfinite, ts)):   # (Python's min/max would skip a NaN)
                return False
            t0 = ts[0]
        elif not (math.isfinite(float(t.min())) and math.isfinite(float(t.max()))):   # NaN propagates
            return False
        else:
            t0 = float(t[0])
        if not t0 > self.last_t:
            return False
        if self.last_t != -math.inf and not t0 - self.last_t <= self.max_jump_s:
            return False
        if t.size > 1:
            if small:
                d = [b - a for a, b in zip(ts, ts[1:])]
                d_lo, d_hi = min(d), max(d)
            else:
                d = np.diff(t)
                d_lo, d_hi = float(d.min()), float(d.max())
            if not (d_lo > 0.0 and d_hi <= self.max_jump_s):
                return False
        for i, v in enumerate(rows):
            if v.size == 0:
                continue
            if small:
                vs = v.tolist()
                flat = [x for row in vs for x in row]
                if not all(map(math.isfinite, flat)):
                    return False
                lo_v, hi_v = min(flat), max(flat)
            else:
                lo_v, hi_v = float(v.min()), float(v.max())
                if not (math.isfinite(lo_v) and math.isfinite(hi_v)):
                    return False
            lim = self.limits[i] if i < len(self.limits) else None
            if lim is None:
                continue
            lo, hi = lim[:2]
            if not (lo <= lo_v and hi_v <= hi and lo_v > _SATURATION_FRACTION * lo and hi_v < _SATURATION_FRACTION * hi):
                return False
            if len(lim) > 2 and not float(np.linalg.norm(v, axis=1).min()) >= lim[2]:   # as _in_range sums it
                return False
        return True

    def keep_one(self, t: float, *values) -> bool:
        """`keep` for one sample: True if (t, values) is kept. Plain Python floats (a node calls it
        per message); the same rule as `keep`."""
        rows = [[float(x) for x in np.ravel(v)] if isinstance(v, np.ndarray) else
                [float(x) for x in (v if isinstance(v, (list, tuple)) else (v,))] for v in values]
        if not (math.isfinite(t) and all(math.isfinite(x) for row in rows for x in row)):
            self.dropped_nonfinite += 1
            return False
        if self.limits and not self._in_range_one(rows):
            self.dropped_range += 1
            return False
        return self._step(t)

    def _in_range_one(self, rows: list[list[float]]) -> bool:
        """`_in_range` for one sample of finite floats (counts it as saturated the same way)."""
        inside, near = True, False
        for v, lim in zip(rows, self.limits):
            if lim is None:
                continue
            lo, hi = lim[:2]
            inside = inside and all(lo <= x <= hi for x in v)
            if len(lim) > 2:
                inside = inside and math.sqrt(sum(x * x for x in v)) >= lim[2]
            near = near or any(x <= _SATURATION_FRACTION * lo or x >= _SATURATION_FRACTION * hi for x in v)
        self.saturated += int(near)
        return inside

    def _in_range(self, rows: list[np.ndarray], finite: np.ndarray) -> np.ndarray:
        """Rows whose values are inside the declared ranges; counts the finite rows near the ends."""
        n = rows[0].shape[0] if rows else 0
        inside, near = np.ones(n, dtype=bool), np.zeros(n, dtype=bool)
        for v, lim in zip(rows, self.limits):
            if lim is None:
                continue
            lo, hi = lim[:2]
            with np.errstate(invalid='ignore'):
                inside &= np.all((v >= lo) & (v <= hi), axis=1)
                if len(lim) > 2:
                    inside &= np.linalg.norm(v, axis=1) >= lim[2]
                near |= np.any((v <= _SATURATION_FRACTION * lo) | (v >= _SATURATION_FRACTION * hi), axis=1)
        self.saturated += int(np.count_nonzero(near & finite))
        return inside

    def _step(self, t: float) -> bool:
        """The order and jump rule for one plausible sample."""
        if self.last_t == -math.inf or (t > self.last_t and t - self.last_t <= self.max_jump_s):
            self._jump_count = 0
            self._kept(t, t)
            return True
        if abs(t - self.last_t) <= self.max_jump_s or (t < self.last_t and not self.allow_back):
            self.dropped_order += 1                     # repeated, out of order, or back in time
            return False
        # a jump: a new time base once `confirm_samples` in a row continue it
        if self._jump_count and t > self._jump_last_t and t - self._jump_last_t <= self.max_jump_s:
            self._jump_count += 1
        else:
            self._jump_count = 1
        self._jump_last_t = t
        if self._jump_count < self.confirm_samples:
            self.dropped_jump += 1
            return False
        self._jump_count = 0
        self.time_base_changes += 1
        self.last_t = t
        return True

    def _kept(self, first: float, last: float) -> None:
        if self.first_t == math.inf:
            self.first_t = first
        self.last_t = last

    @property
    def dropped(self) -> int:
        return self.dropped_nonfinite + self.dropped_range + self.dropped_order + self.dropped_jump

    def counters(self) -> dict[str, int]:
        n = self.name
        return {f'{n}_dropped_nonfinite': self.dropped_nonfinite, f'{n}_dropped_range': self.dropped_range,
                f'{n}_dropped_order': self.dropped_order, f'{n}_dropped_jump': self.dropped_jump,
                f'{n}_saturated': self.saturated, f'{n}_time_base_changes': self.time_base_changes}
