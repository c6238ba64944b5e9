"""`DriftPrediction`: the drift estimate between learner updates, and how far to trust it.

Between two accepted windows (and for as long as the magnetic gate keeps the learner from
updating: coasting) the estimate has two candidates:
  frozen   D_u = h_u . x       the drift at the last update (h_u: regressor row there)
  model    D_u + dD            dD = (h - h_u) . x, the change the model predicts since
The model's change is only as good as what the learned windows covered. Its error variance is
  s^2 = dh P dh'  (parameter uncertainty along the change; grows with time since the update, as P
                   fades and takes the random walk Q)
      + e_r^2                   (extrapolation: the part of dD that lies beyond the dT/dt range the
                                 accepted windows covered, `InputCoverage`)
and the frozen estimate's error is the true change itself. Shrinking the change by
  kappa = dD^2 / (dD^2 + s^2)
gives the least-squares combination of the two (dD^2 standing for the size of the true change):
where the windows covered the inputs, kappa ~ 1 (the model); beyond them it falls towards 1/2,
never predicting more change than the model. The prediction's variance grows by kappa s^2 + e_T^2
(e_T: the part beyond the covered temperature range). Without the shrink (`coast_shrink` false, the
default: on the bundled outage bag the shrink made the hold -> cooling turn worse, docs/estimator.md)
the model's change is applied as it is and its variance grows by s^2 + e_T^2.

An extrapolated part counts by how far it goes relative to what was covered: d / (d + span) for
the temperature (a linear slope carries a little past its data, not to twice the span), and for
dT/dt per sign: cooling when only heating and holds were seen is all extrapolation (relative 1).
Only the dT/dt part shrinks the change: a dT/dt of a sign never seen is a regime the windows say
nothing about (hysteresis and lag make the paper's b*dT/dt wrong exactly there, at the hold ->
cooling turn), while a temperature past the covered range continues a learned slope; its
extrapolation only widens the variance.
"""
from __future__ import annotations

import math

import numpy as np

from .drift_model import DriftModel


class InputCoverage:
    """Ranges of the model's temperature (degC) and dT/dt (degC/s) over the accepted windows."""

    def __init__(self, initial: dict | None = None):
        initial = initial or {}
        if not isinstance(initial, dict):
            raise ValueError('coverage must be a mapping of ranges')
        self.temp = _pair(initial.get('temperature_c'))
        self.rate = _pair(initial.get('temperature_rate_c_s'))

    def add(self, temp_lo: float, temp_hi: float, rate_lo: float, rate_hi: float) -> None:
        if not all(np.isfinite((temp_lo, temp_hi, rate_lo, rate_hi))):
            return
        self.temp = _merge(self.temp, temp_lo, temp_hi)
        self.rate = _merge(self.rate, rate_lo, rate_hi)

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
    """D_hat for a stretch of IMU rows: the model's change since the last update (shrunk by kappa
    with `shrink`), and its added variance at the newest filter event (`refresh`, called at stamps
    the record decides - window ends and confirmations - so the heading sigma does not depend on
    how the samples were chunked)."""

    def __init__(self, model: DriftModel, coverage: InputCoverage, shrink: bool = True):
        self.model = model
        self.coverage = coverage
        self.shrink = shrink                    # False: the model's change as is (kappa = 1), same variance
        self._h_u: np.ndarray | None = None     # regressor row at the last update (rate 0)
        self.kappa = 1.0                        # shrink factor at the newest filter event
        self.var_change = 0.0                   # added variance there along P, (rad/s)^2
        self.var_beyond = 0.0                   # ... and from the inputs beyond the covered ranges
        self.d_last: float | None = None        # newest row's drift estimate without the turn part, rad/s

    def rebase(self, live_row: np.ndarray) -> None:
        """An update (or the start): the frozen candidate is the drift at these inputs."""
        self._h_u = np.array(live_row, dtype=float)
        self.kappa, self.var_change, self.var_beyond, self.d_last = 1.0, 0.0, 0.0, None

    @property
    def var_extra(self) -> float:
        """Variance the model's change since the last update adds to D_hat, (rad/s)^2."""
        return self.var_change + self.var_beyond

    def predict(self, H: np.ndarray, inputs: dict, x: np.ndarray, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(D_hat (N,) rad/s, kappa (N,)) for rows H = model.rows(inputs)."""
        if self._h_u is None or not self.shrink or not len(H):
            return H @ x, np.ones(len(H))
        d, kappa, _, _, turn = self._terms(H, inputs, x, P)
        self.d_last = float(d[-1] - turn[-1])
        return d, kappa

    def refresh(self, inputs: dict, x: np.ndarray, P: np.ndarray) -> None:
        """kappa and the added variance at one row of inputs (the live ones at a filter event)."""
        if self._h_u is None:
            return
        _, kappa, var_change, var_beyond, _ = self._terms(self.model.rows(inputs), inputs, x, P)
        self.kappa, self.var_change, self.var_beyond = float(kappa[-1]), float(var_change[-1]), float(var_beyond[-1])

    def _terms(self, H, inputs, x, P):
        """(D_hat, kappa, added variance along P, added variance beyond the covered inputs, turn-rate
        part of D_hat) per row."""
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
        s2_p = np.einsum('ij,jk,ik->i', dh, P, dh)
        s2_r = (rel_r * (d0 - d_rc)) ** 2
        e_temp2 = (rel_t * (d_rc - d_tc)) ** 2
        if not self.shrink:   # the model's change as it is, with its full error variance
            return d0 + turn, np.ones(len(H)), s2_p, s2_r + e_temp2, turn
        c2 = change * change
        total = c2 + s2_p + s2_r
        kappa = np.divide(c2, total, out=np.ones_like(total), where=total > 0)
        return d_u + kappa * change + turn, kappa, kappa * s2_p, kappa * s2_r + e_temp2, turn


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
