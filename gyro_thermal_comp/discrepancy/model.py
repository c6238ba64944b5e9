"""The model under test: a `ModelSpec` (drift-model terms + the few non-linear settings some effects
need), its design matrices on the binned data, and blocked cross-validated least squares.

Two channels are fitted, each a linear model in named `Term`s (terms.py / thermal.drift_model):

* gyro (per sensor axis, own coefficients, shared settings): target = bin-mean gyro minus the
  reference rate (0 on a static unit: the Earth rate is then constant and lands in `constant`);
  weights 1/var from the bins' own white-noise estimate, so weighted squared errors are in
  chi-square units;
* compass (odom reference with a magnetometer): target = compass heading minus truth heading, rad.

Fitting uses per-block normal equations: the Gram matrix of each cross-validation block is formed
once, so training on "all blocks but k" and scoring block k costs a k x k solve, for every block
and every candidate variant.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from functools import partial
from typing import NamedTuple

import numpy as np

from .data import BinnedData
from .terms import TERMS, die_temperature, drift_model, smooth_temperature, thermal_branch
from .wander import cv_wander, settings as wander_settings

GYRO_BASE = ('constant', 'temperature', 'temperature_rate')   # the paper: D = a*T + b*dT/dt + c
COMPASS_BASE = ('compass_offset',)                             # declination + constant deviation
T_REF_C = 25.0
_DEAD = 0.01   # a column whose plausible contribution (prior_sigma x its spread) is below 1 % of one
               # bin's noise cannot be estimated from this record: it is left out on that axis
_FLAT = ('constant', 'compass_offset')
_REFS_KEPT = 4   # reference-rate arrays (bins x 3) kept for the time-offset candidates


@dataclass(frozen=True)
class ModelSpec:
    """Everything that defines a fitted model, hashable (used as a cache key)."""
    gyro_terms: tuple = GYRO_BASE
    compass_terms: tuple = COMPASS_BASE
    lag_tau_s: float = 0.0                     # thermal_lag: die = first-order lag of T, s
    branch: tuple | None = None                # thermal_hysteresis: (tau_s, rate_scale_degC_s)
    time_offset_s: float = 0.0                 # gyro stamps late by this much vs the reference, s
    rw_q: tuple | None = None                  # rate_random_walk / bias_instability: per-axis wander
                                               # intensity, (rad/s)^2/s; smoothed from neighbours
    rw_tau: tuple | None = None                # bias_instability: per-axis correlation time, s
                                               # (None: a random walk)
    rw_base: 'ModelSpec | None' = None         # the model whose residual the wander is taken from
                                               # (fixed while candidates are compared: one target)
    effects: tuple = ()                        # named effects, in the order found

    def with_terms(self, add=(), remove=(), **changes) -> 'ModelSpec':
        terms = tuple(t for t in self.gyro_terms if t not in remove) + tuple(t for t in add if t not in self.gyro_terms)
        return replace(self, gyro_terms=terms, **changes)

    def settings(self) -> dict:
        out = {}
        if self.lag_tau_s:
            out['thermal_lag_tau_s'] = self.lag_tau_s
        if self.branch:
            out['hysteresis_tau_s'], out['hysteresis_rate_scale_c_s'] = self.branch
        if self.time_offset_s:
            out['time_offset_s'] = self.time_offset_s
        if self.rw_q:
            out.update(wander_settings(self.rw_q, self.rw_tau))
        return out


def base_spec(data: BinnedData) -> ModelSpec:
    terms = GYRO_BASE + (('earth_rate_north',) if data.reference == 'odom' else ())
    return ModelSpec(gyro_terms=terms)


# ---------------------------------------------------------------------------------- block fitting
def _psolve(G: np.ndarray, g: np.ndarray) -> np.ndarray:
    """Least-squares solution of G b = g for a PSD Gram matrix (pseudo-inverse: collinear columns
    share the fit instead of blowing up)."""
    w, V = np.linalg.eigh(G)
    keep = w > max(w.max(), 1e-300) * 1e-11
    return V[:, keep] @ ((V[:, keep].T @ g) / w[keep])


class CrossValidation(NamedTuple):
    """Blocked cross-validation of one target/design pair (`BlockStats.cv`), chi-square units."""
    held_out: np.ndarray        # (K,) held-out weighted SSE per fold
    train_rss: np.ndarray       # (K,) training RSS per fold
    betas: np.ndarray           # (K, k) training coefficients per fold (scaled columns)
    held_out_batch: np.ndarray  # (nb,) held-out weighted SSE per batch


class BlockStats:
    """Weighted normal equations per batch (a short stretch of bins) for one target/design pair.

    Batches nest in the K contiguous cross-validation folds. Training on "all folds but k" sums the
    other folds' batch Grams; every batch of fold k is then scored with that fit, which gives the
    held-out squared error per batch (for the significance test) and per fold.

    Memory: the per-batch Grams (batches x k x k) are reduced to fold sums and per-batch held-out
    errors as soon as they are formed, and no (bins x k x k) array of outer products is ever made.
    An analysis keeps hundreds of these (one per candidate variant and axis), so what one keeps must
    not grow with the record: per fold k x k, per batch one number."""

    def __init__(self, X: np.ndarray, y: np.ndarray, w: np.ndarray, batch: np.ndarray,
                 batch_fold: np.ndarray, n_folds: int, prior_sigma: np.ndarray | None = None):
        self.scale = np.sqrt(np.sum(w[:, None] * X * X, axis=0) / np.sum(w))
        self.scale[self.scale == 0] = 1.0
        # Gaussian prior N(0, prior_sigma^2) on each coefficient (inf: flat), in chi-square units
        ps = np.full(X.shape[1], np.inf) if prior_sigma is None else np.asarray(prior_sigma, float)
        self.prior = np.diag(np.where(np.isfinite(ps), 1.0 / (ps * self.scale) ** 2, 0.0))
        Xs = X / self.scale
        self.y_mean = float(np.sum(w * y) / np.sum(w))   # every channel has an intercept
        yc = y - self.y_mean
        nb, k = batch_fold.size, X.shape[1]
        Xw = Xs * w[:, None]
        # per-batch Gram matrices, one column pair at a time (each product as the outer product
        # would give it, so the sums are the same to the bit)
        G = np.empty((nb, k, k))
        for i in range(k):
            for j in range(k):
                G[:, i, j] = np.bincount(batch, weights=Xw[:, i] * Xs[:, j], minlength=nb)
        g = np.stack([np.bincount(batch, weights=Xw[:, j] * yc, minlength=nb) for j in range(k)], axis=1)
        s = np.bincount(batch, weights=w * yc * yc, minlength=nb)
        n = np.bincount(batch, minlength=nb)
        self.batch_fold = batch_fold
        self.k, self.n_folds = k, n_folds
        self.n_total = int(n.sum())                                              # bins used
        self.n_fold = np.bincount(batch_fold, weights=n, minlength=n_folds)     # (K,) bins per fold
        self._G, self._g, self._s = G.sum(0), g.sum(0), float(s.sum())          # all-data sums
        self._full = None
        self._cv = self._cross_validate(G, g, s)

    def full(self):
        """(beta in original column units, weighted RSS) of the all-data fit (y centred)."""
        if self._full is None:
            G, g = self._G, self._g
            b = _psolve(G + self.prior, g)
            self._full = (b / self.scale, float(self._s - 2.0 * b @ g + b @ G @ b))
        return self._full

    def _cross_validate(self, G, g, s) -> 'CrossValidation':
        K = self.n_folds
        Gf = np.stack([G[self.batch_fold == f].sum(0) for f in range(K)])
        gf = np.stack([g[self.batch_fold == f].sum(0) for f in range(K)])
        sf = np.array([s[self.batch_fold == f].sum() for f in range(K)])
        Gt, gt, st = Gf.sum(0), gf.sum(0), sf.sum()
        train, betas = np.zeros(K), np.zeros((K, self.k))
        for f in range(K):
            Gk, gk = Gt - Gf[f], gt - gf[f]
            beta = _psolve(Gk + self.prior, gk)
            train[f] = st - sf[f] - 2.0 * beta @ gk + beta @ Gk @ beta
            betas[f] = beta
        bb = betas[self.batch_fold]                                  # (nb, k)
        held_b = s - 2.0 * np.einsum('bk,bk->b', bb, g) + np.einsum('bi,bij,bj->b', bb, G, bb)
        held = np.bincount(self.batch_fold, weights=held_b, minlength=K)
        return CrossValidation(held, train, betas, held_b)

    def cv(self) -> CrossValidation:
        """Held-out and training errors of the K-fold fits."""
        return self._cv

    def predict_cv(self, X: np.ndarray, fold: np.ndarray) -> np.ndarray:
        """Held-out prediction of every bin from its own fold's training fit, target units.
        (Centring y by the all-data mean is exact here: every design has an intercept column.)"""
        betas = self.cv().betas
        return np.einsum('nk,nk->n', X / self.scale, betas[fold]) + self.y_mean

    def predict_full(self, X: np.ndarray) -> np.ndarray:
        beta, _ = self.full()
        return X @ beta + self.y_mean


@dataclass(frozen=True, eq=False)
class Component:
    """One fitted component of a channel (a gyro axis, or the compass): its fit, and how to rebuild
    its target and design. These (bins x k) arrays are rebuilt on demand (`design()`), never kept:
    an analysis holds one Component per candidate variant and axis, and keeping them made its
    memory grow as bins x variants (2.2 GB for an 8 h record)."""
    w: np.ndarray            # (N,) weights, 1/white-noise variance (0 outside the mask) (shared)
    mask: np.ndarray         # (N,) bins used (shared)
    names: tuple             # (k,) term names of the columns of X
    stats: BlockStats        # the normal equations on the masked bins, reduced (see BlockStats)
    build: object            # () -> (y (N,) target on all bins, X (N, k) design on all bins)

    def design(self) -> tuple[np.ndarray, np.ndarray]:
        """(y, X) on all bins (rows outside `mask` are not used)."""
        return self.build()


class ChannelFit:
    """One channel (3 gyro axes, or the compass) of one spec: its components' fits."""

    def __init__(self, comps: list[Component]):
        self.comps = comps

    @property
    def n_params(self) -> int:
        return sum(len(c.names) for c in self.comps)

    def heldout_batches(self) -> np.ndarray:
        """(nb,) held-out weighted SSE per batch, summed over components."""
        return sum(c.stats.cv().held_out_batch for c in self.comps)

    def train_rss(self) -> np.ndarray:
        """(components, folds) training RSS."""
        return np.array([c.stats.cv().train_rss for c in self.comps])

    def train_n(self) -> np.ndarray:
        """(components, folds) number of training bins."""
        return np.array([c.stats.n_fold.sum() - c.stats.n_fold for c in self.comps])

    def full_rss(self) -> np.ndarray:
        return np.array([c.stats.full()[1] for c in self.comps])

    def n_obs(self) -> np.ndarray:
        return np.array([c.stats.n_total for c in self.comps])

    def bic(self) -> float:
        """Gaussian BIC with each component's own unknown scale: sum N ln(RSS/N) + p ln N."""
        n = self.n_obs()
        return float(np.sum(n * np.log(self.full_rss() / n)) + self.n_params * np.log(n.max()))

    def train_bic(self) -> np.ndarray:
        n = self.train_n()
        rss = self.train_rss()
        return np.sum(n * np.log(rss / n), axis=0) + self.n_params * np.log(n.max(axis=0))


# ---------------------------------------------------------------------------------- the analysis
class Analysis:
    """Binned data + derived inputs + cross-validation blocks; builds and caches channel fits."""

    def __init__(self, data: BinnedData, n_folds: int = 10, temp_window_s: float = 61.0,
                 batch_s: float = 60.0):
        self.data = data
        d = data
        mask = d.valid.copy()
        if d.has_odom:
            # keep clear of the truth's ends, so every time-shifted reference (|shift| <= 1 s) exists
            margin = 1.0 + 2.0 * d.imu_dt
            with np.errstate(invalid='ignore'):
                mask &= (d.t_first - margin >= d.theta_t[0]) & (d.t_last + margin <= d.theta_t[-1])
        if mask.sum() < 10 * n_folds:
            raise ValueError(f'too little data to analyse: {int(mask.sum())} usable {d.bin_s:g} s bins')
        self.mask = mask
        self.n_folds = n_folds
        self.batch, self.batch_fold = _batches(mask, n_folds, max(1, int(round(batch_s / d.bin_s))))
        self.fold = np.where(mask, self.batch_fold[np.maximum(self.batch, 0)], -1)
        self.temp, self.temp_rate = smooth_temperature(d.temp_c, d.bin_s, temp_window_s)
        self.gyro_var = d.gyro_bin_var()
        self.gyro_w = np.where(mask[:, None], 1.0 / self.gyro_var, 0.0)
        self.compass_mask = None
        self.compass_outliers = 0
        if d.has_compass and np.isfinite(d.compass_noise_var):
            cm = mask & (d.n_mag > 0) & np.isfinite(d.compass)
            if cm.sum() >= 10 * n_folds:
                w = np.where(cm, 1.0 / d.compass_bin_var(), 0.0)
                cm = _robust_compass_mask(d, cm, w)
                self.compass_mask = cm
                self.compass_w = np.where(cm, w, 0.0)
                self.compass_outliers = int(((d.n_mag > 0) & mask).sum() - cm.sum())
        self._wander: dict = {}
        self._fits: dict = {}
        self.wander_scores: dict = {}   # spec -> wander.score_wander's result, shared by candidates
        self._refs: dict = {}

    # -- inputs ---------------------------------------------------------------------------------
    def reference_rate(self, shift_s: float) -> np.ndarray:
        key = round(float(shift_s), 9)
        if key not in self._refs:
            ref = self.data.reference_rate(key)
            self._refs[key] = np.where(np.isfinite(ref), ref, 0.0)
            # the time-offset grid has ~70 shifts: keep only the unshifted and the latest few
            while len(self._refs) > _REFS_KEPT:
                del self._refs[next(k for k in self._refs if k != 0.0)]
        else:
            self._refs[key] = self._refs.pop(key)   # most recently used last
        return self._refs[key]

    def thermal_inputs(self, spec: ModelSpec) -> dict:
        temp, rate = self.temp, self.temp_rate
        if spec.lag_tau_s > 0:
            temp, rate = die_temperature(temp, self.data.bin_s, spec.lag_tau_s)
        out = {'temperature': temp, 'temperature_rate': rate}
        if spec.branch is not None:
            out['thermal_branch'] = thermal_branch(rate, self.data.bin_s, *spec.branch)
        return out

    def gyro_inputs(self, spec: ModelSpec, axis: int) -> dict:
        d = self.data
        ref = self.reference_rate(spec.time_offset_s)
        inputs = self.thermal_inputs(spec)
        o1, o2 = (axis + 1) % 3, (axis + 2) % 3
        inputs.update({
            'rate': ref[:, axis], 'rate_other_1': ref[:, o1], 'rate_other_2': ref[:, o2],
            'specific_force_x': d.accel[:, 0], 'specific_force_y': d.accel[:, 1], 'specific_force_z': d.accel[:, 2],
            'earth_north': (np.nan_to_num(d.earth_north[:, axis]) if d.earth_north is not None
                            else np.zeros(len(d.t))),
            'rate_derivative': np.gradient(ref[:, axis], d.bin_s),
        })
        return inputs

    def gyro_target(self, spec: ModelSpec, axis: int) -> np.ndarray:
        y = self.data.gyro[:, axis] - self.reference_rate(spec.time_offset_s)[:, axis]
        if spec.rw_q:
            y = y - self.wander(spec)[:, axis]
        return y

    def wander(self, spec: ModelSpec, per_batch: bool = False) -> np.ndarray:
        """(N, 3) wandering bias of the residual of `spec.rw_base` (the deterministic model in force
        when the wander was last updated), each fold smoothed from the other folds only
        (wander.cv_wander); subtracted from the gyro target when rw_q is set. Every candidate
        compared in one round shares it, so all are fitted to the same target."""
        det = spec.rw_base if spec.rw_base is not None else replace(spec, rw_q=None, rw_tau=None)
        key = (det, spec.rw_q, spec.rw_tau, per_batch)
        if key not in self._wander:
            self._wander[key] = cv_wander(self, det, spec.rw_q, spec.rw_tau, per_batch=per_batch)
        return self._wander[key]

    # -- designs --------------------------------------------------------------------------------
    def _alive(self, names, X, mask, noise) -> np.ndarray:
        spread = X[mask].std(axis=0)
        prior = np.array([TERMS[n].prior_sigma for n in names])
        keep = prior * spread >= _DEAD * noise
        for i, n in enumerate(names):
            if n in _FLAT:
                keep[i] = True
        return keep

    def gyro_design(self, spec: ModelSpec, axis: int):
        """(y, X, names) on all bins for one gyro axis (rows outside `mask` are not used)."""
        model = drift_model(spec.gyro_terms, T_REF_C)
        X = model.rows(self.gyro_inputs(spec, axis))
        noise = float(np.sqrt(np.median(self.gyro_var[self.mask, axis])))
        keep = self._alive(spec.gyro_terms, X, self.mask, noise)
        return self.gyro_target(spec, axis), X[:, keep], tuple(n for n, k in zip(spec.gyro_terms, keep) if k)

    def compass_design(self, spec: ModelSpec):
        d = self.data
        model = drift_model(spec.compass_terms, T_REF_C)
        X = model.rows({'heading': np.nan_to_num(d.compass_heading)})
        noise = float(np.sqrt(np.median(1.0 / self.compass_w[self.compass_mask])))
        keep = self._alive(spec.compass_terms, X, self.compass_mask, noise)
        return np.nan_to_num(d.compass), X[:, keep], tuple(n for n, k in zip(spec.compass_terms, keep) if k)

    def fit(self, spec: ModelSpec, channel: str) -> ChannelFit:
        key = (spec, channel)
        if key not in self._fits:
            comps = []
            if channel == 'gyro':
                for a in range(3):
                    y, X, names = self.gyro_design(spec, a)
                    comps.append(self._comp(y, X, self.gyro_w[:, a], self.mask, names,
                                            partial(self._gyro_yx, spec, a)))
            elif channel == 'compass':
                y, X, names = self.compass_design(spec)
                comps.append(self._comp(y, X, self.compass_w, self.compass_mask, names,
                                        partial(self._compass_yx, spec)))
            else:
                raise ValueError(channel)
            self._fits[key] = ChannelFit(comps)
        return self._fits[key]

    def _gyro_yx(self, spec: ModelSpec, axis: int):
        return self.gyro_design(spec, axis)[:2]

    def _compass_yx(self, spec: ModelSpec):
        return self.compass_design(spec)[:2]

    def _interleaved_yx(self, spec: ModelSpec, base: Component, axis: int):
        y, X = base.design()
        if spec.rw_q:   # the wander of each batch smoothed from the other batches only
            y = self.gyro_target(replace(spec, rw_q=None), axis) - self.wander(spec, per_batch=True)[:, axis]
        return y, X

    def _comp(self, y, X, w, mask, names, build, batch_fold=None) -> Component:
        # the intercept-like terms carry a flat prior (the target is centred); all others the
        # term's plausible magnitude, so a regressor cannot mimic another with an absurd coefficient
        prior = np.array([np.inf if n in _FLAT else TERMS[n].prior_sigma for n in names])
        stats = BlockStats(X[mask], y[mask], w[mask], self.batch[mask],
                           self.batch_fold if batch_fold is None else batch_fold, self.n_folds, prior)
        return Component(w=w, mask=mask, names=names, stats=stats, build=build)

    def residuals(self, spec: ModelSpec, channel: str, held_out: bool = True,
                  interleaved: bool = False) -> np.ndarray:
        """(N, components) residual (target - prediction), NaN outside the channel's mask.

        held_out: each bin predicted by a fit that did not see it: with the selection's contiguous
        folds, or (interleaved=True) with folds made of every K-th batch, so each held-out batch is
        interpolated rather than extrapolated in time and temperature (used for the before/after
        figures: they measure the model, not how far a block can be extrapolated); a random-walk
        bias is then interpolated from the neighbouring batches."""
        if interleaved:
            fit = self.fit_interleaved(spec, channel)
            fold = np.where(self.mask, self.interleaved_fold[np.maximum(self.batch, 0)], -1)
        else:
            fit = self.fit(spec, channel)
            fold = self.fold
        out = np.full((len(self.data.t), len(fit.comps)), np.nan)
        for j, c in enumerate(fit.comps):
            m = c.mask
            y, X = c.design()
            pred = c.stats.predict_cv(X[m], fold[m]) if held_out else c.stats.predict_full(X[m])
            out[m, j] = y[m] - pred
        return out

    @property
    def interleaved_fold(self) -> np.ndarray:
        return np.arange(self.batch_fold.size) % self.n_folds

    def fit_interleaved(self, spec: ModelSpec, channel: str) -> ChannelFit:
        """As `fit`, with folds made of every K-th batch (see `residuals`)."""
        key = ('interleaved', spec, channel)
        if key not in self._fits:
            base = self.fit(spec, channel)
            comps = []
            for a, c in enumerate(base.comps):
                build = partial(self._interleaved_yx, spec if channel == 'gyro' else replace(spec, rw_q=None), c, a)
                y, X = build()
                comps.append(self._comp(y, X, c.w, c.mask, c.names, build, self.interleaved_fold))
            self._fits[key] = ChannelFit(comps)
        return self._fits[key]

    def coefficients(self, spec: ModelSpec, channel: str) -> list[dict]:
        """All-data coefficients per component: {term name: value (SI)}."""
        fit = self.fit(spec, channel)
        out = []
        for c in fit.comps:
            beta, _ = c.stats.full()
            coef = dict(zip(c.names, beta.tolist()))
            for flat in _FLAT:   # the intercept carries the target's mean, taken out before fitting
                if flat in coef:
                    coef[flat] += c.stats.y_mean
            out.append(coef)
        return out

    def channels(self) -> list[str]:
        return ['gyro'] + (['compass'] if self.compass_mask is not None else [])

    def channel_mask(self, channel: str) -> np.ndarray:
        return self.mask if channel == 'gyro' else self.compass_mask

    def channel_var(self, channel: str) -> np.ndarray:
        """(N, components) white-noise variance of each bin's target."""
        if channel == 'gyro':
            return self.gyro_var
        return (1.0 / np.where(self.compass_w > 0, self.compass_w, np.nan))[:, None]


def _robust_compass_mask(d: BinnedData, mask: np.ndarray, w: np.ndarray, k: float = 6.0,
                         dilate_s: float = 10.0, windows_s=(1.0, 10.0, 30.0)) -> np.ndarray:
    """Leave out magnetic interference: stretches where the compass disagrees with the richest compass
    model (offset + 1st and 2nd heading harmonics, fitted robustly) by more than k robust sigma - a
    single bin, or the mean of a 10 s or 30 s window (a weak disturbance lasting a while is as
    coherent as a strong short one; each scale with its own robust spread, so a misfit of the model
    that runs through the whole record is not taken for interference) - and their neighbours within
    dilate_s (interference fades in and out). A disturbance that rotates the field without changing
    its norm is invisible to a norm/dip gate, but not to this."""
    h = np.nan_to_num(d.compass_heading)
    X = np.stack([np.ones_like(h), np.sin(h), np.cos(h), np.sin(2 * h), np.cos(2 * h)], axis=1)
    y = np.nan_to_num(d.compass)
    use = mask.copy()
    sw = np.sqrt(w)
    lengths = [max(1, int(round(win / d.bin_s))) for win in windows_s]
    grow = np.ones(2 * max(1, int(round(dilate_s / d.bin_s))) + 1)
    for _ in range(8):
        beta = np.linalg.lstsq(X[use] * sw[use, None], y[use] * sw[use], rcond=None)[0]
        z = np.where(mask, (y - X @ beta) * sw, 0.0)
        bad = np.zeros(mask.size, bool)
        for L in lengths:
            cnt = np.convolve(mask.astype(float), np.ones(L), mode='same')
            with np.errstate(invalid='ignore', divide='ignore'):
                zm = np.nan_to_num(np.convolve(z, np.ones(L), mode='same') / np.sqrt(cnt))   # window mean, sigmas
            centre = np.median(zm[use]) if use.any() else 0.0
            scale = max(1.4826 * np.median(np.abs(zm[use] - centre)) if use.any() else 1.0, 1.0)
            bad |= mask & (np.abs(zm - centre) > k * scale)
        new = mask & ~(np.convolve(bad.astype(float), grow, mode='same') > 0)
        if np.array_equal(new, use):
            break
        use = new
    return use


def _batches(mask: np.ndarray, n_folds: int, batch_len: int):
    """Batch id per bin (-1 outside the mask) and fold id per batch.

    The usable bins are cut in time order into batches of `batch_len` bins; consecutive batches form
    n_folds contiguous, (nearly) equal folds (blocked CV: a block's neighbours in time are mostly in
    the same block, so slowly correlated noise cannot leak from training into the held-out block)."""
    batch = np.full(mask.size, -1, dtype=int)
    idx = np.flatnonzero(mask)
    nb = max(n_folds, int(np.ceil(idx.size / batch_len)))
    batch[idx] = np.arange(idx.size) * nb // idx.size
    return batch, np.arange(nb) * n_folds // nb
