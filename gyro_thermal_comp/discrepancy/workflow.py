"""`discover()`: find where the drift model and a bag disagree, name the missing effect, add it,
re-fit, look again.

    result = discover('bags/static_ramp', reference='static', report_dir='out/discover')
    result.verdict, result.effects, result.candidates     # see DiscoveryResult.to_dict()

1. bin the bag (data.py): raw IMU, temperature, magnetometer, and the reference (a static unit, or
   /ground_truth/odom) - never the simulator's truth drift or config;
2. fit the current model (the paper's a*T + b*dT/dt + c to start with) and localise its held-out
   residual by time and regime (localise.py);
3. score every library candidate on held-out blocks and by BIC (selection.py, candidates.py);
4. name the most important significant one (or nothing), add it to the model, repeat (at most
   `max_effects` times) - two hidden effects come out one after the other, larger first;
5. measure the gap before/after on held-out data (metrics.py): noise-debiased residual RMS and the
   heading error; test what is left for whiteness (stochastic.py); write the report (report.py).

Verdict: `effect_found` when at least one effect is named; otherwise `unexplained_residual` when
a wander was refused its name because the residual lacks its signature (a spectral line, a step,
temperature-locked structure: `unexplained_reason` says which, signature.py) or the residual is
still significantly non-white (structure no candidate explains), else `no_missing_effect`.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..strict_json import json_safe
from ..thermal.drift_model import DriftModel
from .candidates import GYRO, LIBRARY, STOCHASTIC
from .choice import choose, unexplained_reason
from .data import BinnedData, load_bins
from .localise import localise
from .lowfreq import low_frequency
from .outside import audit
from .metrics import ChannelSeries, debiased_rms, heading_error, noise_floor, pick_window, rms
from .model import T_REF_C, Analysis, ModelSpec, base_spec
from .report import write_report
from .selection import CandidateScore, Criteria, score_all
from .stochastic import whiteness
from .terms import drift_model

VERDICTS = ('effect_found', 'no_missing_effect', 'unexplained_residual')


@dataclass
class Iteration:
    spec: ModelSpec
    scores: list[CandidateScore]
    chosen: CandidateScore | None
    checks: list[dict]


@dataclass
class DiscoveryResult:
    verdict: str
    effects: list[str]
    reference: str
    iterations: list[Iteration]
    spec_before: ModelSpec
    spec_after: ModelSpec
    channels: dict                     # per channel: before/after metrics
    whiteness_after: dict
    localisation: dict
    coefficients: dict
    data_summary: dict
    primary_channel: str = GYRO
    report_dir: Path | None = None
    files: list = field(default_factory=list)
    series: dict[str, ChannelSeries] = field(default_factory=dict, repr=False)   # per channel, for the figures
    unexplained_reason: str | None = None   # one line: structure found that no candidate explains
    snr_threshold: float = 5.0              # Criteria.snr_detect used for the detection limits

    @property
    def effect(self) -> str | None:
        return self.effects[0] if self.effects else None

    def drift_model(self) -> DriftModel:
        """The discovered gyro drift model as a `thermal.drift_model.DriftModel` (terms in order);
        the inputs it expects beyond T, dT/dt and rate are listed by `input_settings()`."""
        return drift_model(self.spec_after.gyro_terms, T_REF_C)

    def input_settings(self) -> dict:
        """Non-linear settings found: thermal_lag_tau_s (lag T by it before every thermal term: see
        terms.die_temperature), hysteresis_tau_s / hysteresis_rate_scale_c_s (terms.thermal_branch
        input), time_offset_s (gyro stamps late by it), rate_random_walk_dps_rts (bias random walk
        for the filter's process noise) or bias_instability_dps / bias_instability_tau_s
        (Gauss-Markov bias)."""
        return self.spec_after.settings()

    @property
    def candidates(self) -> dict:
        """First-round score of every library candidate (None: not testable on this record)."""
        return {s.name: (round(float(s.score), 6) if s.testable else None) for s in self.iterations[0].scores}

    @property
    def detection(self) -> dict:
        """Round-1 matched-filter SNR and detection limit of every testable deterministic candidate
        (detection.py): {name: {detection_snr, detection_limit, detection_unit, snr_threshold}}."""
        return {s.name: {**s.detection, 'snr_threshold': self.snr_threshold}
                for s in self.iterations[0].scores if s.detection.get('detection_snr') is not None}

    def to_dict(self) -> dict:
        prim = self.channels[self.primary_channel]
        return json_safe({
            'verdict': self.verdict,
            'unexplained_reason': self.unexplained_reason,
            'effect': self.effect,
            'effects': list(self.effects),
            'candidates': self.candidates,
            'detection': self.detection,
            'residual_rms_before': prim['residual_rms_before'],
            'residual_rms_after': prim['residual_rms_after'],
            'residual_rms_unit': prim['unit'],
            'residual_window_s': prim['window_s'],
            'residual_rms_noise_floor': prim['residual_rms_noise_floor'],
            'heading_error_rms_before': prim['heading_error_rms_before_deg'],
            'heading_error_rms_after': prim['heading_error_rms_after_deg'],
            'heading_error_unit': 'deg',
            'primary_channel': self.primary_channel,
            'reference': self.reference,
            'model_before': _spec_dict(self.spec_before),
            'model_after': _spec_dict(self.spec_after),
            'channels': self.channels,
            'iterations': [{'round': i + 1, 'model': _spec_dict(it.spec),
                            'chosen': it.chosen.name if it.chosen else None,
                            'encompassing_checks': it.checks,
                            'candidates': [s.to_dict() for s in it.scores]} for i, it in enumerate(self.iterations)],
            'remaining_structure': self.whiteness_after,
            'localisation': self.localisation,
            'coefficients_after': self.coefficients,
            'data': self.data_summary,
            'report_files': [str(p) for p in self.files],
        })

    def to_json(self, indent: int | None = 2) -> str:
        return json.dumps(self.to_dict(), indent=indent)


def _spec_dict(spec: ModelSpec) -> dict:
    return {'gyro_terms': list(spec.gyro_terms), 'compass_terms': list(spec.compass_terms),
            'settings': spec.settings(), 'effects': list(spec.effects)}


def discover(bag, reference: str = 'static', report_dir=None, *, bin_s: float = 1.0, max_effects: int = 3,
             n_folds: int = 10, criteria: Criteria | None = None, library=LIBRARY,
             data: BinnedData | None = None) -> DiscoveryResult:
    """Run the discrepancy workflow on a bag (folder or .mcap path) or an iterable of SensorChunks.

    reference: 'static' (the unit did not move: true rate = Earth rate, a constant) or 'odom'
    (/ground_truth/odom gives the true body rate and heading). report_dir: write figures, summary.md
    and discovery.json there. `data`: already binned data (skips reading `bag`)."""
    crit = criteria or Criteria()
    data = data if data is not None else load_bins(bag, reference, bin_s)
    an = Analysis(data, n_folds=n_folds)
    spec0 = base_spec(data)
    spec = spec0
    iterations: list[Iteration] = []
    for _ in range(max_effects + 1):
        scores = score_all(an, spec, crit, library)
        chosen, checks = choose(an, spec, scores, crit, library) if len(iterations) < max_effects else (None, [])
        iterations.append(Iteration(spec, scores, chosen, checks))
        if chosen is None:
            break
        spec = chosen.spec
        if spec.rw_q and chosen.channel != STOCHASTIC:
            # a regressor joined a model with a random-walk bias: take the wander from the new residual
            spec = replace(spec, rw_base=replace(spec, rw_q=None, rw_tau=None, rw_base=None))
    # a named gyro regressor may only stand in for a step or a sinusoid (outside.py)
    spec, shape_audit, shape_reason = audit(an, spec, [(it.spec, it.chosen) for it in iterations
                                                       if it.chosen is not None and it.chosen.channel == GYRO])
    effects = list(spec.effects)
    reason = shape_reason or next((r for r in (unexplained_reason(it.checks) for it in iterations) if r), None)

    channels, series = {}, {}
    for ch in an.channels():
        channels[ch], series[ch] = _channel_metrics(an, spec0, spec, ch)
    white = _whiteness(an, spec)
    white['outside_shape'] = shape_audit
    if reason is None and not effects and white['structured']:
        slow = white['gyro']['low_frequency']
        reason = slow['reason'] if slow['structured'] else _whiteness_reason(white)
    if effects:
        verdict = 'effect_found'
    elif white['structured'] or reason:
        verdict = 'unexplained_residual'
    else:
        verdict = 'no_missing_effect'
    first = next((s for s in iterations[0].scores if s.name == (effects[0] if effects else None)), None)
    primary = 'compass' if (first is not None and first.channel == 'compass') else GYRO
    loc = {'before': localise(an, spec0, series), 'after': localise(an, spec, series, after=True)}
    coefs = {ch: an.coefficients(spec, ch) for ch in an.channels()}
    result = DiscoveryResult(
        verdict=verdict, effects=effects, reference=data.reference, iterations=iterations, spec_before=spec0,
        spec_after=spec, channels=channels, whiteness_after=white, localisation=loc,
        coefficients=coefs, data_summary=_data_summary(an), primary_channel=primary, series=series,
        unexplained_reason=reason, snr_threshold=crit.snr_detect)
    if report_dir is not None:
        write_report(result, an, Path(report_dir))
    return result


def _channel_metrics(an: Analysis, before: ModelSpec, after: ModelSpec, ch: str) -> tuple[dict, ChannelSeries]:
    """(the channel's entry of discovery.json, in degrees; its per-bin series)."""
    d = an.data
    mask = an.channel_mask(ch)
    var = an.channel_var(ch)
    r0 = an.residuals(before, ch, interleaved=True)
    r1 = an.residuals(after, ch, interleaved=True)
    w = pick_window(r0, var, mask, d.bin_s, d.duration_s)

    def rms_deg(r, v):
        return math.degrees(debiased_rms(r, v, mask, d.bin_s, w))
    out = {'unit': 'deg/s' if ch == GYRO else 'deg', 'window_s': w,
           'residual_rms_before': rms_deg(r0, var),
           'residual_rms_after': rms_deg(r1, var),
           'residual_rms_noise_floor': math.degrees(noise_floor(var, mask, d.bin_s, w)),
           'residual_rms_per_component_before': [rms_deg(r0[:, [j]], var[:, [j]]) for j in range(r0.shape[1])],
           'residual_rms_per_component_after': [rms_deg(r1[:, [j]], var[:, [j]]) for j in range(r1.shape[1])],
           'white_noise_per_bin': math.degrees(float(np.sqrt(np.median(var[mask], axis=0)).mean()))}
    out['shrink_ratio'] = (out['residual_rms_after'] / out['residual_rms_before']
                           if out['residual_rms_before'] > 0 else float('nan'))
    if ch == GYRO:
        e0 = heading_error(r0[:, 2], mask, d.t, d.bin_s)
        e1 = heading_error(r1[:, 2], mask, d.t, d.bin_s)
        # what white noise alone would give: angle random walk of the heading-axis bins
        arw = math.sqrt(float(np.median(var[mask, 2])) * d.bin_s)
        out.update({'heading_error_rms_before_deg': math.degrees(rms(e0, mask)),
                    'heading_error_rms_after_deg': math.degrees(rms(e1, mask)),
                    'heading_error_max_before_deg': math.degrees(float(np.max(np.abs(e0[mask])))),
                    'heading_error_max_after_deg': math.degrees(float(np.max(np.abs(e1[mask])))),
                    'angle_random_walk_deg_per_rts': math.degrees(arw)})
        return out, ChannelSeries(r0, r1, var, mask, e_before=e0, e_after=e1)
    out.update({'heading_error_rms_before_deg': math.degrees(rms(r0[:, 0], mask)),
                'heading_error_rms_after_deg': math.degrees(rms(r1[:, 0], mask))})
    return out, ChannelSeries(r0, r1, var, mask)


def _whiteness(an: Analysis, spec: ModelSpec) -> dict:
    """Is anything left? Block-mean chi-square tests of the final in-sample residuals (conservative)
    and, on the gyro, the shape-free test for slow structure (lowfreq.py)."""
    out, structured = {}, False
    for ch in an.channels():
        r = an.residuals(spec, ch, held_out=False, interleaved=True)
        wt = whiteness(r, an.channel_var(ch), an.channel_mask(ch), an.data.bin_s)
        worst = max(wt.tests, key=lambda x: x['ratio'] if x['p'] < 0.5 else 0, default=None)
        flag = wt.p_min < 1e-3
        out[ch] = {'p_value': wt.p_min, 'structured': flag, 'worst': worst, 'tests': wt.tests}
        if ch == GYRO:
            slow = low_frequency(an, spec)
            out[ch]['low_frequency'] = {**slow.to_dict(), 'reason': slow.reason if slow.found else None}
            flag |= slow.found
        structured |= flag
    out['structured'] = structured
    return out


def _whiteness_reason(white: dict) -> str:
    """One line for a residual that fails the whiteness test while no wander was tested."""
    ch, w = min(((c, v) for c, v in white.items() if isinstance(v, dict)), key=lambda cv: cv[1]['p_value'])
    worst = w['worst'] or {}
    axis = ('xyz'[worst['component']] if ch == GYRO else 'compass') if worst else '?'
    return (f"non-white residual (no candidate shape): {worst.get('scale_s', float('nan')):g} s means "
            f"{worst.get('ratio', float('nan')):.1f}x white noise on {ch} {axis}, p = {w['p_value']:.1g}")


def _data_summary(an: Analysis) -> dict:
    d = an.data
    m = an.mask
    return {'bin_s': d.bin_s, 'bins_used': int(m.sum()), 'duration_s': d.duration_s,
            'imu_rate_hz': 1.0 / d.imu_dt if d.imu_dt > 0 else None,
            'temperature_range_c': [float(np.nanmin(an.temp[m])), float(np.nanmax(an.temp[m]))],
            'max_abs_temperature_rate_c_s': float(np.max(np.abs(an.temp_rate[m]))),
            'gyro_noise_dps_rthz': (np.degrees(np.sqrt(d.gyro_noise_var * d.imu_dt))).tolist(),
            'has_compass': an.compass_mask is not None, 'folds': an.n_folds, 'notes': list(d.notes)}
