"""Streaming drift truth of the second truth family: the paper model plus drawn effect shapes.

    D_i = a_i T_die + b_i dT_die/dt + c_i                       (paper model, always)
        + k2_i (T_die - 25)^2 + k3_i (T_die - 25)^3            curvature
        + h_i m(t)                                              hysteresis, m in [-1, 1]
        + p_i sin(2 pi t / P + phi)                             periodic
        + sum_k s_ki [t >= t_k]                                 bias_step
T_die: the case temperature, or its first-order lag (tau), or two first-order lags in cascade
(tau1, tau2; dT_die/dt = (x1 - T_die)/tau2, so a step's response starts with zero slope).
Hysteresis branch state m, from a relay r = sign(dT_die/dt) set only where |dT_die/dt| > deadband
(held otherwise, 0 before the first branch):
  sign:        m = r
  relaxation:  m = first-order lag of r (tau_h): the branch offset builds up and stays at holds
  tanh:        m = tanh(k u / w) / tanh(k), u = T_die - play(T_die; half-width w) in [-w, w]:
               a loop in temperature that saturates w degC after each reversal.
Same interface as thermal.ThermalDrift: step(T_case, dT_case/dt, t) -> (D (N, 3) rad/s, T_die).
"""
from __future__ import annotations

import math

import numpy as np
from scipy.signal import lfilter

from .thermal import T_REF_C


class _Lag:
    """First-order lag y' = (x - y)/tau on samples, state carried (lfilter, exact for held inputs)."""

    def __init__(self, tau_s: float, rate_hz: float, y0: float):
        self.tau = tau_s
        self.alpha = math.exp(-1.0 / (rate_hz * tau_s))
        self.zi = np.array([self.alpha * y0])

    def __call__(self, x):
        y, self.zi = lfilter([1.0 - self.alpha], [1.0, -self.alpha], x, zi=self.zi)
        return y


class _Relay:
    """+1 after |rate| > deadband heating, -1 after cooling, held in between (0 before either)."""

    def __init__(self, deadband: float):
        self.deadband, self.state = deadband, 0.0

    def __call__(self, rate):
        active = np.abs(rate) > self.deadband
        idx = np.maximum.accumulate(np.where(active, np.arange(len(rate)), -1)) if len(rate) else np.zeros(0, int)
        out = np.where(idx >= 0, np.sign(rate[np.maximum(idx, 0)]), self.state)
        if len(out):
            self.state = float(out[-1])
        return out


class _Play:
    """Play (backlash) operator of half-width w: p follows x only when |x - p| would exceed w."""

    def __init__(self, half_width: float, x0: float):
        self.w, self.p = half_width, x0

    def __call__(self, x):
        w, p = self.w, self.p
        out = np.empty(len(x))
        for i, xi in enumerate(x.tolist()):     # sequential by nature; ~0.3 us a sample
            p = min(max(p, xi - w), xi + w)
            out[i] = p
        self.p = p
        return out


class FamilyBDrift:
    """Drift truth (rad/s, 3 axes) of one family-B unit, streamed chunk by chunk.

    `shapes`: the truth's shape records (family_b.py), only the present ones; `a, b, c` in deg/s
    units per axis; `t_case0_c`: case temperature at t = 0 (the lags start in equilibrium)."""

    def __init__(self, *, a_dps_per_c, b_dps_per_c_per_s, c_dps, shapes: dict, rate_hz: float, t_case0_c: float):
        self.a, self.b, self.c = (np.radians(np.asarray(v, dtype=float)) for v in (a_dps_per_c, b_dps_per_c_per_s,
                                                                                    c_dps))
        self.shapes = shapes
        lag = shapes.get('lag')
        self.lags = []
        if lag is not None:
            taus = [lag['tau_s']] if lag['variant'] == 'first_order' else [lag['tau1_s'], lag['tau2_s']]
            self.lags = [_Lag(tau, rate_hz, t_case0_c) for tau in taus]
        hyst = shapes.get('hysteresis')
        self.relay = self.play = self.branch_lag = None
        if hyst is not None:
            self.h = np.radians(np.asarray(hyst['size_dps']))
            if hyst['variant'] == 'tanh':
                self.play = _Play(hyst['half_width_c'], t_case0_c)
            else:
                self.relay = _Relay(hyst['deadband_c_s'])
                if hyst['variant'] == 'relaxation':
                    self.branch_lag = _Lag(hyst['tau_s'], rate_hz, 0.0)

    def die_temperature(self, t_case_c, dt_case_c_s):
        """(T_die degC, dT_die/dt degC/s) for one chunk."""
        if not self.lags:
            return t_case_c, dt_case_c_s
        prev, y = None, t_case_c
        for lag in self.lags:          # cascade: each stage lags the one before
            prev, y = y, lag(y)
        return y, (prev - y) / self.lags[-1].tau

    def branch_state(self, t_die, dt_die):
        """Hysteresis state m in [-1, 1] for one chunk."""
        hyst = self.shapes['hysteresis']
        if self.play is not None:
            k, w = hyst['sharpness'], hyst['half_width_c']
            return np.tanh(k * (t_die - self.play(t_die)) / w) / math.tanh(k)
        m = self.relay(dt_die)
        return self.branch_lag(m) if self.branch_lag is not None else m

    def step(self, t_case_c, dt_case_c_s, t_s):
        """One chunk of consecutive samples at times t_s -> (D (N, 3) rad/s, T_die (N,) degC)."""
        t_die, dt_die = self.die_temperature(np.asarray(t_case_c, float), np.asarray(dt_case_c_s, float))
        td, dd = t_die[:, None], dt_die[:, None]
        drift = self.a * td + self.b * dd + self.c
        s = self.shapes
        if 'curvature' in s:
            x = td - T_REF_C
            drift = drift + np.radians(np.asarray(s['curvature']['k2_dps_per_c2'])) * x ** 2 \
                + np.radians(np.asarray(s['curvature']['k3_dps_per_c3'])) * x ** 3
        if 'hysteresis' in s:
            drift = drift + self.h * self.branch_state(t_die, dt_die)[:, None]
        t = np.asarray(t_s, dtype=float)[:, None]
        if 'periodic' in s:
            p = s['periodic']
            drift = drift + np.radians(np.asarray(p['size_dps'])) * np.sin(2 * np.pi * t / p['period_s']
                                                                           + p['phase_rad'])
        for step in s.get('bias_step', {}).get('steps', ()):
            drift = drift + np.radians(np.asarray(step['size_dps'])) * (t >= step['t_s'])
        return drift, t_die
