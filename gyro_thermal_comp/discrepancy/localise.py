"""Where does the model miss? The held-out residual split by time segment and by regime.

Regimes: heating / holding / cooling, low vs high |dT/dt|, temperature quartiles, turning vs
straight, rate magnitude, specific force (dynamic part), and for the compass, heading sectors.
Per group: bins, mean heading-axis residual (deg/s) with its z-score (mean over its white-noise
standard error: the sign says which way the model is off), the noise-debiased RMS over all axes
(deg/s) and the chi-square excess z-score (how far the group is from white noise, sign-free).
Thresholds are relative to the record (a fraction of its own heating rate or turn rate), so the
split adapts to an oven run and to a car alike.
"""
from __future__ import annotations

import math

import numpy as np

from .metrics import ChannelSeries
from .model import Analysis, ModelSpec

N_SEGMENTS = 12


def _group(r, var, sel) -> dict:
    n = int(sel.sum())
    if n == 0:
        return {'bins': 0}
    rz, vz = r[sel, -1], var[sel, -1]
    mean = float(np.mean(rz))
    se = math.sqrt(float(np.sum(vz))) / n
    chi = np.sum(r[sel] ** 2 / var[sel]) - r.shape[1] * n
    ms = float(np.mean(r[sel] ** 2 - var[sel]))
    return {'bins': n, 'mean_heading_axis_dps': math.degrees(mean), 'mean_z': mean / se if se > 0 else 0.0,
            'rms_debiased_dps': math.degrees(math.sqrt(max(ms, 0.0))),
            'excess_z': float(chi / math.sqrt(2.0 * r.shape[1] * n))}


def _regime(name, labels: dict, r, var, mask, variable: str, unit: str) -> dict:
    groups = {k: _group(r, var, mask & sel) for k, sel in labels.items()}
    used = [g for g in groups.values() if g['bins'] > 0]
    out = {'variable': variable, 'unit': unit, 'groups': groups}
    if len(used) >= 2:
        means = [(k, g) for k, g in groups.items() if g['bins'] > 0]
        hi = max(means, key=lambda kg: kg[1]['mean_heading_axis_dps'])
        lo = min(means, key=lambda kg: kg[1]['mean_heading_axis_dps'])
        se = math.hypot(hi[1]['mean_heading_axis_dps'] / hi[1]['mean_z'] if hi[1]['mean_z'] else 0.0,
                        lo[1]['mean_heading_axis_dps'] / lo[1]['mean_z'] if lo[1]['mean_z'] else 0.0)
        diff = hi[1]['mean_heading_axis_dps'] - lo[1]['mean_heading_axis_dps']
        out['contrast'] = {'high': hi[0], 'low': lo[0], 'difference_dps': diff,
                           'z': diff / se if se > 0 else 0.0}
        out['worst_group'] = max(means, key=lambda kg: kg[1]['excess_z'])[0]
    return out


def _split(values, mask, edges, names) -> dict:
    out = {}
    for i, nm in enumerate(names):
        lo, hi = edges[i], edges[i + 1]
        out[nm] = mask & (values >= lo) & ((values < hi) if i < len(names) - 1 else (values <= hi))
    return out


def localise(an: Analysis, spec: ModelSpec, series: dict[str, ChannelSeries] | None = None,
             after: bool = False) -> dict:
    """Residual by time segment and regime for `spec` (held-out residuals), as discovery.json's
    `localisation` entry. `series` may carry the residuals already computed by the workflow per
    channel (`after`: take its r_after, else r_before)."""
    d = an.data

    def residual(channel: str) -> np.ndarray:
        if series and channel in series:
            return series[channel].r_after if after else series[channel].r_before
        return an.residuals(spec, channel)
    r = residual('gyro')
    var, mask = an.gyro_var, an.mask & np.isfinite(r).all(axis=1)
    t = d.t
    out = {}
    # time segments
    idx = np.flatnonzero(mask)
    edges = np.linspace(t[idx[0]] - 0.5 * d.bin_s, t[idx[-1]] + 0.5 * d.bin_s, N_SEGMENTS + 1)
    segs = []
    for i in range(N_SEGMENTS):
        sel = mask & (t >= edges[i]) & (t < edges[i + 1])
        g = _group(r, var, sel)
        if g['bins']:
            g.update({'start_s': float(edges[i]), 'end_s': float(edges[i + 1]),
                      'temperature_c': float(np.mean(an.temp[sel]))})
            segs.append(g)
    out['segments'] = segs
    out['worst_segments'] = sorted(segs, key=lambda g: -g['excess_z'])[:3]
    regimes = {}
    # thermal regimes
    rate = an.temp_rate
    p95 = float(np.percentile(np.abs(rate[mask]), 95))
    if p95 > 0:
        thr = 0.1 * p95
        regimes['heating_cooling'] = _regime('heating_cooling', {
            'heating': rate > thr, 'holding': np.abs(rate) <= thr, 'cooling': rate < -thr},
            r, var, mask, 'dT/dt', 'degC/s')
        regimes['heating_cooling']['threshold_c_s'] = thr
        moving = np.abs(rate) > thr
        if np.sum(mask & moving) > 20:
            med = float(np.median(np.abs(rate[mask & moving])))
            regimes['temperature_rate'] = _regime('temperature_rate', {
                'low_rate': moving & (np.abs(rate) <= med), 'high_rate': moving & (np.abs(rate) > med)},
                r, var, mask, '|dT/dt|', 'degC/s')
            regimes['temperature_rate']['split_c_s'] = med
    temp = an.temp
    if np.ptp(temp[mask]) > 0:
        q = np.percentile(temp[mask], [0, 25, 50, 75, 100])
        regimes['temperature'] = _regime('temperature', _split(temp, mask, q, ['Q1', 'Q2', 'Q3', 'Q4']),
                                         r, var, mask, 'T', 'degC')
        regimes['temperature']['quartile_edges_c'] = q.tolist()
    # motion regimes
    if d.has_odom:
        w = an.reference_rate(0.0)
        wz = np.abs(w[:, 2])
        p99 = float(np.percentile(wz[mask], 99))
        if p99 > math.radians(1.0):
            thr = 0.1 * p99
            regimes['turning'] = _regime('turning', {'turning': wz > thr, 'straight': wz <= thr},
                                         r, var, mask, '|w_z|', 'rad/s')
            regimes['turning']['threshold_rad_s'] = thr
            mag = np.linalg.norm(w, axis=1)
            turn = mask & (wz > thr)
            if turn.sum() > 30:
                q = np.percentile(mag[turn], [0, 100 / 3, 200 / 3, 100])
                regimes['rate'] = _regime('rate', _split(mag, turn, q, ['low', 'mid', 'high']),
                                          r, var, turn, '|w|', 'rad/s')
        dyn = np.linalg.norm(d.accel - np.median(d.accel[mask], axis=0), axis=1)
        if np.percentile(dyn[mask], 99) > 0.05:
            q = np.percentile(dyn[mask], [0, 100 / 3, 200 / 3, 100])
            regimes['specific_force'] = _regime('specific_force', _split(dyn, mask, q, ['low', 'mid', 'high']),
                                                r, var, mask, '|f - median f|', 'm/s^2')
    out['regimes'] = regimes
    if an.compass_mask is not None:
        rc = residual('compass')
        vc = an.channel_var('compass')
        cm = an.compass_mask & np.isfinite(rc[:, 0])
        hd = np.degrees(np.nan_to_num(d.compass_heading)) % 360.0
        sectors = {f'{int(a)}-{int(a) + 45}deg': cm & (hd >= a) & (hd < a + 45) for a in range(0, 360, 45)}
        comp = {}
        for k, sel in sectors.items():
            n = int(sel.sum())
            if n:
                comp[k] = {'bins': n, 'mean_deg': math.degrees(float(np.mean(rc[sel, 0]))),
                           'rms_deg': math.degrees(float(np.sqrt(np.mean(rc[sel, 0] ** 2))))}
        out['compass_by_heading'] = comp
    return out
