"""The one-page calibration report of a unit: drift against temperature with the fit, and the residual
(PNG), and what was fitted and how to use it (markdown)."""
from __future__ import annotations

import io
import math
from pathlib import Path

import numpy as np

from ..sources.timebase import format_utc
from .unit import UnitCalibration

SMOOTH_S = 600.0
_LABEL = {'measured': 'measured drift (heading-axis rate - reference), 1 s bins',
          'learned': 'drift the STKF learned (no independent reference), every 10 s'}


def residual_rms_deg_s(cal: UnitCalibration) -> float:
    r = np.asarray(cal.drift['residual_rad_s'], float)
    return math.degrees(float(np.sqrt(np.mean(r ** 2)))) if r.size else float('nan')


def _running_mean(t_s: np.ndarray, v: np.ndarray, window_s: float) -> np.ndarray | None:
    """Centred moving mean of samples at a regular step over `window_s` (None if it spans < 3 samples)."""
    if len(t_s) < 3:
        return None
    n = int(round(window_s / float(np.median(np.diff(t_s)))))
    if n < 3 or n > len(v):
        return None
    k = np.ones(n)
    return np.convolve(v, k, mode='same') / np.convolve(np.ones_like(v), k, mode='same')   # edges: what is there


def figure_png(cal: UnitCalibration) -> bytes:
    """Two panels: drift and fit against temperature; the residual against time."""
    import matplotlib
    matplotlib.use('Agg')
    from matplotlib.figure import Figure
    d = cal.drift
    temp = np.asarray(d['temperature_c'], float)
    drift, fit = np.degrees(np.asarray(d['drift_rad_s'], float)), np.degrees(np.asarray(d['fit_rad_s'], float))
    resid, t_h = np.degrees(np.asarray(d['residual_rad_s'], float)), np.asarray(d['t_s'], float) / 3600.0
    fig = Figure(figsize=(8.27, 8.0), dpi=100)
    ax1, ax2 = fig.subplots(2, 1)
    ax1.plot(temp, drift, '.', ms=1.5, alpha=0.35, color='0.4', label=_LABEL[d['kind']])
    order = np.argsort(temp, kind='stable')
    ax1.plot(temp[order], fit[order], '.', ms=1.0, color='C3', label='fit: ' + ', '.join(cal.state['terms']))
    ax1.set_xlabel('gyro temperature (degC)')
    ax1.set_ylabel('drift (deg/s)')
    ax1.set_title(f'unit {cal.unit}: heading-axis drift, {Path(d["log"]).name}')
    ax1.legend(loc='best', fontsize=7, markerscale=6)
    ax1.grid(alpha=0.3)
    ax2.plot(t_h, resid, '.', ms=1.5, color='C0', label='per sample')
    smooth = _running_mean(t_h * 3600.0, resid, SMOOTH_S)
    if smooth is not None:
        ax2.plot(t_h, smooth, color='C1', lw=1.2, label=f'{SMOOTH_S / 60:.0f} min mean (structure the fit leaves)')
        ax2.legend(loc='best', fontsize=7)
    ax2.axhline(0.0, color='0.3', lw=0.8)
    ax2.set_xlabel('time in the log (h)')
    ax2.set_ylabel('residual (deg/s)')
    ax2.set_title(f'residual: rms {residual_rms_deg_s(cal):.3g} deg/s')
    ax2.grid(alpha=0.3)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format='png', metadata={'Software': None})
    return buf.getvalue()


def markdown(cal: UnitCalibration, files: dict[str, str]) -> str:
    """The report's text; `files` names the written files (model, state, figure)."""
    lines = [f'# Gyro thermal calibration: unit {cal.unit}', '',
             '| log | format | reference | start (UTC) | duration | temperature |', '|---|---|---|---|---|---|']
    for log in cal.logs:
        lo, hi = log['temperature_c']
        lines.append(f"| {Path(log['path']).name} | {log['kind']} | {log['reference']} | {format_utc(log['start_ns'])} "
                     f"| {log['duration_s'] / 60:.1f} min | {lo:.1f} .. {hi:.1f} degC |")
    for log in cal.logs:
        if log.get('notes'):
            lines.append(f"\n{Path(log['path']).name}: " + '; '.join(log['notes']))
    lines += ['', '## Model and learned state', '', '| term | value | 1-sigma | unit |', '|---|---|---|---|']
    from ..thermal.drift_model import BUILTIN_TERMS
    for name, (value, sigma) in cal.coefficients().items():
        lines.append(f'| {name} | {value:.4g} | {sigma:.2g} | {BUILTIN_TERMS[name].unit} |')
    lag = cal.model.get('inputs', {}).get('thermal_lag_tau_s', 0.0)
    lines += ['', f"Reference temperature {cal.state['temperature_ref_c']:g} degC"
              + (f'; die temperature lag {lag:.0f} s' if lag else '') + '.',
              f"Residual rms {residual_rms_deg_s(cal):.3g} deg/s ({_LABEL[cal.drift['kind']]}).",
              "The constant's 1-sigma includes the bias's turn-on repeatability: each start of the unit "
              'measures it again over its still period; the temperature terms are kept as learned. The '
              "compass deviation map is the vehicle's: the node learns it there.", '']
    lines += [f'- {n}' for n in cal.notes]
    lines += ['', f"![drift against temperature]({files['figure']})", '', '## Use it', '',
              'Run `stkf_node` with these two parameters (a copy of the state file: the node keeps learning '
              'into it):', '', '```yaml', 'stkf_drift_estimator:', '  ros__parameters:',
              f"    drift_model_file: /path/to/{files['model']}", f"    state_file: /path/to/{files['state']}",
              '```', '']
    return '\n'.join(lines)
