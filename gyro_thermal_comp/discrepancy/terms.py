"""Drift-model terms the discrepancy library can add, as `thermal.drift_model.Term`s, and the
input signals they need.

`DriftModel` takes `Term` objects as well as builtin names, so a discovered effect becomes a longer
term list (and a longer STKF state) with no change to the filter. This package keeps its own term
table, `TERMS` (thermal's builtin terms, which include every term the estimator can run online,
plus `LIBRARY_TERMS`), and `drift_model(names)` resolves
any mix of builtin and library names in it and hands the `Term` objects to `DriftModel`; thermal's
own table is never changed. Terms whose input is not one of the estimator's own (temperature,
temperature_rate, rate) need that input supplied alongside; the helpers below compute them from
binned or streamed data.

Inputs (all (N,) arrays, SI units, temperature degC):
  temperature, temperature_rate      smoothed T and dT/dt of the temperature reading; with a
                                     thermal_lag these are the die's, `die_temperature()` (the lag
                                     is a setting of the input, not a term: every thermal term then
                                     sees the die temperature, as the physics says)
  thermal_branch                     heating/cooling branch state in [-1, 1], `thermal_branch()`
  rate                               true rate about this gyro axis, rad/s
  rate_other_1, rate_other_2         true rates about the two other axes (cyclic order), rad/s
  specific_force_x/_y/_z             specific force, m/s^2, sensor frame
  earth_north                        sensor-axis component of the unit north vector (Earth rate)
  rate_derivative                    d(rate)/dt, rad/s^2
  heading                            true heading, rad (compass terms)
"""
from __future__ import annotations

import numpy as np
from scipy.signal import lfilter, savgol_filter

from ..constants import EARTH_RATE_RAD_S
from ..thermal.drift_model import BUILTIN_TERMS, DriftModel, Term


def _col(name):
    """A term that is one named input as is."""
    return lambda inputs, t_ref: inputs[name]


# prior_sigma: plausible 1-sigma of the coefficient (SI) for a MEMS rate gyro, generous (a few times
# datasheet values: g-sensitivity 0.1 deg/s/g, cross-axis 2 %). It sizes the STKF prior and, in the
# discrepancy fits, is the Gaussian prior of the coefficient (so one regressor cannot imitate another
# with an absurd coefficient) and decides whether a regressor is excited enough to be estimated.
# (temperature_cubed and thermal_branch are thermal's own builtin terms: the estimator runs them
# from a model file, thermal/model_file.py)
LIBRARY_TERMS: dict[str, Term] = {t.name: t for t in (
    Term('specific_force_x', 'rad/s/(m/s^2)', _col('specific_force_x'), ('specific_force_x',),
         prior_sigma=1.8e-4, q_sigma=1e-9),
    Term('specific_force_y', 'rad/s/(m/s^2)', _col('specific_force_y'), ('specific_force_y',),
         prior_sigma=1.8e-4, q_sigma=1e-9),
    Term('specific_force_z', 'rad/s/(m/s^2)', _col('specific_force_z'), ('specific_force_z',),
         prior_sigma=1.8e-4, q_sigma=1e-9),
    Term('cross_rate_1', '1', _col('rate_other_1'), ('rate_other_1',), prior_sigma=2e-2, q_sigma=1e-7),
    Term('cross_rate_2', '1', _col('rate_other_2'), ('rate_other_2',), prior_sigma=2e-2, q_sigma=1e-7),
    Term('earth_rate_north', 'rad/s', _col('earth_north'), ('earth_north',),
         prior_sigma=EARTH_RATE_RAD_S, q_sigma=0.0),
    # linearised stamp offset: gyro(t) = w(t - dt) ~ w - dt * dw/dt, so the coefficient is -dt (s)
    Term('rate_derivative', 's', _col('rate_derivative'), ('rate_derivative',), prior_sigma=0.05, q_sigma=0.0),
    # compass deviation: psi_compass - psi_true = offset + 1st (hard iron) + 2nd (soft iron) harmonics
    Term('compass_offset', 'rad', lambda inputs, t_ref: np.ones_like(inputs['heading']), ('heading',),
         prior_sigma=0.2),
    Term('compass_sin1', 'rad', lambda inputs, t_ref: np.sin(inputs['heading']), ('heading',), prior_sigma=0.05),
    Term('compass_cos1', 'rad', lambda inputs, t_ref: np.cos(inputs['heading']), ('heading',), prior_sigma=0.05),
    Term('compass_sin2', 'rad', lambda inputs, t_ref: np.sin(2 * inputs['heading']), ('heading',), prior_sigma=0.02),
    Term('compass_cos2', 'rad', lambda inputs, t_ref: np.cos(2 * inputs['heading']), ('heading',), prior_sigma=0.02),
)}

TERMS: dict[str, Term] = {**BUILTIN_TERMS, **LIBRARY_TERMS}   # every term known here, by name


def term(name: str) -> Term:
    try:
        return TERMS[name]
    except KeyError:
        raise KeyError(f'unknown drift-model term {name!r}; known: {sorted(TERMS)}') from None


def drift_model(names, temperature_ref_c: float = 25.0) -> DriftModel:
    """A DriftModel from builtin and library term names (passed to it as `Term` objects)."""
    return DriftModel([term(n) for n in names], temperature_ref_c)


# ------------------------------------------------------------------------------------------ inputs
def smooth_temperature(temp_c: np.ndarray, step_s: float, window_s: float = 61.0):
    """(T, dT/dt) on a regular grid from per-bin mean readings (NaN where a bin had none).

    Centred local quadratic regression (Savitzky-Golay): no lag, and the slope is unbiased for
    a quadratic trend, which the offline fit can afford (a causal estimator cannot). Readings are
    quantised (0.06 degC) and noisy, so differencing them would swamp dT/dt."""
    temp = np.asarray(temp_c, float)
    ok = np.isfinite(temp)
    if ok.sum() < 2:
        raise ValueError('too few temperature readings')
    idx = np.arange(temp.size)
    filled = np.interp(idx, idx[ok], temp[ok])
    n = int(round(window_s / step_s)) | 1          # odd window length, bins
    n = min(n, temp.size if temp.size % 2 else temp.size - 1)
    if n < 5:
        return filled, np.gradient(filled, step_s)
    poly = min(2, n - 1)
    return (savgol_filter(filled, n, poly, mode='interp'),
            savgol_filter(filled, n, poly, deriv=1, delta=step_s, mode='interp'))


def first_order_lag(u: np.ndarray, step_s: float, tau_s: float) -> np.ndarray:
    """y' = (u - y)/tau sampled every step_s, exact for an input that is linear between samples
    (ramp-invariant discretisation); starts in equilibrium, y[0] = u[0]."""
    u = np.asarray(u, float)
    if tau_s <= 0:
        return u.copy()
    a = np.exp(-step_s / tau_s)
    b = tau_s / step_s * (1.0 - a)
    y, _ = lfilter([1.0 - b, b - a], [1.0, -a], u, zi=np.array([b * u[0]]))
    return y


def die_temperature(temp_c: np.ndarray, step_s: float, tau_s: float):
    """(T_die, dT_die/dt): the temperature of a die lagging the sensed one by a first-order lag of
    time constant tau_s (thermal_lag). dT_die/dt = (T - T_die)/tau."""
    t_die = first_order_lag(temp_c, step_s, tau_s)
    rate = (np.asarray(temp_c) - t_die) / tau_s if tau_s > 0 else np.gradient(t_die, step_s)
    return t_die, rate


def thermal_branch(temp_rate_c_s: np.ndarray, step_s: float, tau_s: float, scale_c_s: float) -> np.ndarray:
    """Heading/cooling branch state m in [-1, 1] (thermal_hysteresis): tanh(dT/dt / scale) is +1
    while heating, -1 while cooling, 0 at a hold; m follows it through a first-order lag of tau_s,
    so the branch is remembered for a while after the temperature stops changing. Starts at 0 (no
    thermal history)."""
    u = np.tanh(np.asarray(temp_rate_c_s, float) / scale_c_s)
    if tau_s <= 0:
        return u
    a = np.exp(-step_s / tau_s)
    y, _ = lfilter([1.0 - a], [1.0, -a], u, zi=np.zeros(1))
    return y
