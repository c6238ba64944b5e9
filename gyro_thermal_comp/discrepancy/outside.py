"""A named regressor against shapes outside the library: a bias step, a spectral line.

A flexible library regressor can take a shape it does not have for its own: the hysteresis branch
state (a level that switches where the temperature turns and relaxes over tau) fits a bias step
that happens while the unit cools (without this check a step was named `thermal_hysteresis` in 7 of 10 bags).
So, after the last round, each named gyro regressor D is asked whether a step (one time, every gyro
axis its own height) or a sinusoid (one frequency, every axis its own amplitude and phase) C
explains the residual of the model without it (M - D: a D that took C in whole leaves no trace of C
in M's residual). If one does, D is refitted with C in the model, and D's name is withdrawn when it
no longer adds significantly (M - D + C against M + C) and C fits M - D's residual at least as well
as D does (a true effect of moderate size is partly mimicked by a step or a sinusoid, and D may then
add nothing significant given it: the better fit keeps the verdict). D was standing in for C, and no
library effect has C's shape, so the verdict says what C is (`unexplained_residual` when nothing
else is named).

* C given M - D, on the 30 s coarse means, whitened (lowfreq.whitened_coarse), with M - D's regressors
  projected out: the largest chi-square over step times (every coarse boundary but the first and last
  2) or frequencies (2x oversampled, periods from half the record to 4 coarse bins), summed over
  the axes. Its null distribution (no shape: the residual is white noise) is the maximum of the
  same projections of white noise: Monte Carlo on this record's own design (fixed seed), so its p
  is exact for the scan; Bonferroni over the two families; `ALPHA`.
* D given M - D + C, on the 1 s bins (on coarse means a vehicle's cross-axis regressors, the other
  axes' rates, average out: the bundled vehicle_loop's true cross-axis error was withdrawn that
  way): the drop of the weighted residual sum of squares, chi-square with D's added columns (and
  its non-linear settings, e.g. the hysteresis tau and rate scale, as estimated) as degrees of
  freedom, at `ALPHA`. The settings were fitted to these data, which makes D look more
  significant than it is: the check errs towards keeping a name.

A true library effect D is in M - D's residual, so the scan there often finds a shape that mimics
part of it; D keeps its name while it adds significantly given that shape, or fits better than it
(docs/discrepancy.md gives the second truth family's answers). Only shapes no library effect can
take part in: a heating/cooling split (signature.py's temperature-locked columns) overlaps the
hysteresis and the lag, and withdrew a true 60 s lag on the bundled static_ramp (which also holds
a small hysteresis) when it was tried here.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from scipy import stats

from .lowfreq import projector, slices, whitened_coarse
from .model import ModelSpec
from .wander import coarse_grid

ALPHA = 0.01
EDGE = 2                  # coarse bins at each end where no step is placed
FAMILIES = ('step', 'periodic')
MAX_CANDIDATES = 240      # step times / frequencies scanned at most (2 h of 30 s bins: all of them;
                          # longer records every k-th: bounded memory, a step placed within k bins)
_MC_DRAWS, _MC_SEED = 2000, 20251126
_MC_FLOATS = 1 << 16      # white-noise draws and their projections held at once per axis (0.5 MB)


@dataclass(frozen=True)
class OutsideShape:
    """The strongest shape outside the library left in a model's gyro residual."""
    family: str           # one of FAMILIES
    where_s: float        # step time or period, s
    chi2: float           # summed over the axes
    p: float              # family-wise (the scan, Bonferroni over the families)
    size_dps: list        # per axis: step height or sine amplitude, deg/s

    @property
    def found(self) -> bool:
        return self.p < ALPHA

    def describe(self) -> str:
        where = (f'step at t = {self.where_s:.0f} s' if self.family == 'step'
                 else f'periodic, period {self.where_s:.0f} s')
        axis = int(np.argmax(np.abs(self.size_dps)))
        return f"{where} (gyro axis {'xyz'[axis]} {abs(self.size_dps[axis]):.2g} deg/s, p = {self.p:.1g})"

    def to_dict(self) -> dict:
        return {'family': self.family, 'where_s': round(self.where_s, 1), 'chi2': round(self.chi2, 2),
                'p': float(f'{self.p:.3g}'), 'size_dps': [float(f'{x:.3g}') for x in self.size_dps]}


class _Family:
    """The candidate shapes of one family on a record's coarse bins: raw columns (J, P, g) per
    axis (P candidates of g columns), and where each sits (s)."""

    def __init__(self, series, family: str, span_s: float, step_s: float):
        self.family = family
        t = series[0].t
        self.at = np.arange(EDGE, t.size - EDGE)                    # step: first coarse bin after it
        self.at = self.at[::-(-self.at.size // MAX_CANDIDATES)]
        if family == 'step':
            self.where = 0.5 * (t[self.at - 1] + t[self.at])
        else:
            f = np.arange(2.0 / span_s, 1.0 / (4.0 * step_s), 0.5 / span_s)
            self.where = 1.0 / f[::-(-f.size // MAX_CANDIDATES)]

    def columns(self, c) -> np.ndarray:
        """(J, P, g) raw columns on one axis's coarse bins."""
        if self.family == 'step':
            return (np.arange(c.t.size)[:, None] >= self.at[None, :]).astype(float)[:, :, None]
        ph = 2.0 * np.pi * np.outer(c.t, 1.0 / self.where)
        return np.stack([np.sin(ph), np.cos(ph)], axis=-1)

    def basis(self, c, perp) -> np.ndarray:
        """(J, P, g) whitened columns after X, orthonormal within each candidate."""
        A = self.columns(c) * c.s[:, None, None]
        J, P, g = A.shape
        A = perp(A.reshape(J, P * g)).reshape(J, P, g)
        if g == 1:
            norm = np.sqrt(np.sum(A * A, axis=0))
            return A / np.where(norm > 0, norm, np.inf)
        return np.stack([np.linalg.qr(A[:, i, :])[0] for i in range(P)], axis=1)


def _scan(bases: list, rs: list) -> np.ndarray:
    """(..., P) chi-square of every candidate, summed over axes: bases (J, P, g), rs (..., J) per axis."""
    total = 0.0
    for U, r in zip(bases, rs):
        J, P, g = U.shape
        total = total + np.sum(((r @ U.reshape(J, P * g)) ** 2).reshape(r.shape[:-1] + (P, g)), axis=-1)
    return total


def _null_max(bases: list, perps: list) -> np.ndarray:
    """Sorted Monte Carlo draws of the scan's maximum for white noise (this record's design), in
    slices of draws that keep at most _MC_FLOATS numbers per axis."""
    rng = np.random.default_rng(_MC_SEED)
    J, P, g = bases[0].shape
    per_slice = max(1, _MC_FLOATS // (J + P * g))
    out = []
    for n in slices(_MC_DRAWS, per_slice):
        rs = [perp(rng.standard_normal((U.shape[0], n))).T for U, perp in zip(bases, perps)]
        out.append(_scan(bases, rs).max(axis=-1))
    return np.sort(np.concatenate(out))


def strongest_shapes(an, spec: ModelSpec) -> list[OutsideShape]:
    """Per family, the shape outside the library that best explains `spec`'s gyro residual, with
    its scan p, most significant first (empty: the record is too short to scan)."""
    series, _, span = whitened_coarse(an, spec)
    J = min(c.t.size for c in series)
    step_s = coarse_grid(len(an.data.t), an.data.bin_s).step_s
    if J < 4 * EDGE + 4 or span < 16.0 * step_s:
        return []
    perps = [projector(c.X) for c in series]
    rs = [perp(c.y) for c, perp in zip(series, perps)]
    best = []
    for family in FAMILIES:
        fam = _Family(series, family, span, step_s)
        bases = [fam.basis(c, perp) for c, perp in zip(series, perps)]
        chi = _scan(bases, rs)
        i = int(np.argmax(chi))
        null = _null_max(bases, perps)
        exceed = null.size - int(np.searchsorted(null, chi[i], side='left'))
        p = min(1.0, len(FAMILIES) * (exceed + 1) / (null.size + 1))      # Bonferroni over the families
        best.append(OutsideShape(family, float(fam.where[i]), float(chi[i]), p, _sizes(series, perps, fam, i)))
    return sorted(best, key=lambda b: b.p)


def _sizes(series, perps, fam: _Family, i: int) -> list:
    """Per axis, the fitted step height or sine amplitude (deg/s)."""
    out = []
    for c, perp in zip(series, perps):
        beta = np.linalg.lstsq(perp(fam.columns(c)[:, i, :] * c.s[:, None]), perp(c.y), rcond=None)[0]
        out.append(math.degrees(float(np.hypot(*beta) if beta.size == 2 else beta[0])))
    return out


def adds_given_shape(an, spec: ModelSpec, without: ModelSpec, shape: OutsideShape, n_settings: int) -> dict:
    """Does `spec` still explain more than `without` once the shape is in both? On the 1 s bins (a
    regressor such as the other axes' rates shows only there), weighted by the bins' white-noise
    variance: the drop of the residual sum of squares over the axes, chi-square with the extra
    columns + settings as degrees of freedom. Also which explains `without`'s residual better: the
    shape (`shape_gain`) or what `spec` adds (`effect_gain`), each as its drop of that sum."""
    t = an.data.t
    if shape.family == 'step':
        C = (t >= shape.where_s).astype(float)[:, None]
    else:
        C = np.column_stack([np.sin(2.0 * np.pi * t / shape.where_s), np.cos(2.0 * np.pi * t / shape.where_s)])
    m = an.mask
    rss, cols = np.zeros((2, 2)), [0, 0]      # [model: spec, without][shape: in, out]
    for i, sp in enumerate((spec, without)):
        for a in range(3):
            y, X, _ = an.gyro_design(sp, a)
            sw = np.sqrt(an.gyro_w[m, a])
            for j, A in enumerate((np.column_stack([X[m], C[m]]), X[m])):
                A = A * sw[:, None]
                e = y[m] * sw - A @ np.linalg.lstsq(A, y[m] * sw, rcond=None)[0]
                rss[i, j] += float(e @ e)
            cols[i] += X.shape[1]
    lr = rss[1, 0] - rss[0, 0]
    dof = max(1, cols[0] - cols[1] + n_settings)
    p = float(stats.chi2.sf(lr, dof))
    return {'lr': round(lr, 2), 'dof': dof, 'p': float(f'{p:.3g}'), 'significant': p < ALPHA,
            'shape_gain': round(rss[1, 1] - rss[1, 0], 2), 'effect_gain': round(rss[1, 1] - rss[0, 1], 2)}


def remove_effect(spec: ModelSpec, before: ModelSpec, after: ModelSpec, name: str) -> ModelSpec:
    """`spec` without what one round (`before` -> `after`) added: its terms, settings and name."""
    added = [t for t in after.gyro_terms if t not in before.gyro_terms]
    changes = {f: getattr(before, f) for f in ('lag_tau_s', 'branch', 'time_offset_s')
               if getattr(after, f) != getattr(before, f)}
    return replace(spec.with_terms(remove=added, **changes), effects=tuple(e for e in spec.effects if e != name))


def audit(an, spec: ModelSpec, rounds: list) -> tuple[ModelSpec, dict | None, str | None]:
    """Withdraw the names of gyro regressors that stand in for a shape outside the library.

    rounds: (model before, chosen CandidateScore) of every round that named a gyro regressor, in
    order. Each named regressor is refitted with every significant shape (most significant first)
    and withdrawn at the first one it adds nothing to. Returns (the model without the withdrawn
    effects, the record for the report or None, a one-line reason or None)."""
    if not rounds or spec.rw_q:
        return spec, None, None
    record = {'shapes': {}, 'found': False, 'given_shape': {}, 'withdrawn': []}
    why = None
    for before, chosen in reversed(rounds):
        without = remove_effect(spec, before, chosen.spec, chosen.name)
        # scanned without D: a D that took a shape in whole leaves no trace of it in M's residual
        shapes = strongest_shapes(an, without)
        found = [sh for sh in shapes if sh.found]
        record['shapes'][chosen.name] = [sh.to_dict() for sh in shapes]
        record['found'] = record['found'] or bool(found)
        for shape in found:
            test = adds_given_shape(an, spec, without, shape, _settings_of(before, chosen.spec))
            record['given_shape'][f'{chosen.name} | {shape.family}'] = test
            # D adds nothing given C: withdrawn unless D fits M - D's residual better than C
            if not test['significant'] and test['shape_gain'] >= test['effect_gain']:
                spec = without
                record['withdrawn'].append(chosen.name)
                why = why or shape
                break
    if not any(record['shapes'].values()):      # every scan too short: nothing was asked
        return spec, None, None
    if why is None:
        return spec, record, None
    names = ', '.join(record['withdrawn'])
    return spec, record, f'{why.describe()}; {names} only stood in for it (adds nothing once it is in the model)'


def _settings_of(before: ModelSpec, after: ModelSpec) -> int:
    """Non-linear settings a round estimated (lag tau: 1; hysteresis tau and rate scale: 2; offset: 1)."""
    n = int(after.lag_tau_s != before.lag_tau_s) + int(after.time_offset_s != before.time_offset_s)
    return n + (2 if after.branch != before.branch else 0)
