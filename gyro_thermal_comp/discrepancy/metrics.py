"""How big the model-data gap is: noise-debiased residual RMS and the heading error it causes.

Each 1 s bin of an ADXRS623-class gyro carries ~0.04 deg/s of white noise, far above a thermal
model error of a few 1e-3 deg/s, so the raw RMS of a residual says little about the model. The
structured part is measured instead on W-second means, with the white-noise variance the bins
themselves report subtracted:  rms_W = sqrt(max(0, mean(m_j^2 - v_j))).  W is the averaging time
at which the "before" residual departs most significantly from white noise, and the same W is used
"after". All residuals here are held-out (each block predicted by a fit to the other blocks).
"""
from __future__ import annotations

import math

import numpy as np

WINDOWS_S = (1.0, 10.0, 60.0, 300.0)


def window_means(r: np.ndarray, var: np.ndarray, mask: np.ndarray, bin_s: float, window_s: float):
    """(means, white variance of each mean) of r (N, C) over windows; windows at least half full."""
    step = max(1, int(round(window_s / bin_s)))
    n = r.shape[0]
    idx = np.arange(n) // step
    nb = int(idx[-1]) + 1
    ms, vs = [], []
    for j in range(r.shape[1]):
        use = mask & np.isfinite(r[:, j])
        cnt = np.bincount(idx, weights=use.astype(float), minlength=nb)
        s = np.bincount(idx, weights=np.where(use, r[:, j], 0.0), minlength=nb)
        sv = np.bincount(idx, weights=np.where(use, var[:, j], 0.0), minlength=nb)
        ok = cnt >= max(1, 0.5 * step)
        ms.append(s[ok] / cnt[ok])
        vs.append(sv[ok] / cnt[ok] ** 2)
    return ms, vs


def debiased_rms(r, var, mask, bin_s, window_s) -> float:
    """Structured residual RMS over all components (same units as r)."""
    ms, vs = window_means(r, var, mask, bin_s, window_s)
    num = sum(float(np.sum(m * m - v)) for m, v in zip(ms, vs))
    den = sum(m.size for m in ms)
    return math.sqrt(max(0.0, num / den)) if den else float('nan')


def noise_floor(var, mask, bin_s, window_s) -> float:
    """One standard deviation of `debiased_rms` for pure white noise, as an RMS (same units as r):
    below this the structured residual cannot be told from noise on this record."""
    ms, vs = window_means(np.zeros_like(var), var, mask, bin_s, window_s)
    v = np.concatenate(vs)
    return math.sqrt(math.sqrt(2.0 / v.size) * float(np.mean(v))) if v.size else float('nan')


def excess_z(r, var, mask, bin_s, window_s) -> float:
    """How far the window means exceed white noise: (chi2 - dof)/sqrt(2 dof)."""
    ms, vs = window_means(r, var, mask, bin_s, window_s)
    chi2 = sum(float(np.sum(m * m / v)) for m, v in zip(ms, vs))
    dof = sum(m.size for m in ms)
    return (chi2 - dof) / math.sqrt(2.0 * dof) if dof else float('nan')


def pick_window(r, var, mask, bin_s, duration_s) -> float:
    cands = [w for w in WINDOWS_S if w >= bin_s and w <= duration_s / 10.0] or [bin_s]
    zs = [excess_z(r, var, mask, bin_s, w) for w in cands]
    return cands[int(np.nanargmax(zs))] if np.any(np.isfinite(zs)) else cands[0]


def heading_error(r_z: np.ndarray, mask: np.ndarray, t: np.ndarray, bin_s: float, ref_window_s: float = 60.0):
    """Heading error (rad) of dead reckoning with the model's drift removed: the running integral of
    the heading-axis rate residual, minus its mean over the first `ref_window_s` (design 5: the
    start offset is not the model's fault). Bins outside the mask contribute nothing."""
    step = np.where(mask & np.isfinite(r_z), r_z, 0.0) * bin_s
    e = np.cumsum(step)
    first = mask & (t <= t[np.argmax(mask)] + ref_window_s)
    return e - (e[first].mean() if np.any(first) else 0.0)


def rms(x: np.ndarray, mask: np.ndarray) -> float:
    v = x[mask & np.isfinite(x)]
    return float(np.sqrt(np.mean(v * v))) if v.size else float('nan')
