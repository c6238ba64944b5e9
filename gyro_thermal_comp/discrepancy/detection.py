"""Matched-filter detection limits: how large a deterministic candidate effect must be for this
record to show it, so "below the detection limit" is a number.

The best possible test for an effect of known shape s(t) in the bins' white noise (weights w =
1/variance) uses only the part of s the current model cannot absorb, P s (P projects out the
model's regressors, weighted): SNR = sqrt(sum_axes sum_bins w (P s)^2) (= sqrt(lambda), the
noncentrality of docs/discrepancy.md, "Detection limits"). An effect enters the model linearly
through its coefficient(s), so SNR is proportional to its size:

* terms added (curvature, hysteresis, g-sensitivity, scale factor, cross-axis, compass): the shape
  is the added columns in the direction of the fitted coefficients; size = |coefficients| per
  component, in the first added term's unit (SI);
* time_offset: s = dt x d(rate)/dt (linearised), size |dt| in s;
* thermal_lag: not linear in its time constant; SNR(tau) of the fitted thermal coefficients seen
  through a die lag tau, on the candidate's tau grid; the limit is the smallest tau reaching it.

`detection_snr` is the SNR at the fitted size; `detection_limit` the size (the same on every
component) at which SNR = `Criteria.snr_detect` (5: a 1 %-level test then has 97 % power).
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from .candidates import BY_NAME, STOCHASTIC
from .terms import TERMS


def _perp_norm2(u: np.ndarray, X: np.ndarray, w: np.ndarray, m: np.ndarray) -> float:
    """sum w (P u)^2 on the bins m, P projecting out the columns of X (weighted)."""
    sw = np.sqrt(w[m])
    Q, _ = np.linalg.qr(X[m] * sw[:, None])
    z = u[m] * sw
    z = z - Q @ (Q.T @ z)
    return float(z @ z)


def detection(an, spec, sc, snr_detect: float) -> dict:
    """{'detection_snr', 'detection_limit', 'detection_unit'} of a scored deterministic candidate
    (None values when not applicable: stochastic, not testable)."""
    none = {'detection_snr': None, 'detection_limit': None, 'detection_unit': None}
    if not sc.testable or sc.channel == STOCHASTIC or sc.spec is None:
        return none
    ch = 'compass' if sc.channel == 'compass' else 'gyro'
    base, var = an.fit(spec, ch), an.fit(sc.spec, ch)
    if sc.spec.lag_tau_s != spec.lag_tau_s:
        return _lag(an, spec, sc, var, snr_detect)
    snr2, unit2, unit = 0.0, 0.0, None
    for j, (cb, cv) in enumerate(zip(base.comps, var.comps)):
        _, Xb = cb.design()
        if sc.spec.time_offset_s != spec.time_offset_s:
            ref = an.reference_rate(0.0)[:, j]
            u = np.gradient(ref, an.data.bin_s)
            size, unit = abs(sc.spec.time_offset_s), 's'
        else:
            added = [i for i, n in enumerate(cv.names) if n not in cb.names]
            if not added:
                continue
            _, Xv = cv.design()
            beta = cv.stats.full()[0][added]
            size = float(np.linalg.norm(beta))
            direction = beta / size if size > 0 else np.full(len(added), 1.0 / math.sqrt(len(added)))
            u = Xv[:, added] @ direction
            unit = unit or TERMS[cv.names[added[0]]].unit
        n2 = _perp_norm2(u, Xb, cb.w, cb.mask)
        unit2 += n2
        snr2 += size * size * n2
    if unit2 <= 0:
        return none
    return {'detection_snr': math.sqrt(snr2), 'detection_limit': snr_detect / math.sqrt(unit2),
            'detection_unit': unit}


def _lag(an, spec, sc, var, snr_detect: float) -> dict:
    """SNR of the fitted thermal coefficients seen through a die lag, at the fitted tau and on the
    tau grid (smallest tau with SNR >= snr_detect, log-interpolated)."""
    base = an.fit(spec, 'gyro')
    betas = [dict(zip(c.names, c.stats.full()[0])) for c in var.comps]

    def snr(tau: float) -> float:
        total = 0.0
        for a, cb in enumerate(base.comps):
            _, Xb = cb.design()
            _, Xt, names = an.gyro_design(replace(spec, lag_tau_s=tau), a)
            s = Xt @ np.array([betas[a].get(n, 0.0) for n in names])
            total += _perp_norm2(s, Xb, cb.w, cb.mask)
        return math.sqrt(total)
    out = {'detection_snr': snr(sc.spec.lag_tau_s), 'detection_limit': None, 'detection_unit': 's'}
    taus = sorted({v.lag_tau_s for v in BY_NAME[sc.name].variants(an, spec)})
    prev = None
    for tau in taus:
        val = snr(tau)
        if val >= snr_detect:
            if prev is None:
                out['detection_limit'] = tau
            else:   # log-log interpolation between the grid points around the crossing
                t0, s0 = prev
                f = math.log(snr_detect / s0) / math.log(val / s0) if s0 > 0 else 1.0
                out['detection_limit'] = float(t0 * (tau / t0) ** f)
            break
        prev = (tau, val)
    return out
