"""The discovery report: discovery.json, a one-page summary.md and PNG figures.

Figures use `matplotlib.figure.Figure` with the Agg canvas directly, so the global matplotlib
backend of the host program is never touched. Degrees and deg/s on every axis.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .candidates import BY_NAME
from .metrics import window_means
from .model import Analysis


def write_report(result, an: Analysis, out_dir: Path) -> list[Path]:
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    files = [plot_residual_time(result, an, out_dir / 'residual_vs_time.png'),
             plot_residual_regime(result, an, out_dir / 'residual_vs_regime.png'),
             plot_candidate_scores(result, out_dir / 'candidate_scores.png'),
             plot_heading_error(result, an, out_dir / 'heading_error.png')]
    files = [f for f in files if f is not None]
    result.files = files + [out_dir / 'summary.md', out_dir / 'discovery.json']
    (out_dir / 'summary.md').write_text(summary_markdown(result))
    (out_dir / 'discovery.json').write_text(result.to_json())
    result.report_dir = out_dir
    return result.files


# ---------------------------------------------------------------------------------- figures
def _figure(rows: int = 1, height: float = 3.6):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    fig = Figure(figsize=(10, height * rows), constrained_layout=True)
    FigureCanvasAgg(fig)
    return fig, [fig.add_subplot(rows, 1, i + 1) for i in range(rows)]


def _save(fig, path: Path) -> Path:
    fig.savefig(path, dpi=100)
    return path


def _time_scale(an: Analysis):
    return (1 / 60.0, 'min') if an.data.duration_s > 1200 else (1.0, 's')


def plot_residual_time(result, an: Analysis, path: Path) -> Path:
    """Held-out residual (window means) vs time, before and after, per channel with the +-2 sigma
    band white noise alone would give."""
    channels = [c for c in ('gyro', 'compass') if c in result.series]
    fig, axes = _figure(len(channels))
    scale, unit = _time_scale(an)
    for ax, ch in zip(axes, channels):
        ser = result.series[ch]
        w = max(result.channels[ch]['window_s'], 10.0)
        comp = 2 if ch == 'gyro' else 0
        r0, r1, var, mask = ser.r_before[:, [comp]], ser.r_after[:, [comp]], ser.var[:, [comp]], ser.mask
        t = _window_t(an, mask, w)
        for r, lab, col in ((r0, 'before', 'tab:gray'), (r1, 'after', 'tab:blue')):
            m, v = window_means(r, var, mask, an.data.bin_s, w)
            ax.plot(t[:m[0].size] * scale, np.degrees(m[0]), '.-', ms=3, lw=0.8, color=col, label=f'{lab} (held-out)')
        m, v = window_means(r0, var, mask, an.data.bin_s, w)
        band = np.degrees(2 * np.sqrt(np.median(v[0])))
        ax.axhspan(-band, band, color='tab:green', alpha=0.12, lw=0, label='white noise +-2 sigma')
        ax.set_xlabel(f'time ({unit})')
        ax.set_ylabel('heading-axis rate residual (deg/s)' if ch == 'gyro' else 'compass - truth heading (deg)')
        ax.set_title(f'{ch}: {w:g} s means of the held-out residual')
        ax.legend(loc='best', fontsize=8)
        ax.grid(alpha=0.3)
    return _save(fig, path)


def _window_t(an, mask, w):
    step = max(1, int(round(w / an.data.bin_s)))
    n = len(an.data.t)
    idx = np.arange(n) // step
    nb = int(idx[-1]) + 1
    cnt = np.bincount(idx, weights=mask.astype(float), minlength=nb)
    tt = np.bincount(idx, weights=np.where(mask, an.data.t, 0.0), minlength=nb)
    ok = cnt >= max(1, 0.5 * step)
    return tt[ok] / cnt[ok]


_REGIME = {
    'thermal_curvature': ('temperature', 'temperature T (degC)'),
    'thermal_hysteresis': ('temperature', 'temperature T (degC), heating vs cooling'),
    'thermal_lag': ('temperature_rate', 'dT/dt (degC/s)'),
    'g_sensitivity': ('force_x', 'specific force f_x (m/s^2)'),
    'scale_factor': ('rate', 'true rate w_z (deg/s)'),
    'scale_factor_thermal': ('rate_temperature', 'w_z x (T - 25 degC) (deg/s degC)'),
    'cross_axis': ('rate_cross', 'true rate w_z (deg/s), x-axis residual'),
    'time_offset': ('rate_derivative', 'dw_z/dt (deg/s^2)'),
    'compass_deviation': ('heading', 'true heading (deg)'),
    'rate_random_walk': ('time', 'time (s)'),
    'bias_instability': ('time', 'time (s)'),
}


def plot_residual_regime(result, an: Analysis, path: Path) -> Path:
    """Held-out residual against the variable the first named effect depends on, before/after."""
    key, label = _REGIME.get(result.effect or '', ('temperature', 'temperature T (degC)'))
    ch = 'compass' if key == 'heading' else 'gyro'
    if ch not in result.series:
        return None
    ser = result.series[ch]
    d = an.data
    comp = 0 if (ch == 'compass' or key == 'rate_cross') else 2
    w = an.reference_rate(0.0)
    x = {'temperature': an.temp, 'temperature_rate': an.temp_rate, 'force_x': d.accel[:, 0],
         'rate': np.degrees(w[:, 2]), 'rate_temperature': np.degrees(w[:, 2]) * (an.temp - 25.0),
         'rate_cross': np.degrees(w[:, 2]), 'rate_derivative': np.degrees(np.gradient(w[:, 2], d.bin_s)),
         'heading': np.degrees(np.nan_to_num(d.compass_heading)) if d.compass_heading is not None else None,
         'time': d.t}[key]
    mask = ser.mask & np.isfinite(x)
    fig, (ax,) = _figure(1, 4.2)
    groups = [('all', mask)]
    if result.effect == 'thermal_hysteresis':
        thr = 0.1 * np.percentile(np.abs(an.temp_rate[mask]), 95)
        groups = [('heating', mask & (an.temp_rate > thr)), ('cooling', mask & (an.temp_rate < -thr))]
    for when, residual, style in (('before', ser.r_before, dict(color='tab:gray')),
                                  ('after', ser.r_after, dict(color='tab:blue'))):
        r = residual[:, comp]
        for gname, gm in groups:
            xs, ys, es = _binned(x, r, ser.var[:, comp], gm, 24)
            ls = '-' if gname in ('all', 'heating') else '--'
            ax.errorbar(xs, np.degrees(ys), yerr=np.degrees(es), fmt='o' + ls, ms=3, lw=0.9, capsize=2,
                        label=f"{when}{'' if gname == 'all' else ' ' + gname}", **style)
    ax.axhline(0, color='k', lw=0.6)
    ax.set_xlabel(label)
    ax.set_ylabel('held-out residual (deg/s)' if ch == 'gyro' else 'held-out residual (deg)')
    ax.set_title(f"residual vs regime variable of {result.effect or 'the temperature (no effect named)'}")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    return _save(fig, path)


def _binned(x, r, var, mask, n):
    xs, ys, es = [], [], []
    v = x[mask]
    if v.size < n:
        return np.array(xs), np.array(ys), np.array(es)
    edges = np.unique(np.percentile(v, np.linspace(0, 100, n + 1)))
    for lo, hi in zip(edges[:-1], edges[1:]):
        sel = mask & (x >= lo) & (x <= hi) & np.isfinite(r)
        k = int(sel.sum())
        if k:
            xs.append(float(np.mean(x[sel])))
            ys.append(float(np.mean(r[sel])))
            es.append(math.sqrt(float(np.sum(var[sel]))) / k)
    return np.array(xs), np.array(ys), np.array(es)


def plot_candidate_scores(result, path: Path) -> Path:
    scores = result.iterations[0].scores
    fig, (ax,) = _figure(1, 0.35 * len(scores) + 1.2)
    names = [s.name for s in scores]
    vals = [s.score if s.testable else 0.0 for s in scores]
    cols = ['tab:green' if s.significant else ('tab:orange' if s.testable else 'lightgray') for s in scores]
    y = np.arange(len(names))
    ax.barh(y, vals, color=cols)
    for i, s in enumerate(scores):
        txt = (f'dchi2 {s.delta_chi2_cv:.0f}, t {s.t_batch:.1f}, dBIC {s.delta_bic:.0f}' if s.testable
               else f'not testable: {s.reason}')
        ax.text(0.01, i, txt, va='center', fontsize=7)
    ax.set_yticks(y, names)
    ax.invert_yaxis()
    ax.axvline(0, color='k', lw=0.6)
    ax.set_xlabel('score: fraction of the held-out model-data gap removed (round 1)')
    ax.set_title(f'candidates (green: significant) - verdict {result.verdict}'
                 + (f": {', '.join(result.effects)}" if result.effects else ''))
    ax.grid(alpha=0.3, axis='x')
    return _save(fig, path)


def plot_heading_error(result, an: Analysis, path: Path) -> Path:
    ser = result.series.get('gyro')
    if ser is None or ser.e_before is None:
        return None
    scale, unit = _time_scale(an)
    fig, (ax,) = _figure(1, 3.8)
    t, m = an.data.t, ser.mask
    ax.plot(t[m] * scale, np.degrees(ser.e_before[m]), color='tab:gray', lw=1, label='before (paper model)')
    ax.plot(t[m] * scale, np.degrees(ser.e_after[m]), color='tab:blue', lw=1, label='after (model + named effects)')
    arw = result.channels['gyro']['angle_random_walk_deg_per_rts']
    tt = t[m] - t[m][0]
    # the fitted constant absorbs the record's mean noise rate, so white noise alone gives a
    # Brownian bridge, not a free random walk
    env = arw * np.sqrt(tt * (tt[-1] - tt) / max(tt[-1], 1e-9))
    ax.fill_between(t[m] * scale, -env, env, color='tab:green', alpha=0.12, lw=0,
                    label='white noise alone, 1 sigma (angle random walk, ends pinned by the fit)')
    ax.set_xlabel(f'time ({unit})')
    ax.set_ylabel('heading error (deg)')
    ax.set_title('dead-reckoned heading error with the held-out drift prediction removed')
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    return _save(fig, path)


# ---------------------------------------------------------------------------------- markdown
def _f(x, fmt='{:.4g}'):
    return 'n/a' if x is None or (isinstance(x, float) and not math.isfinite(x)) else fmt.format(x)


def summary_markdown(result) -> str:
    d = result.to_dict()
    lines = ['# Model-discrepancy report', '']
    verdict = {'effect_found': 'missing effect found', 'no_missing_effect': 'no missing effect found',
               'unexplained_residual': 'unexplained residual: structure remains that no candidate explains'}
    named = f" - {', '.join(f'`{e}`' for e in result.effects)}" if result.effects else ''
    lines += [f'**Verdict: {verdict[result.verdict]}**{named}', '']
    if result.unexplained_reason:
        lines += [f'Unexplained: {result.unexplained_reason}.', '']
    dd = d['data']
    t_lo, t_hi = dd['temperature_range_c']
    lines.append(f"Reference `{result.reference}`; {dd['bins_used']} bins of {dd['bin_s']:g} s "
                 f"({dd['duration_s'] / 60:.0f} min), T {t_lo:.1f}..{t_hi:.1f} degC, "
                 f"gyro noise {np.mean(dd['gyro_noise_dps_rthz']):.3g} deg/s/sqrt(Hz).")
    lines += ['', '## What was found, in order', '']
    if result.effects:
        for i, it in enumerate(result.iterations):
            if it.chosen is None or it.chosen.name not in result.effects:   # withdrawn: outside.py
                continue
            c = it.chosen
            lines.append(f'{i + 1}. **{c.name}** - score {c.score:.2f} (share of the held-out gap removed), '
                         f'held-out dchi2 {c.delta_chi2_cv:.0f}, t {c.t_batch:.1f}, dBIC {c.delta_bic:.0f}; '
                         f"settings {c.settings or '-'}. {BY_NAME[c.name].doc()}")
        after = d['model_after']
        lines += ['', f"Model after: gyro terms {after['gyro_terms']}, compass terms {after['compass_terms']}, "
                      f"settings {after['settings'] or '-'}."]
    else:
        lines.append('No candidate improved the held-out fit significantly (t test on the held-out gains and '
                     'dBIC >= 10).')
    w = d['remaining_structure']
    p_text = f"p = {_f(w['gyro']['p_value'], '{:.2g}')} gyro"
    if 'compass' in w:
        p_text += f", {_f(w['compass']['p_value'], '{:.2g}')} compass"
    left = '**yes** - something no candidate explains is left' if w['structured'] else 'none detected'
    lines += ['', f'Remaining structure (block-mean chi-square test of the final residual): {left} ({p_text}).']
    lines += ['', '## The gap, before and after (held-out)', '',
              '| channel | residual RMS before | after | noise floor | window | heading error RMS before | after |',
              '|---|---|---|---|---|---|---|']
    for ch, m in d['channels'].items():
        u = m['unit']
        lines.append(f"| {ch} | {_f(m['residual_rms_before'])} {u} | {_f(m['residual_rms_after'])} {u} | "
                     f"{_f(m['residual_rms_noise_floor'])} {u} | {m['window_s']:g} s | "
                     f"{_f(m['heading_error_rms_before_deg'], '{:.2f}')} deg | "
                     f"{_f(m['heading_error_rms_after_deg'], '{:.2f}')} deg |")
    lines += ['', 'Residual RMS is the structured part: window means with the white noise the bins report '
                  'subtracted (0 = indistinguishable from noise).']
    lines += ['', '## Every candidate (round 1)', '',
              '| candidate | score | dchi2 held-out | t | dBIC | significant | matched-filter SNR | '
              f'size at SNR {result.snr_threshold:g} | note |', '|---|---|---|---|---|---|---|---|---|']
    for s in result.iterations[0].scores:
        det = s.detection or {}
        snr = _f(det.get('detection_snr'), '{:.1f}')
        limit = (f"{_f(det.get('detection_limit'), '{:.3g}')} {det.get('detection_unit') or ''}"
                 if det.get('detection_snr') is not None else '-')
        if s.testable:
            lines.append(f'| {s.name} | {s.score:.3f} | {s.delta_chi2_cv:.1f} | {s.t_batch:.2f} | {s.delta_bic:.1f} | '
                         f"{'yes' if s.significant else 'no'} | {snr if det.get('detection_snr') is not None else '-'} | "
                         f"{limit} | {s.note or ''} |")
        else:
            lines.append(f'| {s.name} | - | - | - | - | - | - | - | not testable: {s.reason} |')
    loc = d['localisation']['before']
    lines += ['', '## Where the starting model misses most', '']
    for g in loc.get('worst_segments', []):
        lines.append(f"- {g['start_s']:.0f}-{g['end_s']:.0f} s (T {g['temperature_c']:.1f} degC): mean heading-axis "
                     f"residual {g['mean_heading_axis_dps']:+.4f} deg/s (z {g['mean_z']:+.1f}), structured RMS "
                     f"{g['rms_debiased_dps']:.4f} deg/s, excess z {g['excess_z']:.1f}")
    contrasts = [(k, r) for k, r in loc.get('regimes', {}).items() if 'contrast' in r]
    contrasts.sort(key=lambda kr: -abs(kr[1]['contrast']['z']))
    for k, r in contrasts[:4]:
        c = r['contrast']
        lines.append(f"- {k}: '{c['high']}' vs '{c['low']}' differ by {c['difference_dps']:+.4f} deg/s "
                     f"(z {c['z']:.1f}); worst group '{r.get('worst_group')}'")
    if 'compass_by_heading' in loc:
        worst = max(loc['compass_by_heading'].items(), key=lambda kv: abs(kv[1]['mean_deg']), default=None)
        if worst:
            lines.append(f"- compass: largest mean error {worst[1]['mean_deg']:+.2f} deg at heading {worst[0]}")
    lines += ['', '## Figures', '']
    for f in result.files:
        if str(f).endswith('.png'):
            lines.append(f'![{Path(f).stem}]({Path(f).name})')
    lines += ['', 'Method: docs/discrepancy.md. Full numbers: discovery.json.']
    return '\n'.join(lines) + '\n'
