"""How well can ANY estimator predict the drift through an outage? A noise floor from the record.

Before an outage the compass gives one drift measurement per window of `window_s`, each with the
gyro's white noise averaged over the window: sigma_y = ARW / sqrt(window_s) (rad/s). Suppose the
truth were exactly a drift model with regressors h(t) (the paper's `a T + b dT/dt + c`) and an
estimator used every window since the still period with no forgetting - the most information the
record holds. Its least-squares parameters have covariance C = sigma_y^2 (H^T H)^-1, and the heading
error it accumulates over the outage, integral of h(t) (x_hat - x) dt = g (x_hat - x) with
g = integral of h over the outage, has the standard deviation

    sigma_outage = sqrt(g C g^T)      (rad)

No unbiased estimator of that model does better (Gauss-Markov); a real one also forgets, and the
real drift is richer than the model. The median of |N(0, sigma)| is 0.674 sigma.

That floor assumes a drift with no randomness of its own. A real gyro's bias also wanders (bias
instability, rate random walk), and what it does after the outage starts is in no record:
`wander_floor_rad` is the heading error that wander alone leaves over an outage, for the best
prediction from the exact bias at its start. Both are independent of each other, so no estimator's
excess is below sqrt(outage_floor^2 + wander_floor^2) in the rms.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from ..thermal.drift_model import PAPER_TERMS, DriftModel

MEDIAN_ABS_NORMAL = 0.6745  # median of |x| for x ~ N(0, 1)


def outage_floor_rad(t_s: np.ndarray, temp_c: np.ndarray, temp_rate_c_s: np.ndarray,
                     spans_s: Sequence[tuple[float, float]], arw_rad_sqrt_s: float,
                     window_s: float = 10.0, learn_from_s: float = 30.0,
                     terms: Sequence[str] = PAPER_TERMS) -> np.ndarray:
    """1-sigma heading error (rad) of the best linear unbiased drift prediction over each outage.

    `t_s`, `temp_c`, `temp_rate_c_s`: the temperature estimate (s, degC, degC/s), any sampling;
    `spans_s`: outages as (start, end) s; windows before `learn_from_s` (the still period) and
    inside any outage are not measurements."""
    t = np.asarray(t_s, dtype=float)
    edges = np.arange(t[0], t[-1] + window_s, window_s)
    mid = 0.5 * (edges[:-1] + edges[1:])
    temp = np.interp(mid, t, np.asarray(temp_c, dtype=float))
    rate = np.interp(mid, t, np.asarray(temp_rate_c_s, dtype=float))
    model = DriftModel(tuple(terms))
    H = model.rows({'temperature': temp, 'temperature_rate': rate, 'rate': np.zeros_like(mid)})
    in_outage = np.zeros(mid.size, dtype=bool)
    for t0, t1 in spans_s:
        in_outage |= (edges[1:] > t0) & (edges[:-1] < t1)
    usable = ~in_outage & (edges[:-1] >= t[0] + learn_from_s)
    var_y = arw_rad_sqrt_s ** 2 / window_s
    out = []
    for t0, t1 in spans_s:
        before = usable & (edges[1:] <= t0)
        inside = (mid >= t0) & (mid < t1)
        if np.count_nonzero(before) <= H.shape[1] or not np.any(inside):
            out.append(np.nan)
            continue
        info = H[before].T @ H[before] / var_y
        g = H[inside].sum(axis=0) * window_s
        out.append(float(np.sqrt(max(g @ np.linalg.lstsq(info, g, rcond=None)[0], 0.0))))
    return np.array(out)


def wander_floor_rad(duration_s: float, bias_instability_rad_s: float, tau_s: float,
                     rate_random_walk_rad_s_sqrt_s: float) -> float:
    """1-sigma heading error (rad) that the gyro bias's own wander leaves over an outage of
    `duration_s` (s), for the best prediction from the exact bias at the outage start.

    The wander: a first-order Gauss-Markov bias (stationary 1-sigma `bias_instability_rad_s`, time
    constant `tau_s`), best predicted as its start value decaying with exp(-t/tau), plus a rate random
    walk (`rate_random_walk_rad_s_sqrt_s`, rad/s per sqrt(s)), best predicted as its start value.
    Their innovations after the start are unknowable from any record; integrated over T, x = T/tau:

        var_GM  = (sigma tau)^2 (2x - 3 + 4 exp(-x) - exp(-2x))
        var_RRW = q^2 T^3 / 3
    """
    t = float(duration_s)
    var = rate_random_walk_rad_s_sqrt_s ** 2 * t ** 3 / 3.0
    if tau_s > 0.0 and bias_instability_rad_s > 0.0:
        x = t / tau_s
        # for x << 1 the bracket cancels to 2 x^3 / 3 - x^4 / 2 (+ O(x^5)): its series, not the difference
        bracket = 2.0 * x - 3.0 + 4.0 * np.exp(-x) - np.exp(-2.0 * x) if x > 1e-2 else \
            2.0 * x ** 3 / 3.0 - x ** 4 / 2.0
        var += (bias_instability_rad_s * tau_s) ** 2 * bracket
    return float(np.sqrt(var))
