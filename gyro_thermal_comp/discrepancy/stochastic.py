"""Stochastic bias wander (rate random walk) and residual whiteness.

A random-walk bias is not a regressor: nothing measured predicts it. What it does predict is that
the residual's level in a stretch of time is close to the level just before and after (a local-level
state-space model: u_{j+1} = u_j + eta, Var(eta) = q * step; observed through the white noise of
each coarse bin, whose variance is known from the bins' own noise estimate). So the candidate is
scored like the others on held-out blocks: a Kalman/RTS smoother run over the training blocks
interpolates the wander into the held-out block. q is estimated by maximum likelihood.

`whiteness` asks the model-free question: is the residual consistent with white noise of the
known level, at averaging times from 10 s to a tenth of the record? (block-mean chi-square test).
"""
from __future__ import annotations

import math

import numpy as np
from scipy import stats
from scipy.optimize import minimize_scalar

COARSE_S = 30.0   # coarse bins for the wander: far below any realistic wander time scale


def coarse_index(n_bins: int, bin_s: float, coarse_s: float = COARSE_S) -> tuple[np.ndarray, int]:
    step = max(1, int(round(coarse_s / bin_s)))
    idx = np.arange(n_bins) // step
    return idx, int(idx[-1]) + 1 if n_bins else 0


def coarse_means(r: np.ndarray, var: np.ndarray, use: np.ndarray, idx: np.ndarray, n_coarse: int):
    """Inverse-variance means of fine residuals per coarse bin (NaN where no fine bin is used) and
    their white-noise variance."""
    w = np.where(use, 1.0 / var, 0.0)
    sw = np.bincount(idx, weights=w, minlength=n_coarse)
    swr = np.bincount(idx, weights=np.where(use, w * r, 0.0), minlength=n_coarse)
    with np.errstate(invalid='ignore', divide='ignore'):
        return np.where(sw > 0, swr / sw, np.nan), np.where(sw > 0, 1.0 / sw, np.inf)


def local_level(m: np.ndarray, v: np.ndarray, q_step: float):
    """Kalman filter + RTS smoother of a random walk observed in white noise.

    m: (J,) coarse means (NaN = missing), v: (J,) their variances, q_step: random-walk variance per
    coarse step. Diffuse start (the first observation sets the level). Returns (smoothed level (J,),
    log-likelihood of the observations after the first)."""
    J = m.size
    xf, pf, xp, pp = np.zeros(J), np.full(J, np.inf), np.zeros(J), np.full(J, np.inf)
    x, p, ll = 0.0, math.inf, 0.0
    obs = np.isfinite(m)
    ml, vl = m.tolist(), v.tolist()
    for j in range(J):
        if j:
            p = p + q_step
        xp[j], pp[j] = x, p
        if obs[j]:
            if p == math.inf:
                x, p = ml[j], vl[j]
            else:
                s = p + vl[j]
                e = ml[j] - x
                k = p / s
                ll -= 0.5 * (math.log(2.0 * math.pi * s) + e * e / s)
                x += k * e
                p = (1.0 - k) * p
        xf[j], pf[j] = x, p
    xs = xf.copy()
    for j in range(J - 2, -1, -1):
        if not np.isfinite(pf[j]):
            xs[j] = xs[j + 1]
        elif pp[j + 1] > 0 and np.isfinite(pp[j + 1]):
            xs[j] = xf[j] + pf[j] / pp[j + 1] * (xs[j + 1] - xp[j + 1])
    return xs, ll


def fit_q(m: np.ndarray, v: np.ndarray):
    """Maximum-likelihood random-walk variance per coarse step: (q_step, ll(q_step), ll(0))."""
    ok = np.isfinite(m)
    if ok.sum() < 5:
        return 0.0, 0.0, 0.0
    v_med = float(np.median(v[ok]))
    ll0 = local_level(m, v, 0.0)[1]
    f = lambda lg: -local_level(m, v, v_med * 10.0 ** lg)[1]
    grid = np.arange(-6.0, 2.01, 1.0)
    vals = [f(g) for g in grid]
    i = int(np.argmin(vals))
    lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]
    res = minimize_scalar(f, bounds=(lo, hi), method='bounded', options={'xatol': 0.02})
    best_lg, best = (res.x, res.fun) if res.fun < vals[i] else (grid[i], vals[i])
    if -best <= ll0:
        return 0.0, ll0, ll0
    return float(v_med * 10.0 ** best_lg), float(-best), float(ll0)


def wander_at(r, var, train, idx, n_coarse, q_step, centres_c, t_fine):
    """Smoothed wander from the training bins' residuals, interpolated at every fine bin."""
    m, v = coarse_means(r, var, train, idx, n_coarse)
    xs, _ = local_level(m, v, q_step)
    return np.interp(t_fine, centres_c, xs)


def score_random_walk(an, spec):
    """Held-out chi-square gain per batch, Delta BIC, per-axis q ((rad/s)^2 per s), the coarse-bin
    log-likelihood of the joint model (regression + random walk) and the number of coarse bins, for
    adding a random-walk bias to `spec`'s gyro model."""
    fit = an.fit(spec, 'gyro')
    d = an.data
    idx, nc = coarse_index(len(d.t), d.bin_s)
    step_s = d.bin_s * max(1, int(round(COARSE_S / d.bin_s)))
    centres = (np.arange(nc) + 0.5) * step_s
    K = an.n_folds
    gains = np.zeros(an.batch_fold.size)
    delta_ll, q_axes, ll_total = 0.0, [], 0.0
    n_coarse_used = 0
    for a, c in enumerate(fit.comps):
        m = c['mask']
        var = an.gyro_var[:, a]
        st = c['stats']
        held, _, betas, _ = st.cv()
        Xs = c['X'] / st.scale
        # all-data fit: likelihood gain and q
        r_full = np.where(m, c['y'] - st.predict_full(c['X']), 0.0)
        mc, vc = coarse_means(r_full, var, m, idx, nc)
        q, ll1, ll0 = fit_q(mc, vc)
        delta_ll += ll1 - ll0
        ll_total += ll1
        n_coarse_used = max(n_coarse_used, int(np.isfinite(mc).sum()))
        q_axes.append(q / step_s)
        for k in range(K):
            r_k = np.where(m, c['y'] - (Xs @ betas[k] + st.y_mean), 0.0)
            train = m & (an.fold != k)
            test = m & (an.fold == k)
            mt, vt = coarse_means(r_k, var, train, idx, nc)
            qk, _, _ = fit_q(mt, vt)
            if qk == 0.0:
                continue   # no wander found in training: the prediction is the model's own
            xs, _ = local_level(mt, vt, qk)
            u = np.interp(d.t[test], centres, xs)
            w = an.gyro_w[test, a]
            r = r_k[test]
            gains += np.bincount(an.batch[test], weights=w * (r * r - (r - u) ** 2), minlength=gains.size)
    delta_bic = 2.0 * delta_ll - len(fit.comps) * math.log(max(n_coarse_used, 2))
    return gains, float(delta_bic), q_axes, float(ll_total), n_coarse_used


def cv_wander(an, spec, q_axes, per_batch: bool = False) -> np.ndarray:
    """(N, 3) wander of `spec`'s residual at each fold (or each batch), smoothed from the other
    folds (batches) only, so a held-out stretch's own noise never enters its own correction."""
    fit = an.fit(spec, 'gyro')
    d = an.data
    idx, nc = coarse_index(len(d.t), d.bin_s)
    step_s = d.bin_s * max(1, int(round(COARSE_S / d.bin_s)))
    centres = (np.arange(nc) + 0.5) * step_s
    out = np.zeros((len(d.t), 3))
    for a, c in enumerate(fit.comps):
        m = c['mask']
        if q_axes[a] <= 0:
            continue
        r = np.where(m, c['y'] - c['stats'].predict_full(c['X']), 0.0)
        groups, n_groups = (an.batch, an.batch_fold.size) if per_batch else (an.fold, an.n_folds)
        for k in range(n_groups):
            test = m & (groups == k)
            if test.any():
                out[test, a] = wander_at(r, an.gyro_var[:, a], m & (groups != k), idx, nc, q_axes[a] * step_s,
                                         centres, d.t[test])
    return out


# ---------------------------------------------------------------------------------- whiteness
def whiteness(resid: np.ndarray, var: np.ndarray, mask: np.ndarray, bin_s: float,
              scales_s=(10.0, 30.0, 100.0, 300.0, 1000.0), min_blocks: int = 10) -> dict:
    """Block-mean chi-square test of a residual against white noise of known per-bin variance.

    For each averaging time L and component, the block means m_j of the residual have variance
    v_j = sum(var)/n^2 under white noise, and sum(m_j^2 / v_j) ~ chi2(#blocks). In-sample
    residuals make the test conservative (the fit removed some variance). Returns per scale the
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
        for j in range(resid.shape[1]):
            use = mask & np.isfinite(resid[:, j])
            cnt = np.bincount(idx, weights=use.astype(float), minlength=nb)
            s = np.bincount(idx, weights=np.where(use, resid[:, j], 0.0), minlength=nb)
            sv = np.bincount(idx, weights=np.where(use, var[:, j], 0.0), minlength=nb)
            ok = full & (cnt > 0)
            mj = s[ok] / cnt[ok]
            vj = sv[ok] / cnt[ok] ** 2
            chi2 = float(np.sum(mj * mj / vj))
            dof = int(ok.sum())
            p = float(stats.chi2.sf(chi2, dof))
            n_tests += 1
            rows.append({'scale_s': step * bin_s, 'component': j, 'ratio': chi2 / dof, 'p': p, 'blocks': dof})
            pmin = min(pmin, p)
    return {'tests': rows, 'p_min': min(1.0, pmin * max(n_tests, 1)), 'n_tests': n_tests}
