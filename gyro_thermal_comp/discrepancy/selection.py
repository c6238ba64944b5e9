"""Scoring candidates against the current model and choosing one, by statistics only.

For every testable candidate:

* held-out gain: blocked K-fold cross-validation. Each contiguous block is predicted by the model
  fitted to the other blocks (the candidate's non-linear setting also chosen on them); the gain
  is the drop of the held-out weighted squared error, in chi-square units of the bins' own white
  noise. `t_batch` = gain / its noise standard error: per batch the gain is |delta|^2 + 2 e.delta
  (delta: the change of the held-out prediction, e: the candidate's held-out residual), and only
  the second part is noise; its variance comes from the batches' own (2 e.delta)^2 (`_t_noise`).
* information criterion: Delta BIC of the all-data fits (each component with its own unknown
  residual scale, so unmodelled structure does not inflate it; each estimated setting counts as a
  parameter).
* score: the fraction of the current model's held-out excess (chi-square above white noise) that
  the candidate removes; 1 = the whole gap explained, <= 0 = no help.

An effect is significant when its held-out gain is positive with t_batch above the one-sided
Student-t quantile at level `alpha` AND Delta BIC exceeds `bic_min` (10: "very strong" evidence on
the Kass & Raftery scale); a wander is tested on interleaved folds and must pass its own model
check. Which significant candidate is named: choice.py.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import stats

from .candidates import GYRO, LIBRARY, STOCHASTIC, Candidate
from .detection import detection
from .model import Analysis, ModelSpec
from .terms import TERMS
from .wander import BatchGains, score_wander, settings as wander_settings


@dataclass(frozen=True)
class Criteria:
    alpha: float = 0.01       # one-sided level of the held-out gain t test
    bic_min: float = 10.0     # Delta BIC for "very strong" evidence
    plausible: float = 10.0   # a fitted coefficient beyond this many prior sigmas (an order of
                              # magnitude past the term's plausible size) is not a physical finding
    model_p: float = 1e-3     # a wander model whose innovations fail whiteness at this level is
                              # not what the structure is (the same level as the verdict's test)
    snr_detect: float = 5.0   # matched-filter SNR that defines a candidate's detection limit
                              # (detection.py: a 1 %-level test has 97 % power there)

    def t_crit(self, dof: float) -> float:
        return float(stats.t.ppf(1.0 - self.alpha, max(dof, 1.0)))


@dataclass
class CandidateScore:
    name: str
    channel: str
    testable: bool
    reason: str | None = None
    gains: np.ndarray | None = None       # (K,) held-out chi-square gain per fold
    batch_gains: np.ndarray | None = None  # (nb,) ... per batch
    held: np.ndarray | None = None        # (nb,) held-out chi-square of the candidate model per batch
    t_batch: float = float('nan')         # held-out gain / its noise standard error (see _t_noise)
    dof: float = float('nan')             # ... its degrees of freedom
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
    loglik: float = float('nan')          # wander: coarse-bin log-likelihood of the joint model
    model_p: float = 1.0                  # wander: p-value of its own model check (misfit_p)
    n_coarse: int = 0
    note: str = ''
    detection: dict = field(default_factory=dict)   # detection_snr, detection_limit (detection.py)

    def to_dict(self) -> dict:
        f = lambda x: None if x is None or (isinstance(x, float) and not math.isfinite(x)) else round(float(x), 6)
        return {'name': self.name, 'channel': self.channel, 'testable': self.testable, 'reason': self.reason,
                'score': f(self.score), 'delta_chi2_cv': f(self.delta_chi2_cv), 't_cv': f(self.t_cv),
                'delta_bic': f(self.delta_bic), 't_batch': f(self.t_batch), 't_dof': f(self.dof),
                'plausibility_sigmas': f(self.plausibility),
                'significant': self.significant, 'n_added_parameters': self.n_added,
                'settings': self.settings, 'note': self.note or None,
                **{k: (f(v) if isinstance(v, float) else v) for k, v in self.detection.items()},
                'fold_gains': None if self.gains is None else [round(float(g), 3) for g in self.gains]}


def t_spread(gains: np.ndarray) -> float:
    """Mean over its standard error from the spread (Diebold-Mariano over batches or folds)."""
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
        wander = score_wander(an, spec)[cand.markov]
        gains_b, cross_b = wander.contiguous.gains, wander.contiguous.cross
        tau = tuple(wander.tau_s) if cand.markov else None
        sc = CandidateScore(cand.name, cand.channel, True, delta_bic=wander.delta_bic,
                            n_added=len(wander.q) * cand.n_settings,
                            spec=replace(cand.named(spec), rw_q=tuple(wander.q), rw_tau=tau, rw_base=spec),
                            settings=wander_settings(wander.q, tau))
        sc.loglik, sc.n_coarse, sc.model_p = wander.loglik, wander.n_coarse, wander.model_p
        sc.note = f'tested on interleaved folds: held-out dchi2 {float(wander.interleaved.gains.sum()):.0f} there'
        # a wander is tested on interleaved folds (see wander.score_wander)
        tested = wander.interleaved
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
        cross_b = _cross_terms(an, spec, [variants[c] for c in choice], ch)
        tested = BatchGains(gains_b, cross_b)   # a regressor is tested on its own gain
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
    sc.t_cv = t_spread(sc.gains)
    sc.t_batch, sc.dof = _t_noise(tested.gains, tested.cross)
    sc.score = sc.delta_chi2_cv / excess
    sc.significant = bool(tested.gains.sum() > 0 and sc.t_batch >= crit.t_crit(sc.dof)
                          and sc.delta_bic >= crit.bic_min)
    if sc.significant and sc.model_p < crit.model_p:
        sc.significant = False
        sc.note = (f'its innovations are not white (p = {sc.model_p:.1g}): the structure is not a wandering '
                   'bias (periodic, or a shape it only follows)')
    if sc.significant and sc.plausibility > crit.plausible:
        sc.significant = False
        sc.note = (f'implausible: a fitted coefficient is {sc.plausibility:.0f} prior sigmas from 0 (it imitates '
                   'another effect)')
    return sc


def _cross_terms(an: Analysis, spec: ModelSpec, fold_variant: list, ch: str) -> np.ndarray:
    """(nb,) per batch, e.W.delta: the candidate's held-out residual e (fold k predicted by
    fold_variant[k]) times the change delta it makes to the current model's held-out residual."""
    r0 = an.residuals(spec, ch)
    r1 = np.full_like(r0, np.nan)
    for k, v in enumerate(fold_variant):
        rows = an.fold == k
        r1[rows] = an.residuals(v, ch)[rows]
    w = an.gyro_w if ch == GYRO else an.compass_w[:, None]
    m = an.channel_mask(ch)
    prod = np.nansum(w * r1 * (r0 - r1), axis=1)
    return np.bincount(an.batch[m], weights=prod[m], minlength=an.batch_fold.size)


def _t_noise(gains: np.ndarray, cross: np.ndarray) -> tuple[float, float]:
    """Held-out gain over its noise standard error. The gain of a batch is |delta|^2 + 2 e.delta
    (chi-square units): the first part is the structure explained, only the second is noise, so its
    variance is estimated from the batches' own (2 e.delta)^2 (a sandwich over batches: colour
    within a batch is allowed for) - not from the spread of the gains, which also counts the
    explained structure's unevenness (a lag shows only where the heating rate changes) as noise.
    Degrees of freedom: Welch-Satterthwaite over the batch terms (few when the structure is confined
    to a few batches)."""
    v = (2.0 * cross) ** 2
    sv = float(v.sum())
    if sv <= 0.0:
        return (math.inf if gains.sum() > 0 else 0.0), 1.0
    # each v_b is one squared normal term (E v^2 = 3 (E v)^2): nu = 3 (sum v)^2 / sum v^2
    dof = float(np.clip(3.0 * sv * sv / float(np.sum(v * v)), 1.0, v.size - 1))
    return float(gains.sum() / math.sqrt(sv)), dof


def _plausibility(an: Analysis, spec: ModelSpec, variant: ModelSpec, ch: str) -> float:
    """Largest |coefficient| / prior sigma among the terms the candidate added (all-data fit)."""
    old = set(spec.gyro_terms if ch == GYRO else spec.compass_terms)
    worst = 0.0
    for coef in an.coefficients(variant, ch):
        for name, value in coef.items():
            if name not in old and name not in ('constant', 'compass_offset'):
                worst = max(worst, abs(value) / TERMS[name].prior_sigma)
    return worst


def _settings(v: ModelSpec, base: ModelSpec) -> dict:
    out = {k: val for k, val in v.settings().items() if base.settings().get(k) != val}
    added = [t for t in v.gyro_terms if t not in base.gyro_terms] + \
        [t for t in v.compass_terms if t not in base.compass_terms]
    if added:
        out['terms_added'] = added
    return out


def score_all(an: Analysis, spec: ModelSpec, crit: Criteria, library=LIBRARY) -> list[CandidateScore]:
    """Every candidate scored against `spec`, each with its matched-filter detection limit."""
    scores = [evaluate(an, spec, c, crit) for c in library]
    for s in scores:
        s.detection = detection(an, spec, s, crit.snr_detect)
    return scores


def brief(s: CandidateScore) -> dict:
    """A significance record of a candidate score (for the encompassing checks in the report)."""
    return {'significant': s.significant, 'delta_chi2_cv': None if not s.testable else round(s.delta_chi2_cv, 2),
            't': None if not s.testable else round(s.t_batch, 2),
            'delta_bic': None if not s.testable else round(s.delta_bic, 2), 'reason': s.reason}


def channel_of_score(s: CandidateScore) -> str:
    return GYRO if s.channel == STOCHASTIC else s.channel
