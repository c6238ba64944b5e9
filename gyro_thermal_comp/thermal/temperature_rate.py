"""Temperature and its rate dT/dt from a slow, quantized, noisy sensor stream.

Differencing two samples of a 0.06 degC-quantized sensor at 1 Hz gives rates of 0 or +-0.06 degC/s,
ten times the real ramp. Instead each accepted sample gets a local linear regression over the
trailing `window_s` seconds: the slope is dT/dt (degC/s) and the line evaluated at the sample time
is the smoothed temperature (no lag for a linear trend). Streaming: only the last window is kept.

Bad samples: NaN/inf values, readings outside the sensor's range and non-increasing stamps are
dropped and counted (input_guard.StreamGuard). A reading that jumps from the last kept one by more
than `max_rate_c_s` x the time between them + `step_tolerance_c` is dropped too (`dropped_rate`): one
such spike would otherwise bend dT/dt for a whole window and with it the learned b. A new level that
`confirm_samples` readings in a row agree on is a real step and is taken (the regression restarts).
A reading that has not changed for `stuck_after_s` is flagged (`stuck`): with a real, noisy sensor
that means a frozen driver or a dead sensor. No reading for `timeout_s` makes the temperature
unknown (`at` returns valid = False) instead of holding a stale value as if it were live.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..input_guard import StreamGuard


@dataclass(frozen=True)
class TemperatureEstimate:
    t: np.ndarray          # (M,) s, stamps of the accepted samples
    temp_c: np.ndarray     # (M,) degC, regression line at t
    rate_c_s: np.ndarray   # (M,) degC/s, regression slope


_NO_ESTIMATE = TemperatureEstimate(np.empty(0), np.empty(0), np.empty(0))   # (never written to)


class TemperatureRateEstimator:
    """Streaming local-linear-regression smoother and differentiator for temperature."""

    _BLOCK = 8192  # samples per vectorised block: keeps cumulative sums well conditioned

    def __init__(self, window_s: float = 60.0, min_span_fraction: float = 0.25,
                 stuck_after_s: float = 600.0, hold_max_s: float = 5.0, timeout_s: float = np.inf,
                 range_c: tuple[float, float] | None = None, max_rate_c_s: float = np.inf,
                 step_tolerance_c: float = 2.0, checked: bool = False, confirm_samples: int = 10):
        if window_s <= 0:
            raise ValueError('window_s must be > 0')
        self.window_s = float(window_s)
        # a slope from a span much shorter than the window is mostly quantization noise: report 0
        self.min_span_s = float(min_span_fraction) * self.window_s
        self.stuck_after_s = float(stuck_after_s)
        self.hold_max_s = float(hold_max_s)
        self._buf_t = np.empty(0)
        self._buf_v = np.empty(0)
        self.last: tuple[float, float, float] | None = None  # (t, temp_c, rate_c_s) latest estimate
        self._last_raw = np.nan
        self._last_change_t = np.nan
        self.timeout_s = float(timeout_s)
        self.max_rate_c_s = float(max_rate_c_s)
        self.step_tolerance_c = float(step_tolerance_c)
        self.confirm_samples = int(confirm_samples)
        # finite, in-range readings with increasing stamps; `checked`: the caller's guard saw to that
        self.guard = None if checked else StreamGuard('temperature', limits=(range_c,) if range_c else None)
        self.first_t = np.inf   # stamp of the first reading taken, s
        self.dropped_rate = 0
        self._kept: tuple[float, float] | None = None   # (t, raw degC) of the newest kept reading
        self._rate_refused = 0                           # readings refused in a row

    # -- state ---------------------------------------------------------------------------------
    @property
    def stuck(self) -> bool:
        """True when the raw reading has been identical for longer than `stuck_after_s`."""
        return self.last is not None and self.last[0] - self._last_change_t > self.stuck_after_s

    def stuck_for_s(self) -> float:
        return 0.0 if self.last is None else float(self.last[0] - self._last_change_t)

    # -- streaming update -----------------------------------------------------------------------
    def update(self, t, temp_c) -> TemperatureEstimate:
        """Consume raw samples (any count, time order expected); return estimates at accepted ones."""
        t = np.asarray(t, dtype=float).reshape(-1)
        v = np.asarray(temp_c, dtype=float).reshape(-1)
        if self.guard is not None:
            ok = self.guard.keep(t, v)
            t, v = t[ok], v[ok]
        if t.size and self.first_t == np.inf:
            self.first_t = float(t[0])
        if np.isfinite(self.max_rate_c_s) and t.size:
            plausible = self._plausible_steps(t, v)
            t, v = t[plausible], v[plausible]
        if t.size == 0:
            return TemperatureEstimate(t, v, v.copy())
        self._track_changes(t, v)
        outs = [self._regress_block(t[i:i + self._BLOCK], v[i:i + self._BLOCK])
                for i in range(0, t.size, self._BLOCK)]
        est = TemperatureEstimate(*(np.concatenate(c) for c in zip(*outs)))
        self.last = (float(est.t[-1]), float(est.temp_c[-1]), float(est.rate_c_s[-1]))
        return est

    def _plausible_steps(self, t: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Readings within the rate limit of the newest kept one (a step confirmed by
        `confirm_samples` refused readings in a row restarts the regression)."""
        keep = np.ones(t.size, dtype=bool)
        if self._kept is not None:
            # the usual case: every reading within the limit of the one before (then each is kept
            # and the newest kept is always the one before); the loop below decides the others
            prev_t = np.concatenate(([self._kept[0]], t[:-1]))
            prev_v = np.concatenate(([self._kept[1]], v[:-1]))
            if not np.any(np.abs(v - prev_v) > self.max_rate_c_s * (t - prev_t) + self.step_tolerance_c):
                self._kept, self._rate_refused = (float(t[-1]), float(v[-1])), 0
                return keep
        for k, (tk, vk) in enumerate(zip(t.tolist(), v.tolist())):   # slow stream: 1-100 Hz
            if self._kept is not None and abs(vk - self._kept[1]) > \
                    self.max_rate_c_s * (tk - self._kept[0]) + self.step_tolerance_c:
                self._rate_refused += 1
                if self._rate_refused < self.confirm_samples:
                    keep[k] = False
                    self.dropped_rate += 1
                    continue
                self._buf_t, self._buf_v = np.empty(0), np.empty(0)   # a real step: start afresh
            self._rate_refused = 0
            self._kept = (tk, vk)
        return keep

    def _track_changes(self, t: np.ndarray, v: np.ndarray) -> None:
        prev = np.concatenate(([self._last_raw], v[:-1]))
        changed = v != prev  # NaN initial prev counts as a change
        if np.any(changed):
            self._last_change_t = float(t[np.flatnonzero(changed)[-1]])
        self._last_raw = float(v[-1])

    def _regress_block(self, t: np.ndarray, v: np.ndarray):
        all_t = np.concatenate((self._buf_t, t))
        all_v = np.concatenate((self._buf_v, v))
        t0, v0 = all_t[0], all_v[0]  # anchor: sums of small numbers
        tt, vv = all_t - t0, all_v - v0
        zero = np.zeros(1)
        c1 = np.concatenate((zero, np.cumsum(np.ones_like(tt))))
        ct = np.concatenate((zero, np.cumsum(tt)))
        cv = np.concatenate((zero, np.cumsum(vv)))
        ctt = np.concatenate((zero, np.cumsum(tt * tt)))
        ctv = np.concatenate((zero, np.cumsum(tt * vv)))
        end = np.arange(self._buf_t.size, all_t.size) + 1           # exclusive end per new sample
        start = np.searchsorted(all_t, all_t[end - 1] - self.window_s, side='right')
        n = c1[end] - c1[start]
        st, sv = ct[end] - ct[start], cv[end] - cv[start]
        mean_t, mean_v = st / n, sv / n
        sxx = (ctt[end] - ctt[start]) - st * mean_t
        sxv = (ctv[end] - ctv[start]) - st * mean_v
        span = all_t[end - 1] - all_t[start]
        usable = (n >= 3) & (span >= self.min_span_s) & (sxx > 0)
        slope = np.where(usable, sxv / np.where(sxx > 0, sxx, 1.0), 0.0)
        t_end = all_t[end - 1] - t0
        level = mean_v + slope * (t_end - mean_t) + v0
        keep = all_t > all_t[-1] - self.window_s
        self._buf_t, self._buf_v = all_t[keep], all_v[keep]
        return all_t[end - 1], level, slope

    # -- causal lookup at other sensors' times ------------------------------------------------
    def at(self, est: TemperatureEstimate, t_query: np.ndarray,
           before: tuple[float, float, float] | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Temperature, rate and validity at `t_query` from estimates stamped <= each query time.

        `est` are this call's estimates, `before` the latest estimate preceding them. Between
        samples the line is extrapolated with its slope for at most `hold_max_s`, then held.
        Queries with no earlier estimate at all, or none within `timeout_s`, are invalid.
        """
        tq = np.asarray(t_query, dtype=float)
        if est.t.size == 0 and before is not None:  # no new readings: extrapolate the last line
            since = tq - before[0]
            age = np.minimum(np.maximum(since, 0.0), self.hold_max_s)   # np.clip, without its dispatch
            fresh = since <= self.timeout_s
            return before[1] + before[2] * age, np.where(fresh, before[2], 0.0), fresh
        if before is not None:
            et = np.concatenate(([before[0]], est.t))
            ev = np.concatenate(([before[1]], est.temp_c))
            er = np.concatenate(([before[2]], est.rate_c_s))
        else:
            et, ev, er = est.t, est.temp_c, est.rate_c_s
        idx = et.searchsorted(tq, side='right') - 1
        valid = idx >= 0
        j = np.maximum(idx, 0)
        if et.size == 0:
            return np.full(tq.shape, np.nan), np.zeros(tq.shape), np.zeros(tq.shape, dtype=bool)
        since = tq - et[j]
        age = np.minimum(np.maximum(since, 0.0), self.hold_max_s)   # np.clip, without its dispatch
        temp = np.where(valid, ev[j] + er[j] * age, np.nan)
        fresh = valid & (since <= self.timeout_s)   # stale: held, and no rate
        return temp, np.where(fresh, er[j], 0.0), fresh

    def update_at(self, samples, t_query: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """`update` with new `samples` (TemperatureSamples or None), then `at` the query stamps."""
        before = self.last
        if samples is not None and samples.t.size:
            estimate = self.update(samples.t, samples.temp_c)
        else:
            estimate = _NO_ESTIMATE
        return self.at(estimate, t_query, before)
