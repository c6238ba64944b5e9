"""Reference outputs of the pure core on every bundled bag, to prove a refactor changes nothing.

`compute(bag)` runs what the package computes from that bag:
- thermal bags: every thermal method (the STKF with its full per-sample output, the KF /
  whole-record MLR / LSM / uncompensated baselines that reuse its pipeline), and what the STKF node
  publishes (`node.*`: the estimator, the fast path and the node's orientation variances with the
  node's defaults, per published sample). On the outage bag also what the demo runs with the
  calibration record `static_ramp_unit2` (another run of the same unit): the calibrated `mlr`, and
  `stkf_model`, the STKF running the drift model `discover` names on it (`calibration.*`: both fits);
- carousel bags: the demodulator with the encoder and with the gyro as angle source.
Per-sample columns are kept at every DECIMATE-th sample (a changed computation moves far more than
one sample in 20), per-revolution ones whole. Stored in test/reference/NAME.npz with the
provenance of the run that wrote it (commit, command, versions); compared by
test/test_reference_outputs.py to the tolerance of gyro_thermal_comp.bag_compare (rtol 1e-9 plus
1e-12 of each unit's scale; string and integer columns exactly).

    .venv/bin/python test/reference_outputs.py                      # compare every bag
    .venv/bin/python test/reference_outputs.py --write BAG [BAG...]  # after a deliberate change

`--write` names the bags whose outputs the change was meant to move (every thermal bag:
`--write static_ramp static_ramp_outages vehicle_loop null`) and prints, per quantity, how far each
moved from the reference it replaces, for the commit message.
"""
from __future__ import annotations

import argparse
import importlib.metadata
import json
import platform
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
BAGS = REPO / 'bags'
STORE = Path(__file__).resolve().parent / 'reference'
DECIMATE = 20
CHUNK_S = 60.0
THERMAL_BAGS = ('static_ramp', 'static_ramp_outages', 'vehicle_loop', 'null')
CAROUSEL_BAGS = ('carousel_vertical', 'carousel_horizontal', 'carousel_wheel')
CALIBRATION_BAG = 'static_ramp_unit2'             # the demo's calibration record for ...
CALIBRATED_BAGS = ('static_ramp_outages',)        # ... the bag of the same unit
PROVENANCE = 'provenance'                         # the key of the JSON text that says who wrote a file


def compute(name: str) -> dict[str, np.ndarray]:
    return _thermal(name) if name in THERMAL_BAGS else _carousel(BAGS / name, name)


def _thermal(name: str) -> dict[str, np.ndarray]:
    from gyro_thermal_comp.bag_io import read_chunks
    from gyro_thermal_comp.evaluation.suite import all_methods
    from gyro_thermal_comp.thermal.estimator import ThermalDriftEstimator
    bag = BAGS / name
    out, calibration, model_file = {}, None, None
    if name in CALIBRATED_BAGS:
        calibration, model_file, out = _calibration()
    methods = [m for m in all_methods(None, peers=False, calibration=calibration, model_file=model_file)
               if not getattr(m, 'not_applicable', None)]
    for m in methods:
        if callable(getattr(m, 'fit', None)):
            m.fit(read_chunks(bag, CHUNK_S))
    cols: dict[str, list] = {}
    offset = 0
    for chunk in read_chunks(bag, CHUNK_S):
        n = 0 if chunk.imu is None else chunk.imu.t.size
        keep = np.flatnonzero((offset + np.arange(n)) % DECIMATE == 0)
        offset += n
        for m in methods:
            if type(m) is ThermalDriftEstimator:
                est_out = m.process(chunk)
                track = est_out.track
                for field in ('gyro_compensated', 'temperature_c', 'temperature_rate_c_s', 'roll_rad',
                              'pitch_rad', 'gate_open', 'reasons', 'params', 'param_sigmas', 'valid'):
                    cols.setdefault(f'{m.name}.{field}', []).append(np.asarray(getattr(est_out, field))[keep])
            else:
                track = m.update(chunk)
            for field in ('t', 'heading_rad', 'drift_rad_s', 'heading_sigma_rad', 'coasting'):
                value = getattr(track, field, None)
                if value is not None and np.size(value):
                    cols.setdefault(f'{m.name}.{field}', []).append(np.asarray(value)[keep])
    out.update({k: np.concatenate(v) for k, v in cols.items()})
    for stkf in (m for m in methods if type(m) is ThermalDriftEstimator):
        diagnostics = stkf.diagnostics()   # estimates only: counter names are not outputs
        for key in ('drift_sigma_rad_s', 'compass_sigma_rad', 'heading_sigma_rad'):
            out[f'{stkf.name}.{key}'] = np.asarray(diagnostics[key])
        out[f'{stkf.name}.state.x'] = np.asarray(stkf.get_state()['x'])
        out[f'{stkf.name}.state.P'] = np.asarray(stkf.get_state()['P'])
    out.update(_node(bag))
    return out


def _calibration():
    """The demo's calibration from CALIBRATION_BAG: (MLR calibration, discovered drift model file,
    their numbers as reference columns)."""
    from gyro_thermal_comp.cli import mlr_calibration
    from gyro_thermal_comp.discrepancy import discover
    from gyro_thermal_comp.discrepancy.model_export import model_file_from_discovery
    bag = BAGS / CALIBRATION_BAG
    calibration = mlr_calibration(bag)
    model = model_file_from_discovery(discover(bag), str(bag))
    nan = np.nan
    cols = {'calibration.mlr.terms': np.array(calibration.terms), 'calibration.mlr.x': np.asarray(calibration.x),
            'calibration.mlr.cov': np.asarray(calibration.cov), 'calibration.mlr.windows': np.array(calibration.windows),
            'calibration.model.terms': np.array([t.name for t in model.terms]),
            'calibration.model.priors': np.array([[nan if v is None else v for v in (t.prior, t.prior_sigma, t.q_sigma)]
                                                  for t in model.terms]),
            'calibration.model.lag_tau_s': np.array(nan if model.lag_tau_s is None else model.lag_tau_s),
            'calibration.model.branch': np.array(model.branch if model.branch is not None else (nan, nan))}
    return calibration, model, cols


def node_compensator(values: dict):
    """What the STKF node runs (estimator + fast path) with its own orientation variances, for its
    parameter values: (ThermalCompensator, OrientationVariance)."""
    from gyro_thermal_comp.nodes.orientation_uncertainty import OrientationVariance
    from gyro_thermal_comp.nodes.parameters import config_from_params
    from gyro_thermal_comp.thermal.compensator import ThermalCompensator
    cfg = config_from_params(values)
    variance = OrientationVariance.from_params(values, cfg)
    comp = ThermalCompensator(cfg, values['output_delay_s'], held=lambda out, chunk: variance.held_tilt(
        out, chunk.imu.accel, comp.estimator.tilt_max_rate_rad_s))
    return comp, variance


def _node(bag: Path) -> dict[str, np.ndarray]:
    """The numbers the STKF node publishes with its defaults, every DECIMATE-th published sample."""
    from gyro_thermal_comp.bag_io import BagReader
    from gyro_thermal_comp.nodes.parameters import all_specs
    comp, variance = node_compensator({s.name: s.default for s in all_specs()})
    outs = []
    with BagReader(bag) as reader:
        origin = reader.time_origin_ns
        for chunk in reader.chunks(CHUNK_S, streams=['imu', 'mag', 'temperature']):
            outs.append(comp.run(chunk, origin))
    comp.finish()
    outs.append(comp.take_ready()[1])
    outs = [o for o in outs if o is not None]
    ok = np.concatenate([o.ok for o in outs])

    def col(get):
        return np.concatenate([get(o) for o in outs])[ok][::DECIMATE]
    heading_var = col(lambda o: o.heading_var)
    return {'node.published': np.array(int(ok.sum())), 'node.not_published': np.array(comp.not_published),
            'node.ns': col(lambda o: o.ns), 'node.anchor_ns': col(lambda o: o.anchor_ns),
            'node.gyro_compensated_rad_s': col(lambda o: o.gyro_compensated),
            'node.heading_rad': col(lambda o: o.heading), 'node.heading_var_rad2': heading_var,
            'node.yaw_var_rad2': variance.yaw_variance(heading_var),
            **{f'node.{k}_{"rad2" if k.endswith("var") else "rad"}': col(lambda o, k=k: o.held[k])
               for k in ('roll', 'pitch', 'roll_var', 'pitch_var')}}


def _carousel(bag: Path, name: str) -> dict[str, np.ndarray]:
    from gyro_thermal_comp.bag_io import read_chunks
    from gyro_thermal_comp.carousel.config import CarouselConfig
    from gyro_thermal_comp.evaluation.carousel import CAROUSEL_TO_BODY, run_demodulator
    base = CarouselConfig.wheel() if name == 'carousel_wheel' else CarouselConfig.turntable()
    base = replace(base, carousel_to_body=tuple(map(tuple, CAROUSEL_TO_BODY[name])))
    out = {}
    for source in ('auto', 'gyro'):
        records, biases, flips, _ = run_demodulator(read_chunks(bag, CHUNK_S),
                                                        replace(base, angle_source=source))
        for field in records[0].__dataclass_fields__ if records else ():
            out[f'{source}.record.{field}'] = np.array([_plain(getattr(r, field)) for r in records])
        for field in biases[0].__dataclass_fields__ if biases else ():
            out[f'{source}.bias.{field}'] = np.array([_plain(getattr(b, field)) for b in biases])
        out[f'{source}.flips'] = np.array(len(flips))
    return out


def _plain(v):
    return np.nan if v is None else v



# unit suffixes of the output names, longest first
UNITS = ('_rad2_s2', '_rad2', '_m_s2', '_rad_s', '_c_s', '_rad', '_m', '_s', '_c')


def _unit(key: str) -> str | None:
    return next((u for u in UNITS if key.endswith(u)), None)


def unit_scales(reference: dict[str, np.ndarray]) -> dict[str, float]:
    """Largest finite |value| per unit suffix over the record's float fields. A field's rounding
    error scales with the inputs it is computed from, not with itself: an in-plane accelerometer bias
    of 0.08 m/s^2 estimated from specific forces of 9.8 m/s^2 differed by 1.8e-13 on another CPU."""
    scales: dict[str, float] = {}
    for k, v in reference.items():
        unit = _unit(k)
        v = np.asarray(v)
        if unit and v.dtype.kind == 'f' and v.size and np.any(np.isfinite(v)):
            scales[unit] = max(scales.get(unit, 0.0), float(np.nanmax(np.abs(v[np.isfinite(v)]))))
    return scales


def _outputs(record: dict) -> dict:
    return {k: v for k, v in record.items() if k != PROVENANCE}


def differences(ours: dict[str, np.ndarray], reference: dict[str, np.ndarray], label: str) -> list[str]:
    """One line per key missing, added, or different (floats to bag_compare's tolerance, its scale
    the largest field of the same unit in the record). The provenance is not an output."""
    from gyro_thermal_comp.bag_compare import ATOL_SCALE, RTOL, _excess
    ours, reference = _outputs(ours), _outputs(reference)
    problems = [f'{label}: {k} missing' for k in sorted(set(reference) - set(ours))]
    problems += [f'{label}: {k} not in the reference' for k in sorted(set(ours) - set(reference))]
    scales = unit_scales(reference)
    for k in sorted(set(ours) & set(reference)):
        a, b = np.asarray(ours[k]), np.asarray(reference[k])
        if a.shape != b.shape:
            problems.append(f'{label}: {k} shape {a.shape} != reference {b.shape}')
        elif a.dtype.kind == 'f' or b.dtype.kind == 'f':
            unit_scale = scales.get(_unit(k), 0.0)
            # the unit's scale joins both as one equal element: _excess takes atol from max |value|
            excess, diff = _excess(np.append(a.astype(float).ravel(), unit_scale),
                                   np.append(b.astype(float).ravel(), unit_scale), RTOL, ATOL_SCALE)
            if excess > 0:
                problems.append(f'{label}: {k} differs by up to {diff:.3g} (beyond rtol {RTOL:g} + '
                                f'{ATOL_SCALE:g} of its unit\'s scale)')
        elif not np.array_equal(a, b):
            problems.append(f'{label}: {k} differs at {int(np.count_nonzero(a != b))} of {a.size} entries')
    return problems


def deltas(ours: dict[str, np.ndarray], reference: dict[str, np.ndarray]) -> list[str]:
    """Per quantity, how far new outputs moved from a reference: the largest |change| (and relative to
    the quantity's largest |value|) for floats, the entries changed for the rest; one line for all
    that did not move at all."""
    ours, reference = _outputs(ours), _outputs(reference)
    lines, same = [], 0
    for k in sorted(set(ours) | set(reference)):
        if k not in reference:
            lines.append(f'  {k}: new')
            continue
        if k not in ours:
            lines.append(f'  {k}: removed')
            continue
        a, b = np.asarray(ours[k]), np.asarray(reference[k])
        if a.shape != b.shape:
            lines.append(f'  {k}: shape {b.shape} -> {a.shape}')
        elif a.dtype.kind == 'f' or b.dtype.kind == 'f':
            a, b = a.astype(float), b.astype(float)
            moved = ~((a == b) | (np.isnan(a) & np.isnan(b)))
            if not moved.any():
                same += 1
                continue
            finite = moved & np.isfinite(a) & np.isfinite(b)
            change = float(np.max(np.abs(a[finite] - b[finite]))) if finite.any() else 0.0
            scale = float(np.max(np.abs(b[np.isfinite(b)]))) if np.isfinite(b).any() else 0.0
            line = f'  {k}: {int(moved.sum())} of {a.size} moved, max |change| {change:.3g}'
            line += f' ({change / scale:.2g} of the largest |value|, {scale:.3g})' if scale else ''
            if (moved & ~finite).any():
                line += f', {int((moved & ~finite).sum())} to or from a non-finite value'
            lines.append(line)
        elif np.array_equal(a, b):
            same += 1
        else:
            lines.append(f'  {k}: {int(np.count_nonzero(a != b))} of {a.size} entries changed')
    return lines + [f'  {same} quantities unchanged']


def provenance(argv: list[str]) -> dict:
    """Who wrote a reference: the commit (and whether the package differed from it), the command,
    the versions of what computed it."""
    def git(*args):
        return subprocess.run(['git', *args], cwd=REPO, capture_output=True, text=True).stdout.strip()
    versions = {p: importlib.metadata.version(p) for p in ('gyro_thermal_comp', 'numpy', 'scipy', 'filterpy')}
    return {'commit': git('rev-parse', 'HEAD') or 'unknown',
            'package_modified': bool(git('status', '--porcelain', '--', 'gyro_thermal_comp', 'test/reference_outputs.py')),
            'command': ' '.join(['test/reference_outputs.py', *argv]),
            'python': platform.python_version(), 'machine': platform.machine(), 'versions': versions}


def read(name: str) -> tuple[dict[str, np.ndarray], dict]:
    """A stored reference: (outputs, provenance; {} for a file written without one)."""
    with np.load(STORE / f'{name}.npz') as ref:
        record = dict(ref)
    return _outputs(record), json.loads(str(record[PROVENANCE])) if PROVENANCE in record else {}


def describe(prov: dict) -> str:
    if not prov:
        return 'no provenance stored'
    modified = ' with the package modified' if prov.get('package_modified') else ''
    return f"written at {prov['commit'][:12]}{modified} by `{prov['command']}`, numpy {prov['versions']['numpy']}"


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    everything = THERMAL_BAGS + CAROUSEL_BAGS
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('--write', action='store_true', help='store the outputs of the named bags as their new reference')
    p.add_argument('bags', nargs='*', metavar='BAG',
                   help=f'bags (default without --write: all of {", ".join(everything)})')
    args = p.parse_args(argv)
    unknown = [b for b in args.bags if b not in everything]
    if unknown:
        p.error(f'unknown bag(s) {", ".join(unknown)}; choose from {", ".join(everything)}')
    if args.write and not args.bags:
        p.error('--write needs the bags it rewrites, named (every thermal bag: '
                f'--write {" ".join(THERMAL_BAGS)}); a reference is rewritten only on purpose')
    failed = False
    for name in args.bags or everything:
        ours = compute(name)
        path = STORE / f'{name}.npz'
        if args.write:
            old, old_prov = read(name) if path.exists() else ({}, {})
            prov = provenance(argv)
            STORE.mkdir(exist_ok=True)
            np.savez_compressed(path, **ours, **{PROVENANCE: np.array(json.dumps(prov, sort_keys=True))})
            print(f'wrote {path.relative_to(REPO)} ({len(ours)} arrays); against the reference it replaces '
                  f'({describe(old_prov)}):')
            print('\n'.join(deltas(ours, old)))
            continue
        ref, prov = read(name)
        problems = differences(ours, ref, name)
        print('\n'.join(problems) or f'{name}: identical to the reference ({describe(prov)})')
        failed |= bool(problems)
    return int(failed)


if __name__ == '__main__':
    sys.path.insert(0, str(REPO))
    sys.exit(main())
