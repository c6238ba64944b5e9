"""How long the STKF needs to learn the drift model: from a cold start, when the drift estimate
enters and stays within a band of the true drift (the README's "learning time").

    .venv/bin/python benchmarks/learning_time.py bags/static_ramp [more bags with ground truth]

With `--write` its table replaces the "Learning time" section of benchmarks/RESULTS.md.

Reads the bag in chunks (any length), runs the estimator with default settings, compares its drift
estimate (rad/s, z gyro) with /ground_truth/gyro_bias at the IMU stamps. A bag that never settles in
a band prints 'not within'. Learning needs the temperature to change: on a vehicle whose gate closes
often, or at constant temperature, the constant term is all there is to learn.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))   # bench_report.py beside this script
from bench_report import code_state, cpu_model, replace_section  # noqa: E402

from gyro_thermal_comp.bag_io import BagError, read_chunks
from gyro_thermal_comp.thermal import EstimatorConfig, ThermalDriftEstimator

BANDS_DEG_S = (0.05, 0.02, 0.01)


def drift_error(bag: str) -> tuple[np.ndarray, np.ndarray]:
    """Time since the first IMU sample (s) and |estimated - true| z drift (rad/s)."""
    est = ThermalDriftEstimator(EstimatorConfig())
    t, d, truth_t, truth = [], [], [], []
    for chunk in read_chunks(bag, 60.0, streams=['imu', 'mag', 'temperature', 'gyro_bias']):
        out = est.process(chunk)
        t.append(out.track.t)
        d.append(out.track.drift_rad_s)
        if chunk.gyro_bias is not None:
            truth_t.append(chunk.gyro_bias.t)
            truth.append(chunk.gyro_bias.vec[:, 2])
    if not truth:
        raise BagError(f'{bag}: no /ground_truth/gyro_bias')
    t, d = np.concatenate(t), np.concatenate(d)
    return t - t[0], np.abs(d - np.interp(t, np.concatenate(truth_t), np.concatenate(truth)))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('bags', nargs='+')
    parser.add_argument('--write', action='store_true', help='write the table into benchmarks/RESULTS.md')
    args = parser.parse_args(argv)
    rows = []
    for bag in args.bags:
        try:
            t, err = drift_error(bag)
        except (BagError, OSError) as exc:
            print(f'learning_time: error: {exc}', file=sys.stderr)
            return 1
        cells = []
        for band in BANDS_DEG_S:
            outside = np.flatnonzero(~(err <= np.radians(band)))   # NaN (before any estimate) is outside
            if len(outside) and outside[-1] == len(t) - 1:
                print(f'{bag}: not within {band} deg/s at the end of the record ({t[-1]:.0f} s)')
                cells.append('not at the end')
            else:
                since = t[outside[-1] + 1] if len(outside) else 0.0
                print(f'{bag}: |drift error| <= {band} deg/s from {since:.0f} s on (record {t[-1]:.0f} s)')
                cells.append(f'from {since:.0f} s')
        rows.append(f"| {Path(bag).name} ({t[-1]:.0f} s) | {' | '.join(cells)} |")
    if args.write:
        state = code_state()
        replace_section(TITLE, '\n'.join([
            TITLE, '', f"`.venv/bin/python benchmarks/learning_time.py {' '.join(args.bags)} --write` (default "
            f"settings, cold start; {time.strftime('%Y-%m-%d %H:%M')}, {cpu_model()}, commit {state['git_head']}):", '',
            '| bag | ' + ' | '.join(f'within {b} deg/s' for b in BANDS_DEG_S) + ' |',
            '|---|' + '---|' * len(BANDS_DEG_S), *rows]))
    return 0


TITLE = '## Learning time'


if __name__ == '__main__':
    sys.exit(main())
