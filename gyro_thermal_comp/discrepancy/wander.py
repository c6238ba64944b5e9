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
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from scipy import stats

COARSE_S = 30.0   # coarse bins for the wander: far below any realistic wander time scale
_Q_GRID = np.arange(-6.0, 2.01, 0.5)   # log10(q_step / median coarse-bin noise variance)
_FILTER_FLOATS = 1 << 18   # innovations held at once by loglik_grid (2 MB)


class CoarseGrid(NamedTuple):
    """Coarse bins of COARSE_S over the fine bins of the binned data."""
    idx: np.ndarray      # (N,) coarse bin of each fine bin
    n: int               # number of coarse bins
    step_s: float        # coarse bin width, s (a whole number of fine bins)
    centres: np.ndarray  # (n,) coarse bin centres, s, on the fine bins' clock


def coarse_grid(n_bins: int, bin_s: float) -> CoarseGrid:
    step = max(1, int(round(COARSE_S / bin_s)))
    idx = np.arange(n_bins) // step
    n = int(idx[-1]) + 1 if n_bins else 0
    step_s = bin_s * step
    return CoarseGrid(idx, n, step_s, (np.arange(n) + 0.5) * step_s)


def coarse_means(r: np.ndarray, var: np.ndarray, use: np.ndarray, grid: CoarseGrid):
    """Inverse-variance means of fine residuals per coarse bin (NaN where no fine bin is used) and
    their white-noise variance."""
    w = np.where(use, 1.0 / var, 0.0)
    sw = np.bincount(grid.idx, weights=w, minlength=grid.n)
    swr = np.bincount(grid.idx, weights=np.where(use, w * r, 0.0), minlength=grid.n)
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
    random walk; a Gauss-Markov state starts stationary). Missing bins (NaN) are skipped.

    The grid is taken in slices of at most _FILTER_FLOATS innovations: all of them at once is
    (coarse bins x grid points x columns), 20 MB for an 8 h record, the largest array of the
    analysis. Each grid point is computed alone, so slicing changes no result."""
    q = np.asarray(q_steps, float)
    f = np.asarray(phis, float)
    per_point = max(1, int(np.isfinite(m).sum()) * (1 + X.shape[1]))
    n_slices = -(-q.size * per_point // _FILTER_FLOATS)
    if n_slices <= 1:
        return _loglik_slice(m, v, X, q, f)
    # near-equal slices of at least 2 points (one point would reduce S by another summation)
    n_slices = min(n_slices, max(1, q.size // 2))
    return np.concatenate([_loglik_slice(m, v, X, qs, fs)
                           for qs, fs in zip(np.array_split(q, n_slices), np.array_split(f, n_slices))])


def _loglik_slice(m, v, X, q_steps, phis):
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


@dataclass(frozen=True)
class WanderEstimate:
    """One wander model at its maximum (restricted) likelihood."""
    q_step: float      # state noise variance per coarse step (0: no wander found)
    tau_s: float       # correlation time, s (inf: random walk)
    loglik: float      # log-likelihood at the optimum


@dataclass(frozen=True)
class WanderFit:
    """Both wander models fitted to one series of coarse means (`fit_wander`)."""
    loglik_none: float               # log-likelihood without any wander
    random_walk: WanderEstimate
    gauss_markov: WanderEstimate

    def of(self, markov: bool) -> WanderEstimate:
        return self.gauss_markov if markov else self.random_walk


def fit_wander(m: np.ndarray, v: np.ndarray, X: np.ndarray, step_s: float, stages: int = 3) -> WanderFit:
    """Maximum-likelihood (REML) state noise per coarse step and correlation time of both models,
    the random walk and the Gauss-Markov bias, fitted on one grid. Grid search on log10 q and log2
    tau (from 2 coarse steps to the record length), refined on finer grids around each model's
    best. A model that does not beat "no wander" is returned as q_step 0, tau inf."""
    ok = np.isfinite(m)
    ll0 = float(loglik_grid(m, v, X, np.zeros(1), np.ones(1))[0]) if ok.sum() >= 5 + X.shape[1] else 0.0
    none = WanderEstimate(0.0, math.inf, ll0)
    if ok.sum() < 5 + X.shape[1]:
        return WanderFit(ll0, none, none)
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
    found = {markov: WanderEstimate(float(v_med * 10.0 ** lq), float(step_s * 2.0 ** lt) if markov else math.inf, ll)
             if ll > ll0 else none for markov, (lq, lt, ll) in best.items()}
    return WanderFit(ll0, random_walk=found[False], gauss_markov=found[True])


def coarse_design(X: np.ndarray, var: np.ndarray, use: np.ndarray, grid: CoarseGrid) -> np.ndarray:
    """(coarse bins, k) inverse-variance means of the design columns per coarse bin, each column
    scaled to unit RMS (the REML determinant needs no units)."""
    w = np.where(use, 1.0 / var, 0.0)
    sw = np.bincount(grid.idx, weights=w, minlength=grid.n)
    cols = [np.bincount(grid.idx, weights=w * X[:, i], minlength=grid.n) for i in range(X.shape[1])]
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


def wander_at(r, var, train, grid: CoarseGrid, q_step, phi, t_fine):
    """Smoothed wander from the training bins' residuals, interpolated at the times t_fine."""
    m, v = coarse_means(r, var, train, grid)
    xs, _ = local_level(m, v, q_step, phi)
    return np.interp(t_fine, grid.centres, xs)


@dataclass(frozen=True, eq=False)
class BatchGains:
    """Held-out chi-square gain per batch of a candidate and its noise cross term per batch
    (selection._t_noise)."""
    gains: np.ndarray   # (nb,)
    cross: np.ndarray   # (nb,)


@dataclass(frozen=True, eq=False)
class WanderScore:
    """Adding a wandering bias of one kind (random walk or Gauss-Markov) to a spec's gyro model."""
    contiguous: BatchGains     # held-out on the contiguous folds: ranks it against the regressors
    interleaved: BatchGains    # held-out on interleaved folds (every K-th batch): does it exist
    delta_bic: float
    q: list[float]             # per axis, continuous intensity, (rad/s)^2 per s (the stationary
                               # variance of the Gauss-Markov bias is q tau / 2)
    tau_s: list[float]         # per axis, correlation time, s (inf: random walk)
    loglik: float              # coarse-bin log-likelihood of the joint model (regression + wander)
    n_coarse: int              # coarse bins used
    model_p: float             # p-value of the model check `misfit_p`, Bonferroni over the axes


@dataclass
class _AxisSums:
    """One wander kind summed over the gyro axes (score_wander)."""
    dll: float = 0.0                            # log-likelihood gain over no wander
    loglik: float = 0.0
    p: float = 1.0                              # smallest misfit_p over the axes with a wander
    q: list[float] = field(default_factory=list)
    tau_s: list[float] = field(default_factory=list)


def score_wander(an, spec) -> dict[bool, WanderScore]:
    """Adding a wandering bias to `spec`'s gyro model, both kinds at once (cached per spec):
    {False: random walk, True: Gauss-Markov}.

    The contiguous gain ranks a wander against the regressors (as their gains are); whether it
    exists at all is tested on interleaved folds: a wander whose memory is shorter than a
    contiguous fold cannot be predicted in a fold's interior, but can in a held-out minute."""
    if spec in an.wander_scores:
        return an.wander_scores[spec]
    fit = an.fit(spec, 'gyro')
    grid = coarse_grid(len(an.data.t), an.data.bin_s)
    step_s = grid.step_s
    sums = {markov: _AxisSums() for markov in (False, True)}
    n_used = 0
    for a, c in enumerate(fit.comps):
        m = c.mask
        var = an.gyro_var[:, a]
        y, X = c.design()
        r_full = np.where(m, y - c.stats.predict_full(X), 0.0)
        mc, vc = coarse_means(r_full, var, m, grid)
        Xc = coarse_design(X, var, m, grid)
        wander_fit = fit_wander(mc, vc, Xc, step_s)
        n_used = max(n_used, int(np.isfinite(mc).sum()))
        for markov, acc in sums.items():
            est = wander_fit.of(markov)
            if est.q_step > 0:
                acc.p = min(acc.p, misfit_p(mc, vc, Xc, est.q_step, phi_of(est.tau_s, step_s), 2 if markov else 1))
            acc.dll += est.loglik - wander_fit.loglik_none
            acc.loglik += est.loglik
            acc.q.append(q_cont_of(est.q_step, est.tau_s, step_s))
            acc.tau_s.append(est.tau_s)
    contiguous = _heldout_gain(an, fit, an.fold)
    fold_i = np.where(an.mask, an.interleaved_fold[np.maximum(an.batch, 0)], -1)
    interleaved = _heldout_gain(an, an.fit_interleaved(spec, 'gyro'), fold_i)
    out = {}
    for markov, acc in sums.items():
        dbic = 2.0 * acc.dll - (2 if markov else 1) * len(fit.comps) * math.log(max(n_used, 2))
        out[markov] = WanderScore(contiguous[markov], interleaved[markov], float(dbic), acc.q, acc.tau_s,
                                  float(acc.loglik), n_used,
                                  min(1.0, acc.p * len(fit.comps)))     # Bonferroni over the axes
    an.wander_scores[spec] = out
    return out


def _heldout_gain(an, fit, fold: np.ndarray) -> dict[bool, BatchGains]:
    """{markov: gains}: each fold's wander, with its settings estimated on the other folds,
    smoothed from the other folds' residuals of the regression fitted without it."""
    d = an.data
    grid = coarse_grid(len(d.t), d.bin_s)
    out = {markov: BatchGains(np.zeros(an.batch_fold.size), np.zeros(an.batch_fold.size)) for markov in (False, True)}
    for a, c in enumerate(fit.comps):
        m = c.mask
        var = an.gyro_var[:, a]
        st = c.stats
        betas = st.cv().betas
        y, X = c.design()
        Xs = X / st.scale
        for k in range(an.n_folds):
            r_k = np.where(m, y - (Xs @ betas[k] + st.y_mean), 0.0)
            test = m & (fold == k)
            train = m & (fold != k)
            mt, vt = coarse_means(r_k, var, train, grid)
            wander_fit = fit_wander(mt, vt, coarse_design(X, var, train, grid), grid.step_s, stages=2)
            w = an.gyro_w[test, a]
            r = r_k[test]
            for markov, acc in out.items():
                est = wander_fit.of(markov)
                if est.q_step == 0.0:
                    continue   # no wander found in training: the prediction is the model's own
                xs, _ = local_level(mt, vt, est.q_step, phi_of(est.tau_s, grid.step_s))
                u = np.interp(d.t[test], grid.centres, xs)
                nb = acc.gains.size
                acc.gains[:] += np.bincount(an.batch[test], weights=w * (r * r - (r - u) ** 2), minlength=nb)
                acc.cross[:] += np.bincount(an.batch[test], weights=w * (r - u) * u, minlength=nb)
    return out


def cv_wander(an, spec, q_axes, tau_axes=None, per_batch: bool = False) -> np.ndarray:
    """(N, 3) wander of `spec`'s residual at each fold (or each batch), smoothed from the other
    folds (batches) only, so a held-out stretch's own noise never enters its own correction."""
    fit = an.fit(spec, 'gyro')
    d = an.data
    grid = coarse_grid(len(d.t), d.bin_s)
    out = np.zeros((len(d.t), 3))
    for a, c in enumerate(fit.comps):
        m = c.mask
        if q_axes[a] <= 0:
            continue
        tau = tau_axes[a] if tau_axes else math.inf
        q_step, phi = q_step_of(q_axes[a], tau, grid.step_s), phi_of(tau, grid.step_s)
        y, X = c.design()
        r = np.where(m, y - c.stats.predict_full(X), 0.0)
        groups, n_groups = (an.batch, an.batch_fold.size) if per_batch else (an.fold, an.n_folds)
        for k in range(n_groups):
            test = m & (groups == k)
            if test.any():
                out[test, a] = wander_at(r, an.gyro_var[:, a], m & (groups != k), grid, q_step, phi, d.t[test])
    return out


def settings(q_axes, tau_axes) -> dict:
    """Report units: random walk K (deg/s/sqrt(s)); Gauss-Markov sigma (deg/s) and tau (s)."""
    if tau_axes is None:
        return {'rate_random_walk_dps_rts': [round(math.degrees(math.sqrt(q)), 8) for q in q_axes]}
    return {'bias_instability_dps': [round(math.degrees(math.sqrt(0.5 * q * t)), 8) if q > 0 else 0.0
                                     for q, t in zip(q_axes, tau_axes)],
            'bias_instability_tau_s': [round(t, 1) if q > 0 else None for q, t in zip(q_axes, tau_axes)]}
