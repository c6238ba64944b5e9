"""`DriftLearning`: update windows, their drift measurements and the parameter learner.

Every `window_s` the drift measurement of the window (stkf.DriftWindow, docs/design.md eq. 4-6 in
their exact form) is formed. If the gate stayed open over the window and `confirm_s` after it (an
interference that begins slowly is caught before its window is used), the learner steps with it;
otherwise it only fades (predicts). While the gate is shut the estimator coasts on the parameters.

A window's R counts the gyro's angle random walk and the compass's white noise. On a vehicle the
compass also errs slowly (the vehicle pitching as it speeds up and brakes while the tilt is a long
average, a straight that is not quite straight): the innovations then run well beyond their
predicted spread (diagnostics `window_r_scale` says by how much in variance). With
`adaptive_r` the window's R is scaled by what the recent innovations show (covariance matching:
the median of innovation^2 / its variance with the window's own R, over `innovation_windows`
windows, divided by chi-square(1)'s median 0.455; at most `R_SCALE_MAX`), so the learner weighs
the windows as noisy as they are and its P, the coasting sigma and the divergence test stay honest.
The scale is taken only where it is significant: the median of n chi-square(1) values scatters by
2.33 / sqrt(n) of itself (skewed upwards), so a ratio below 1 + 3.5 x that (2.5 for 30 windows,
3.6 for 10; a consistent filter passes it about 1 % of the time, by simulation) leaves R as
computed. Static units then keep R as it was (their ratios a little above 1 are that scatter, or
model error, which R must not absorb).
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Callable

import numpy as np

from .backtest import DriftBacktest
from .coasting import DriftPrediction
from .imu_stretch import CompassContext
from .learner import ParameterLearner
from .stkf import DriftWindow


@dataclass(frozen=True)
class WindowMeasurement:
    """One drift measurement y = h . x + v, v ~ N(0, R), over [t0, t1] (logged for MLR, analysis)."""
    t0: float
    t1: float
    y: float              # rad/s
    h: np.ndarray         # (n,) window-mean regressor row
    R: float              # (rad/s)^2
    clean: bool           # no closed gate or time gap in the window
    ranges: tuple = (np.nan,) * 4   # model temperature lo, hi (degC) and dT/dt lo, hi (degC/s) in it


@dataclass(frozen=True)
class _Pending:
    measurement: WindowMeasurement
    confirm_at: float     # s


@dataclass(frozen=True)
class LearningSettings:
    window_s: float
    edge_s: float
    confirm_s: float
    r_floor_rad_s: float
    innovation_windows: int
    learn: bool
    adaptive_r: bool = True


R_SCALE_MAX = 100.0        # a window 10x noisier (in sigma) than its own R says is the most believed
R_SCALE_MIN_WINDOWS = 10   # windows before the scale is estimated
NIS_MEDIAN = 0.4549        # the median of chi-square with 1 degree of freedom
# relative 1-sigma scatter of the median of n chi-square(1) values, times sqrt(n):
# 1 / (2 f(m) m) with m the median and f the density there (0.471)
NIS_MEDIAN_SCATTER = 2.333


class DriftLearning:
    """Schedules the windows and steps the learner. `rebase(delta_rate_rad_s, t_s)` is told every
    change of the live drift estimate (the gate re-expresses its history with it); `prediction`
    takes the inputs each accepted window covered and restarts from every update."""

    def __init__(self, settings: LearningSettings, n_params: int, rebase: Callable[[float, float], None],
                 prediction: DriftPrediction):
        self.settings = settings
        self.n_params = n_params
        self._rebase = rebase
        self.prediction = prediction
        self._ranges = [np.inf, -np.inf, np.inf, -np.inf]   # the current window's input ranges
        self.learner: ParameterLearner | None = None   # set by `start`
        self.window: DriftWindow | None = None
        self.i_d = 0.0                          # int g D_hat dt since the window start, rad
        self.i_h = np.zeros(n_params)           # int g H dt since the window start
        self._pending: _Pending | None = None
        self.t_last_gap = -np.inf               # latest time gap, s
        self.t_last_untrusted = -np.inf         # latest sample with a stale temperature, s
        self.sigma_d = 0.0                      # 1-sigma of D_hat at the live temperature, rad/s
        self._innovations = deque(maxlen=settings.innovation_windows)  # accepted (gamma, S)
        self._nis_own_r = deque(maxlen=settings.innovation_windows)    # gamma^2 / S with the window's own R
        self.r_scale = 1.0                      # factor on the windows' R (adaptive_r)
        self.backtest = DriftBacktest()         # what past predictions missed beyond P, by age (backtest.py)
        # every window's measurement (MLR fits them all); bounded so that a node running for weeks
        # keeps a constant footprint (1e5 windows: 11 days at 10 s)
        self.window_log: deque[WindowMeasurement] = deque(maxlen=100_000)
        self.counters = {'windows_used': 0, 'windows_rejected': 0, 'windows_gated': 0}

    def start(self, learner: ParameterLearner, t_start: float, t_origin: float, live_row: np.ndarray) -> None:
        """First window: from now to a window grid point at least half a window away."""
        self.learner = learner
        self.prediction.rebase(live_row, t_start)
        self.backtest.add_update(t_start, learner.x, learner.P)
        self.update_sigma_d(live_row)
        w = self.settings.window_s
        t1 = t_origin + math.ceil((t_start - t_origin) / w - 1e-9) * w
        if t1 - t_start < 0.5 * w:
            t1 += w
        self._new_window(t_start, t1)

    def next_tick(self) -> float:
        if self._pending is not None:
            return min(self.window.t1, self._pending.confirm_at)
        return self.window.t1

    def fire(self, tick: float, arw_rad_sqrt_s: float, compass_var_rad2: float, t_last_closed: float,
             live_row: np.ndarray) -> None:
        """Confirm a pending window and/or close the current one at `tick` (s)."""
        p = self._pending
        if p is not None and tick >= p.confirm_at:
            self._pending = None
            clean = self._clean(t_last_closed, p.measurement.t0)
            self.counters['windows_gated'] += int(not clean)
            self._learn(p.measurement if clean else None, tick, live_row)
        w = self.window
        if tick < w.t1:
            return
        s = self.settings
        meas = w.measurement(arw_rad_sqrt_s, compass_var_rad2, s.r_floor_rad_s ** 2)
        clean = self._clean(t_last_closed, w.t0)
        if meas is not None:
            y, h, R, _ = meas
            self.window_log.append(WindowMeasurement(w.t0, w.t1, y, h.copy(), R, clean, tuple(self._ranges)))
        if meas is not None and clean and s.confirm_s > 0:
            self._pending = _Pending(self.window_log[-1], w.t1 + s.confirm_s)
        elif meas is not None and clean:
            self._learn(self.window_log[-1], tick, live_row)
        else:
            self.counters['windows_gated'] += int(meas is not None)
            self._learn(None, tick, live_row)
        self._new_window(w.t1, w.t1 + s.window_s)

    def _clean(self, t_last_closed: float, t0: float) -> bool:
        return t_last_closed <= t0 and self.t_last_gap < t0 and self.t_last_untrusted < t0

    def _learn(self, meas: WindowMeasurement | None, t: float, live_row: np.ndarray) -> None:
        if not self.settings.learn:
            return
        if meas is None:
            self.learner.step(None)
        else:
            x_before, r_used = self.learner.x, meas.R * self.r_scale
            res = self.learner.step(meas.y, meas.h, r_used)
            self.counters['windows_used' if res.accepted else 'windows_rejected'] += 1
            self._update_r_scale(res.innovation, res.innovation_var, meas.R)
            if res.accepted:
                if np.isfinite(res.innovation) and np.isfinite(res.innovation_var):
                    self._innovations.append((res.innovation, res.innovation_var))
                self.prediction.coverage.add(meas.t1, *meas.ranges)
                self.backtest.add_window(meas.t0, meas.t1, meas.y, meas.h, r_used)
                self.backtest.add_update(t, self.learner.x, self.learner.P)
                # the gate must not read the estimator's own correction as interference
                d_before = self.prediction.d_last
                self.prediction.rebase(live_row, t)
                self._rebase(float(live_row @ (self.learner.x - x_before)) if d_before is None
                             else float(live_row @ self.learner.x) - d_before, t)
        self.update_sigma_d(live_row)

    def _update_r_scale(self, gamma: float, s_var: float, r_own: float) -> None:
        """Covariance matching on every window with an innovation (refused ones too: the median
        keeps an undetected disturbance from inflating R)."""
        if not self.settings.adaptive_r or not (np.isfinite(gamma) and np.isfinite(s_var)):
            return
        s_own = s_var - r_own * (self.r_scale - 1.0)   # the innovation variance had R been the window's own
        if s_own > 0:
            self._nis_own_r.append(gamma * gamma / s_own)
        n = len(self._nis_own_r)
        if n >= R_SCALE_MIN_WINDOWS:
            ratio = float(np.median(self._nis_own_r)) / NIS_MEDIAN
            significant = ratio > 1.0 + 3.5 * NIS_MEDIAN_SCATTER / np.sqrt(n)
            self.r_scale = min(ratio, R_SCALE_MAX) if significant else 1.0

    def update_sigma_d(self, live_row: np.ndarray) -> None:
        """1-sigma of D_hat at the live temperature and rate (docs/design.md eq. 14): coasting into
        a ramp makes b and a uncertain in D_hat."""
        var = max(live_row @ self.learner.P @ live_row, 0.0)
        # the learner's P knows nothing of model error: a drift estimate lagging a ramp leaves
        # recent innovations of one sign, so their mean beyond what white noise explains is added.
        # (Their mean square would not do: over 30 windows it scatters by a quarter of S, and that
        # scatter alone would read as a drift uncertainty of half the window noise.)
        if len(self._innovations) >= 2:
            g = np.asarray(self._innovations)
            var += max(float(np.mean(g[:, 0])) ** 2 - float(np.mean(g[:, 1])) / len(g), 0.0)
        self.sigma_d = float(np.sqrt(var))

    def note_inputs(self, temp_c: np.ndarray, temp_rate_c_s: np.ndarray) -> None:
        """The model's temperature and dT/dt over IMU rows of the current window."""
        if temp_c.size:
            r = self._ranges
            self._ranges = [min(r[0], float(temp_c.min())), max(r[1], float(temp_c.max())),
                            min(r[2], float(temp_rate_c_s.min())), max(r[3], float(temp_rate_c_s.max()))]

    def _new_window(self, t0: float, t1: float) -> None:
        self.window = DriftWindow(t0, t1, self.settings.edge_s, self.n_params)
        self._ranges = [np.inf, -np.inf, np.inf, -np.inf]
        self.i_d = 0.0
        self.i_h = np.zeros(self.n_params)

    def integrals_from_window_start(self, t_mag: np.ndarray, ctx: CompassContext) -> tuple[np.ndarray, np.ndarray]:
        """Window integrals (I_D rad, I_H) at compass stamps. A compass sample at or just after a
        window start whose IMU sample precedes it: that sample's integrals belong to the previous
        window; integrate from the window start."""
        i_d, i_h = ctx.i_d, ctx.i_h
        if self.window is None:
            return i_d, i_h
        old = ctx.t_imu < self.window.t0
        if np.any(old):
            since = np.maximum(t_mag - self.window.t0, 0.0)
            i_d = np.where(old, ctx.g_tilt * ctx.d_hat * since, i_d)
            i_h = np.where(old[:, None], (ctx.g_tilt * since)[:, None] * ctx.h, i_h)
        return i_d, i_h

    def add_compass(self, t_mag: np.ndarray, q_rad: np.ndarray, i_h: np.ndarray) -> None:
        if self.window is not None:
            self.window.add(t_mag, q_rad, i_h)
