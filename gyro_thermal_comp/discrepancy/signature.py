"""Does the residual a wandering bias would explain look like one, or like deterministic structure?

A random walk or a Gauss-Markov bias, once fitted, follows any slow shape: a slow sinusoid, a bias
step, a heating/cooling loop the library's hysteresis term does not match. Naming one is a claim
about the residual's statistics, so before `rate_random_walk` / `bias_instability` is named the
residual is asked whether a deterministic shape describes it better *given* the wander. Per gyro
axis that has a wander, on the 30 s coarse means m (white-noise variances v) with the model's own
regressors X estimated jointly:

    LR = 2 [max ML log-lik(m | X, C, wander) - max ML log-lik(m | X, wander)]

(the wander's q, and tau for the Gauss-Markov bias, profiled on a grid including "no wander"),
for four families of columns C:

* `periodic`: sin/cos at a frequency between 2 cycles per record and a period of 4 coarse bins
  (a spectral line; a wander's spectrum is smooth: 1/f^2, or Lorentzian);
* `step`: a level change at one coarse bin (a changepoint; a wander's increments have no outlier);
* `two_steps`: level changes at two coarse bins (a bias that jumps twice);
* `temperature_locked`: the last heating/cooling sign b (held through holds) times 1, T - T_mean,
  (T - T_mean)^2: the residual splits on heating and cooling (a loop of any smooth shape).

The candidate C are the few best of a scan (least squares after projecting X out). LR is not
chi2(#columns) here: the slow columns trade against the wander's own q, and the ML profile
over-rewards that; so its null tail is calibrated per family (`TAIL`), on simulated wanders only
(random walks K = 5e-5..3e-3 deg/s/sqrt(s), Gauss-Markov biases sigma 1e-3..3e-2 deg/s, tau
50..1000 s, in 0.04 deg/s/sqrt(Hz) white noise over 1, 1.5 and 2 h of the static ramp with
a*T + b*dT/dt + c, strong enough to be named; never on the deterministic cases asserted on;
`benchmarks/discrepancy_sweep.py --calibrate-signature N` re-measures it): above its 90th
percentile the tail is exponential, p = 0.1 exp(-(LR - q90) / scale); Bonferroni over families and
axes. The wander's signature holds when that p stays above `alpha`, and when no shape alone (no
wander) describes the residual as well as simulated shapes of its family are described
(`MUST_BEAT`: the wander must win outright; a step has a random walk's spectrum). What both cost
on simulated wanders and shapes: docs/discrepancy.md, "Naming under misspecification".
Descriptive only: the long-tau slope of the residual's Allan deviation (+1/2 random walk, ~0 bias
instability floor, -1/2 white), from allantools.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from .wander import _Q_GRID, _filter, coarse_design, coarse_grid, coarse_means

ALPHA = 1e-2                       # family-wise level over families and axes: false alarms on wanders
TOP = 3                            # candidates per family taken from the scan to the profiled fit
FAMILIES = ('periodic', 'step', 'two_steps', 'temperature_locked')
# null tail of LR (the shape given the wander) per family (module doc), on simulated wanders: 90th
# percentile, mean excess above it (exponential tail scale), mean candidates scanned there
TAIL = {'periodic': (14.5, 3.3, 43), 'step': (13.9, 3.6, 176), 'two_steps': (25.4, 3.1, 17124),
        'temperature_locked': (9.0, 4.0, 1)}
# The wander must win outright. A step has a random walk's 1/f^2 spectrum, and a marginal line or
# loop moves a wander's likelihood about as much as it moves its own: no statistic of the residual
# tells them apart near the limit. So the wander is named only when D = 2 [log L(shape alone) -
# log L(wander alone)] stays below what simulated shapes of that family give it: the 1st
# percentile of D over steps (one; two), sinusoids and loops whose wander would be significant
# (family-A-style arrays, benchmarks/discrepancy_sweep.py --calibrate-signature); (that D, mean
# candidates scanned). A longer record scans more candidates: + 2 ln(n / n_ref), the growth of a
# chi-square maximum.
MUST_BEAT = {'periodic': (22.3, 42), 'step': (17.4, 183), 'two_steps': (20.8, 19808),
             'temperature_locked': (16.8, 1)}


def step_margin(family: str, n_scanned: int) -> float:
    """D at and above which the family's best shape describes the residual too well for a wander."""
    c, n_ref = MUST_BEAT[family]
    return c + 2.0 * math.log(max(1.0, n_scanned / n_ref))


def calibrated_p(family: str, lr: float, n_scanned: int) -> float:
    """P(LR >= lr) under a wander: 0.1 exp(-(lr - q90) / scale), scaled by the number of
    candidates scanned relative to the calibration's (a longer record offers more of them)."""
    q90, scale, n_ref = TAIL[family]
    # below q90 the answer is p >= 0.1 anyway (no overflow far below it)
    return float(min(1.0, 0.1 * math.exp(min(-(lr - q90) / scale, 10.0)) * max(1.0, n_scanned / n_ref)))


@dataclass(frozen=True)
class FamilyTest:
    """One family's best deterministic alternative on one axis."""
    family: str
    axis: int
    lr: float            # 2 x log-likelihood gain of adding its columns (wander re-profiled)
    n_columns: int
    n_scanned: int       # candidates the best was chosen from (covered by the calibration)
    p: float             # calibrated null p of lr (not yet corrected over families / axes)
    detail: dict         # period_s / step_t_s, amplitude_dps (sine amplitude, step height, loop RMS)
    wander_lr: float = float('nan')   # 2 x log-lik gain of the wander given the shape
    alone_lr: float = float('nan')    # D = 2 [log L(shape alone) - log L(wander alone)] = lr - wander_lr
    beats_wander: bool = False        # D >= step_margin: the shape alone describes it as well as shapes do

    def to_dict(self) -> dict:
        return {'family': self.family, 'axis': self.axis, 'lr': round(self.lr, 2), 'n_columns': self.n_columns,
                'n_scanned': self.n_scanned, 'p': float(f'{self.p:.3g}'),
                'wander_given_shape_lr': round(self.wander_lr, 2), 'shape_alone_lr': round(self.alone_lr, 2),
                'shape_alone_beats_wander': self.beats_wander, **self.detail}


@dataclass(frozen=True)
class Signature:
    """The verdict on one wander: does its residual look like it (`holds`)?"""
    holds: bool
    kind: str | None                 # family of the structure found (None when it holds)
    reason: str | None               # one line, e.g. 'periodic residual, period 1200 s, 9.1 sigma (axis z)'
    p_min: float                     # smallest p, Bonferroni over families and axes
    tests: list = field(default_factory=list)
    allan_slope: list = field(default_factory=list)   # per axis, long-tau ADEV slope (None: no wander)

    def to_dict(self) -> dict:
        return {'holds': self.holds, 'kind': self.kind, 'reason': self.reason, 'p_min': float(f'{self.p_min:.3g}'),
                'allan_slope_long_tau': self.allan_slope, 'tests': [t.to_dict() for t in self.tests]}


# ---------------------------------------------------------------------------------- likelihood
def _phis(markov: bool, n: int, step_s: float) -> np.ndarray:
    if not markov:
        return np.ones(1)
    taus = step_s * np.exp2(np.arange(1.0, math.log2(max(4, n)) + 0.01, 0.5))
    return np.exp(-step_s / taus)


def profile_loglik(m: np.ndarray, v: np.ndarray, X: np.ndarray, markov: bool, step_s: float):
    """(max over the wander's (q, phi) of the ML log-likelihood of m = X beta + wander + white (GLS
    beta), the same with no wander). ML, not REML: REML likelihoods of different X do not compare.
    Two stages: half-decade q grid, then tenth-decade around the best."""
    ok = np.isfinite(m)
    v_med = float(np.median(v[ok]))
    phis = _phis(markov, int(ok.sum()), step_s)

    def grid(lq):
        q = np.concatenate([[0.0], v_med * 10.0 ** lq])
        qq, ff = np.meshgrid(q, phis)
        Ew, S = _filter(m, v, X, qq.ravel(), ff.ravel())
        A = np.einsum('jpa,jpb->pab', Ew[:, :, 1:], Ew[:, :, 1:])
        b = np.einsum('jpa,jp->pa', Ew[:, :, 1:], Ew[:, :, 0])
        c = np.einsum('jp,jp->p', Ew[:, :, 0], Ew[:, :, 0])
        rss = c - np.einsum('pa,pa->p', b, _solve(A, b))
        ll = -0.5 * (np.sum(np.log(S), axis=0) + rss)
        i = int(np.argmax(ll))
        return float(ll[i]), (np.log10(qq.ravel()[i] / v_med) if qq.ravel()[i] > 0 else None), float(ll[0])
    ll, lq, ll_none = grid(_Q_GRID)
    if lq is not None:
        ll = max(ll, grid(lq + 0.1 * np.arange(-5, 6))[0])
    return ll, ll_none


def _solve(A, b):
    """Batched least-squares solve tolerant of collinear columns (pseudo-inverse)."""
    return np.einsum('pab,pb->pa', np.linalg.pinv(A, rcond=1e-10), b)


# ---------------------------------------------------------------------------------- scans
def _project(cols: np.ndarray, X: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Columns with X projected out (weighted least squares)."""
    sw = np.sqrt(w)[:, None]
    Q, _ = np.linalg.qr(X * sw)
    c = cols * sw
    return c - Q @ (Q.T @ c)


def _scan_scores(r_perp, C_perp) -> np.ndarray:
    """Least-squares chi-square of each single column (after X) against the projected residual."""
    den = np.sum(C_perp * C_perp, axis=0)
    return np.where(den > 0, (C_perp.T @ r_perp) ** 2 / np.where(den > 0, den, 1.0), 0.0)


def _sine_candidates(t, r_perp, X, w, period_max_s, step_s):
    """Top frequencies of a 4x-oversampled scan (sin and cos together); periods from
    period_max_s (half the record) down to 4 coarse bins."""
    f = np.arange(1.0 / period_max_s, 1.0 / (4.0 * step_s), 0.25 / (t[-1] - t[0] + step_s))
    scores = np.empty(f.size)
    for i, fi in enumerate(f):
        C = _project(np.column_stack([np.sin(2 * np.pi * fi * t), np.cos(2 * np.pi * fi * t)]), X, w)
        beta = np.linalg.lstsq(C, r_perp, rcond=None)[0]
        scores[i] = float(np.sum((C @ beta) ** 2))
    picks = []
    for i in np.argsort(-scores):
        if all(abs(f[i] - f[j]) * (t[-1] - t[0]) >= 1.0 for j in picks):
            picks.append(i)
        if len(picks) == TOP:
            break
    # scanned at 4x oversampling: about a quarter as many independent frequencies
    return [(f[i], np.column_stack([np.sin(2 * np.pi * f[i] * t), np.cos(2 * np.pi * f[i] * t)])) for i in picks], \
        max(1, f.size // 4)


def _step_candidates(t, r_perp, X, w, edge: int = 2):
    J = t.size
    idx = np.arange(edge, J - edge)
    H = (np.arange(J)[:, None] >= idx[None, :]).astype(float)
    scores = _scan_scores(r_perp, _project(H, X, w))
    picks = []
    for i in np.argsort(-scores):
        if all(abs(int(idx[i]) - int(idx[j])) >= 3 for j in picks):
            picks.append(i)
        if len(picks) == TOP:
            break
    return [(0.5 * (t[idx[i] - 1] + t[idx[i]]), H[:, [i]]) for i in picks], idx.size


def _two_step_candidates(t, r_perp, X, w, edge: int = 2, gap: int = 3):
    """Top pairs of step times (a bias that jumps twice: a piecewise-constant wander of two
    changepoints), from the exact least-squares chi-square of every pair after X."""
    J = t.size
    idx = np.arange(edge, J - edge)
    Hp = _project((np.arange(J)[:, None] >= idx[None, :]).astype(float), X, w)
    G = Hp.T @ Hp
    b = Hp.T @ r_perp
    i, j = np.triu_indices(idx.size, k=gap)
    det = G[i, i] * G[j, j] - G[i, j] ** 2
    ok = det > 1e-12 * G[i, i] * G[j, j]
    score = np.where(ok, (b[i] ** 2 * G[j, j] - 2.0 * b[i] * b[j] * G[i, j] + b[j] ** 2 * G[i, i])
                     / np.where(ok, det, 1.0), 0.0)
    picks = []
    for k in np.argsort(-score):
        if all(max(abs(int(i[k]) - int(i[q])), abs(int(j[k]) - int(j[q]))) >= gap for q in picks):
            picks.append(k)
        if len(picks) == TOP:
            break
    times = lambda n: 0.5 * (t[idx[n] - 1] + t[idx[n]])
    H = lambda n: (np.arange(J) >= idx[n]).astype(float)
    return [((times(i[k]), times(j[k])), np.column_stack([H(i[k]), H(j[k])])) for k in picks], int(i.size)


def _branch_sign(rate: np.ndarray) -> np.ndarray:
    """+1 after heating, -1 after cooling, held through holds (0 before the first change)."""
    thr = 0.1 * float(np.percentile(np.abs(rate), 95))
    s = np.where(rate > thr, 1.0, np.where(rate < -thr, -1.0, np.nan))
    idx = np.where(np.isfinite(s), np.arange(s.size), 0)
    np.maximum.accumulate(idx, out=idx)
    held = s[idx]
    return np.where(np.isfinite(held), held, 0.0)


def _temperature_candidates(temp, rate):
    """b x [1, T - Tm, (T - Tm)^2], b the last heating/cooling sign held through holds: a heating
    and a cooling curve in T, each quadratic - a loop of any smooth shape. (A smooth function of T
    alone is the library's thermal_curvature; a relaxing branch its thermal_hysteresis; adding
    either here made the family fit random walks as well: its null tail doubled.)"""
    dT = temp - np.mean(temp)
    b = _branch_sign(rate)
    return [(0.0, np.column_stack([b, b * dT, b * dT ** 2]))], 1


# ---------------------------------------------------------------------------------- the test
def _unit_cols(C: np.ndarray) -> np.ndarray:
    rms = np.sqrt(np.mean(C * C, axis=0))
    return C / np.where(rms > 0, rms, 1.0)


def axis_tests(m, v, X, t, temp, rate, markov: bool, step_s: float, axis: int) -> list[FamilyTest]:
    """The three families' best alternatives on one axis's coarse series (NaN bins dropped)."""
    ok = np.isfinite(m) & np.isfinite(temp) & np.isfinite(rate) & np.all(np.isfinite(X), axis=1)
    m, v, X, t, temp, rate = m[ok], v[ok], X[ok], t[ok], temp[ok], rate[ok]
    w = 1.0 / v
    r_perp = _project(m[:, None], X, w)[:, 0]
    ll0, _ = profile_loglik(m, v, X, markov, step_s)
    span = t[-1] - t[0] + step_s
    out = []
    sines, n_f = _sine_candidates(t, r_perp, X, w, span / 2.0, step_s)
    steps, n_s = _step_candidates(t, r_perp, X, w)
    pairs, n_p = _two_step_candidates(t, r_perp, X, w)
    temps, n_t = _temperature_candidates(temp, rate)
    for fam, cands, n_scan, label in (('periodic', sines, n_f, 'period_s'), ('step', steps, n_s, 'step_t_s'),
                                      ('two_steps', pairs, n_p, 'step_t_s'), ('temperature_locked', temps, n_t, None)):
        best = None
        for key, C in cands:
            ll, ll_none = profile_loglik(m, v, np.column_stack([X, _unit_cols(C)]), markov, step_s)
            if best is None or 2.0 * (ll - ll0) > best[0]:
                best = (2.0 * (ll - ll0), key, C, 2.0 * (ll - ll_none))
        if best is None:
            continue
        lr, key, C, wander_lr = best
        amp = _amplitude(m, w, X, C, fam)
        detail = {'amplitude_dps': float(f'{math.degrees(amp):.3g}')}
        if label:
            where = (1.0 / key) if fam == 'periodic' else key
            detail[label] = [round(float(x), 1) for x in where] if fam == 'two_steps' else round(float(where), 1)
        # the shape alone (no wander) against the wander alone: D, against what shapes give (MUST_BEAT)
        alone = lr - wander_lr
        out.append(FamilyTest(fam, axis, max(lr, 0.0), C.shape[1], n_scan, calibrated_p(fam, lr, n_scan), detail,
                              wander_lr, alone, alone >= step_margin(fam, n_scan)))
    return out


def _amplitude(m, w, X, C, family: str) -> float:
    """Size of the alternative's fitted shape (weighted LS with X): sine amplitude, step height
    (the larger of two), or the RMS of the temperature-locked part (rad/s)."""
    beta = np.linalg.lstsq(np.column_stack([X, C]) * np.sqrt(w)[:, None], m * np.sqrt(w), rcond=None)[0]
    coef = beta[X.shape[1]:]
    if family == 'periodic':
        return float(np.hypot(*coef))
    if family in ('step', 'two_steps'):
        return float(np.max(np.abs(coef)))
    part = C @ coef
    return float(np.sqrt(np.mean((part - part.mean()) ** 2)))


def allan_slope(m: np.ndarray, step_s: float) -> float | None:
    """log-log slope of the overlapping Allan deviation of the coarse means between the two
    longest averaging times with >= 8 independent samples (descriptive)."""
    import allantools
    x = m[np.isfinite(m)]
    if x.size < 32:
        return None
    taus = step_s * np.exp2(np.arange(0, int(math.log2(x.size / 8)) + 1))
    t2, ad, _, _ = allantools.oadev(x, rate=1.0 / step_s, data_type='freq', taus=taus)
    if t2.size < 2 or np.any(ad[-2:] <= 0):
        return None
    return round(float(np.log(ad[-1] / ad[-2]) / np.log(t2[-1] / t2[-2])), 2)


def wander_signature(an, spec, q_axes, tau_axes, alpha: float = ALPHA) -> Signature:
    """Test the residual of `spec` (the model the wander is added to) on every gyro axis with a
    wander (q > 0). `tau_axes` None: random walk; else Gauss-Markov."""
    markov = tau_axes is not None
    fit = an.fit(spec, 'gyro')
    d = an.data
    grid = coarse_grid(len(d.t), d.bin_s)
    tc, _ = coarse_means(an.temp, np.ones(len(d.t)), an.mask, grid)
    rc, _ = coarse_means(an.temp_rate, np.ones(len(d.t)), an.mask, grid)
    tests, slopes = [], []
    for a, c in enumerate(fit.comps):
        if not q_axes[a] > 0:
            slopes.append(None)
            continue
        y, X = c.design()
        r = np.where(c.mask, y - c.stats.predict_full(X), 0.0)
        mc, vc = coarse_means(r, an.gyro_var[:, a], c.mask, grid)
        Xc = coarse_design(X, an.gyro_var[:, a], c.mask, grid)
        slopes.append(allan_slope(mc, grid.step_s))
        tests += axis_tests(mc, vc, Xc, grid.centres, tc, rc, markov, grid.step_s, a)
    n_tests = max(1, len({(t.family, t.axis) for t in tests}))
    worst = min(tests, key=lambda x: x.p, default=None)
    p_min = 1.0 if worst is None else min(1.0, worst.p * n_tests)
    if worst is not None and p_min < alpha:
        return Signature(False, worst.family, _reason(worst, p_min), p_min, tests, slopes)
    # a wander that some shape alone describes as well as such shapes are described (MUST_BEAT) is
    # no evidence of a wander: it must win outright
    beaten = [x for x in tests if x.beats_wander]
    if beaten:
        alone = max(beaten, key=lambda x: x.alone_lr - step_margin(x.family, x.n_scanned))
        return Signature(False, alone.family, _reason(alone, p_min, alone=True), p_min, tests, slopes)
    return Signature(True, None, None, p_min, tests, slopes)


def _reason(t: FamilyTest, p: float, alone: bool = False) -> str:
    """One line; sigma = the two-sided normal equivalent of the family-wise p; `alone`: the shape
    alone describes the residual as well as or better than the wander alone (D = 2 dlogL)."""
    if alone:
        how = f'the shape alone fits as well as the wander: 2 dlogL {t.alone_lr:.0f}'
    else:
        how = f'{float(stats.norm.isf(max(p, 1e-300) / 2.0)):.1f} sigma'
    where = f"(gyro axis {'xyz'[t.axis]}, {t.detail['amplitude_dps']:.2g} deg/s, {how})"
    if t.family == 'periodic':
        return f"periodic residual, period {t.detail['period_s']:.0f} s {where}"
    if t.family == 'step':
        return f"step at t = {t.detail['step_t_s']:.0f} s {where}"
    if t.family == 'two_steps':
        return f"steps at t = {t.detail['step_t_s'][0]:.0f} s and {t.detail['step_t_s'][1]:.0f} s {where}"
    return f"residual locked to the temperature history (heating/cooling split or a function of T) {where}"
