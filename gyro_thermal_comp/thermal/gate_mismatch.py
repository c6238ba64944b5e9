"""`HeadingRateMismatch`: the compass heading moves while the gyro heading does not (the paper's
test; the gyro is blind to magnetic fields).

r = psi_gyro - psi_compass, averaged over `mismatch_smooth_s`, moves at the residual drift rate,
which may be large while the drift model is still learning; interference instead bends r. So while
open the test is the second difference |r(t) - 2 r(t - W/2) + r(t - W)| over W = `mismatch_window_s`,
blind to any steady drift. Once the gate is shut for any reason other than a turn, the test passes
again only when r has been stable (at most a straight line, i.e. a residual drift) over
`mismatch_settle_s` AND either agrees with its value at the last open instant, within an allowance
growing with angle random walk and drift uncertainty, or the gate has been shut for `mismatch_max_s`
and r has been stable for the whole last `mismatch_settle_s` (a disturbance that breathes is never
accepted), or r has been a drift line (below). So a disturbance that only rotates the field keeps
the gate shut until the compass comes back to where the gyro says it should be, and a coasting error
larger than the allowance cannot lock the gate for ever.

A drift line: over the last `mismatch_line_s` r has stayed within `mismatch_line_rms_rad` (rms) of a
straight line whose slope is beyond `mismatch_sigma` x the drift uncertainty and moves r by more
than the bend threshold over the window, with r stable over `mismatch_settle_s` the whole time (a
disturbance's onset or its breathing starts the line again). That is the drift estimate being
wrong, not a field: a disturbance breathes or moves with the vehicle, and does not keep a constant
rate for minutes, while a drift model extrapolating past its calibration does. A steady offset (a
disturbance that holds still) has no slope and stays shut. The heading filter refuses a steady
disagreement the same way for `reject_max_s` before accepting it.
"""
from __future__ import annotations

from collections import deque

from .gate_test_base import GateTest, Observation
from .trails import LineTrail, Trail, push_trail, sqrt_or_nan


class HeadingRateMismatch(GateTest):
    name = 'heading_rate_mismatch'

    def __init__(self, gate):
        super().__init__(gate)
        cfg = gate.cfg
        self._smooth = Trail(cfg.mismatch_smooth_s)
        self._smooth_sum = 0.0
        self._smooth_var: deque = deque()      # compass variance of each entry of _smooth
        self._smooth_var_sum = 0.0
        self._win = Trail(cfg.mismatch_window_s)
        self._win_half = Trail(0.5 * cfg.mismatch_window_s)
        self._settle = Trail(cfg.mismatch_settle_s)
        self._settle_half = Trail(0.5 * cfg.mismatch_settle_s)
        self._line = LineTrail(cfg.mismatch_line_s)   # r since the shut and since it was last unstable
        self.frozen: tuple | None = None       # (t, r) at the last open instant
        self._stable_since: float | None = None
        self._line_told = False                # this shut's drift line was reported
        self.drift_lines: list = []            # (t s, heading variance rad^2) not yet taken
        self.n_drift_lines = 0

    def enabled(self) -> bool:
        return self.cfg.mismatch_enabled

    def set_config(self, cfg) -> None:
        for trail, window_s in ((self._smooth, cfg.mismatch_smooth_s), (self._win, cfg.mismatch_window_s),
                                (self._win_half, 0.5 * cfg.mismatch_window_s),
                                (self._settle, cfg.mismatch_settle_s),
                                (self._settle_half, 0.5 * cfg.mismatch_settle_s),
                                (self._line, cfg.mismatch_line_s)):
            trail.window_s = window_s

    def begin(self, obs: Observation) -> None:
        self.thr = float(self.cfg.mismatch_rad)

    def value(self, obs: Observation, active: bool) -> float:
        if obs.turn_closes:   # a turn restarts the history: the deviation at the new heading differs
            self.clear()
            self.frozen = None
            return 0.0
        return self._mismatch(obs.t, obs.r, self.thr, obs.arw2, obs.drift, obs.var, obs.was_open)

    def on_shut(self, obs: Observation) -> None:
        if obs.turn_closes:
            self.frozen = None
        else:
            self._freeze()

    def on_reopen(self, obs: Observation) -> None:
        self.frozen = None

    def trails(self) -> tuple:
        """Every trail of r (re-expressed together when the drift estimate changes)."""
        return self._smooth, self._win, self._win_half, self._settle, self._settle_half, self._line

    def rebased(self, shift) -> None:
        """The trails' values were re-expressed (`shift` re-expresses one deque of (t, r))."""
        self._line.rebuild()
        self._smooth_sum = sum(v for _, v in self._smooth.q)
        if self.frozen is not None:
            self.frozen = shift(deque([self.frozen]))[0]

    def clear(self) -> None:
        for trail in (self._smooth, self._win, self._win_half, self._settle, self._settle_half):
            trail.q.clear()
        self._line.clear()
        self._smooth_sum = 0.0
        self._smooth_var.clear()
        self._smooth_var_sum = 0.0

    def _bend_threshold(self, thr: float, var_smooth: float, arw2: float) -> float:
        """`mismatch_rad`, raised to `mismatch_noise_sigma` sigma of the bend's noise: three smoothed
        compass values (weights 1, -2, 1) and the angle random walk over the window. A 5 Hz compass
        averages few samples per second, and a fixed 1 deg would then fire on noise."""
        noise = sqrt_or_nan(6.0 * var_smooth + arw2 * self.cfg.mismatch_window_s)
        return max(thr, self.cfg.mismatch_noise_sigma * noise)

    def _allow(self, age_s: float, thr: float, arw2: float, drift: float) -> float:
        """Disagreement explained by angle random walk and drift uncertainty over age_s (k sigma)."""
        return thr + self.cfg.mismatch_sigma * sqrt_or_nan(arw2 * age_s + (drift * age_s) ** 2)

    def _mismatch(self, t_now: float, r_now: float, thr: float, arw2: float, drift: float, var_i: float,
                  was_open: bool) -> float:
        """Test value as a fraction of its threshold (the module docstring). Called per observation:
        the trails are pushed inline (`push_trail`), not through methods."""
        cfg = self.cfg
        # moving average of r over `mismatch_smooth_s` and its variance from compass noise
        q, qv = self._smooth.q, self._smooth_var
        q.append((t_now, r_now))
        qv.append(var_i)
        self._smooth_sum += r_now
        self._smooth_var_sum += var_i
        cut = t_now - cfg.mismatch_smooth_s
        while len(q) > 1 and q[0][0] <= cut:
            self._smooth_sum -= q.popleft()[1]
            self._smooth_var_sum -= qv.popleft()
        n = len(q)
        r_now, var_smooth = self._smooth_sum / n, max(self._smooth_var_sum, 0.0) / n ** 2
        thr = self._bend_threshold(thr, var_smooth, arw2)
        win = self._win
        bend = abs(r_now - 2.0 * push_trail(self._win_half, t_now, r_now) + push_trail(win, t_now, r_now))
        if win.q[-1][0] - win.q[0][0] < 0.9 * cfg.mismatch_window_s:
            bend = 0.0  # not yet a second difference: a residual-drift slope would read as a bend
        bend_settle = abs(r_now - 2.0 * push_trail(self._settle_half, t_now, r_now)
                          + push_trail(self._settle, t_now, r_now))
        if was_open or self.frozen is None:
            return bend / thr
        t_f, r_f = self.frozen
        age = t_now - t_f
        stable = self._settle.span() >= 0.9 * cfg.mismatch_settle_s and \
            bend_settle <= self._allow(cfg.mismatch_settle_s, thr, arw2, 0.0)
        consistent = abs(r_now - r_f) <= self._allow(age, thr, arw2, drift)
        if not stable:
            self._stable_since = None
            self._line.clear()   # an onset or a breathing bend would tilt the line: start it again
        elif self._stable_since is None:
            self._stable_since = t_now
        self._line.push(t_now, r_now)
        settled = stable and t_now - self._stable_since >= cfg.mismatch_settle_s
        if stable and (consistent or (age > cfg.mismatch_max_s and settled)):
            return 0.0
        slope = self._drift_line(thr, drift, var_smooth) if stable else None
        if slope is None:
            return 2.0
        if not self._line_told:
            self._line_told = True
            self.n_drift_lines += 1
            self.drift_lines.append((t_now, (r_now - r_f) ** 2 + (slope * age) ** 2))
        return 0.0

    def _drift_line(self, thr: float, drift: float, var_smooth: float) -> float | None:
        """The slope (rad/s) if r has been a straight line over `mismatch_line_s` whose slope the drift
        uncertainty does not explain: the drift estimate is wrong, not the field (module docstring)."""
        cfg, line = self.cfg, self._line
        if cfg.mismatch_line_s <= 0 or line.span() < 0.9 * cfg.mismatch_line_s:
            return None
        slope, rms = line.line()
        steady = rms <= max(cfg.mismatch_line_rms_rad, 2.0 * sqrt_or_nan(var_smooth))
        drifting = abs(slope) > cfg.mismatch_sigma * drift and abs(slope) * line.span() > thr
        return slope if steady and drifting else None

    def _freeze(self) -> None:
        """At closing: remember r at the last trusted instant (the mismatch window's start; the
        last window may already hold the onset)."""
        w = self._win.q
        self.frozen = (w[0][0], w[0][1]) if w else None
        self._stable_since = None
        self._line_told = False
        self._line.clear()   # the line is judged on the shut alone
