"""The measured-data targets on a real recording: the CATS tag's temperature-calibration run.

    .venv/bin/python benchmarks/real_cats.py                 # periods 1 and 2 (development)
    .venv/bin/python benchmarks/real_cats.py --held-out      # period 3 only: the independent check

The recording (a marine-mammal IMU tag at rest in three orientations, 1 Hz, 74.5 h) ships in the
PyPI wheel scikit-diveMove 0.4.0 under AGPL-3.0: it is fetched here (`pip download --no-deps`), never
committed. `gyro-thermal-comp import` converts each rest period with the shipped column map
(config/import/cats.yaml: FRU declared, levelled so the vertical axis is +z). Everything below runs
the node's core with its default parameters (thermal/compensator.py, what `stkf_node` runs; the
published yaw variance as the node adds its floors):

1. Learning with the defaults: the gate's open share, filter updates in every hour the gate is open,
   and every shut with its reason and length.
2. Coasting: the compass removed over 1 h spans through the warm-up and 2 h through the temperature
   turn, chosen by one rule from the period's own temperature (`spans`), so a held-out period gets
   spans nobody chose for it. Per span, both at its end: the coast (change of the published heading;
   the truth is no change) and the frozen drift (the raw rate minus the drift published at the
   span start, integrated). Target: median |coast| / max(|frozen|, 5 deg) <= 0.7, no span worse
   than frozen by more than 10 deg. Beside it, what a causal least-squares reference reaches on the
   same spans (`reference_coasting`): whether the target is within reach of the data at all.
3. With the compass: max over hours of |hourly mean heading - first-hour mean| (spans and the hour
   after each left out) at most 2 deg above the same for the tilt-compensated compass; the
   published 2-sigma covers the error against the first-hour mean in >= 90 % of samples.
4. `discover --reference static` on each period: what it names; a simulated twin of the period
   (sim/twin.py) printed against the record before and after the named effects are added; the
   structure named on period 1 (never its coefficients: each period's vertical gyro is another
   sensor axis) run on the other period's spans against the default terms.
Writes its RESULTS.md section (a development run) or prints only (--held-out, --no-results, and a
trial with --set FIELD=JSON: an estimator setting changed).
"""
from __future__ import annotations

import argparse
import datetime
import json
import math
import subprocess
import sys
import time
import zipfile
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

import numpy as np

from gyro_thermal_comp.angles import wrap_angle
from gyro_thermal_comp.bag_io import read_chunks
from gyro_thermal_comp.nodes.orientation_uncertainty import OrientationVariance
from gyro_thermal_comp.nodes.parameters import all_specs, config_from_params
from gyro_thermal_comp.samples import MagSamples, slice_samples
from gyro_thermal_comp.sim import twin
from gyro_thermal_comp.stamps import ns_at
from gyro_thermal_comp.thermal.compass import compass_heading
from gyro_thermal_comp.thermal.compensator import ThermalCompensator
from gyro_thermal_comp.thermal.model_file import DriftModelFile, TermSetting
from gyro_thermal_comp.thermal.reasons import reasons_by_bit

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from bench_report import code_state, cpu_model, replace_section  # noqa: E402

WHEEL = 'scikit-diveMove==0.4.0'
MEMBER = 'skdiveMove/tests/data/cats_temperature_calib.nc'
COLUMN_MAP = HERE.parent / 'config' / 'import' / 'cats.yaml'
DEV_PERIODS, HELD_OUT = ('1', '2'), ('3',)
SECTION = '## Real recording: the CATS tag'
CHUNK_S = 600.0
TWIN_SEEDS = 5
RATIO_TARGET, WORSE_TOLERANCE_DEG, FROZEN_FLOOR_DEG = 0.7, 10.0, 5.0
HEADING_MARGIN_DEG, COVERAGE_TARGET = 2.0, 0.90


class FetchError(RuntimeError):
    pass


def fetch(cache: Path) -> Path:
    """The recording from the wheel on PyPI, once into `cache`."""
    nc = cache / Path(MEMBER).name
    if nc.exists():
        return nc
    cache.mkdir(parents=True, exist_ok=True)
    proc = subprocess.run([sys.executable, '-m', 'pip', 'download', WHEEL, '--no-deps', '--quiet', '-d', str(cache)],
                          capture_output=True, text=True)
    wheels = sorted(cache.glob('scikit_diveMove-0.4.0-*.whl'))
    if proc.returncode != 0 or not wheels:
        raise FetchError(f'pip download {WHEEL} failed: {(proc.stderr or proc.stdout).strip().splitlines()[-1:]}')
    with zipfile.ZipFile(wheels[0]) as z, open(nc, 'wb') as out:
        out.write(z.read(MEMBER))
    return nc


def convert(nc: Path, cache: Path, period: str) -> Path:
    """Period `period` as a levelled rosbag2 (gyro_thermal_comp.sources)."""
    from gyro_thermal_comp.sources.importer import import_recording
    out = cache / f'period_{period}'
    if not (out / 'metadata.yaml').exists():
        import_recording(nc, out, column_map=COLUMN_MAP, period=period, level=True, overwrite=True)
    return out


# ---------------------------------------------------------------------------------------- spans
def spans(t: np.ndarray, temp_c: np.ndarray) -> list[tuple[float, float, str]]:
    """Compass-removed spans by one rule on the period's temperature: 1 h spans every 2 h from where
    the warm-up (after the coldest point) has covered 20 % of its rise to where it has covered
    80 %, and 2 h centred on the warmest point after the cold if the record turns there (cools by
    0.2 degC or more within its last hours). Each starts after at least 2 h of record."""
    i_min = int(np.argmin(temp_c))
    after = slice(i_min, None)
    i_max = i_min + int(np.argmax(temp_c[after]))
    lo, hi = float(temp_c[i_min]), float(temp_c[i_max])
    out = []
    if hi - lo > 1.0:
        rise = temp_c[i_min:i_max + 1]
        t20 = float(t[i_min + int(np.argmax(rise >= lo + 0.2 * (hi - lo)))])
        t80 = float(t[i_min + int(np.argmax(rise >= lo + 0.8 * (hi - lo)))])
        start = max(t20, t[0] + 7200.0)
        while start + 3600.0 <= t80 + 3600.0 and start + 3600.0 <= t[-1]:
            out.append((start, start + 3600.0, 'warm-up'))
            start += 7200.0
    t_turn = float(t[i_max])
    if temp_c[i_max] - temp_c[-1] >= 0.2 and t_turn + 3600.0 <= t[-1]:
        a = max(t_turn - 3600.0, out[-1][1] + 3600.0 if out else t[0] + 7200.0)
        if a + 7200.0 <= t[-1]:
            out.append((a, a + 7200.0, 'temperature turn'))
    return out


# ---------------------------------------------------------------------------------------- runs
def node_config(model_file: DriftModelFile | None = None, settings: dict | None = None):
    """The node's default parameters and its estimator configuration, with `model_file` and any
    `settings` (EstimatorConfig fields: a trial, never a development run's figures)."""
    values = {s.name: s.default for s in all_specs()}
    cfg = config_from_params(values)
    if model_file is not None:
        cfg = replace(cfg, drift_model_file=model_file)
    for key, value in (settings or {}).items():   # a dotted key sets a field of a nested config (gate.x)
        value = tuple(value) if isinstance(value, list) else value
        outer, _, inner = key.rpartition('.')
        cfg = replace(cfg, **({outer: replace(getattr(cfg, outer), **{inner: value})} if outer else {key: value}))
    return values, cfg


def run_core(bag: Path, removed=(), model_file: DriftModelFile | None = None, settings: dict | None = None,
             prepare=None) -> dict:
    """The node's core over the bag with the compass removed over `removed` spans (s since the
    first stamp): per IMU sample the published heading, its yaw variance as published, the
    compensated and raw heading-axis rates, the gate and its reasons; filter updates per chunk.
    `prepare(estimator)`, if given, runs on the estimator before the first sample (an ablation)."""
    values, cfg = node_config(model_file, settings)
    comp = ThermalCompensator(cfg, values['output_delay_s'])
    if prepare is not None:
        prepare(comp.estimator)
    orient = OrientationVariance.from_params(values, cfg)
    cols = {k: [] for k in ('t', 'heading', 'yaw_var', 'wz', 'raw_t', 'raw_wz', 'open', 'reasons', 'temp',
                            'mag_t', 'compass')}
    updates, t0 = [], None

    def take(fo):
        if fo is None:
            return
        ok = fo.ok
        cols['t'].append((fo.ns[ok] - origin) * 1e-9)
        cols['heading'].append(fo.heading[ok])
        cols['yaw_var'].append(orient.yaw_variance(fo.heading_var[ok]))
        cols['wz'].append(fo.gyro_compensated[ok, 2])

    origin = 0
    for chunk in read_chunks(bag, CHUNK_S):
        if chunk.imu is None:
            continue
        if t0 is None:
            t0 = float(chunk.imu.t[0])
        mag = chunk.mag
        if mag is not None and removed:
            rel = mag.t - t0
            keep = np.ones(rel.size, bool)
            for a, b in removed:
                keep &= ~((rel >= a) & (rel < b))
            mag = slice_samples(mag, keep) if keep.any() else None
            chunk = chunk.with_streams(mag=mag)
        if chunk.mag is not None and chunk.mag.t.size:
            # the tilt-compensated compass, from the accelerometer at the nearest IMU sample
            k = np.clip(np.searchsorted(chunk.imu.t, chunk.mag.t), 0, chunk.imu.t.size - 1)
            cols['mag_t'].append(chunk.mag.t - t0)
            cols['compass'].append(np.atleast_1d(compass_heading(chunk.mag.field, chunk.imu.accel[k], 0.0).heading_rad))
        comp.add_many(ns_at(chunk.imu.t, origin), chunk.imu.gyro, chunk.imu.accel)
        out = comp.estimate(chunk, origin)
        take(comp.take_ready()[1])
        cols['raw_t'].append(chunk.imu.t - t0)
        cols['raw_wz'].append(chunk.imu.gyro[:, 2])
        cols['open'].append(out.gate_open)
        cols['reasons'].append(out.reasons)
        cols['temp'].append(out.temperature_c)
        updates.append((float(chunk.imu.t[-1] - t0), comp.estimator.counters().get('filter_updates', 0)))
    comp.finish()
    take(comp.take_ready()[1])
    r = {k: np.concatenate(v) if v else np.empty(0) for k, v in cols.items()}
    r['t'] = r['t'] - t0
    r['updates'] = np.array(updates)
    r['diagnostics'] = comp.estimator.diagnostics()
    return r


# ---------------------------------------------------------------------------------------- targets
def learning(r: dict) -> dict:
    """Target 1: open share, updates in every hour with the gate open, shuts by reason."""
    t, is_open, reasons = r['raw_t'], r['open'], r['reasons']
    hours = int(t[-1] // 3600.0) + 1
    upd = r['updates']
    per_hour = np.diff(np.concatenate(([0.0], np.interp(np.arange(1, hours + 1) * 3600.0, upd[:, 0], upd[:, 1]))))
    open_hours = [h for h in range(hours) if np.any(is_open[(t >= h * 3600.0) & (t < (h + 1) * 3600.0)])]
    dt = np.diff(t, append=t[-1])
    shut_s = {name: float(np.sum(dt[(reasons & bit) != 0])) for name, bit in reasons_by_bit()}
    return {'open_share': float(np.mean(is_open)), 'hours': hours, 'open_hours': len(open_hours),
            'open_hours_without_update': [h for h in open_hours if per_hour[h] < 1],
            'updates': int(upd[-1, 1]), 'shut_s_by_reason': {k: round(v, 1) for k, v in shut_s.items() if v > 0},
            'window_s': r['diagnostics']['window_s'], 'arw_deg_sqrt_s': r['diagnostics']['arw_deg_sqrt_s'],
            'gate_reference_slopes_per_c': r['diagnostics']['gate_reference']['slopes_per_c']}


def coasting(r: dict, removed) -> list[dict]:
    """Target 2, per span: the coast and the frozen drift at its end, deg."""
    t, heading = r['t'], np.unwrap(r['heading'])
    drift_pub = np.interp(t, r['raw_t'], r['raw_wz']) - r['wz']
    out = []
    for a, b, kind in removed:
        ia, ib = int(np.searchsorted(t, a)), int(np.searchsorted(t, b)) - 1
        coast = math.degrees(heading[ib] - heading[ia])
        m = (r['raw_t'] >= t[ia]) & (r['raw_t'] <= t[ib])
        raw_t, raw_w = r['raw_t'][m], r['raw_wz'][m]
        frozen = math.degrees(float(np.sum((raw_w[1:] - drift_pub[ia]) * np.diff(raw_t))))
        out.append({'span_h': [round(a / 3600, 2), round(b / 3600, 2)], 'kind': kind, 'coast_deg': round(coast, 2),
                    'frozen_deg': round(frozen, 2), 'ratio': round(abs(coast) / max(abs(frozen), FROZEN_FLOOR_DEG), 3),
                    'worse_by_deg': round(abs(coast) - abs(frozen), 2)})
    return out


REFERENCE_BLOCK_S, REFERENCE_ANCHOR_S = 600.0, 1800.0


def reference_coasting(r: dict, removed) -> dict:
    """Target 2's reach, judged by a causal least-squares reference on the same run's data: before
    each span, the drift measured per 10 min block (mean raw heading-axis rate minus the compass
    heading's slope; blocks without compass left out) is fitted over the whole past with the
    paper's terms (a T + b dT/dt + c) and with a T + c; through the span only the fit's change is
    predicted. Anchored twice: at the drift the node published at the span start (the target's own
    frozen), and at the drift measured over the 30 min before the span (frozen then against that
    anchor). Per fit and anchor: the ratios per span, their median and the worst excess, deg."""
    t, w, temp = r['raw_t'], r['raw_wz'], r['temp']
    mt, compass = r['mag_t'], np.unwrap(r['compass'])
    mag_rate_hz = mt.size / max(mt[-1] - mt[0], 1.0)

    def measured(a, b):
        m, k = (t >= a) & (t < b), (mt >= a) & (mt < b)
        if m.sum() < 0.5 * (b - a) or k.sum() < 0.5 * (b - a) * mag_rate_hz:
            return math.nan
        return float(np.mean(w[m]) - np.polyfit(mt[k], compass[k], 1)[0])

    edges = np.arange(t[0], t[-1], REFERENCE_BLOCK_S)
    blocks = np.array([(a + REFERENCE_BLOCK_S, measured(a, a + REFERENCE_BLOCK_S),
                        float(np.mean(temp[(t >= a) & (t < a + REFERENCE_BLOCK_S)]))) for a in edges[:-1]])
    drift_pub = np.interp(r['t'], t, w) - r['wz']
    fits, anchors = ('a T + b dT/dt + c', 'a T + c'), ('published', 'measured')
    rows = {(fit, anchor): [] for fit in fits for anchor in anchors}
    for a, b, _ in removed:
        past = blocks[(blocks[:, 0] <= a) & np.isfinite(blocks[:, 1])]
        rate = np.gradient(past[:, 2], past[:, 0])
        m = (t >= a) & (t <= b)
        ts, ws, T = t[m], w[m], temp[m]
        dt = np.diff(ts)
        span_rate = np.gradient(np.convolve(T, np.ones(301) / 301.0, 'same'), ts)
        t_start = np.mean(temp[(t >= a - 60.0) & (t < a)])
        frozen = {'published': drift_pub[int(np.searchsorted(r['t'], a))],
                  'measured': measured(a - REFERENCE_ANCHOR_S, a)}
        frozen = {k: math.degrees(float(np.sum((ws[1:] - anc) * dt))) for k, anc in frozen.items()}
        for fit in fits:
            cols = [np.ones(len(past)), past[:, 2]] + ([rate] if 'dT/dt' in fit else [])
            coef = np.linalg.lstsq(np.stack(cols, 1), past[:, 1], rcond=None)[0]
            change = coef[1] * (T - t_start)
            if 'dT/dt' in fit:
                change = change + coef[2] * (span_rate - rate[-1])
            predicted = math.degrees(float(np.sum(change[1:] * dt)))
            for anchor in anchors:
                coast = frozen[anchor] - predicted
                rows[fit, anchor].append((abs(coast) / max(abs(frozen[anchor]), FROZEN_FLOOR_DEG),
                                          abs(coast) - abs(frozen[anchor])))
    return {f'{fit}, {anchor} anchor': {'ratios': [round(x, 2) for x, _ in v],
                                       'worse_by_deg': [round(x, 1) for _, x in v]}
            for (fit, anchor), v in rows.items()}


def _error(angle: np.ndarray, t: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """The angle against its first-hour mean (the truth: no rotation), wrapped once, rad."""
    first = (t < 3600.0) & keep
    ref = float(np.angle(np.mean(np.exp(1j * angle[first]))))
    return wrap_angle(angle - ref)


def _hourly_deviation(t, angle, keep) -> float:
    """Max over hours (at least half their time kept) of |hourly mean - first-hour mean|, deg."""
    per_s = t.size / max(float(t[-1] - t[0]), 1.0)
    err = _error(angle, t, keep)
    devs = [abs(np.mean(err[m])) for h in range(int(t[-1] // 3600.0) + 1)
            if (m := (t >= h * 3600.0) & (t < (h + 1) * 3600.0) & keep).sum() > 0.5 * 3600.0 * per_s]
    return float(math.degrees(max(devs)))


def heading_hold(r: dict, removed) -> dict:
    """Target 3: the heading's hourly deviation from its first hour against the compass's, and the
    published 2-sigma's coverage of the error against the first-hour mean (the truth: no rotation)."""
    def outside(t):
        keep = np.ones(t.size, bool)
        for a, b, _ in removed:
            keep &= ~((t >= a) & (t < b + 3600.0))
        return keep
    t, h = r['t'], r['heading']
    keep = outside(t)
    err = np.degrees(_error(h, t, keep))
    cover = np.abs(err) <= 2.0 * np.degrees(np.sqrt(r['yaw_var']))
    mt, compass = r['mag_t'], r['compass']
    return {'heading_deviation_deg': round(_hourly_deviation(t, h, keep), 2),
            'compass_deviation_deg': round(_hourly_deviation(mt, compass, outside(mt)), 2),
            'coverage': round(float(np.mean(cover[keep])), 4), 'coverage_all_samples': round(float(np.mean(cover)), 4),
            'max_abs_error_deg': round(float(np.max(np.abs(err[keep]))), 2)}


def discovery(bag: Path) -> dict:
    from gyro_thermal_comp.discrepancy.model_export import model_file_from_discovery
    from gyro_thermal_comp.discrepancy.workflow import discover
    res = discover(bag, reference='static')
    model = model_file_from_discovery(res, str(bag))
    settings = res.spec_after.settings()
    return {'verdict': res.verdict, 'effects': list(res.effects), 'unexplained_reason': res.unexplained_reason,
            'settings': settings, 'model': model.to_dict()}


def structure_only(model: dict) -> DriftModelFile:
    """A discovered model's structure without its coefficients (another sensor axis learns its own):
    its terms, their random walks, its input settings."""
    d = json.loads(json.dumps(model))
    for term in d['terms']:
        term.pop('prior', None)
        term.pop('prior_sigma', None)
    d.pop('coverage', None)
    return DriftModelFile.from_dict(d)


def twin_check(bag: Path, disc: dict) -> dict:
    """The twin of the period against the record, with the paper's model and with the named effects."""
    rec = twin.Record.from_chunks(read_chunks(bag, 3600.0))
    cfg = twin.twin_config(rec)
    effects = twin.effects_from_discovery(disc['settings'], disc['effects'])
    named = cfg.with_effects(rec, **effects) if effects else cfg
    measured = twin.statistics(rec)

    def median_stats(c):
        runs = [twin.statistics(twin.simulate_twin(c, rec.t, rec.temp_c, seed)) for seed in range(TWIN_SEEDS)]
        return {k: float(np.median([s[k] for s in runs])) for k in runs[0]}
    before, after = median_stats(cfg), median_stats(named)
    return {'record': measured, 'twin': before, 'twin_named': after, 'effects': effects,
            'disagreement': twin.disagreement(measured, before), 'disagreement_named': twin.disagreement(measured, after)}


def period_run(nc: Path, cache: Path, period: str, model: dict | None, do_discover: bool,
               settings: dict | None = None) -> dict:
    t_start = time.time()
    bag = convert(nc, cache, period)
    full = run_core(bag, settings=settings)
    removed = spans(full['raw_t'], full['temp'])
    cut = run_core(bag, [(a, b) for a, b, _ in removed], settings=settings)
    out = {'period': period, 'bag': str(bag), 'spans': [[a, b, k] for a, b, k in removed],
           'learning': learning(full), 'coasting': coasting(cut, removed), 'heading': heading_hold(cut, removed),
           'reference_coasting': reference_coasting(cut, removed)}
    if model is not None:   # another period's discovered structure on this period's spans
        with_model = run_core(bag, [(a, b) for a, b, _ in removed], structure_only(model), settings)
        out['coasting_with_other_structure'] = coasting(with_model, removed)
    if do_discover:
        out['discovery'] = discovery(bag)
        out['twin'] = twin_check(bag, out['discovery'])
    out['elapsed_s'] = round(time.time() - t_start, 1)
    return out


# ---------------------------------------------------------------------------------------- report
def _median_ratio(rows):
    return float(np.median([r['ratio'] for r in rows])) if rows else math.nan


def report(results: list[dict], args) -> tuple[str, list[str]]:
    lines, failed = [], []
    for res in results:
        p, ln, hh = res['period'], res['learning'], res['heading']
        lines += [f"### Period {p}", '',
                  f"- Learning with the defaults: gate open {100 * ln['open_share']:.1f} % (target >= 50 %); "
                  f"{ln['updates']} filter updates; hours with the gate open {ln['open_hours']} of {ln['hours']}, "
                  f"of them without an update: {ln['open_hours_without_update'] or 'none'} (target: none); drift window "
                  f"{ln['window_s']:g} s, angle random walk in force {ln['arw_deg_sqrt_s']:.3f} deg/sqrt(s).",
                  f"- Shut, s by reason: {ln['shut_s_by_reason'] or 'never'}; the gate's references' temperature "
                  f"slopes (per degC): {ln['gate_reference_slopes_per_c']}.", '',
                  '| span (h) | kind | coast (deg) | frozen (deg) | \\|coast\\| / max(\\|frozen\\|, 5) |',
                  '|---|---|---|---|---|']
        lines += [f"| {r['span_h'][0]}-{r['span_h'][1]} | {r['kind']} | {r['coast_deg']} | {r['frozen_deg']} | {r['ratio']} |"
                  for r in res['coasting']]
        lines += ['', f"- Heading with the compass: max hourly deviation {hh['heading_deviation_deg']} deg against the "
                  f"compass's {hh['compass_deviation_deg']} deg (target <= compass + {HEADING_MARGIN_DEG:g}); published "
                  f"2-sigma covers {100 * hh['coverage']:.1f} % of the samples (target >= 90 %; "
                  f"{100 * hh['coverage_all_samples']:.1f} % with the spans); max |error| {hh['max_abs_error_deg']} deg."]
        if 'coasting_with_other_structure' in res:
            other = res['coasting_with_other_structure']
            lines.append(f"- The structure discovered on the other period, learned online here: median |coast| "
                         f"{np.median([abs(r['coast_deg']) for r in other]):.1f} deg against "
                         f"{np.median([abs(r['coast_deg']) for r in res['coasting']]):.1f} with the default terms "
                         f"(per span: {[r['coast_deg'] for r in other]}).")
        if 'discovery' in res:
            d, tw = res['discovery'], res['twin']
            lines.append(f"- `discover --reference static`: {d['verdict']}, named {d['effects'] or 'nothing'}"
                         + (f" ({d['unexplained_reason']})" if d['unexplained_reason'] else '')
                         + f"; model file terms {[t['name'] for t in d['model']['terms']]}.")
            lines += ['', '| twin statistic | record | twin (paper model) | twin + named |', '|---|---|---|---|']
            lines += [f"| {k} | {tw['record'][k]:.4g} | {tw['twin'][k]:.4g} | {tw['twin_named'][k]:.4g} |"
                      for k in tw['record']]
            lines += ['', f"- Twin against record, rms of log10 ratios: {tw['disagreement']['total']:.3f} with the "
                      f"paper's model, {tw['disagreement_named']['total']:.3f} with {tw['effects'] or 'nothing named'}."]
        lines.append('')
        if ln['open_share'] < 0.5:
            failed.append(f'period {p}: gate open {ln["open_share"]:.2f} < 0.5')
        if ln['open_hours_without_update']:
            failed.append(f'period {p}: open hours without an update {ln["open_hours_without_update"]}')
        if hh['heading_deviation_deg'] > hh['compass_deviation_deg'] + HEADING_MARGIN_DEG:
            failed.append(f"period {p}: heading deviation {hh['heading_deviation_deg']} > compass "
                          f"{hh['compass_deviation_deg']} + {HEADING_MARGIN_DEG:g}")
        if hh['coverage'] < COVERAGE_TARGET:
            failed.append(f"period {p}: coverage {hh['coverage']:.3f} < {COVERAGE_TARGET}")
    rows = [r for res in results for r in res['coasting']]
    median, worst = _median_ratio(rows), max((r['worse_by_deg'] for r in rows), default=math.nan)
    lines.append(f"**Coasting over all {len(rows)} spans:** median |coast| / max(|frozen|, 5 deg) {median:.2f} "
                 f"(target <= {RATIO_TARGET}); worst |coast| - |frozen| {worst:.1f} deg (tolerance "
                 f"{WORSE_TOLERANCE_DEG:g}).")
    refs = [res['reference_coasting'] for res in results if 'reference_coasting' in res]
    if refs:
        lines += ['', 'The causal least-squares reference on the same spans (`reference_coasting`: the whole past '
                  "fitted, only its change predicted), over both periods' spans:", '',
                  '| reference | ratios per span | median | worst \\|coast\\| - \\|frozen\\| (deg) |',
                  '|---|---|---|---|']
        for key in refs[0]:
            ratios = [x for ref in refs for x in ref[key]['ratios']]
            worse = [x for ref in refs for x in ref[key]['worse_by_deg']]
            lines.append(f'| {key} | {ratios} | {np.median(ratios):.2f} | {max(worse):.1f} |')
    if not median <= RATIO_TARGET:
        failed.append(f'coasting median ratio {median:.2f} > {RATIO_TARGET}')
    if not worst <= WORSE_TOLERANCE_DEG:
        failed.append(f'a span worse than frozen by {worst:.1f} deg > {WORSE_TOLERANCE_DEG:g}')
    for res in results:   # each named effect must bring the twin closer (none named: nothing to add)
        if 'twin' in res and res['twin']['effects'] and \
                not res['twin']['disagreement_named']['total'] < res['twin']['disagreement']['total']:
            failed.append(f"period {res['period']}: the twin's disagreement did not fall with the named effects")
    other = [res for res in results if 'coasting_with_other_structure' in res]
    for res in other:
        a = np.median([abs(r['coast_deg']) for r in res['coasting_with_other_structure']])
        b = np.median([abs(r['coast_deg']) for r in res['coasting']])
        if not a < b:
            failed.append(f"period {res['period']}: the other period's structure did not lower the median coast")
    return '\n'.join(lines) + '\n', failed


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    p.add_argument('--held-out', action='store_true', help='run period 3 only (the independent check)')
    p.add_argument('--cache', type=Path, default=Path.home() / '.cache' / 'gyro_thermal_comp' / 'cats',
                   help='where the wheel, the recording and its bags are kept (default: %(default)s)')
    p.add_argument('--jobs', type=int, default=2, help='periods run in this many processes')
    p.add_argument('--no-discover', action='store_true', help='leave target 4 out (discover takes minutes a period)')
    p.add_argument('--no-results', action='store_true', help='print only; do not write RESULTS.md')
    p.add_argument('--set', action='append', default=[], metavar='FIELD=JSON',
                   help='an estimator setting for a trial (e.g. fading_s=1.0); prints only')
    args = p.parse_args(argv)
    try:
        settings = {k: json.loads(v) for k, v in (item.split('=', 1) for item in args.set)}
        node_config(settings=settings)
    except (ValueError, TypeError) as exc:
        print(f'real_cats: --set takes FIELD=JSON with an estimator setting: {exc}', file=sys.stderr)
        return 2
    try:
        nc = fetch(args.cache)
    except (FetchError, OSError, zipfile.BadZipFile, KeyError) as exc:
        print(f'real_cats: cannot fetch the recording: {exc}', file=sys.stderr)
        return 2
    periods = HELD_OUT if args.held_out else DEV_PERIODS
    started = time.time()
    date = datetime.datetime.now().isoformat(timespec='minutes')
    do_discover = not args.no_discover
    # the structure named on period 1 runs on the held-out period's spans: discover period 1 first
    model_1 = discovery(convert(nc, args.cache, '1'))['model'] if do_discover and args.held_out else None
    with ProcessPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        futures = [pool.submit(period_run, nc, args.cache, per, model_1, do_discover, settings) for per in periods]
        results = [f.result() for f in futures]
    if not args.held_out and do_discover:   # period 1's structure on period 2's spans
        res_1 = next(r for r in results if r['period'] == '1')
        res_2 = next(r for r in results if r['period'] == '2')
        bag_2 = Path(res_2['bag'])
        removed = [tuple(s) for s in res_2['spans']]
        with_model = run_core(bag_2, [(a, b) for a, b, _ in removed], structure_only(res_1['discovery']['model']),
                              settings)
        res_2['coasting_with_other_structure'] = coasting(with_model, removed)
    text, failed = report(results, args)
    command = 'python benchmarks/real_cats.py' + (' --held-out' if args.held_out else '') + \
        (' --no-discover' if args.no_discover else '') + ''.join(f' --set {item}' for item in args.set)
    header = (f"{SECTION}{' (held-out period 3)' if args.held_out else ' (development periods 1 and 2)'}\n\n"
              f"`{command}` ({date}, {cpu_model()}, {(time.time() - started) / 60:.0f} min, commit "
              f"{code_state()['git_head']}; the recording is fetched, never committed). Every figure below is "
              f"the node's core with its default parameters{' and the settings set' if settings else ''}.\n\n")
    section = header + text + ('\n**Targets missed:** ' + '; '.join(failed) + '\n' if failed else '\n**All targets met.**\n')
    print(section)
    if settings:   # a trial: printed, never the recorded figures
        return 1 if failed else 0
    (HERE / 'results').mkdir(exist_ok=True)
    (HERE / 'results' / ('real_cats_held_out.json' if args.held_out else 'real_cats.json')).write_text(
        json.dumps(results, indent=1, default=float))
    if not args.no_results and not args.held_out:
        replace_section(SECTION, section)
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main())
