"""Reference outputs of the pure core on every bundled bag, to prove a refactor changes nothing.

`compute(bag)` runs what the package computes from that bag: for the thermal bags every thermal
method (STKF with its full per-sample output, the KF / whole-record MLR / LSM / uncompensated
baselines that reuse its pipeline; the calibrated `mlr` needs a calibration record and is left
out), for the carousel bags the demodulator with the encoder and with the gyro as angle source.
Per-sample columns are kept at every DECIMATE-th sample (a changed computation moves far more than
one sample in 20), per-revolution ones whole. Stored in test/reference/NAME.npz:

    .venv/bin/python test/reference_outputs.py --write      # after a deliberate behaviour change

and compared by test/test_reference_outputs.py to the tolerance of gyro_thermal_comp.bag_compare
(issue 10: rtol 1e-9 plus 1e-12 of each field's scale; string and integer columns exactly).
"""
from __future__ import annotations

import argparse
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


def compute(name: str) -> dict[str, np.ndarray]:
    return _thermal(BAGS / name) if name in THERMAL_BAGS else _carousel(BAGS / name, name)


def _thermal(bag: Path) -> dict[str, np.ndarray]:
    from gyro_thermal_comp.bag_io import read_chunks
    from gyro_thermal_comp.evaluation.suite import all_methods
    from gyro_thermal_comp.thermal.estimator import ThermalDriftEstimator
    methods = [m for m in all_methods(None, peers=False) if not getattr(m, 'not_applicable', None)]
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
                out = m.process(chunk)
                track = out.track
                for field in ('gyro_compensated', 'temperature_c', 'temperature_rate_c_s', 'roll_rad',
                              'pitch_rad', 'gate_open', 'reasons', 'params', 'param_sigmas', 'valid'):
                    cols.setdefault(f'{m.name}.{field}', []).append(np.asarray(getattr(out, field))[keep])
            else:
                track = m.update(chunk)
            for field in ('t', 'heading_rad', 'drift_rad_s', 'heading_sigma_rad', 'coasting'):
                value = getattr(track, field, None)
                if value is not None and np.size(value):
                    cols.setdefault(f'{m.name}.{field}', []).append(np.asarray(value)[keep])
    out = {k: np.concatenate(v) for k, v in cols.items()}
    stkf = methods[0]
    diagnostics = stkf.diagnostics()   # estimates only: counter names are not outputs
    for key in ('drift_sigma_rad_s', 'compass_sigma_rad', 'heading_sigma_rad'):
        out[f'stkf.{key}'] = np.asarray(diagnostics[key])
    out['stkf.state.x'] = np.asarray(stkf.get_state()['x'])
    out['stkf.state.P'] = np.asarray(stkf.get_state()['P'])
    return out


def _carousel(bag: Path, name: str) -> dict[str, np.ndarray]:
    from gyro_thermal_comp.bag_io import read_chunks
    from gyro_thermal_comp.carousel.config import CarouselConfig
    from gyro_thermal_comp.carousel.evaluation import CAROUSEL_TO_BODY, run_demodulator
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
UNITS = ('_rad2_s2', '_m_s2', '_rad_s', '_c_s', '_rad', '_m', '_s', '_c')


def unit_scales(reference: dict[str, np.ndarray]) -> dict[str, float]:
    """Largest finite |value| per unit suffix over the record's float fields. A field's rounding
    error scales with the inputs it is computed from, not with itself: an in-plane accelerometer bias
    of 0.08 m/s^2 estimated from specific forces of 9.8 m/s^2 differed by 1.8e-13 on another CPU."""
    scales: dict[str, float] = {}
    for k, v in reference.items():
        unit = next((u for u in UNITS if k.endswith(u)), None)
        v = np.asarray(v)
        if unit and v.dtype.kind == 'f' and v.size and np.any(np.isfinite(v)):
            scales[unit] = max(scales.get(unit, 0.0), float(np.nanmax(np.abs(v[np.isfinite(v)]))))
    return scales


def differences(ours: dict[str, np.ndarray], reference: dict[str, np.ndarray], label: str) -> list[str]:
    """One line per key missing, added, or different (floats to bag_compare's tolerance, its scale
    the largest field of the same unit in the record)."""
    from gyro_thermal_comp.bag_compare import ATOL_SCALE, RTOL, _excess
    problems = [f'{label}: {k} missing' for k in sorted(set(reference) - set(ours))]
    problems += [f'{label}: {k} not in the reference' for k in sorted(set(ours) - set(reference))]
    scales = unit_scales(reference)
    for k in sorted(set(ours) & set(reference)):
        a, b = np.asarray(ours[k]), np.asarray(reference[k])
        if a.shape != b.shape:
            problems.append(f'{label}: {k} shape {a.shape} != reference {b.shape}')
        elif a.dtype.kind == 'f' or b.dtype.kind == 'f':
            unit_scale = scales.get(next((u for u in UNITS if k.endswith(u)), None), 0.0)
            # the unit's scale joins both as one equal element: _excess takes atol from max |value|
            excess, diff = _excess(np.append(a.astype(float).ravel(), unit_scale),
                                   np.append(b.astype(float).ravel(), unit_scale), RTOL, ATOL_SCALE)
            if excess > 0:
                problems.append(f'{label}: {k} differs by up to {diff:.3g} (beyond rtol {RTOL:g} + '
                                f'{ATOL_SCALE:g} of its unit\'s scale)')
        elif not np.array_equal(a, b):
            problems.append(f'{label}: {k} differs at {int(np.count_nonzero(a != b))} of {a.size} entries')
    return problems


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('--write', action='store_true', help='store the outputs as the new reference')
    p.add_argument('bags', nargs='*', default=THERMAL_BAGS + CAROUSEL_BAGS)
    args = p.parse_args(argv)
    failed = False
    for name in args.bags:
        ours = compute(name)
        path = STORE / f'{name}.npz'
        if args.write:
            STORE.mkdir(exist_ok=True)
            np.savez_compressed(path, **ours)
            print(f'wrote {path.relative_to(REPO)} ({len(ours)} arrays)')
            continue
        with np.load(path) as ref:
            problems = differences(ours, dict(ref), name)
        print('\n'.join(problems) or f'{name}: identical to the reference')
        failed |= bool(problems)
    return int(failed)


if __name__ == '__main__':
    sys.path.insert(0, str(REPO))
    sys.exit(main())
