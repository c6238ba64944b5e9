"""Residual whiteness: is what the model leaves consistent with white noise of the known level, at
averaging times from 10 s to a tenth of the record? (block-mean chi-square test). Model-free: it
decides between "no missing effect" and "unexplained residual" when no candidate is named. The
stochastic candidates themselves (random walk, Gauss-Markov bias) live in wander.py.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

from .metrics import window_sums


@dataclass(frozen=True)
class Whiteness:
    """The block-mean chi-square tests of one residual (`whiteness`)."""
    tests: list[dict]   # per scale and component: scale_s, component, ratio, p, blocks (report rows)
    p_min: float        # smallest p-value, Bonferroni-corrected over all tests
    n_tests: int


def whiteness(resid: np.ndarray, var: np.ndarray, mask: np.ndarray, bin_s: float,
              scales_s=(10.0, 30.0, 100.0, 300.0, 1000.0), min_blocks: int = 10) -> Whiteness:
    """Block-mean chi-square test of a residual against white noise of known per-bin variance.

    For each averaging time L and component, the block means m_j of the residual have variance
    v_j = sum(var)/n^2 under white noise, and sum(m_j^2 / v_j) ~ chi2(#blocks). In-sample
    residuals make the test conservative (the fit removed some variance). Gives per scale the
    ratio observed/expected and the p-value; `p_min` is Bonferroni-corrected over all tests."""
    resid = np.atleast_2d(resid.T).T
    var = np.atleast_2d(var.T).T
    rows, pmin, n_tests = [], 1.0, 0
    n = len(mask)
    for L in scales_s:
        step = max(1, int(round(L / bin_s)))
        idx = np.arange(n) // step
        nb = int(idx[-1]) + 1
        full = np.bincount(idx, weights=mask.astype(float), minlength=nb) >= 0.5 * step
        if full.sum() < min_blocks:
            continue
        for j, sums in enumerate(window_sums(resid, var, mask, step)):
            ok = full & (sums.count > 0)
            mj = sums.total[ok] / sums.count[ok]
            vj = sums.var_total[ok] / sums.count[ok] ** 2
            chi2 = float(np.sum(mj * mj / vj))
            dof = int(ok.sum())
            p = float(stats.chi2.sf(chi2, dof))
            n_tests += 1
            rows.append({'scale_s': step * bin_s, 'component': j, 'ratio': chi2 / dof, 'p': p, 'blocks': dof})
            pmin = min(pmin, p)
    return Whiteness(tests=rows, p_min=min(1.0, pmin * max(n_tests, 1)), n_tests=n_tests)
