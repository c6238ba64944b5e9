"""Is slow deterministic structure left that no candidate explains? A test that needs no shape.

A step, a slow sinusoid or a heating/cooling loop of a shape outside the library is answered
`no_missing_effect` when no candidate is significant, unless something asks the residual directly.
The block-mean whiteness test (stochastic.py) spreads its power over every block and scale; the
deterministic shapes that matter here are slow, so this test looks where they put their power:

* per gyro axis, the 30 s coarse means of the current model's target, whitened by the bins' own
  white-noise variance (wander.coarse_means), with the model's regressors (coarse means of its
  design) projected out - by linearity the coarse model is exact under the null;
* the cosines cos(pi k (t - t0) / span), k = 1 .. J/2 (J coarse bins: periods from twice the record
  down to 4 coarse bins), projected out of the regressors too and orthonormalised: under "white
  noise of the known variance", the residual's coordinates z[axis, k] are iid N(0, 1) exactly;
* statistics, summed over the three axes (a thermal effect shows on every axis, each with its own
  size and sign): the K lowest components, K = 1, 2, 4 .. 32 (chi2(3K): a step, a loop, a slow
  sinusoid), and the strongest window of 3 neighbouring components (chi2(9), Bonferroni over the
  windows: a spectral line of any frequency and phase);
* their smallest p is referred to its own distribution under the null, by Monte Carlo on iid
  normals (fixed seed: reproducible; it depends only on J): `p` is exact for the combination.

It assumes the bins' noise is white with the variance they report; on the first truth family's
null bags (static 2 h, with and without the temperature sensor's noise; vehicle 30 min) the false
alarms match `ALPHA` (docs/discrepancy.md, "Shape-free residual test").
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from scipy import stats

from .wander import coarse_design, coarse_grid, coarse_means

ALPHA = 0.01             # false alarms on null records (the level of every other test)
CUMULATIVE = (1, 2, 4, 8, 16, 32)   # K lowest components
WINDOW = 3               # neighbouring components of a spectral line (a sinusoid leaks into ~3)
MIN_COMPONENTS = 4       # fewer (a record under 4 min): no test
_MC_DRAWS, _MC_SEED = 20000, 20251125
_MC_FLOATS = 1 << 16     # normal draws held at once (0.5 MB)
_NULL_MIN_P: dict[int, np.ndarray] = {}   # components per axis -> sorted null draws of the smallest p


@dataclass(frozen=True)
class LowFrequency:
    """The test's outcome on one model's gyro residual."""
    p: float                  # family-wise p (Monte Carlo null of the smallest p); 1: not tested
    found: bool               # p < alpha
    statistic: str            # which statistic was smallest: 'lowest K' or 'window'
    components: list          # cosine indices it covers (k: period 2 span / k)
    period_s: tuple           # the periods those components span, s (longest, shortest)
    ratio: float              # its chi-square over its degrees of freedom (1: white noise)
    axis_share: list          # share of that chi-square per gyro axis x, y, z
    n_components: int         # cosines tested per axis

    @property
    def reason(self) -> str:
        """One line: what is left and how sure."""
        lo, hi = self.period_s
        if self.statistic == 'window':
            where = f'the band of periods {lo:.0f}..{hi:.0f} s holds'
        elif len(self.components) == 1:
            where = f'the slowest cosine (period {lo:.0f} s) holds'
        else:
            where = f'the {len(self.components)} slowest cosines (periods {lo:.0f}..{hi:.0f} s) hold'
        axis = 'xyz'[int(np.argmax(self.axis_share))]
        return (f'slow residual structure no candidate explains: {where} {self.ratio:.1f}x the white '
                f'noise power (gyro, most on axis {axis}), p = {self.p:.1g}')

    def to_dict(self) -> dict:
        return {'p_value': float(f'{self.p:.3g}'), 'structured': self.found, 'statistic': self.statistic,
                'components': self.components, 'period_s': [round(x, 1) for x in self.period_s],
                'chi2_ratio': round(self.ratio, 3), 'axis_share': [round(x, 3) for x in self.axis_share],
                'n_components': self.n_components, 'alpha': ALPHA}


def projector(X: np.ndarray):
    """A -> A with the columns of X (J, k) projected out (A: (J,) or (J, m))."""
    Q, _ = np.linalg.qr(X)
    return lambda A: A - Q @ (Q.T @ A)


def slices(total: int, per: int) -> list[int]:
    """Monte Carlo draws in slices of at most `per` (bounded memory), `total` in all."""
    return [per] * (total // per) + ([total % per] if total % per else [])


def components(t: np.ndarray, y: np.ndarray, X: np.ndarray, s: np.ndarray, t0: float, span_s: float,
               n: int) -> np.ndarray:
    """(n,) coordinates of the whitened series y (J,) (coarse means times s = 1/sigma) on the first n
    cosines of the record [t0, t0 + span_s], whitened alike, after the whitened regressors X (J, k)
    are projected out: iid N(0, 1) when y = X beta + unit white noise."""
    B = np.cos(np.pi * np.outer(t - t0, np.arange(1, n + 1)) / span_s) * s[:, None]
    perp = projector(X)
    Q2, _ = np.linalg.qr(perp(B))
    return Q2.T @ perp(y)


def _p_values(Z: np.ndarray) -> np.ndarray:
    """(..., statistics) p of each statistic for coordinates Z (..., axes, n)."""
    sq = np.sum(Z * Z, axis=-2)                                     # (..., n) summed over axes
    axes = Z.shape[-2]
    cum = np.cumsum(sq, axis=-1)
    ps = [stats.chi2.sf(cum[..., K - 1], axes * K) for K in CUMULATIVE if K <= sq.shape[-1]]
    win = np.lib.stride_tricks.sliding_window_view(sq, WINDOW, axis=-1).sum(-1)
    ps.append(np.minimum(1.0, win.shape[-1] * stats.chi2.sf(win.max(-1), axes * WINDOW)))
    return np.stack(ps, axis=-1)


def _null_min_p(n: int, axes: int = 3) -> np.ndarray:
    """Sorted smallest p over the statistics, for iid N(0, 1) coordinates (Monte Carlo, fixed seed)."""
    key = (n, axes)
    if key not in _NULL_MIN_P:
        rng = np.random.default_rng(_MC_SEED)
        block = max(1, min(_MC_DRAWS, _MC_FLOATS // (axes * n)))
        draws = [_p_values(rng.standard_normal((k, axes, n))).min(-1) for k in slices(_MC_DRAWS, block)]
        _NULL_MIN_P[key] = np.sort(np.concatenate(draws))
    return _NULL_MIN_P[key]


def family_p(Z: np.ndarray) -> tuple[float, int]:
    """(p of the smallest statistic p under the null, index of that statistic) for Z (axes, n)."""
    ps = _p_values(Z)
    i = int(np.argmin(ps))
    null = _null_min_p(Z.shape[1], Z.shape[0])
    return float((np.searchsorted(null, ps[i], side='right') + 1) / (null.size + 1)), i


class CoarseSeries(NamedTuple):
    """One gyro axis's coarse means, whitened (each coarse bin times s = 1/its white-noise sigma)."""
    t: np.ndarray      # (J,) coarse bin centres used, s
    y: np.ndarray      # (J,) whitened target (gyro - reference [- wander]), coarse means
    X: np.ndarray      # (J, k) whitened coarse means of the model's design
    s: np.ndarray      # (J,) 1 / white-noise sigma of each coarse mean


def whitened_coarse(an, spec) -> tuple[list[CoarseSeries], float, float]:
    """([per gyro axis CoarseSeries], record start t0, span), s. Coarse means (wander.COARSE_S) of
    the target and of the design with the same weights: y = X beta + white noise holds for them
    exactly when it holds for the bins."""
    d = an.data
    grid = coarse_grid(len(d.t), d.bin_s)
    series = []
    for a in range(3):
        y, X, _ = an.gyro_design(spec, a)
        var = an.gyro_var[:, a]
        m, v = coarse_means(y, var, an.mask, grid)
        Xc = coarse_design(X, var, an.mask, grid)
        ok = np.isfinite(m) & np.all(np.isfinite(Xc), axis=1)
        s = 1.0 / np.sqrt(v[ok])
        series.append(CoarseSeries(grid.centres[ok], m[ok] * s, Xc[ok] * s[:, None], s))
    t_all = np.concatenate([c.t for c in series])
    if not t_all.size:
        return series, 0.0, 0.0
    t0 = float(t_all.min()) - 0.5 * grid.step_s
    return series, t0, float(t_all.max()) + 0.5 * grid.step_s - t0


def low_frequency(an, spec, alpha: float = ALPHA) -> LowFrequency:
    """The test on `spec`'s gyro residual (all three axes; see the module doc)."""
    series, t0, span = whitened_coarse(an, spec)
    n = min(c.t.size for c in series) // 2
    if n < MIN_COMPONENTS:
        return LowFrequency(1.0, False, 'none', [], (math.nan, math.nan), math.nan, [0.0, 0.0, 0.0], 0)
    Z = np.array([components(c.t, c.y, c.X, c.s, t0, span, n) for c in series])
    p, i = family_p(Z)
    n_cum = sum(K <= n for K in CUMULATIVE)
    if i < n_cum:
        ks = list(range(1, CUMULATIVE[i] + 1))
        stat = 'lowest K'
    else:
        sq = np.sum(Z * Z, axis=0)
        win = np.convolve(sq, np.ones(WINDOW), mode='valid')
        j = int(np.argmax(win))
        ks = list(range(j + 1, j + WINDOW + 1))
        stat = 'window'
    per_axis = np.sum(Z[:, [k - 1 for k in ks]] ** 2, axis=1)
    chi2 = float(per_axis.sum())
    return LowFrequency(p, p < alpha, stat, ks, (2.0 * span / ks[0], 2.0 * span / ks[-1]), chi2 / (3 * len(ks)),
                        (per_axis / chi2).tolist() if chi2 > 0 else [0.0, 0.0, 0.0], n)

