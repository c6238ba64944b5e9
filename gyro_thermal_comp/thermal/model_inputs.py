"""`ModelInputs`: the drift model's inputs at the IMU stamps, computed causally from the smoothed
sensed temperature (T, dT/dt) - what a discovered effect needs beyond the paper's T and dT/dt.

- die-temperature lag (`lag_tau_s` > 0, `discover`'s thermal_lag): the die that drifts lags the
  sensor that reads T: T_die' = (T - T_die)/tau. Every thermal term then sees T_die and
  dT_die/dt = (T - T_die)/tau, as the physics says (and as discrepancy/terms.py fits it);
- heating/cooling branch (`branch_tau_s`, `branch_rate_scale_c_s`, `discover`'s thermal_hysteresis):
  m' = (tanh(dT_die/dt / scale) - m)/tau_m, +1 after heating, -1 after cooling, relaxing to 0 at a
  hold; the `thermal_branch` term is h * m.

Both are first-order lags over the IMU stamps, exact for a temperature held over each step (the
IMU steps are milliseconds, the time constants minutes). They start when the first temperature
reading is known: in equilibrium (T_die = T) and with no branch history (m = 0). A time gap of
many time constants simply lets them settle to the input.
"""
from __future__ import annotations

import math

import numpy as np

from .drift_model import DriftModel

_MAX_DECAY = 30.0   # time constants per vectorised segment: exp(30) keeps the running sums exact


class ModelInputs:
    """Causal T_die, dT_die/dt and branch state from (t s, T degC, dT/dt degC/s, known) at IMU stamps."""

    def __init__(self, lag_tau_s: float = 0.0, branch_tau_s: float | None = None,
                 branch_rate_scale_c_s: float | None = None):
        if not (math.isfinite(lag_tau_s) and lag_tau_s >= 0):
            raise ValueError(f'lag_tau_s must be >= 0 s, got {lag_tau_s}')
        if (branch_tau_s is None) != (branch_rate_scale_c_s is None):
            raise ValueError('the branch needs both branch_tau_s and branch_rate_scale_c_s')
        if branch_tau_s is not None and not (branch_tau_s >= 0 and branch_rate_scale_c_s > 0):
            raise ValueError('branch_tau_s must be >= 0 s and branch_rate_scale_c_s > 0 degC/s')
        self.lag_tau_s = float(lag_tau_s)
        self.branch = None if branch_tau_s is None else (float(branch_tau_s), float(branch_rate_scale_c_s))
        self._t: float | None = None      # stamp of the newest state, s
        self._die = math.nan              # T_die there, degC
        self._m = 0.0                     # branch state there
        self.last: dict[str, float] | None = None   # newest inputs (for the live regressor row)

    @property
    def trivial(self) -> bool:
        """True when the inputs are the sensed T and dT/dt as they are (the paper's model)."""
        return self.lag_tau_s == 0 and self.branch is None

    def live(self, model: DriftModel) -> dict[str, np.ndarray]:
        """The newest inputs as one row with no turn (rate 0): the live drift's and its sigma's; before
        any, the model's neutral inputs at its reference temperature."""
        if self.last is None:
            return model.neutral_inputs(model.temperature_ref_c)
        return {**{k: np.array([v]) for k, v in self.last.items()}, 'rate': np.zeros(1)}

    def at(self, t: np.ndarray, temp_c: np.ndarray, temp_rate_c_s: np.ndarray, known: np.ndarray,
           rate_rad_s: np.ndarray) -> dict[str, np.ndarray]:
        """Named inputs for `DriftModel.rows` at stamps t (increasing, s)."""
        out = {'temperature': temp_c, 'temperature_rate': temp_rate_c_s, 'rate': rate_rad_s}
        if self.trivial or t.size == 0:
            if t.size:
                self.last = {k: float(v[-1]) for k, v in out.items()}
            return out
        temp, rate = temp_c, temp_rate_c_s
        if self.lag_tau_s > 0:
            temp = self._lag_die(t, temp_c, known)
            rate = np.where(np.isfinite(temp), (temp_c - temp) / self.lag_tau_s, 0.0)
            temp = np.where(np.isfinite(temp), temp, temp_c)   # before the first reading: as sensed
        out['temperature'], out['temperature_rate'] = temp, rate
        if self.branch is not None:
            tau_m, scale = self.branch
            u = np.tanh(rate / scale)
            out['thermal_branch'] = u if tau_m == 0 else _first_order(t, u, self._t, self._m, tau_m)
            self._m = float(out['thermal_branch'][-1])
        self._t = float(t[-1])
        self.last = {k: float(v[-1]) for k, v in out.items()}
        return out

    def _lag_die(self, t, temp_c, known) -> np.ndarray:
        """T_die at t (NaN until the first known reading)."""
        die = np.full(t.size, np.nan)
        start = 0
        if not math.isfinite(self._die):
            first = np.flatnonzero(known)
            if first.size == 0:
                return die
            start = int(first[0])
            self._die, self._t = float(temp_c[start]), float(t[start])   # in equilibrium
        die[start:] = _first_order(t[start:], temp_c[start:], self._t, self._die, self.lag_tau_s)
        self._die = float(die[-1])
        return die


def _first_order(t: np.ndarray, u: np.ndarray, t_prev: float | None, y_prev: float, tau_s: float) -> np.ndarray:
    """y_k = a_k y_{k-1} + (1 - a_k) u_k, a_k = exp(-(t_k - t_{k-1})/tau), vectorised:
    y_k = e^{-L_k} (y_prev + sum_{j<=k} (1 - a_j) u_j e^{L_j}), L the decay since the segment start."""
    t_prev = float(t[0]) if t_prev is None else t_prev
    dt = np.diff(np.concatenate(([t_prev], t)))
    decay = np.cumsum(np.maximum(dt, 0.0) / tau_s)
    out = np.empty(t.size)
    i = 0
    while i < t.size:   # one segment of at most _MAX_DECAY time constants (a normal stretch: one)
        a0 = math.exp(-(decay[i] - (decay[i - 1] if i else 0.0)))   # the first step alone: it may be a gap
        out[i] = a0 * y_prev + (1.0 - a0) * u[i]
        base = decay[i]
        j = i + 1 + int(np.searchsorted(decay[i + 1:], base + _MAX_DECAY, side='right'))
        seg = decay[i + 1:j] - base
        if seg.size:
            w = -np.expm1(-np.diff(np.concatenate(([0.0], seg)))) * np.exp(seg)   # (1 - a_j) e^{L_j}
            out[i + 1:j] = np.exp(-seg) * (out[i] + np.cumsum(w * u[i + 1:j]))
        y_prev = float(out[j - 1])
        i = j
    return out
