"""Temperature profiles and the thermal drift truth of a 3-axis gyro.

The paper (Feng et al. 2015, eq. 2) models the drift as D = a*T + b*dT/dt + c. Its MLR baseline
still leaves +-15 deg of heading error over ~2 h because real drift is not that: this truth adds,
each switchable, curvature in T, a heating/cooling hysteresis and a lag of the die temperature
behind the temperature the sensor reads (effects.py gives the exact terms).

Temperatures in degC, times in s, drift in rad/s.
"""
from __future__ import annotations

import numpy as np
from scipy.interpolate import CubicHermiteSpline
from scipy.signal import lfilter

T_REF_C = 25.0               # reference temperature of curvature and scale-factor terms, degC
HYSTERESIS_RATE_C_S = 0.002  # |dT/dt| above which a branch counts as heating/cooling, degC/s


class TemperatureProfile:
    """Case temperature T(t) and its exact derivative: a C1 cubic Hermite curve through knots.

    Knots are given on a normalised shape (0 = start temperature, 1 = peak) and mapped affinely onto
    [start_c, peak_c], so one shape serves any temperature span. Before the first and after the last
    knot the temperature holds.
    """

    def __init__(self, knots, start_c: float, peak_c: float):
        t, y, slope = (np.asarray(col, dtype=float) for col in zip(*knots))
        span = peak_c - start_c
        self._t0, self._t1 = t[0], t[-1]
        self._curve = CubicHermiteSpline(t, start_c + span * y, span * slope)
        self._slope = self._curve.derivative()

    def __call__(self, t_s) -> tuple[np.ndarray, np.ndarray]:
        """(T in degC, dT/dt in degC/s) at times t_s."""
        t = np.asarray(t_s, dtype=float)
        tc = np.clip(t, self._t0, self._t1)
        inside = (t >= self._t0) & (t <= self._t1)
        return self._curve(tc), np.where(inside, self._slope(tc), 0.0)


def approach_knots(t_start: float, y_start: float, y_target: float, tau_s: float,
                   t_end: float, round_s: float = 120.0, step_s: float = 200.0) -> list:
    """Knots of a hold at y_start that turns, within round_s, into an exponential approach to y_target
    with time constant tau_s (a heated or cooled mass): y = y_target + (y1 - y_target)*exp(-dt/tau)."""
    slope0 = (y_target - y_start) / tau_s
    y1 = y_start + 0.5 * round_s * slope0           # a parabolic corner: slope grows linearly
    t1 = t_start + round_s
    knots = [(t_start, y_start, 0.0)]
    for dt in np.arange(0.0, t_end - t1 + step_s, step_s):
        y = y_target + (y1 - y_target) * np.exp(-dt / tau_s)
        knots.append((t1 + dt, y, (y_target - y) / tau_s))
    return knots


def static_ramp_shape() -> list:
    """Lab oven run of the paper's static test: hold, heat 23 -> 58 degC at a non-uniform rate (fast in
    the middle), hold ~8 min, then natural cooling back towards ambient (~24 degC after 2 h).

    Knots (t s, shape, d shape/dt) on the 23..58 degC scale (shape = (T - 23)/35)."""
    heat = [(0.0, 23.0, 0.0), (120.0, 23.0, 0.0), (600.0, 25.5, 0.010), (1200.0, 33.5, 0.017),
            (1500.0, 39.5, 0.022), (1900.0, 47.5, 0.016), (2400.0, 54.5, 0.010), (2800.0, 58.0, 0.0)]
    knots = [(t, (temp - 23.0) / 35.0, slope / 35.0) for t, temp, slope in heat]
    return knots + approach_knots(3300.0, 1.0, 0.0, tau_s=1100.0, t_end=40000.0)


def warm_up_shape(hold_s: float, tau_s: float, t_end: float) -> list:
    """Hold at the start temperature, then warm up exponentially towards the peak (cabin, self-heating)."""
    hold = [(0.0, 0.0, 0.0)] if hold_s > 0 else []   # no hold: the approach starts at 0 (knots strictly increase)
    return hold + approach_knots(hold_s, 0.0, 1.0, tau_s, t_end)


class ThermalDrift:
    """Streaming thermal drift truth D (rad/s, 3 axes) from the case temperature, chunk by chunk.

    T_die = first-order lag of T_case (thermal_lag; exact when 0), dT_die/dt = (T_case - T_die)/tau.
    D_i = a_i*T_die + b_i*dT_die/dt + c_i + k_i*(T_die - 25)^2 + h_i*m, with m the hysteresis state.
    Coefficients in deg/s units (as recorded in the config), converted here.
    """

    def __init__(self, *, a_dps_per_c, b_dps_per_c_per_s, c_dps, curvature_dps_per_c2, hysteresis_dps,
                 lag_s: float, hysteresis_tau_s: float, rate_hz: float, t_case0_c: float):
        self.a, self.b, self.c = (np.radians(np.asarray(v, dtype=float)) for v in
                                  (a_dps_per_c, b_dps_per_c_per_s, c_dps))
        self.k2 = np.radians(np.asarray(curvature_dps_per_c2, dtype=float))
        self.h = np.radians(np.asarray(hysteresis_dps, dtype=float))
        self.lag_s = float(lag_s)
        self._alpha_lag = np.exp(-1.0 / (rate_hz * lag_s)) if lag_s > 0 else 0.0
        self._zi_lag = np.array([self._alpha_lag * t_case0_c])   # start in equilibrium
        self._alpha_h = np.exp(-1.0 / (rate_hz * hysteresis_tau_s))
        self._zi_h = np.zeros(1)                                  # no thermal history at start

    def step(self, t_case_c: np.ndarray, dt_case_c_s: np.ndarray, t_s=None):
        """One chunk of consecutive samples -> (D (N, 3) rad/s, T_die (N,) degC). t_s (the samples' times)
        is unused: this truth is time-invariant; the second family's (family_b_drift.py) is not."""
        if self.lag_s > 0:
            al = self._alpha_lag
            t_die, self._zi_lag = lfilter([1.0 - al], [1.0, -al], t_case_c, zi=self._zi_lag)
            dt_die = (t_case_c - t_die) / self.lag_s
        else:
            t_die, dt_die = t_case_c, dt_case_c_s
        ah = self._alpha_h
        m, self._zi_h = lfilter([1.0 - ah], [1.0, -ah], np.tanh(dt_die / HYSTERESIS_RATE_C_S), zi=self._zi_h)
        td, dd, mm = t_die[:, None], dt_die[:, None], m[:, None]
        drift = self.a * td + self.b * dd + self.c + self.k2 * (td - T_REF_C) ** 2 + self.h * mm
        return drift, t_die
