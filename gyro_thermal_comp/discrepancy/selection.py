"""Scoring candidates against the current model and choosing one, by statistics only.

For every testable candidate:

* held-out gain: blocked K-fold cross-validation. Each contiguous block is predicted by the model
  fitted to the other blocks (the candidate's non-linear setting also chosen on them); the gain
  is the drop of the held-out weighted squared error, in chi-square units of the bins' own white
  noise. `t_cv` = mean gain / its standard error over the K blocks (fold-to-fold spread).
* information criterion: Delta BIC of the all-data fits (each component with its own unknown
  residual scale, so unmodelled structure does not inflate it; each estimated setting counts as a
  parameter).
* score: the fraction of the current model's held-out excess (chi-square above white noise) that
  the candidate removes; 1 = the whole gap explained, <= 0 = no help.

An effect is significant when its held-out gain is positive with t_cv above the one-sided
Student-t quantile at level `alpha` AND Delta BIC exceeds `bic_min` (10: "very strong" evidence on
the Kass & Raftery scale). Among significant candidates the one with the largest score is taken,
unless a candidate with fewer parameters is not significantly worse than it (same two tests on the
pair): then the simpler explanation is named.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import stats

from .candidates import GYRO, LIBRARY, STOCHASTIC, Candidate
from .model import Analysis, ModelSpec
from .stochastic import score_random_walk


@dataclass(frozen=True)
class Criteria:
    alpha: float = 0.01       # one-sided level of the held-out gain t test (batch means)
    bic_min: float = 10.0     # Delta BIC for "very strong" evidence
    plausible: float = 10.0   # a fitted coefficient beyond this many prior sigmas (an order of
                              # magnitude past the term's plausible size) is not a physical finding

    def t_crit(self, n_folds: int) -> float:
        return float(stats.t.ppf(1.0 - self.alpha, n_folds - 1))


@dataclass
class CandidateScore:
    name: str
    channel: str
    testable: bool
    reason: str | None = None
    gains: np.ndarray | None = None       # (K,) held-out chi-square gain per fold
    batch_gains: np.ndarray | None = None  # (nb,) ... per batch
    held: np.ndarray | None = None        # (nb,) held-out chi-square of the candidate model per batch
    t_batch: float = float('nan')
    t_robust: float = float('nan')
    delta_chi2_cv: float = float('nan')
    t_cv: float = float('nan')
    delta_bic: float = float('nan')
    score: float = float('nan')           # fraction of the held-out excess removed
    significant: bool = False
    n_added: int = 0
    spec: ModelSpec | None = None
    settings: dict = field(default_factory=dict)
    bic: float = float('nan')
    plausibility: float = 0.0             # max |added coefficient| / its prior sigma
    loglik: float = float('nan')          # random walk: coarse-bin log-likelihood of the joint model
    n_coarse: int = 0
    note: str = ''

    def to_dict(self) -> dict:
        f = lambda x: None if x is None or (isinstance(x, float) and not math.isfinite(x)) else round(float(x), 6)
        return {'name': self.name, 'channel': self.channel, 'testable': self.testable, 'reason': self.reason,
                'score': f(self.score), 'delta_chi2_cv': f(self.delta_chi2_cv), 't_cv': f(self.t_cv),
                'delta_bic': f(self.delta_bic), 't_batch': f(self.t_batch), 'plausibility_sigmas': f(self.plausibility),
                'significant': self.significant, 'n_added_parameters': self.n_added,
                'settings': self.settings, 'note': self.note or None,
                'fold_gains': None if self.gains is None else [round(float(g), 3) for g in self.gains]}


def _t(gains: np.ndarray) -> float:
    sd = float(np.std(gains, ddof=1))
    if sd == 0.0:
        return math.inf if np.mean(gains) > 0 else 0.0
    return float(np.mean(gains) / (sd / math.sqrt(gains.size)))


def channel_of(c: Candidate) -> str:
    return GYRO if c.channel == STOCHASTIC else c.channel


def evaluate(an: Analysis, spec: ModelSpec, cand: Candidate, crit: Criteria) -> CandidateScore:
    """Score one candidate against `spec` (see module doc)."""
    reason = cand.applicable(an, spec)
    ch = channel_of(cand)
    if reason is None and spec.rw_q and cand.channel == STOCHASTIC:
        reason = 'already in the model'
    if reason is not None:
        return CandidateScore(cand.name, cand.channel, False, reason)
    cur = an.fit(spec, ch)
    cur_held_b = cur.heldout_batches()
    n_obs = float(cur.n_obs().sum())
    excess = max(float(cur_held_b.sum()) - n_obs, math.sqrt(2.0 * n_obs))
    if cand.channel == STOCHASTIC:
        gains_b, dbic, q, ll, n_coarse = score_random_walk(an, spec)
        sc = CandidateScore(cand.name, cand.channel, True, delta_bic=dbic, n_added=len(q),
                            spec=replace(cand.named(spec), rw_q=tuple(q), rw_base=spec),
                            settings={'rate_random_walk_dps_rts': [round(math.degrees(math.sqrt(x)), 8) for x in q]})
        sc.loglik, sc.n_coarse = ll, n_coarse
    else:
        variants = cand.variants(an, spec)
        fits = [an.fit(v, ch) for v in variants]
        bics = [f.bic() for f in fits]
        best = int(np.argmin(bics))
        extra = cand.refine(an, spec, variants[best])
        if extra:
            variants += extra
            fits += [an.fit(v, ch) for v in extra]
            bics += [f.bic() for f in fits[-len(extra):]]
            best = int(np.argmin(bics))
        # per fold: the variant its training blocks prefer (their own BIC), scored on the fold
        tb = np.array([f.train_bic() for f in fits])            # (V, K)
        choice = np.argmin(tb, axis=0)
        held_b = np.array([fits[choice[an.batch_fold[b]]].heldout_batches()[b] for b in range(an.batch_fold.size)])
        gains_b = cur_held_b - held_b
        penalty = cand.n_settings * math.log(float(cur.n_obs().max()))
        sc = CandidateScore(cand.name, cand.channel, True,
                            delta_bic=float(cur.bic() - bics[best] - penalty), bic=float(bics[best] + penalty),
                            n_added=fits[best].n_params - cur.n_params + cand.n_settings,
                            spec=cand.named(variants[best]), settings=_settings(variants[best], spec))
        sc.plausibility = _plausibility(an, spec, variants[best], ch)
    sc.batch_gains = gains_b
    sc.held = cur_held_b - gains_b
    sc.gains = np.bincount(an.batch_fold, weights=gains_b, minlength=an.n_folds)
    sc.delta_chi2_cv = float(np.sum(gains_b))
    sc.t_cv = _t(sc.gains)
    sc.t_batch = _t(gains_b)
    sc.t_robust = _t_robust(gains_b)
    sc.score = sc.delta_chi2_cv / excess
    sc.significant = bool(sc.delta_chi2_cv > 0 and sc.t_batch >= crit.t_crit(sc.batch_gains.size)
                          and sc.delta_bic >= crit.bic_min)
    if sc.significant and sc.plausibility > crit.plausible:
        sc.significant = False
        sc.note = (f'implausible: a fitted coefficient is {sc.plausibility:.0f} prior sigmas from 0 (it imitates '
                   'another effect)')
    return sc


def _plausibility(an: Analysis, spec: ModelSpec, variant: ModelSpec, ch: str) -> float:
    """Largest |coefficient| / prior sigma among the terms the candidate added (all-data fit)."""
    from .terms import TERMS
    old = set(spec.gyro_terms if ch == GYRO else spec.compass_terms)
    worst = 0.0
    for coef in an.coefficients(variant, ch):
        for name, value in coef.items():
            if name not in old and name not in ('constant', 'compass_offset'):
                worst = max(worst, abs(value) / TERMS[name].prior_sigma)
    return worst


def _t_robust(g: np.ndarray) -> float:
    """Sum of batch gains over its standard error with the batch spread taken robustly (MAD): a
    real effect confined to a few batches does not inflate the noise estimate."""
    mad = 1.4826 * float(np.median(np.abs(g - np.median(g))))
    if mad == 0.0:
        return 0.0
    return float(np.sum(g) / (mad * math.sqrt(g.size)))


def _settings(v: ModelSpec, base: ModelSpec) -> dict:
    out = {k: val for k, val in v.settings().items() if base.settings().get(k) != val}
    added = [t for t in v.gyro_terms if t not in base.gyro_terms] + \
        [t for t in v.compass_terms if t not in base.compass_terms]
    if added:
        out['terms_added'] = added
    return out


def score_all(an: Analysis, spec: ModelSpec, crit: Criteria, library=LIBRARY) -> list[CandidateScore]:
    return [evaluate(an, spec, c, crit) for c in library]


def choose(an: Analysis, spec: ModelSpec, scores: list[CandidateScore], crit: Criteria,
           library=LIBRARY, challengers: int = 3) -> tuple[CandidateScore | None, list[dict]]:
    """The significant candidate that best explains the gap, with the encompassing checks made.

    The top-scoring significant candidate B is challenged by the next few significant ones A of
    the same channel: does A still help once B is in the model, and B once A is? If B does and A
    does not, B stays; if the reverse, A explains what B explained and more, and replaces B; if
    neither helps significantly given the other, `_undecided` applies parsimony (nested effects,
    e.g. scale_factor within scale_factor_thermal, resolve to the simpler); if both do, both are
    real and the larger comes first. A random-walk bias can soak up
    any slow structure once fitted, so against it the joint model (regressor + random walk, its
    strength re-estimated) is compared with each alone. Returns (choice or None, checks made)."""
    by_name = {c.name: c for c in library}
    sig = sorted([s for s in scores if s.significant], key=lambda s: -s.score)
    if not sig:
        return None, []
    checks = []
    rw = next((s for s in sig if s.channel == STOCHASTIC), None)
    dets = [s for s in sig if s.channel != STOCHASTIC]
    if not dets:
        return rw, checks
    best = dets[0]
    if rw is not None and rw.score > best.score:
        best, look = _measured_first(an, rw, sig, scores, by_name, crit)
        checks.append(look)
        if best.channel == STOCHASTIC:
            return best, checks     # weighed against every significant regressor already
    # (a random walk that did not top the scores waits for a later round: measured causes first)
    for other in [s for s in dets if s.name != best.name][:challengers]:
        if channel_of_score(other) != channel_of_score(best):
            continue
        o_given_b, b_given_o = _pair(an, best, other, by_name, crit)
        if b_given_o['significant'] and not o_given_b['significant']:
            outcome = best.name
        elif o_given_b['significant'] and not b_given_o['significant']:
            outcome = other.name
        elif not o_given_b['significant'] and not b_given_o['significant']:
            outcome = _undecided(best, other, o_given_b, b_given_o)
        else:   # both real: the larger first, the other in a later round
            outcome = max((best, other), key=lambda s: s.score).name
        checks.append({'a': best.name, 'b': other.name, 'b_given_a': o_given_b, 'a_given_b': b_given_o,
                       'kept': outcome})
        if outcome == other.name:
            best = other
    return best, checks


def _given_random_walk(an, det: CandidateScore, rw: CandidateScore, by_name, crit):
    """(record of det given the random walk, record of the random walk given det). det given RW
    compares the joint model (det, then a random walk with re-estimated strength) with the random
    walk alone: held-out gain t test and a Delta BIC on the random walk's coarse-bin likelihood."""
    joint = evaluate(an, det.spec, by_name[rw.name], crit)
    gains = rw.held - joint.held
    dbic = 2.0 * (joint.loglik - rw.loglik) - det.n_added * math.log(max(rw.n_coarse, 2))
    sig = bool(np.sum(gains) > 0 and _t(gains) >= crit.t_crit(gains.size) and dbic >= crit.bic_min)
    rec = {'significant': sig, 'delta_chi2_cv': round(float(np.sum(gains)), 2), 't': round(_t(gains), 2),
           'delta_bic': round(float(dbic), 2), 'reason': None}
    return rec, _brief(joint)


def _measured_first(an, rw: CandidateScore, sig, scores, by_name, crit, width: int = 3):
    """The random walk scored best. It is named only when no measured explanation stands: a
    regressor that still helps significantly with the random walk also in the model (joint fit,
    random-walk strength re-estimated) is named first - a random walk is what remains once all
    measured causes are taken out; failing that, the two-step look-ahead below."""
    standing = [d for d in [s for s in sig if s.channel == GYRO][:width]
                if _given_random_walk(an, d, rw, by_name, crit)[0]['significant']]
    if standing:
        d = max(standing, key=lambda s: s.score)
        return d, {'significant_given_random_walk': [s.name for s in standing], 'kept': d.name}
    testable = [s.name for s in scores if s.testable and s.channel == GYRO]
    return _deterministic_path(an, rw, sig, testable, by_name, crit, width)


def _deterministic_path(an, rw: CandidateScore, sig, testable, by_name, crit, width: int = 3):
    """A random walk soaks up any slow structure, including that of two regressor effects at
    once. Before naming it, try each of the best few significant regressors D1 followed by the best
    regressor D2 significant given D1: if some D1 (+ D2) predicts the held-out batches at least as well as
    the random walk, the measured quantities explain the gap and that D1 is taken."""
    dets = [s for s in sig if s.channel == GYRO][:width]
    if not dets:
        return rw, {'look_ahead': None}
    paths = []
    for d1 in dets:
        held, names = d1.held, [d1.name]
        second = [evaluate(an, d1.spec, by_name[n], crit) for n in testable if n != d1.name]
        second = [s for s in second if s.significant]
        if second:
            d2 = max(second, key=lambda s: s.delta_chi2_cv)
            held, names = d2.held, names + [d2.name]
        paths.append((float(np.sum(rw.held - held)), _t(held - rw.held), d1, names))
    margin, t_rw, d1, names = max(paths, key=lambda p: p[0])
    # two significant, non-nested explanations: the measured one is kept unless the random walk
    # predicts the held-out batches better by more than one standard error (the one-SE rule)
    chosen = rw if (margin < 0 and t_rw >= 1.0) else d1
    return chosen, {'look_ahead': names, 'heldout_gain_over_random_walk': round(margin, 2),
                    't_random_walk_better': round(t_rw, 2), 'kept': chosen.name}


def _pair(an, a: CandidateScore, b: CandidateScore, by_name, crit) -> tuple[dict, dict]:
    """(b given a, a given b) as brief significance records."""
    n = an.batch_fold.size
    if STOCHASTIC in (a.channel, b.channel):
        det, rw = (a, b) if b.channel == STOCHASTIC else (b, a)
        det_given_rw, rw_given_det = _given_random_walk(an, det, rw, by_name, crit)
        return (rw_given_det, det_given_rw) if b is rw else (det_given_rw, rw_given_det)
    return (_brief(evaluate(an, a.spec, by_name[b.name], crit)),
            _brief(evaluate(an, b.spec, by_name[a.name], crit)))


def _undecided(b: CandidateScore, o: CandidateScore, o_given_b: dict, b_given_o: dict) -> str:
    """Neither adds significantly to the other. A random walk yields to a measured explanation;
    nested effects (one's terms inside the other's) resolve to the simpler; otherwise the simpler
    one is named unless the other predicts the held-out batches better by more than one standard
    error (the one-standard-error rule of cross-validated model selection)."""
    if STOCHASTIC in (b.channel, o.channel):
        return b.name if b.channel != STOCHASTIC else o.name
    simple, rich = sorted((b, o), key=lambda s: (s.n_added, -s.score))
    if 'already in the model' in (o_given_b.get('reason') or '', b_given_o.get('reason') or ''):
        return simple.name
    return rich.name if _t(simple.held - rich.held) >= 1.0 else simple.name


def _brief(s: CandidateScore) -> dict:
    return {'significant': s.significant, 'delta_chi2_cv': None if not s.testable else round(s.delta_chi2_cv, 2),
            't': None if not s.testable else round(s.t_batch, 2),
            'delta_bic': None if not s.testable else round(s.delta_bic, 2), 'reason': s.reason}


def channel_of_score(s: CandidateScore) -> str:
    return GYRO if s.channel == STOCHASTIC else s.channel
