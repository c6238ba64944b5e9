"""Which significant candidate is named (selection.py scores them): encompassing checks between
candidates, parsimony, and the wandering biases weighed against the measured explanations.

* the top-scoring significant candidate is set aside if it only stands for others together
  (`_proxy_check`), then challenged pairwise (A on top of B and B on top of A);
* a wander (random walk or Gauss-Markov, nested: `_wander_choice`) can soak up any slow structure
  once fitted, so it is named only when no measured explanation stands (`_measured_first`,
  `_deterministic_path`) and the residual has a wander's signature (`_signature_check`,
  signature.py): a spectral line, a step or temperature-locked structure gives no stochastic name.
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from .candidates import GYRO, LIBRARY, STOCHASTIC
from .model import Analysis, ModelSpec
from .selection import CandidateScore, Criteria, brief, channel_of_score, evaluate, t_spread
from .signature import wander_signature



def choose(an: Analysis, spec: ModelSpec, scores: list[CandidateScore], crit: Criteria,
           library=LIBRARY, challengers: int = 3) -> tuple[CandidateScore | None, list[dict]]:
    """The significant candidate that best explains the gap, with the checks made.

    A wander (the better of the two, `_wander_choice`) that tops the scores is weighed against the
    measured explanations first (`_measured_first`). Otherwise the top regressor B is set aside if
    it only stands for others together (`_proxy_check`), then challenged by the next few
    significant ones A of the same channel: does A still help once B is in the model, and B once A
    is? If B does and A does not, B stays; if the reverse, A explains what B explained and more, and
    replaces B; if neither helps significantly given the other, `_undecided` applies parsimony
    (nested effects, e.g. scale_factor within scale_factor_thermal, resolve to the simpler, others
    to the better BIC); if both do, both are real and the larger comes first. Returns (choice or
    None, checks made)."""
    by_name = {c.name: c for c in library}
    sig = sorted([s for s in scores if s.significant], key=lambda s: -s.score)
    if not sig:
        return None, []
    checks = []
    rw = _wander_choice([s for s in sig if s.channel == STOCHASTIC], checks, crit)
    dets = [s for s in sig if s.channel != STOCHASTIC]
    if rw is not None and (not dets or rw.score > dets[0].score):
        best, look = _measured_first(an, rw, sig, scores, by_name, crit)
        checks.append(look)
        if best.channel == STOCHASTIC:
            # weighed against every significant regressor already; now: does it look like one?
            best = _signature_check(an, spec, best, dets, checks)
            if best is None or best.channel == STOCHASTIC:
                return best, checks
    else:
        best = dets[0]
    # (a wander that did not top the scores waits for a later round: measured causes first)
    best, dropped = _proxy_check(an, spec, best, dets, by_name, crit, checks)
    for other in [s for s in dets if s.name not in (best.name, dropped)][:challengers]:
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


def _signature_check(an, spec: ModelSpec, wander: CandidateScore, dets: list, checks: list):
    """The wander is named only when the residual has its signature (signature.py). If a
    deterministic shape describes it better, the choice is thermal_hysteresis when the shape is a
    heating/cooling split and that candidate is significant (the physical name, though its shape
    may match only in part), else nothing: no library effect is periodic or a step, so the
    verdict will be `unexplained_residual` with the signature's one-line reason."""
    s = wander_signature(an, spec, wander.spec.rw_q, wander.spec.rw_tau)
    fallback = None
    if not s.holds and s.kind == 'temperature_locked':
        fallback = next((d for d in dets if d.name == 'thermal_hysteresis'), None)
    kept = wander if s.holds else fallback
    checks.append({'a': wander.name, 'signature': s.to_dict(), 'kept': kept.name if kept else None,
                   'unexplained': None if s.holds else s.reason})
    return kept


def unexplained_reason(checks: list) -> str | None:
    """The one-line reason a wander was refused its name (None: none was)."""
    return next((c['unexplained'] for c in checks if c.get('unexplained')), None)


def _proxy_check(an, spec, best: CandidateScore, dets, by_name, crit, checks: list):
    """A flexible effect can top the scores by imitating two others at once (a hysteresis state
    with a short time constant mimics a lag plus a curvature). So the best one is set aside for the
    next best when it does not help significantly with every other significant regressor of its
    channel in the model (settings as each found alone) while those together predict the held-out
    batches significantly better than it does: it stands for them. Nested
    candidates (scale_factor in scale_factor_thermal) and pairs are left to the encompassing
    checks. Returns (choice, name dropped or None)."""
    mine = _added(spec, best.spec)

    def nested(s):
        theirs = _added(spec, s.spec)
        return bool(mine and theirs and (mine <= theirs or theirs <= mine))
    others = [s for s in dets if s.name != best.name and channel_of_score(s) == channel_of_score(best)
              and not nested(s)]
    if len(others) < 2:
        return best, None
    joint = evaluate(an, merge_specs(spec, [o.spec for o in others]), by_name[best.name], crit)
    edge = best.held - (joint.held + joint.batch_gains)          # how much better the others do together
    stands_for = not joint.significant and edge.sum() > 0 and t_spread(edge) >= crit.t_crit(edge.size - 1)
    checks.append({'a': best.name, 'given': [o.name for o in others], 'a_given_others': brief(joint),
                   'others_better_t': round(t_spread(edge), 2), 'kept': others[0].name if stands_for else best.name})
    return (others[0], best.name) if stands_for else (best, None)


def _added(base: ModelSpec, sp: ModelSpec) -> set:
    return set(sp.gyro_terms + sp.compass_terms) - set(base.gyro_terms + base.compass_terms)


def merge_specs(base: ModelSpec, specs: list) -> ModelSpec:
    """`base` with every change each of `specs` made to it (terms, settings, names) applied."""
    out = base
    for sp in specs:
        changes = {f: getattr(sp, f) for f in ('lag_tau_s', 'branch', 'time_offset_s')
                   if getattr(sp, f) != getattr(base, f)}
        compass = tuple(t for t in sp.compass_terms if t not in out.compass_terms)
        out = replace(out.with_terms(add=[t for t in sp.gyro_terms if t not in base.gyro_terms]),
                      compass_terms=out.compass_terms + compass,
                      effects=out.effects + tuple(e for e in sp.effects if e not in out.effects), **changes)
    return out


def _wander_choice(stoch: list, checks: list, crit) -> CandidateScore | None:
    """The random walk is the Gauss-Markov bias with tau -> infinity: when both are significant the
    mean reversion has to earn its extra setting per axis, by Delta BIC of the nested pair's
    coarse-bin likelihoods (as when choosing the order of a time-series model). Held-out blocks
    cannot decide it: the current model's own extrapolation error in a held-out block is a level
    the random walk carries across the block and a mean-reverting state does not."""
    if len(stoch) < 2:
        return stoch[0] if stoch else None
    rw = next(s for s in stoch if s.n_added == min(x.n_added for x in stoch))
    gm = next(s for s in stoch if s is not rw)
    dbic = 2.0 * (gm.loglik - rw.loglik) - (gm.n_added - rw.n_added) * math.log(max(gm.n_coarse, 2))
    kept = gm if dbic >= crit.bic_min else rw
    gains = rw.held - gm.held
    checks.append({'a': rw.name, 'b': gm.name, 'b_given_a': {
        'significant': kept is gm, 'delta_chi2_cv': round(float(np.sum(gains)), 2), 't': round(t_spread(gains), 2),
        'delta_bic': round(float(dbic), 2), 'reason': 'nested: decided by Delta BIC'}, 'kept': kept.name})
    return kept


def _given_random_walk(an, det: CandidateScore, rw: CandidateScore, by_name, crit):
    """(record of det given the random walk, record of the random walk given det). det given RW
    compares the joint model (det, then a random walk with re-estimated strength) with the random
    walk alone: held-out gain t test and a Delta BIC on the random walk's coarse-bin likelihood."""
    joint = evaluate(an, det.spec, by_name[rw.name], crit)
    gains = rw.held - joint.held
    dbic = 2.0 * (joint.loglik - rw.loglik) - det.n_added * math.log(max(rw.n_coarse, 2))
    sig = bool(np.sum(gains) > 0 and t_spread(gains) >= crit.t_crit(gains.size - 1) and dbic >= crit.bic_min)
    rec = {'significant': sig, 'delta_chi2_cv': round(float(np.sum(gains)), 2), 't': round(t_spread(gains), 2),
           'delta_bic': round(float(dbic), 2), 'reason': None}
    return rec, brief(joint)


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
    return _deterministic_path(an, rw, sig, scores, testable, by_name, crit, width)


def _deterministic_path(an, rw: CandidateScore, sig, scores, testable, by_name, crit, width: int = 3):
    """A random walk soaks up any slow structure, including that of two regressor effects at
    once. Before naming it, try each of the best few significant regressors D1 - and the few with
    very strong evidence (Delta BIC) that fail the held-out test alone: effects that interact, such
    as a curvature seen through a lagged die temperature, are only right together - followed by
    the best regressor D2 significant given D1: if some D1 (+ D2) predicts the held-out batches at
    least as well as the random walk (a D1 that is not significant alone only as part of a path
    significant as a whole), the measured quantities explain the gap and that D1 is taken -
    unless the wander still helps significantly on top of that path (D1 did not help on top of the
    wander: we are here because it did not) while the path did not predict better than the
    wander: the wander then encompasses it."""
    strong = sorted([s for s in scores if s.testable and s.channel == GYRO and not s.significant
                     and s.delta_bic >= crit.bic_min], key=lambda s: -s.delta_bic)[:width]
    dets = [s for s in sig if s.channel == GYRO][:width] + strong
    if not dets:
        return rw, {'look_ahead': None, 'kept': rw.name}
    base_held = rw.held + rw.batch_gains                        # the current model's held-out chi-square
    paths = []
    for d1 in dets:
        last, names = d1, [d1.name]
        second = [evaluate(an, d1.spec, by_name[n], crit) for n in testable if n != d1.name]
        second = [s for s in second if s.significant]
        if second:
            last = max(second, key=lambda s: s.delta_chi2_cv)
            names = names + [last.name]
        whole = base_held - last.held
        if not d1.significant and (last is d1 or t_spread(whole) < crit.t_crit(whole.size - 1)):
            continue
        paths.append((float(np.sum(rw.held - last.held)), t_spread(last.held - rw.held), d1, names, last))
    if not paths:
        return rw, {'look_ahead': None, 'kept': rw.name}
    margin, t_rw, d1, names, last = max(paths, key=lambda p: p[0])
    # two significant, non-nested explanations: the measured one is kept unless the random walk
    # predicts the held-out batches better by more than one standard error (the one-SE rule)
    chosen = rw if (margin < 0 and t_rw >= 1.0) else d1
    look = {'look_ahead': names, 'heldout_gain_over_random_walk': round(margin, 2),
            't_random_walk_better': round(t_rw, 2)}
    if chosen is d1 and margin < 0:
        beyond = evaluate(an, last.spec, by_name[rw.name], crit)
        look['random_walk_given_path'] = brief(beyond)
        chosen = rw if beyond.significant else d1
    look['kept'] = chosen.name
    return chosen, look


def _pair(an, a: CandidateScore, b: CandidateScore, by_name, crit) -> tuple[dict, dict]:
    """(b given a, a given b) as brief significance records."""
    if STOCHASTIC in (a.channel, b.channel):
        det, rw = (a, b) if b.channel == STOCHASTIC else (b, a)
        det_given_rw, rw_given_det = _given_random_walk(an, det, rw, by_name, crit)
        return (rw_given_det, det_given_rw) if b is rw else (det_given_rw, rw_given_det)
    return (brief(evaluate(an, a.spec, by_name[b.name], crit)),
            brief(evaluate(an, b.spec, by_name[a.name], crit)))


def _undecided(b: CandidateScore, o: CandidateScore, o_given_b: dict, b_given_o: dict) -> str:
    """Neither adds significantly to the other: they explain the same structure. A random walk yields
    to a measured explanation; nested effects (one's terms inside the other's) resolve to the
    simpler; otherwise the one with the better BIC is named (the Schwarz approximation to the
    posterior odds of two non-nested models; its complexity charge is what a held-out comparison of
    a few chi-square units cannot resolve)."""
    if STOCHASTIC in (b.channel, o.channel):
        return b.name if b.channel != STOCHASTIC else o.name
    simple, rich = sorted((b, o), key=lambda s: (s.n_added, -s.score))
    if 'already in the model' in (o_given_b.get('reason') or '', b_given_o.get('reason') or ''):
        return simple.name
    return min((simple, rich), key=lambda s: s.bic).name
