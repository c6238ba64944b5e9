"""`DriftPrediction`: the drift estimate between learner updates, and how far to trust it.

Between two accepted windows (and for as long as the magnetic gate keeps the learner from
updating: coasting) the estimate has two candidates:
  frozen   D_u = h_u . x       the drift at the last update (h_u: regressor row there)
  model    D_u + dD            dD = (h - h_u) . x, the change the model predicts since
The model's change is only as good as what the learner knows. Its error variance is
  V = dh P dh'   parameter uncertainty along the change: grows with the time since the update, as
                 P fades and takes the random walk Q
    + e^2        extrapolation: the part of dD that lies beyond the temperature and dT/dt ranges
                 of the windows still in the learner's memory (`InputCoverage`), counted by how far
                 out it goes
    + w m(age)^2 what past predictions of this age missed beyond P (backtest.py), for the share w
                 of the change that lies beyond those ranges (its square over the sum of the squares
                 of the parts beyond and inside): inside what it learned on the model interpolates,
                 and its change is as good as P says; beyond, it is as good as its predictions have
                 been on this unit (coefficients that absorbed a wandering bias, a curve the terms
                 cannot follow extrapolate wrong)
One rule weighs the change by it:
  D_hat = D_u + kappa dD,    kappa = max(0, 1 - V / dD^2)
the plug-in least-squares weight of a prediction dD ~ N(true change, V) (kappa = S / (S + V) with
S + V estimated by dD^2). A change the model knows well (dD^2 >> V) is applied as it is; one
within its own uncertainty, or mostly extrapolation by a model whose predictions have missed,
falls back to the drift held at the update, as the thermal calibrations of ArduPilot and PX4 hold
the drift at the edge of their calibrated temperature range. The prediction's variance grows by
kappa V, the model's error where it is followed (`var_change`, `var_beyond`; m(age)^2 is added to
the heading's sigma by the estimator, for any kappa), and by (1 - kappa)^2 dD^2, the change it
foresaw where it is not (`var_unfollowed`). The magnetic gate takes only the model's own account:
the rest is no evidence the field moved, and a wider shut-gate allowance lets a disturbance that
holds still back in.

An extrapolated part counts by how far it goes relative to what was covered: d / (d + span) for
the temperature (a linear slope carries a little past its data, not to twice the span), and for
dT/dt per sign: cooling when only heating and holds were seen is all extrapolation (relative 1).
"""
from __future__ import annotations

import math
from collections import deque

import numpy as np

from .drift_model import DriftModel


class InputCoverage:
    """Ranges of the model's temperature (degC) and dT/dt (degC/s) over the accepted windows still
    in the learner's memory: a fading-memory filter has forgotten what it learned at a temperature
    it last saw hours ago, and its coefficients describe the recent windows only (a tag that cooled
    through 14 degC in its first minutes and then learned a steep slope at 6-8 degC extrapolated that
    slope to 10.5 degC as if 14 degC were still covered). `memory_s` (inf: all) is set from the
    learner's fading; ranges given at construction (a model file's, a state file's) count as seen
    when the record starts."""

    def __init__(self, initial: dict | None = None, memory_s: float = math.inf):
        initial = initial or {}
        if not isinstance(initial, dict):
            raise ValueError('coverage must be a mapping of ranges')
        self.memory_s = memory_s
        temp, rate = _pair(initial.get('temperature_c')), _pair(initial.get('temperature_rate_c_s'))
        self._entries: deque = deque()      # (t s or None: at the first call, lo T, hi T, lo rate, hi rate)
        if temp is not None and rate is not None:
            self._entries.append([None, *temp, *rate])
        self._ranges()

    def _ranges(self) -> None:
        e = self._entries
        if not e:
            self.temp = self.rate = None
            return
        self.temp = (min(x[1] for x in e), max(x[2] for x in e))
        self.rate = (min(x[3] for x in e), max(x[4] for x in e))

    def expire(self, t_s: float) -> None:
        """Forget windows older than the memory at `t_s`."""
        e = self._entries
        for x in e:
            if x[0] is None:
                x[0] = float(t_s)
        cut = t_s - self.memory_s
        dropped = False
        while e and e[0][0] < cut:
            e.popleft()
            dropped = True
        if dropped:
            self._ranges()

    def add(self, t_s: float, temp_lo: float, temp_hi: float, rate_lo: float, rate_hi: float) -> None:
        """An accepted window ending at `t_s` and its input ranges."""
        if not all(np.isfinite((temp_lo, temp_hi, rate_lo, rate_hi))):
            return
        self._entries.append([float(t_s), float(temp_lo), float(temp_hi), float(rate_lo), float(rate_hi)])
        self.temp = _merge(self.temp, temp_lo, temp_hi)
        self.rate = _merge(self.rate, rate_lo, rate_hi)
        self.expire(t_s)

    def to_dict(self) -> dict:
        return {} if self.temp is None else {'temperature_c': list(self.temp), 'temperature_rate_c_s': list(self.rate)}

    def clamp(self, temp: np.ndarray, rate: np.ndarray):
        """(T_c, r_c, rel_T, rel_r): the inputs clamped into the covered ranges and how far each lay
        beyond them, relative (0 inside, -> 1 far out; 1 with nothing covered)."""
        if self.temp is None:
            return temp, rate, np.ones_like(temp), np.ones_like(rate)
        lo, hi = self.temp
        t_c = np.clip(temp, lo, hi)
        d = np.abs(temp - t_c)
        rel_t = d / np.maximum(d + (hi - lo), 1e-300)
        lo, hi = self.rate
        r_c = np.clip(rate, lo, hi)
        d = np.abs(rate - r_c)
        extent = np.where(rate > hi, max(hi, 0.0), max(-lo, 0.0))   # covered extent on that side of a hold
        rel_r = d / np.maximum(d + extent, 1e-300)
        return t_c, r_c, rel_t, rel_r


class DriftPrediction:
    """D_hat for a stretch of IMU rows: the model's change since the last update weighed by how
    well it is known (module docstring), and its added variance at the newest filter event
    (`refresh`, called at stamps the record decides - window ends and confirmations - so the
    heading sigma does not depend on how the samples were chunked). `miss_var(age_s)`: what past
    predictions of that age missed beyond P, (rad/s)^2 (backtest.py; None: nothing)."""

    def __init__(self, model: DriftModel, coverage: InputCoverage, miss_var=None):
        self.model = model
        self.coverage = coverage
        self.miss_var = miss_var
        self._h_u: np.ndarray | None = None     # regressor row at the last update (rate 0)
        self.t_u = -math.inf                    # time of the last update, s
        self.kappa = 1.0                        # weight of the change at the newest filter event
        self.var_change = 0.0                   # added variance there as the model accounts for it, (rad/s)^2
        self.var_beyond = 0.0                   # ... and from the inputs beyond the covered ranges
        self.var_unfollowed = 0.0               # ... and the change foreseen but not followed
        self.d_last: float | None = None        # newest row's drift estimate without the turn part, rad/s

    def rebase(self, live_row: np.ndarray, t_s: float = -math.inf) -> None:
        """An update (or the start) at `t_s`: the frozen candidate is the drift at these inputs."""
        self._h_u = np.array(live_row, dtype=float)
        self.t_u = float(t_s)
        self.kappa, self.var_change, self.var_beyond, self.var_unfollowed, self.d_last = 1.0, 0.0, 0.0, 0.0, None

    @property
    def var_extra(self) -> float:
        """Variance the model's change since the last update adds to D_hat, (rad/s)^2."""
        return self.var_change + self.var_beyond + self.var_unfollowed

    def predict(self, H: np.ndarray, inputs: dict, x: np.ndarray, P: np.ndarray,
                t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(D_hat (N,) rad/s, kappa (N,)) for rows H = model.rows(inputs) at times t (s)."""
        if self._h_u is None or not len(H):
            return H @ x, np.ones(len(H))
        d, kappa, _, _, _, turn = self._terms(H, inputs, x, P, t)
        self.d_last = float(d[-1] - turn[-1])
        return d, kappa

    def refresh(self, inputs: dict, x: np.ndarray, P: np.ndarray, t_s: float) -> None:
        """kappa and the added variance at one row of inputs (the live ones at a filter event, `t_s`)."""
        if self._h_u is None:
            return
        _, kappa, change, beyond, unfollowed, _ = self._terms(self.model.rows(inputs), inputs, x, P, np.array([t_s]))
        self.kappa = float(kappa[-1])
        self.var_change, self.var_beyond, self.var_unfollowed = float(change[-1]), float(beyond[-1]), float(unfollowed[-1])

    def _terms(self, H, inputs, x, P, t):
        """(D_hat, kappa, added variance as the model accounts for it, from the inputs beyond the
        covered ranges, from the change not followed, turn-rate part of D_hat) per row."""
        model = self.model
        zero_rate = {**inputs, 'rate': np.zeros(len(H))}
        # the turn-rate (scale-factor) part is no thermal change: applied as it is
        H0 = model.rows(zero_rate) if 'rate' in model.requires else H
        turn = (H - H0) @ x
        t_c, r_c, rel_t, rel_r = self.coverage.clamp(inputs['temperature'], inputs['temperature_rate'])
        d_rc = model.rows({**zero_rate, 'temperature_rate': r_c}) @ x
        d_tc = model.rows({**zero_rate, 'temperature': t_c, 'temperature_rate': r_c}) @ x
        d_u = float(self._h_u @ x)
        d0 = H0 @ x
        change = d0 - d_u
        dh = H0 - self._h_u
        s2_p = np.maximum(np.einsum('ij,jk,ik->i', dh, P, dh), 0.0)
        beyond2 = (rel_r * (d0 - d_rc)) ** 2 + (rel_t * (d_rc - d_tc)) ** 2
        c2 = change * change
        miss2 = 0.0
        if self.miss_var is not None:   # the record counts for the share of the change that is extrapolation
            outside, inside = d0 - d_tc, d_tc - d_u
            share = np.divide(outside * outside, outside * outside + inside * inside,
                              out=np.zeros_like(c2), where=(outside != 0) | (inside != 0))
            miss2 = share * self.miss_var(np.asarray(t, dtype=float) - self.t_u)
        v = s2_p + beyond2 + miss2
        kappa = np.clip(1.0 - np.divide(v, c2, out=np.full_like(c2, np.inf), where=c2 > 0), 0.0, 1.0)
        kappa = np.where(c2 > 0, kappa, 1.0)
        return d_u + kappa * change + turn, kappa, kappa * s2_p, kappa * beyond2, (1.0 - kappa) ** 2 * c2, turn


def _pair(v) -> tuple[float, float] | None:
    """(lo, hi) from a stored [lo, hi]; ValueError for anything else (a state file is outside data)."""
    if v is None:
        return None
    try:
        lo, hi = (float(x) for x in v)
    except (TypeError, ValueError):
        raise ValueError(f'a coverage range must be [low, high], got {v!r}') from None
    if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
        raise ValueError(f'a coverage range must be finite with low <= high, got {v!r}')
    return lo, hi


def _merge(pair, lo, hi):
    return (float(lo), float(hi)) if pair is None else (min(pair[0], float(lo)), max(pair[1], float(hi)))
