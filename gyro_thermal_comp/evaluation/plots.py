"""PNG figures of an EvaluationReport (matplotlib, Agg canvas; degrees on every axis).

Uses `matplotlib.figure.Figure` with the Agg canvas directly, so importing this module never
changes the global matplotlib backend of the host program.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .report import EvaluationReport
from .scoring import ORACLE, RAW


def _figure(rows: int = 1, height: float = 4.0):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10, height * rows), constrained_layout=True)
    FigureCanvasAgg(fig)
    axes = [fig.add_subplot(rows, 1, i + 1) for i in range(rows)]
    return fig, axes


def _time_axis(report: EvaluationReport):
    """(times in the chosen unit relative to the start, unit label, scale s->unit)."""
    r = report.result
    duration = r.t_end_s - r.t_start_s
    scale, unit = (1.0, 's') if duration <= 1200 else ((1 / 60, 'min') if duration <= 7200 else (1 / 3600, 'h'))
    return (r.series.centers_s() - r.t_start_s) * scale, unit, scale


def _shade_spans(ax, report: EvaluationReport, scale: float) -> None:
    r = report.result
    for i, span in enumerate(r.spans):
        ax.axvspan((span.t_start_s - r.t_start_s) * scale, (span.t_end_s - r.t_start_s) * scale,
                   color='tab:red', alpha=0.12, lw=0, label='magnetic outage' if i == 0 else None)


def _peak(values: np.ndarray) -> float:
    values = np.abs(values[np.isfinite(values)])
    return float(values.max()) if values.size else np.nan


def plot_heading_error(report: EvaluationReport, path) -> Path:
    """Heading error and excess over the oracle vs time (1-s means), outage spans shaded."""
    r = report.result
    t, unit, scale = _time_axis(report)
    fig, (ax_e, ax_x) = _figure(2, 3.5)
    # Scale to the first method (the package's estimator) and the oracle, three times over: a
    # method that ran off by tens of degrees would flatten every other curve. Such methods stay in
    # the plot, clipped, and the legend gives their maximum.
    for ax, series_deg in ((ax_e, lambda n: np.degrees(r.series.error(n))),
                           (ax_x, lambda n: np.degrees(r.series.excess(n)))):
        peak = {n: _peak(series_deg(n)) for n in report.method_names}
        ref = [peak[report.method_names[0]]] if report.method_names else []
        if ax is ax_e and r.has_bias_truth:
            ref.append(_peak(series_deg(ORACLE)))
        lim = 3.0 * max([1.0] + [v for v in ref if np.isfinite(v)])
        for name in report.method_names:
            label = _legend(report, name) + (f' (max {peak[name]:.0f} deg, off scale)' if peak[name] > lim else '')
            ax.plot(t, series_deg(name), lw=1, label=label, **_style(report, name))
        ax.set_ylim(-lim, lim)
    if r.has_bias_truth:
        ax_e.plot(t, np.degrees(r.series.error(ORACLE)), 'k--', lw=0.8, label=ORACLE)
    for ax in (ax_e, ax_x):
        _shade_spans(ax, report, scale)
        ax.grid(True, alpha=0.3)
        ax.set_xlabel(f'time [{unit}]')
    ax_e.set_ylabel('heading error [deg]')
    ax_x.set_ylabel('excess over oracle [deg]')
    ax_e.legend(loc='best', fontsize=8)
    ax_e.set_title('Heading error e(t) (mean of first %.0f s removed)' % r.reference_window_s)
    return _save(fig, path)


def _legend(report: EvaluationReport, name: str) -> str:
    """Offline references (not causal: they saw the whole record) say so in every legend."""
    return f'{name} (offline, not causal)' if name in report.non_causal else name


def _style(report: EvaluationReport, name: str) -> dict:
    return {'ls': ':'} if name in report.non_causal else {}


def plot_drift(report: EvaluationReport, path) -> Path:
    """Each method's drift estimate against the true z-gyro drift (1-s means, deg/s)."""
    r = report.result
    t, unit, scale = _time_axis(report)
    fig, (ax,) = _figure(1, 4.0)
    for name in report.method_names:
        d = r.series.drift(name)
        if np.isfinite(d).any():
            ax.plot(t, np.degrees(d), lw=1, label=_legend(report, name), **_style(report, name))
    if r.has_bias_truth:
        ax.plot(t, np.degrees(r.series.truth_drift()), 'k', lw=1.5, label='true drift')
    _shade_spans(ax, report, scale)
    ax.set_xlabel(f'time [{unit}]')
    ax.set_ylabel('z gyro drift [deg/s]')
    ax.grid(True, alpha=0.3)
    ax.legend(loc='best', fontsize=8)
    ax.set_title('Drift estimate vs truth')
    return _save(fig, path)


def plot_allan(report: EvaluationReport, path) -> Path:
    """Allan deviation of the rate error per method, log-log (paper Fig. 6 style)."""
    r = report.result
    fig, (ax,) = _figure(1, 4.5)
    for name in [RAW] + report.method_names + [ORACLE]:
        tau, adev = r.allan.get(name, (np.array([]), np.array([])))
        ok = np.isfinite(adev) & (adev > 0)
        if not ok.any():
            continue
        style = {'color': 'k', 'ls': '--'} if name == ORACLE else (
            {'color': 'tab:gray', 'lw': 2.5, 'alpha': 0.6} if name == RAW else {'lw': 1})
        ax.loglog(tau[ok], np.degrees(adev[ok]), marker='.', label=_legend(report, name), **style)
    ax.set_xlabel('tau [s]')
    ax.set_ylabel('Allan deviation of rate error [deg/s]')
    ax.grid(True, which='both', alpha=0.3)
    ax.legend(loc='best', fontsize=8)
    ax.set_title('Compensated rate error (1-s bins; tau >= 1 s)')
    return _save(fig, path)


def _save(fig, path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    return path


def save_plots(report: EvaluationReport, out_dir, prefix: str = '') -> list[Path]:
    """All figures as PNGs in `out_dir`; returns their paths."""
    out_dir = Path(out_dir)
    return [plot_heading_error(report, out_dir / f'{prefix}heading_error.png'),
            plot_drift(report, out_dir / f'{prefix}drift.png'),
            plot_allan(report, out_dir / f'{prefix}allan.png')]
