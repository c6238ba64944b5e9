"""Run heading methods side by side over one stream and report them in one table
(docs/design.md section 5).

`evaluate(chunk_source, methods)` makes one pass over the chunks, feeding every chunk to every
method in turn and the outputs to a `HeadingScorer`. Methods with a `fit(chunks)` method (two-pass
offline references such as the whole-record MLR fit) get a fresh iterator first; a `fit` that raises
`NotApplicable` (the record does not have what the method needs), or a `not_applicable` attribute
holding a reason (a calibrated method given no calibration), leaves that method out of the scoring
pass and the report lists it as not applicable with the reason. A method with `causal = False` (it
has seen the record it is scored on) is scored but labelled an offline reference, and
`EvaluationReport.causal_names` leaves it out. Reports are in degrees.
"""
from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field
from typing import Callable, Iterable, Iterator, Sequence

import numpy as np

from ..learning_status import LearningStatus, learning_line
from ..samples import SensorChunk
from ..strict_json import json_safe
from ..thermal.baselines import NotApplicable
from ..thermal.estimator import ThermalDriftEstimator
from ..thermal.temperature_rate import TemperatureRateEstimator
from .information_floor import outage_floor_rad
from .scoring import ORACLE, HeadingScorer, RunningStats, ScoreResult, StatsSummary

ChunkSource = Callable[[], Iterator[SensorChunk]]


@dataclass
class EvaluationReport:
    """Scores of every method on one record, plus how long each method took."""
    result: ScoreResult
    update_time_s: dict[str, float] = field(default_factory=dict)  # wall time inside update()
    fit_time_s: dict[str, float] = field(default_factory=dict)
    imu_samples: int = 0
    outage_floor_rad: list[float] = field(default_factory=list)  # per span (information_floor.py)
    not_applicable: dict[str, str] = field(default_factory=dict)  # method -> why it could not run
    order: list[str] = field(default_factory=list)  # every method as given, scored or not
    non_causal: dict[str, str] = field(default_factory=dict)  # method -> why it is only an offline reference
    learning: dict[str, str] = field(default_factory=dict)  # learning method -> its updates, or why it made none

    @property
    def method_names(self) -> list[str]:
        """The scored methods (not the oracle, not the methods that were not applicable)."""
        return list(self.result.method_names)

    @property
    def causal_names(self) -> list[str]:
        """The scored methods that only use data up to each output's time: what a vehicle could
        run, and what a "best causal method" comparison takes (offline references left out)."""
        return [n for n in self.method_names if n not in self.non_causal]

    def _label(self, name: str) -> str:
        """Table label: offline references carry a `*` (footnote under the table)."""
        return (name[:20] + '*') if name in self.non_causal else name[:21]

    def _all_names(self) -> list[str]:
        """Every method in the order given to `evaluate`, not-applicable ones included."""
        names = [n for n in self.order if n in self.not_applicable or n in self.result.method_names]
        return names + [n for n in self.method_names + list(self.not_applicable) if n not in names]

    def samples_per_s(self, name: str) -> float:
        t = self.update_time_s.get(name, 0.0)
        return self.imu_samples / t if t > 0 else math.inf

    # -- table ------------------------------------------------------------------------------
    _COLUMNS = (  # header, width, row key
        ('method', 22, None),
        ('max|e| deg', 12, 'max_abs_deg'),
        ('mean deg', 11, 'mean_deg'),
        ('var deg^2', 11, 'var_deg2'),
        ('RMS deg', 10, 'rms_deg'),
        ('out max|e|', 12, 'outage_max_abs_deg'),
        ('out exc max', 13, 'outage_excess_max_abs_deg'),
        ('bias mean deg/s', 17, 'bias_error_mean_deg_s'),
        ('bias var (deg/s)^2', 20, 'bias_error_var_deg2_s2'),
    )

    def rows(self) -> dict[str, dict]:
        """Per method (then the oracle): the table numbers in degrees, plus extras for JSON."""
        out = {}
        for name in self.method_names + [ORACLE]:
            s = self.result.scores[name]
            e, eo = _in_degrees(s.error), _in_degrees(s.error_outage)
            x, xo = _in_degrees(s.excess), _in_degrees(s.excess_outage)
            b, bo = _in_degrees(s.bias_error), _in_degrees(s.bias_error_outage)
            out[name] = {
                'max_abs_deg': e.max_abs, 'mean_deg': e.mean, 'var_deg2': e.var,
                'rms_deg': e.rms,
                'outage_max_abs_deg': eo.max_abs, 'outage_mean_deg': eo.mean,
                'outage_var_deg2': eo.var, 'outage_rms_deg': eo.rms,
                'excess_max_abs_deg': x.max_abs, 'excess_rms_deg': x.rms,
                'outage_excess_max_abs_deg': xo.max_abs, 'outage_excess_rms_deg': xo.rms,
                'bias_error_mean_deg_s': b.mean, 'bias_error_var_deg2_s2': b.var,
                'bias_error_rms_deg_s': b.rms,
                'outage_bias_error_mean_deg_s': bo.mean, 'outage_bias_error_var_deg2_s2': bo.var,
                'reference_offset_deg': np.degrees(s.reference_offset_rad),
                'coasting_fraction_in_outage': s.coasting_fraction_in_outage,
                'coasting_fraction_outside': s.coasting_fraction_outside,
                'samples': s.error.n,
                'update_samples_per_s': (self.samples_per_s(name) if name in self.update_time_s
                                         else None),
            }
        return out

    def to_text(self) -> str:
        r = self.result
        rows = self.rows()
        lines = [f'heading error vs /ground_truth/odom: {r.t_end_s - r.t_start_s:.0f} s, '
                 f'{r.samples_scored} samples; e = wrap(psi - psi_true) minus its mean over the '
                 f'first {r.reference_window_s:.0f} s; excess = e - e_oracle']
        if not r.has_bias_truth:
            lines.append('no /ground_truth/gyro_bias: oracle, excess and bias error unavailable')
        if not r.has_outage_truth:
            lines.append('no magnetic-disturbance truth: no outage statistics')
        header = ''.join(h.rjust(w) if i else h.ljust(w) for i, (h, w, _) in enumerate(self._COLUMNS))
        lines += [header, '-' * len(header)]
        for name in self._all_names() + [ORACLE]:
            if name in self.not_applicable:
                lines.append(name[:21].ljust(22) + f'not applicable: {self.not_applicable[name]}')
                continue
            row = rows[name]
            cells = [self._label(name).ljust(22)]
            for _, width, key in self._COLUMNS[1:]:
                cells.append(_fmt(row[key], width, sci=key.startswith('bias')))
            lines.append(''.join(cells))
        for name, why in self.non_causal.items():
            if name in r.method_names:
                lines.append(f'* {name}: not causal, {why}; left out of causal comparisons')
        for name, line in self.learning.items():
            if line.startswith('not learning'):
                lines.append(f'{name}: {line}')
        if r.spans:
            lines += ['', 'outage spans (|mag disturbance| > 0), deg; growth = e(end) - e(start); frozen = the '
                      'excess growth had the drift estimate frozen at the span start; floor = 1-sigma excess '
                      'growth of the best unbiased paper-model prediction (information_floor.py); 2sig cov = '
                      'share of the span whose excess growth the published 2-sigma heading covers']
            head = (f'{"span":>4} {"start s":>9} {"dur s":>7}  {"method":<22}{"growth":>9}'
                    f'{"exc growth":>11}{"frozen":>9}{"max|e|":>9}{"max|exc|":>9}{"2sig cov":>9}{"floor":>8}')
            lines += [head, '-' * len(head)]
            for i, span in enumerate(r.spans):
                for j, n in enumerate(self.method_names + [ORACLE]):
                    sc = span.methods[n]
                    lead = (f'{i:>4} {span.t_start_s - r.t_start_s:>9.1f} {span.duration_s:>7.1f}  '
                            if j == 0 else ' ' * 24)
                    floor = self._floor_deg(i) if j == 0 else None
                    lines.append(lead + self._label(n).ljust(22) + _fmt(np.degrees(sc.growth), 9)
                                 + _fmt(np.degrees(sc.excess_growth), 11)
                                 + _fmt(np.degrees(sc.frozen_excess_growth), 9)
                                 + _fmt(np.degrees(sc.max_abs_error), 9)
                                 + _fmt(np.degrees(sc.max_abs_excess), 9)
                                 + _fmt(sc.sigma_coverage, 9) + ('' if j else _fmt(floor, 8)))
        if self.update_time_s:
            speed = ', '.join(f'{n} {self.samples_per_s(n):,.0f}' for n in self.method_names)
            lines += ['', f'speed, IMU samples/s: {speed}']
        return '\n'.join(lines)

    def __str__(self) -> str:
        return self.to_text()

    def _floor_deg(self, i: int) -> float | None:
        return np.degrees(self.outage_floor_rad[i]) if i < len(self.outage_floor_rad) else None

    # -- JSON -------------------------------------------------------------------------------
    def to_dict(self, *, include_series: bool = False) -> dict:
        r = self.result
        d = {
            'units': 'deg, deg/s, s; times relative to the first scored sample',
            't_start_s': r.t_start_s, 'duration_s': r.t_end_s - r.t_start_s,
            'samples_scored': r.samples_scored, 'samples_unscored': r.samples_unscored,
            'reference_window_s': r.reference_window_s,
            'has_bias_truth': r.has_bias_truth, 'has_outage_truth': r.has_outage_truth,
            'methods': self._json_methods(),
            'causal_methods': self.causal_names,
            'non_causal': {n: why for n, why in self.non_causal.items() if n in r.method_names},
            'spans': [{
                'start_s': s.t_start_s - r.t_start_s, 'duration_s': s.duration_s, 'closed': s.closed,
                'floor_deg': self._floor_deg(i),
                'methods': {n: {'growth_deg': np.degrees(sc.growth),
                                'excess_growth_deg': np.degrees(sc.excess_growth),
                                'frozen_excess_growth_deg': np.degrees(sc.frozen_excess_growth),
                                'sigma_coverage': sc.sigma_coverage,
                                'max_abs_error_deg': np.degrees(sc.max_abs_error),
                                'max_abs_excess_deg': np.degrees(sc.max_abs_excess)}
                            for n, sc in s.methods.items()}} for i, s in enumerate(r.spans)],
            'allan_rate_error': {n: {'tau_s': tau.tolist(), 'adev_deg_s': np.degrees(a).tolist()}
                                 for n, (tau, a) in r.allan.items()},
            'fit_time_s': self.fit_time_s, 'update_time_s': self.update_time_s,
            'learning': self.learning,
        }
        if include_series and r.series is not None:
            s = r.series
            series = {'t_s': (s.centers_s() - r.t_start_s).tolist(),
                      'truth_drift_deg_s': np.degrees(s.truth_drift()).tolist(),
                      'outage_fraction': s.outage_fraction().tolist(),
                      'e_deg:' + ORACLE: np.degrees(s.error(ORACLE)).tolist()}
            for n in self.method_names:   # user-facing JSON keys
                series['e_deg:' + n] = np.degrees(s.error(n)).tolist()
                series['excess_deg:' + n] = np.degrees(s.excess(n)).tolist()
                series['drift_deg_s:' + n] = np.degrees(s.drift(n)).tolist()
            d['series_1s'] = series
        return json_safe(d)

    def _json_methods(self) -> dict[str, dict]:
        """rows() in the order given, with {'status': 'not_applicable', 'reason': ...} for the methods
        that could not run on this record (docs/evaluation.md, "Methods that cannot run on a record");
        each scored method's row says whether it is `causal`."""
        rows = self.rows()
        out = {}
        for name in self._all_names():
            out[name] = ({'status': 'not_applicable', 'reason': self.not_applicable[name]}
                         if name in self.not_applicable else {**rows[name], 'causal': name not in self.non_causal})
        out[ORACLE] = rows[ORACLE]
        return out

    def to_json(self, *, include_series: bool = False, indent: int | None = 2) -> str:
        return json.dumps(self.to_dict(include_series=include_series), indent=indent)


def _in_degrees(stats: RunningStats) -> StatsSummary:
    """Summary of a statistic kept in rad (or rad/s): in deg (deg/s), variance in deg^2."""
    return stats.summary(scale=np.degrees(1.0))


def _fmt(value, width: int, sci: bool = False) -> str:
    if value is None or not np.isfinite(value):
        return '-'.rjust(width)
    if sci:
        return f'{value:.3e}'.rjust(width)
    return (f'{value:.3f}' if abs(value) < 1e4 else f'{value:.3e}').rjust(width)


def evaluate(chunk_source: ChunkSource, methods: Sequence, *, outage_truth: bool = True,
             reference_window_s: float = 60.0, bin_s: float = 1.0,
             outage_threshold_t: float = 0.0, earth_rate_enu_rad_s=None,
             arw_deg_sqrt_s: float = 0.04) -> EvaluationReport:
    """Run every method over one pass of `chunk_source()` and score them together.

    chunk_source: zero-argument callable returning a fresh iterator of time-ordered SensorChunks
        (called once more per method that has `fit(chunks)`, before the scoring pass).
    methods: HeadingMethod objects with unique `name`s. A method whose `fit` raises `NotApplicable`,
        or whose `not_applicable` attribute holds a reason, is not scored;
        `EvaluationReport.not_applicable` holds its reason. A method with `causal = False` is
        scored and listed in `EvaluationReport.non_causal` (reason: its `offline_reason`).
    outage_truth: use the `mag_disturbance` truth stream to find outage spans (spans where its norm
        exceeds `outage_threshold_t`, T); False: whole-record statistics only.
    reference_window_s: length of the start window whose mean error is removed (docs/design.md
        section 5: 60 s).
    bin_s: width of the bins kept for plots and the Allan deviation.
    earth_rate_enu_rad_s: Earth rotation in ENU (rad/s) if the gyro senses it but
        `/ground_truth/gyro_bias` does not include it (see scoring.py).
    arw_deg_sqrt_s: the gyro's angle random walk, for the outage information floor.
    """
    methods = list(methods)
    order = [m.name for m in methods]

    def make_scorer(names):
        return HeadingScorer(names, reference_window_s=reference_window_s, bin_s=bin_s,
                             outage_truth=outage_truth, outage_threshold_t=outage_threshold_t,
                             earth_rate_enu_rad_s=earth_rate_enu_rad_s)

    scorer = make_scorer(order)   # bad names or settings fail before the fit passes
    fit_time, not_applicable = {}, {}
    non_causal = {m.name: ' '.join(str(getattr(m, 'offline_reason', 'not causal')).split())
                  for m in methods if getattr(m, 'causal', True) is False}
    for m in methods:
        reason = getattr(m, 'not_applicable', None)
        if reason:   # e.g. a calibrated method given no calibration: nothing to run
            not_applicable[m.name] = ' '.join(str(reason).split())
            continue
        fit = getattr(m, 'fit', None)
        if callable(fit):
            t0 = time.perf_counter()
            chunks = chunk_source()
            try:
                fit(chunks)
            except NotApplicable as exc:   # this method cannot run on this record; the others can
                not_applicable[m.name] = ' '.join(str(exc).split()) or type(exc).__name__
                continue
            finally:
                close = getattr(chunks, 'close', None)
                if callable(close):   # a generator over a bag: release the file now
                    close()
            fit_time[m.name] = time.perf_counter() - t0
    if not_applicable:
        methods = [m for m in methods if m.name not in not_applicable]
        scorer = make_scorer([m.name for m in methods])
    update_time = {m.name: 0.0 for m in methods}
    # the methods that learn online: whether they did, and if not why (learning_status.py)
    learners = {m.name: LearningStatus(m.cfg.window_s) for m in methods
                if isinstance(m, ThermalDriftEstimator) and m.cfg.learn}
    n_imu = 0
    temperature = _TemperatureTrace()
    for chunk in chunk_source():
        temperature.add(chunk)
        tracks = {}
        for m in methods:
            t0 = time.perf_counter()
            if m.name in learners:
                out = m.process(chunk)
                tracks[m.name] = out.track
            else:
                tracks[m.name] = m.update(chunk)
            update_time[m.name] += time.perf_counter() - t0
            if m.name in learners:
                learners[m.name].add(out.track.t, out.reasons, out.valid, m.counters().get('filter_updates', 0),
                                     m.drift_window_s)
        n_imu += 0 if chunk.imu is None else chunk.imu.t.size
        scorer.add(chunk, tracks)
    result = scorer.finish()
    learning = {m.name: learning_line(learners[m.name], m.counters()) for m in methods if m.name in learners}
    return EvaluationReport(result, update_time, fit_time, n_imu,
                            temperature.outage_floor(result, math.radians(arw_deg_sqrt_s)),
                            not_applicable, order, non_causal, learning)


class _TemperatureTrace:
    """Temperature and dT/dt (the estimator's local regression), kept once per second: enough for
    the information floor, small for hours of data."""

    def __init__(self, every_s: float = 1.0):
        self.est = TemperatureRateEstimator(60.0)
        self.every_s = every_s
        self.rows: list[np.ndarray] = []
        self._next = -np.inf

    def add(self, chunk: SensorChunk) -> None:
        temp = chunk.temperature
        if temp is None or temp.t.size == 0:
            return
        e = self.est.update(temp.t, temp.temp_c)
        keep = np.zeros(e.t.size, dtype=bool)
        for k in range(e.t.size):  # at most a few per second of data
            if e.t[k] >= self._next:
                keep[k] = True
                self._next = e.t[k] + self.every_s
        if np.any(keep):
            self.rows.append(np.column_stack((e.t[keep], e.temp_c[keep], e.rate_c_s[keep])))

    def outage_floor(self, result: ScoreResult, arw_rad_sqrt_s: float) -> list[float]:
        if not result.spans or not self.rows:
            return []
        r = np.concatenate(self.rows)
        if r.shape[0] < 2:
            return []
        spans = [(s.t_start_s, s.t_start_s + s.duration_s) for s in result.spans]
        return outage_floor_rad(r[:, 0], r[:, 1], r[:, 2], spans, arw_rad_sqrt_s).tolist()


def chunks_from_list(chunks: Iterable[SensorChunk]) -> ChunkSource:
    """A chunk source over chunks already in memory (tests, small records)."""
    chunks = list(chunks)
    return lambda: iter(chunks)


__all__ = ['EvaluationReport', 'NotApplicable', 'evaluate', 'chunks_from_list']
