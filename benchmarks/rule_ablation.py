"""Each special-case rule of the gate and the heading filter, off and on: on the simulated truth
families and on the real recording (slow: not part of CI).

    .venv/bin/python benchmarks/rule_ablation.py                  # 4 seeds a family, CATS periods 1-2
    .venv/bin/python benchmarks/rule_ablation.py --seeds 1 --no-real --no-results   # a quick look
    .venv/bin/python benchmarks/rule_ablation.py --baselines      # the drift line in the KF and LSM baselines

One rule is switched off at a time, every other setting at its default:
- `drift_line`: the gate accepts a compass whose disagreement with the gyro has been a steady straight
  line for `mismatch_line_s` (the drift estimate is wrong, not the field): gate.mismatch_line_s = 0.
- `lead_in_rollback`: when the gate shuts on a field seen disturbed, the heading filter undoes the
  compass of the `confirm_s` before (a slowly growing disturbance is in the compass before the field
  tests see it); off, the compass blocks roll nothing back (and so nothing on probation either).
- `probation_rollback`: a reopen after a disturbance is on probation for `reopen_probation_s`; the
  field seen disturbed again within it undoes the compass since the reopen: reopen_probation_s = 0.
- `backtest`: what past drift predictions of the same age missed beyond their variance weighs the
  coasted change and widens the coasting heading sigma: coast_backtest = false.
The simulated families: family A (the named scenarios the defaults are tuned on) and family B
(other effect shapes, reported only), outages and vehicle drives, every variant on the same records
(one pass of the simulator, the variants side by side). Figures: the STKF's max |heading error|
(median and worst over the records) and, on outages, |excess growth| per outage (median and worst).
The real recording: the CATS tag's development periods 1 and 2 (benchmarks/real_cats.py: its
coasting spans, median |coast| / max(|frozen|, 5 deg) and the worst span's excess over frozen; its
hourly heading deviation), and how often each rule acted there with the defaults.
A rule is kept where it helps somewhere (switching it off is worse on balance over the families'
medians and worst records, or in the real recording's coast median) and harms neither; a rule that
never acts on the real recording is neutral there. The verdict is printed per rule. Writes its RESULTS.md section.
`--baselines`: the drift line off and on in the paper's learned baselines (KF, modified LSM), which
run behind the same gate, on the same simulated records.
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from functools import partial
from pathlib import Path

import numpy as np

from gyro_thermal_comp import sim
from gyro_thermal_comp.evaluation.report import evaluate
from gyro_thermal_comp.sim.truth_family import family_configs
from gyro_thermal_comp.thermal.baselines import KfDriftBaseline, LsmBaseline
from gyro_thermal_comp.thermal.estimator import EstimatorConfig, ThermalDriftEstimator

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import real_cats  # noqa: E402
from bench_report import code_state, cpu_model, replace_section  # noqa: E402
from stkf_targets import ARW_DEG_SQRT_S, estimator_config, model_from_calibration, rates  # noqa: E402

SECTION = '## Special-case rules: each off and on'
MODEL_SECTION = '## Special-case rules with a drift model file'
BASELINE_SECTION = '## The drift line in the baselines that share the gate'
BASELINES = ('kf', 'kf_no_drift_line', 'lsm', 'lsm_no_drift_line')
RULES = {   # rule -> (settings that switch it off, what else must be done to the estimator)
    'drift_line': ({'gate.mismatch_line_s': 0.0}, None),
    'lead_in_rollback': ({}, 'no_rollback'),
    'probation_rollback': ({'reopen_probation_s': 0.0}, None),
    'backtest': ({'coast_backtest': False}, None),
}
VARIANTS = ('defaults',) + tuple(f'no_{r}' for r in RULES)
ACTS = {'drift_line': 'gate_drift_lines', 'lead_in_rollback': 'heading_rollbacks',
        'probation_rollback': 'heading_probation_rollbacks'}


def _no_rollback(est: ThermalDriftEstimator) -> None:
    """The compass blocks keep what the heading filter took before a shut (compass_blocks.py)."""
    est.blocks.confirm_s = 0.0


def _variant(name: str) -> tuple[dict, object]:
    if name == 'defaults':
        return {}, None
    settings, hook = RULES[name[3:]]
    return settings, (_no_rollback if hook == 'no_rollback' else None)


def _estimators(model=None) -> list[ThermalDriftEstimator]:
    out = []
    for name in VARIANTS:
        settings, hook = _variant(name)
        est = ThermalDriftEstimator(replace(estimator_config(settings), name=name, drift_model_file=model))
        if hook is not None:
            hook(est)
        out.append(est)
    return out


def sim_case(case, with_model: bool = False) -> dict:
    """Every variant over one simulated record: max |error| and each outage's |excess growth|, deg.
    `with_model`: each runs the drift model `discover` writes from a calibration run of the same unit
    (stkf_targets.py `--model`)."""
    model = None
    if with_model:
        from gyro_thermal_comp.evaluation.synthetic import calibration_config
        reference = 'odom' if case.purpose == 'vehicle' else 'static'
        model = model_from_calibration(calibration_config(case.config), reference)
    estimators = _estimators(model)
    figures = _figures(case, estimators)
    counters = estimators[0].diagnostics()   # the defaults' rule counters, after the record
    return {'label': case.label, 'seed': case.seed, **figures, 'acts': {k: counters[v] for k, v in ACTS.items()}}


def baseline_case(case) -> dict:
    """The KF and LSM baselines with the drift line on and off over one simulated record: max |error|
    and each outage's |excess growth|, deg; how often the line acted in each baseline."""
    on, off = EstimatorConfig(), estimator_config(RULES['drift_line'][0])
    methods = [KfDriftBaseline(on), KfDriftBaseline(off, name='kf_no_drift_line'), LsmBaseline(on), LsmBaseline(off)]
    methods[3].name = 'lsm_no_drift_line'
    figures = _figures(case, methods)
    return {'label': case.label, 'seed': case.seed, **figures,
            'acts': {m.name: m.diagnostics()[ACTS['drift_line']] for m in methods[::2]}}


def _figures(case, methods) -> dict:
    """Each method's max |error| and each outage's |excess growth| over one simulated record, deg."""
    d = evaluate(lambda: sim.simulate(case.config), methods, arw_deg_sqrt_s=ARW_DEG_SQRT_S).to_dict()
    names = [m.name for m in methods]
    return {'max_abs_deg': {n: d['methods'][n]['max_abs_deg'] for n in names},
            'excess_deg': {n: [abs(s['methods'][n]['excess_growth_deg']) for s in d.get('spans', [])] for n in names}}


def _figure_table(results: dict, names, pairs: dict) -> tuple[list[str], dict]:
    """Median and worst of each figure over each group's records (`results`: group -> records), one
    table row per group and figure (none where a group has no outage); and per key of `pairs`
    ((off, on) names), off minus on of every median and worst."""
    lines = ['| records | figure | ' + ' | '.join(names) + ' |', '|---|---|' + '---|' * len(names)]
    worse = {k: [] for k in pairs}
    for key, res in results.items():
        for fig in ('max_abs_deg', 'excess_deg'):
            values = {n: np.array([x for r in res for x in np.atleast_1d(r[fig][n])], dtype=float) for n in names}
            if any(v.size == 0 for v in values.values()):
                continue
            per = {n: (float(np.median(v)), float(np.max(v))) for n, v in values.items()}
            label = 'max \\|e\\|' if fig == 'max_abs_deg' else 'outage \\|excess growth\\|'
            lines.append(f'| {key} ({len(res)}) | {label}, median / worst (deg) | '
                         + ' | '.join(f'{m:.2f} / {w:.2f}' for m, w in per.values()) + ' |')
            for k, (off, on) in pairs.items():
                worse[k] += [per[off][i] - per[on][i] for i in (0, 1)]
    return lines, worse


def _baseline_table(results: dict) -> list[str]:
    lines, worse = _figure_table(results, BASELINES, {b: (f'{b}_no_drift_line', b) for b in ('kf', 'lsm')})
    acts = {b: sum(r['acts'][b] for res in results.values() for r in res) for b in worse}
    lines += ['', 'Times the drift line acted with the defaults, all records: '
              + ', '.join(f'`{b}` {n}' for b, n in acts.items()) + '.', '']
    for b, w in worse.items():
        lines.append(f'- `{b}`: off minus on, summed over the medians and worsts {float(np.sum(w)):+.2f} deg '
                     f'(worse off in {int(np.sum(np.array(w) > 0))} of {len(w)} figures, '
                     f'better in {int(np.sum(np.array(w) < 0))})')
    return lines


def real_period(period: str, cache: Path) -> dict:
    """Every variant over a development period's coasting spans; the defaults' rule counters."""
    bag = real_cats.convert(real_cats.fetch(cache), cache, period)
    full = real_cats.run_core(bag)
    removed = real_cats.spans(full['raw_t'], full['temp'])
    cut_spans = [(a, b) for a, b, _ in removed]
    out = {'period': period, 'acts_with_compass': {k: full['diagnostics'][v] for k, v in ACTS.items()}}
    for name in VARIANTS:
        settings, hook = _variant(name)
        cut = real_cats.run_core(bag, cut_spans, settings=settings, prepare=hook)
        rows = real_cats.coasting(cut, removed)
        out[name] = {'ratio_median': float(np.median([r['ratio'] for r in rows])),
                     'worst_over_frozen_deg': float(max(r['worse_by_deg'] for r in rows)),
                     'hourly_deviation_deg': real_cats.heading_hold(cut, removed)['heading_deviation_deg']}
        if name == 'defaults':
            out['acts_coasting'] = {k: cut['diagnostics'][v] for k, v in ACTS.items()}
    return out


def _sim_table(sim_results: dict) -> tuple[list[str], dict]:
    # per rule: (off - defaults) of each median and each worst figure
    lines, worse = _figure_table(sim_results, VARIANTS, {r: (f'no_{r}', 'defaults') for r in RULES})
    acts = {r: sum(res['acts'][r] for results in sim_results.values() for res in results) for r in ACTS}
    lines += ['', 'Times each rule acted with the defaults, all records: '
              + ', '.join(f'`{r}` {n}' for r, n in acts.items()) + ' (`backtest` is always on).']
    return lines, worse


def _real_table(real_results: list[dict]) -> tuple[list[str], dict, dict]:
    lines = ['| period | figure | ' + ' | '.join(VARIANTS) + ' |', '|---|---|' + '---|' * len(VARIANTS)]
    better, acts = {r: [] for r in RULES}, {r: 0 for r in RULES}
    for res in real_results:
        for fig, label in (('ratio_median', 'coast median ratio'),
                           ('worst_over_frozen_deg', 'worst span over frozen (deg)'),
                           ('hourly_deviation_deg', 'hourly deviation (deg)')):
            lines.append(f"| {res['period']} | {label} | " + ' | '.join(f'{res[n][fig]:.2f}' for n in VARIANTS) + ' |')
        for r in RULES:
            better[r].append(res['defaults']['ratio_median'] - res[f'no_{r}']['ratio_median'])
            if r in ACTS:
                acts[r] += res['acts_with_compass'][r] + res['acts_coasting'][r]
            else:
                acts[r] = None
    return lines, better, acts


def verdicts(worse: dict, better: dict | None, acts: dict | None) -> list[str]:
    """Per rule: kept where it helps somewhere (off is worse on balance over the families' medians
    and worst records: a special case exists for the rare record, so its worst counts as much as the
    typical one; or on the real recording's coast median) and harms neither (a rule that never acts
    on the real recording is neutral there)."""
    out = []
    for r in RULES:
        w = float(np.sum(worse[r]))
        text = f'- `{r}`: off minus on, summed over the families\' medians and worsts {w:+.2f} deg ' \
               f'(worse off in {int(np.sum(np.array(worse[r]) > 0))} of {len(worse[r])} figures, ' \
               f'better in {int(np.sum(np.array(worse[r]) < 0))})'
        helps, harms = w > 0.0, w < 0.0
        if better is not None:
            b = np.array(better[r])   # coast median ratio, on minus off: below 0, the rule helps
            acted = acts[r] is None or acts[r] > 0
            helps |= bool(acted and np.all(b <= 0.0) and np.any(b < 0.0))
            harms |= bool(acted and np.any(b > 0.0))
            act = 'always on' if acts[r] is None else 'never acts there' if acts[r] == 0 else f'acts {acts[r]} times'
            text += f'; real recording: coast median ratio off minus on {", ".join(f"{-x:+.3f}" for x in b)} ({act})'
        out.append(text + f' -> {"kept" if helps and not harms else "does not earn its place"}')
    return out


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('--seeds', type=int, default=4)
    p.add_argument('--jobs', type=int, default=2)
    p.add_argument('--no-real', action='store_true', help='the simulated families only')
    p.add_argument('--model', action='store_true',
                   help='every variant runs the drift model discover writes from a calibration run (no real recording)')
    p.add_argument('--families', nargs='+', default=['A', 'B'], choices=['A', 'B'])
    p.add_argument('--purposes', nargs='+', default=['outages', 'vehicle'], choices=['outages', 'vehicle'])
    p.add_argument('--baselines', action='store_true',
                   help='the drift line off and on in the KF and LSM baselines (simulated records only)')
    p.add_argument('--no-results', action='store_true', help='print only; do not write RESULTS.md')
    p.add_argument('--cache', type=Path, default=Path.home() / '.cache' / 'gyro_thermal_comp' / 'cats')
    args = p.parse_args()
    t_start = time.time()
    cases = []
    for family in args.families:
        for purpose in args.purposes:
            rate = 50.0 if purpose == 'vehicle' else 20.0   # a vehicle's turns need 50 Hz (stkf_targets.py)
            cases += [(f'{family} {purpose}', c)
                      for c in family_configs(family, purpose, range(args.seeds), **rates(rate))]
    if args.baselines:
        return _baselines_main(args, cases, t_start)
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        sim_out = list(pool.map(partial(sim_case, with_model=args.model), [c for _, c in cases]))
        real_out = [] if args.no_real or args.model else \
            list(pool.map(partial(real_period, cache=args.cache), real_cats.DEV_PERIODS))
    sim_results: dict[str, list] = {}
    for (key, _), res in zip(cases, sim_out):
        sim_results.setdefault(key, []).append(res)
    sim_lines, worse = _sim_table(sim_results)
    what = 'the STKF with the discovered drift model' if args.model else 'the STKF'
    lines = [f'Simulated truth families ({what} with each rule off, on the same records):', ''] + sim_lines
    better = acts = None
    if real_out:
        real_lines, better, acts = _real_table(real_out)
        lines += ['', 'The CATS tag, development periods (compass removed over the coasting spans):', ''] + real_lines
    lines += ['', 'Verdicts:', ''] + verdicts(worse, better, acts)
    command = 'python benchmarks/rule_ablation.py ' + ' '.join(sys.argv[1:])
    print('\n'.join(lines))
    print(f'({time.time() - t_start:.0f} s)')
    if args.no_results or (args.no_real and not args.model):
        return 0
    section = MODEL_SECTION if args.model else SECTION
    replace_section(section, f'{section}\n\n`{command}` on {cpu_model()}, {time.strftime("%Y-%m-%d")}, commit '
                    f'{(code_state()["git_head"] or "?")[:7]}, {time.time() - t_start:.0f} s. Variant `no_X` is the '
                    f'defaults with rule X off; what each rule does is in the script\'s docstring.\n\n'
                    + '\n'.join(lines) + '\n')
    return 0


def _baselines_main(args, cases: list, t_start: float) -> int:
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        out = list(pool.map(baseline_case, [c for _, c in cases]))
    results: dict[str, list] = {}
    for (key, _), res in zip(cases, out):
        results.setdefault(key, []).append(res)
    lines = ['Simulated truth families (each baseline with the drift line on and off, on the same records):', '']
    lines += _baseline_table(results)
    command = 'python benchmarks/rule_ablation.py ' + ' '.join(sys.argv[1:])
    print('\n'.join(lines))
    print(f'({time.time() - t_start:.0f} s)')
    if not args.no_results:
        replace_section(BASELINE_SECTION, f'{BASELINE_SECTION}\n\n`{command}` on {cpu_model()}, '
                        f'{time.strftime("%Y-%m-%d")}, commit {(code_state()["git_head"] or "?")[:7]}, '
                        f'{time.time() - t_start:.0f} s.\n\n' + '\n'.join(lines) + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
