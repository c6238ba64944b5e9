"""Stochastic bias wander: a rate random walk or a first-order Gauss-Markov bias (bias instability).

Neither is a regressor: nothing measured predicts it. What each predicts is that the residual's
level in a stretch of time is close to the level just before and after - a state observed through
the white noise of each coarse bin (variance known from the bins' own noise estimate):

    u_{j+1} = phi u_j + eta,   Var(eta) = q_step,   phi = exp(-step / tau)

phi = 1 is the random walk (Allan deviation rising as sqrt(tau) for ever); phi < 1 is the
Gauss-Markov bias, which reverts to the mean over its correlation time tau (the Allan deviation
bump of "bias instability"). The random walk is the tau -> infinity limit (at fixed q): the two are
nested, and the extra setting has to earn its place. Each candidate is scored like the others on
held-out blocks: a Kalman/RTS smoother over the training blocks interpolates the wander into the
held-out block; (q, tau) are estimated by maximum likelihood on the training blocks. The
likelihood conditions on the first coarse bin (diffuse start) for both, so they compare directly.
"""
from __future__ import annotations

import math

import numpy as np
from scipy import stats

COARSE_S = 30.0   # coarse bins for the wander: far below any realistic wander time scale
_Q_GRID = np.arange(-6.0, 2.01, 0.5)   # log10(q_step / median coarse-bin noise variance)


def coarse_index(n_bins: int, bin_s: float, coarse_s: float = COARSE_S) -> tuple[np.ndarray, int]:
    step = max(1, int(round(coarse_s / bin_s)))
    idx = np.arange(n_bins) // step
    return idx, int(idx[-1]) + 1 if n_bins else 0


def coarse_step_s(bin_s: float) -> float:
    return bin_s * max(1, int(round(COARSE_S / bin_s)))


def coarse_means(r: np.ndarray, var: np.ndarray, use: np.ndarray, idx: np.ndarray, n_coarse: int):
    """Inverse-variance means of fine residuals per coarse bin (NaN where no fine bin is used) and
    their white-noise variance."""
    w = np.where(use, 1.0 / var, 0.0)
    sw = np.bincount(idx, weights=w, minlength=n_coarse)
    swr = np.bincount(idx, weights=np.where(use, w * r, 0.0), minlength=n_coarse)
    with np.errstate(invalid='ignore', divide='ignore'):
        return np.where(sw > 0, swr / sw, np.nan), np.where(sw > 0, 1.0 / sw, np.inf)


def local_level(m: np.ndarray, v: np.ndarray, q_step: float, phi: float = 1.0):
    """Kalman filter + RTS smoother of the wander state observed in white noise.

    m: (J,) coarse means (NaN = missing), v: (J,) their variances, q_step: state noise variance per
    coarse step, phi: state transition (1: random walk). Diffuse start (the first observation sets
    the level). Returns (smoothed level (J,), log-likelihood of the observations after the first)."""
    J = m.size
    xf, pf, xp, pp = np.zeros(J), np.full(J, np.inf), np.zeros(J), np.full(J, np.inf)
    x, p, ll = 0.0, math.inf, 0.0
    obs = np.isfinite(m)
    ml, vl = m.tolist(), v.tolist()
    for j in range(J):
        if j:
            x, p = phi * x, phi * phi * p + q_step
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
            xs[j] = xf[j] + pf[j] * phi / pp[j + 1] * (xs[j + 1] - xp[j + 1])
    return xs, ll


def loglik_grid(m: np.ndarray, v: np.ndarray, X: np.ndarray, q_steps: np.ndarray, phis: np.ndarray) -> np.ndarray:
    """Restricted (REML) log-likelihood of the coarse means m (J,) = X beta + wander + white noise
    (variances v), for many (q_step, phi) pairs at once ((P,) arrays in, (P,) out).

    The model's regressors X (J, k: coarse means of its design columns, one of them constant) are
    estimated jointly: every series [m, X_1..X_k] goes through the same Kalman filter, beta is the
    GLS fit of the innovations, and the REML term log det(X' V^-1 X) is added. Without it the
    paper model's a*T + c, fitted first, absorbs the slow part of a random walk, and what is left
    looks mean-reverting. The state starts at 0 (the constant column carries the initial level of a
    random walk; a Gauss-Markov state starts stationary). Missing bins (NaN) are skipped."""
    Ew, S = _filter(m, v, X, q_steps, phis)
    A = np.einsum('jpa,jpb->pab', Ew[:, :, 1:], Ew[:, :, 1:])
    b = np.einsum('jpa,jp->pa', Ew[:, :, 1:], Ew[:, :, 0])
    c = np.einsum('jp,jp->p', Ew[:, :, 0], Ew[:, :, 0])
    rss = c - np.einsum('pa,pa->p', b, np.linalg.solve(A, b[:, :, None])[:, :, 0])
    n = Ew.shape[0] - X.shape[1]
    return -0.5 * (np.sum(np.log(S), axis=0) + rss + np.linalg.slogdet(A)[1] + n * math.log(2.0 * math.pi))


def _filter(m, v, X, q_steps, phis):
    """Standardised innovations (J', P, 1 + k) of [m, X] and their variances (J', P) through the
    Kalman filter of each (q_step, phi) pair (missing bins skipped)."""
    q = np.asarray(q_steps, float)
    f = np.asarray(phis, float)
    ok = np.isfinite(m)
    Y = np.column_stack([m, X])[ok]                                   # (J', 1 + k)
    vv = v[ok]
    gaps = np.diff(np.flatnonzero(ok), prepend=np.flatnonzero(ok)[0])  # steps since the last bin
    with np.errstate(divide='ignore', invalid='ignore'):
        p = np.where(f < 1.0, q / (1.0 - f * f), 0.0)
    x = np.zeros((q.size, Y.shape[1]))
    E = np.empty((Y.shape[0], q.size, Y.shape[1]))
    S = np.empty((Y.shape[0], q.size))
    for j in range(Y.shape[0]):
        for _ in range(int(gaps[j])):
            x, p = f[:, None] * x, f * f * p + q
        s = p + vv[j]
        E[j] = Y[j] - x
        S[j] = s
        k = p / s
        x = x + k[:, None] * E[j]
        p = (1.0 - k) * p
    return E / np.sqrt(S)[:, :, None], S


def misfit_p(m: np.ndarray, v: np.ndarray, X: np.ndarray, q_step: float, phi: float, n_settings: int,
             lags: int = 20) -> float:
    """Does the wander model describe the structure it claims? Under it the standardised one-step
    innovations (after the joint GLS fit of X) are white: Ljung-Box over `lags` coarse bins (10 min),
    p-value with lags - n_settings degrees of freedom. A periodic disturbance, or a deterministic
    shape the wander only follows, leaves them correlated (small p)."""
    Ew, _ = _filter(m, v, X, [q_step], [phi])
    Ew = Ew[:, 0, :]
    beta = np.linalg.lstsq(Ew[:, 1:], Ew[:, 0], rcond=None)[0]
    z = Ew[:, 0] - Ew[:, 1:] @ beta
    n = z.size
    if n <= 2 * lags:
        return 1.0
    acf = np.array([np.dot(z[k:], z[:-k]) for k in range(1, lags + 1)]) / np.dot(z, z)
    q_lb = n * (n + 2.0) * float(np.sum(acf ** 2 / (n - np.arange(1, lags + 1))))
    return float(stats.chi2.sf(q_lb, lags - n_settings))


def fit_wander(m: np.ndarray, v: np.ndarray, X: np.ndarray, step_s: float, stages: int = 3) -> dict:
    """Maximum-likelihood (REML) state noise per coarse step and correlation time of both models,
    fitted on one grid: {False: random walk, True: Gauss-Markov} -> (q_step, tau_s (inf: random
    walk), ll at the optimum); 'll0': ll without wander. Grid search on log10 q and log2 tau (from 2
    coarse steps to the record length), refined on finer grids around each model's best."""
    ok = np.isfinite(m)
    ll0 = float(loglik_grid(m, v, X, np.zeros(1), np.ones(1))[0]) if ok.sum() >= 5 + X.shape[1] else 0.0
    out = {'ll0': ll0, False: (0.0, math.inf, ll0), True: (0.0, math.inf, ll0)}
    if ok.sum() < 5 + X.shape[1]:
        return out
    v_med = float(np.median(v[ok]))
    taus = np.append(np.arange(1.0, math.log2(max(4.0, ok.size)) + 0.01, 1.0), math.inf)
    grids = {None: np.meshgrid(_Q_GRID, taus)}
    best = {}
    for dq, dt in ((None, None), (0.1, 0.25), (0.02, 0.05))[:stages]:
        if dq is not None:
            grids = {False: np.meshgrid(best[False][0] + dq * np.arange(-5, 6), [math.inf]),
                     True: np.meshgrid(best[True][0] + dq * np.arange(-5, 6), best[True][1] + dt * np.arange(-4, 5))}
        gq = np.concatenate([g[0].ravel() for g in grids.values()])
        gt = np.concatenate([g[1].ravel() for g in grids.values()])
        ll = loglik_grid(m, v, X, v_med * 10.0 ** gq, np.exp(-np.exp2(-gt)))
        for markov in (False, True):
            sel = np.flatnonzero(np.isfinite(gt) == markov)
            i = sel[int(np.argmax(ll[sel]))]
            best[markov] = (gq[i], gt[i], float(ll[i]))
    for markov, (lq, lt, ll) in best.items():
        if ll > ll0:
            out[markov] = (float(v_med * 10.0 ** lq), float(step_s * 2.0 ** lt) if markov else math.inf, ll)
    return out


def coarse_design(X: np.ndarray, var: np.ndarray, use: np.ndarray, idx: np.ndarray, n_coarse: int) -> np.ndarray:
    """(n_coarse, k) inverse-variance means of the design columns per coarse bin, each column scaled
    to unit RMS (the REML determinant needs no units)."""
    w = np.where(use, 1.0 / var, 0.0)
    sw = np.bincount(idx, weights=w, minlength=n_coarse)
    cols = [np.bincount(idx, weights=w * X[:, i], minlength=n_coarse) for i in range(X.shape[1])]
    with np.errstate(invalid='ignore', divide='ignore'):
        Xc = np.column_stack(cols) / sw[:, None]
    rms = np.sqrt(np.nanmean(Xc * Xc, axis=0))
    return Xc / np.where(rms > 0, rms, 1.0)


def phi_of(tau_s: float, step_s: float) -> float:
    return 1.0 if not math.isfinite(tau_s) else math.exp(-step_s / tau_s)


def q_step_of(q_c: float, tau_s: float, step_s: float) -> float:
    """State noise per coarse step from the continuous intensity q_c ((rad/s)^2/s): exact for the
    random walk (q_c step) and the Gauss-Markov bias (stationary variance q_c tau / 2)."""
    if not math.isfinite(tau_s):
        return q_c * step_s
    phi = phi_of(tau_s, step_s)
    return 0.5 * q_c * tau_s * (1.0 - phi * phi)


def q_cont_of(q_step: float, tau_s: float, step_s: float) -> float:
    return q_step / q_step_of(1.0, tau_s, step_s)


def wander_at(r, var, train, idx, n_coarse, q_step, phi, centres_c, t_fine):
    """Smoothed wander from the training bins' residuals, interpolated at every fine bin."""
    m, v = coarse_means(r, var, train, idx, n_coarse)
    xs, _ = local_level(m, v, q_step, phi)
    return np.interp(t_fine, centres_c, xs)


def score_wander(an, spec) -> dict:
    """Adding a wandering bias to `spec`'s gyro model, both kinds at once (cached per spec):
    {False: random walk, True: Gauss-Markov} -> (held-out chi-square gain per batch and its noise
    cross term per batch (selection._t_noise) for the contiguous folds, the same for interleaved
    folds (every K-th batch), Delta BIC, per-axis continuous intensity q ((rad/s)^2 per s; the
    stationary variance of the Gauss-Markov bias is q tau / 2) and tau (s, inf: random walk), the
    coarse-bin log-likelihood of the joint model (regression + wander), the number of coarse bins,
    the p-value of the model check `misfit_p`, Bonferroni over the axes with a wander).

    The contiguous gain ranks a wander against the regressors (as their gains are); whether it
    exists at all is tested on interleaved folds: a wander whose memory is shorter than a
    contiguous fold cannot be predicted in a fold's interior, but can in a held-out minute."""
    key = ('wander', spec)
    if key in an.scores:
        return an.scores[key]
    fit = an.fit(spec, 'gyro')
    d = an.data
    idx, nc = coarse_index(len(d.t), d.bin_s)
    step_s = coarse_step_s(d.bin_s)
    acc = {mk: dict(dll=0.0, q=[], tau=[], ll=0.0, p=1.0) for mk in (False, True)}
    n_used = 0
    for a, c in enumerate(fit.comps):
        m = c['mask']
        var = an.gyro_var[:, a]
        r_full = np.where(m, c['y'] - c['stats'].predict_full(c['X']), 0.0)
        mc, vc = coarse_means(r_full, var, m, idx, nc)
        Xc = coarse_design(c['X'], var, m, idx, nc)
        fw = fit_wander(mc, vc, Xc, step_s)
        n_used = max(n_used, int(np.isfinite(mc).sum()))
        for mk, r in acc.items():
            q, tau, ll1 = fw[mk]
            if q > 0:
                r['p'] = min(r['p'], misfit_p(mc, vc, Xc, q, phi_of(tau, step_s), 2 if mk else 1))
            r['dll'] += ll1 - fw['ll0']
            r['ll'] += ll1
            r['q'].append(q_cont_of(q, tau, step_s))
            r['tau'].append(tau)
    contiguous = _heldout_gain(an, fit, an.fold)
    fold_i = np.where(an.mask, an.interleaved_fold[np.maximum(an.batch, 0)], -1)
    interleaved = _heldout_gain(an, an.fit_interleaved(spec, 'gyro'), fold_i)
    out = {}
    for mk, r in acc.items():
        dbic = 2.0 * r['dll'] - (2 if mk else 1) * len(fit.comps) * math.log(max(n_used, 2))
        out[mk] = (contiguous[mk], interleaved[mk], float(dbic), r['q'], r['tau'], float(r['ll']), n_used,
                   min(1.0, r['p'] * len(fit.comps)))                   # Bonferroni over the axes
    an.scores[key] = out
    return out


def _heldout_gain(an, fit, fold: np.ndarray) -> dict:
    """{markov: (gain per batch, cross term per batch)}: each fold's wander, with its settings
    estimated on the other folds, smoothed from the other folds' residuals of the regression fitted
    without it."""
    d = an.data
    idx, nc = coarse_index(len(d.t), d.bin_s)
    step_s = coarse_step_s(d.bin_s)
    centres = (np.arange(nc) + 0.5) * step_s
    out = {mk: (np.zeros(an.batch_fold.size), np.zeros(an.batch_fold.size)) for mk in (False, True)}
    for a, c in enumerate(fit.comps):
        m = c['mask']
        var = an.gyro_var[:, a]
        st = c['stats']
        betas = st.cv()[2]
        Xs = c['X'] / st.scale
        for k in range(an.n_folds):
            r_k = np.where(m, c['y'] - (Xs @ betas[k] + st.y_mean), 0.0)
            test = m & (fold == k)
            train = m & (fold != k)
            mt, vt = coarse_means(r_k, var, train, idx, nc)
            fw = fit_wander(mt, vt, coarse_design(c['X'], var, train, idx, nc), step_s, stages=2)
            w = an.gyro_w[test, a]
            r = r_k[test]
            for mk, (gains, cross) in out.items():
                qk, tk, _ = fw[mk]
                if qk == 0.0:
                    continue   # no wander found in training: the prediction is the model's own
                xs, _ = local_level(mt, vt, qk, phi_of(tk, step_s))
                u = np.interp(d.t[test], centres, xs)
                gains += np.bincount(an.batch[test], weights=w * (r * r - (r - u) ** 2), minlength=gains.size)
                cross += np.bincount(an.batch[test], weights=w * (r - u) * u, minlength=gains.size)
    return out


def cv_wander(an, spec, q_axes, tau_axes=None, per_batch: bool = False) -> np.ndarray:
    """(N, 3) wander of `spec`'s residual at each fold (or each batch), smoothed from the other
    folds (batches) only, so a held-out stretch's own noise never enters its own correction."""
    fit = an.fit(spec, 'gyro')
    d = an.data
    idx, nc = coarse_index(len(d.t), d.bin_s)
    step_s = coarse_step_s(d.bin_s)
    centres = (np.arange(nc) + 0.5) * step_s
    out = np.zeros((len(d.t), 3))
    for a, c in enumerate(fit.comps):
        m = c['mask']
        if q_axes[a] <= 0:
            continue
        tau = tau_axes[a] if tau_axes else math.inf
        q_step, phi = q_step_of(q_axes[a], tau, step_s), phi_of(tau, step_s)
        r = np.where(m, c['y'] - c['stats'].predict_full(c['X']), 0.0)
        groups, n_groups = (an.batch, an.batch_fold.size) if per_batch else (an.fold, an.n_folds)
        for k in range(n_groups):
            test = m & (groups == k)
            if test.any():
                out[test, a] = wander_at(r, an.gyro_var[:, a], m & (groups != k), idx, nc, q_step, phi,
                                         centres, d.t[test])
    return out


def settings(q_axes, tau_axes) -> dict:
    """Report units: random walk K (deg/s/sqrt(s)); Gauss-Markov sigma (deg/s) and tau (s)."""
    if tau_axes is None:
        return {'rate_random_walk_dps_rts': [round(math.degrees(math.sqrt(q)), 8) for q in q_axes]}
    return {'bias_instability_dps': [round(math.degrees(math.sqrt(0.5 * q * t)), 8) if q > 0 else 0.0
                                     for q, t in zip(q_axes, tau_axes)],
            'bias_instability_tau_s': [round(t, 1) if q > 0 else None for q, t in zip(q_axes, tau_axes)]}
