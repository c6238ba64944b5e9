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
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

WINDOWS_S = (1.0, 10.0, 60.0, 300.0)


@dataclass(frozen=True, eq=False)
class ChannelSeries:
    """One channel's held-out residuals before and after, per bin: what the gap is measured on and
    the figures and localisation show. Residuals rad/s (gyro) or rad (compass)."""
    r_before: np.ndarray                   # (N, components) residual of the starting model
    r_after: np.ndarray                    # (N, components) residual with the named effects
    var: np.ndarray                        # (N, components) white-noise variance of each bin
    mask: np.ndarray                       # (N,) bins used
    e_before: np.ndarray | None = None     # (N,) gyro: heading error of dead reckoning, rad
    e_after: np.ndarray | None = None


class WindowSums(NamedTuple):
    """Sums of one residual component over consecutive windows of bins (`window_sums`)."""
    count: np.ndarray       # (windows,) bins used: in the mask, residual finite
    total: np.ndarray       # (windows,) sum of the residual over them
    var_total: np.ndarray   # (windows,) sum of their white-noise variances


def window_sums(r: np.ndarray, var: np.ndarray, mask: np.ndarray, step: int) -> list[WindowSums]:
    """Per component of r (N, C): sums over windows of `step` consecutive bins (window j holds bins
    j*step .. (j+1)*step - 1)."""
    idx = np.arange(r.shape[0]) // step
    nb = int(idx[-1]) + 1
    out = []
    for j in range(r.shape[1]):
        use = mask & np.isfinite(r[:, j])
        out.append(WindowSums(np.bincount(idx, weights=use.astype(float), minlength=nb),
                              np.bincount(idx, weights=np.where(use, r[:, j], 0.0), minlength=nb),
                              np.bincount(idx, weights=np.where(use, var[:, j], 0.0), minlength=nb)))
    return out


def window_means(r: np.ndarray, var: np.ndarray, mask: np.ndarray, bin_s: float, window_s: float):
    """(means, white variance of each mean) of r (N, C) over windows; windows at least half full."""
    step = max(1, int(round(window_s / bin_s)))
    ms, vs = [], []
    for ws in window_sums(r, var, mask, step):
        ok = ws.count >= max(1, 0.5 * step)
        ms.append(ws.total[ok] / ws.count[ok])
        vs.append(ws.var_total[ok] / ws.count[ok] ** 2)
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
    the heading-axis rate residual, minus its mean over the first `ref_window_s` (docs/design.md
    section 5: the start offset is not the model's fault). Bins outside the mask contribute nothing."""
    step = np.where(mask & np.isfinite(r_z), r_z, 0.0) * bin_s
    e = np.cumsum(step)
    first = mask & (t <= t[np.argmax(mask)] + ref_window_s)
    return e - (e[first].mean() if np.any(first) else 0.0)


def rms(x: np.ndarray, mask: np.ndarray) -> float:
    v = x[mask & np.isfinite(x)]
    return float(np.sqrt(np.mean(v * v))) if v.size else float('nan')
