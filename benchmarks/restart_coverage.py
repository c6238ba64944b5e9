"""How often the published yaw 2-sigma covers the heading error in the first 10 min after a restart.

    .venv/bin/python benchmarks/restart_coverage.py            # writes its RESULTS.md section

A node that ran over a whole bundled record saves its state (`state_file`); it is then restarted from
that state at one time of the record after another (every 60 s on `bags/vehicle_loop`: still,
driving straight, in turns, during and after magnetic disturbances; every 600 s on
`bags/static_ramp_outages`: heating, cooling, inside outages), each run over the next 10 min, with
the node's defaults and the site's declination set. Per restart and pooled: the share of truth
samples whose |published yaw - true yaw| <= the published 2-sigma (target 90-99 %), the largest
error, and what the start did with its still period (`still_period.initial_state`).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))   # bench_report.py beside this script
from bench_report import code_state, cpu_model, replace_section  # noqa: E402

from gyro_thermal_comp.bag_io import BagReader  # noqa: E402
from gyro_thermal_comp.evaluation.restarts import node_values, restart, saved_state  # noqa: E402

BAGS = Path(__file__).resolve().parent.parent / 'bags'
PLAN = {'vehicle_loop': np.arange(60.0, 1201.0, 60.0), 'static_ramp_outages': np.arange(300.0, 6601.0, 600.0)}
TITLE = '## Restart coverage'


def declination_rad(bag: Path) -> float:
    """The site's declination, as a robot team sets it from a field model (here the simulator's)."""
    with BagReader(bag) as reader:
        return math.radians(json.loads(next(iter(reader.text('/sim/config'))))['params']['declination_deg'])


def run_bag(name: str, starts) -> list[dict]:
    bag = BAGS / name
    values = node_values(declination_rad=declination_rad(bag))
    state = saved_state(bag, values)
    rows = []
    for start in starts:
        r = restart(bag, float(start), state, values)
        covered = r.covered()
        rows.append({'bag': name, 'start_s': float(start), 'samples': int(covered.size),
                     'covered': int(np.count_nonzero(covered)),
                     'max_abs_error_deg': float(np.degrees(np.max(np.abs(r.error_rad)))),
                     'median_2sigma_deg': float(np.degrees(2 * np.median(r.sigma_rad))),
                     'still_s': float(r.estimator.still_end_s - start), 'still_use': r.estimator.still_use})
        print(f"{name} {start:6.0f} s: {100 * rows[-1]['covered'] / rows[-1]['samples']:5.1f} % covered, "
              f"max |e| {rows[-1]['max_abs_error_deg']:5.1f} deg, still {rows[-1]['still_s']:4.1f} s "
              f"({rows[-1]['still_use']})", flush=True)
    return rows


def section(rows: list[dict], seconds: float) -> str:
    state = code_state()
    lines = [TITLE, '',
             f'`.venv/bin/python benchmarks/restart_coverage.py` ({time.strftime("%Y-%m-%d %H:%M")}, {cpu_model()}, '
             f'commit {state["git_head"]}{" + uncommitted changes" if state["package_uncommitted_changes"] else ""}, '
             f'{seconds:.0f} s). Warm start from the state saved at the end of the whole record, restarted at each '
             'time, 10 min each, node defaults with the declination set; covered = |yaw error| <= published '
             '2-sigma (target 90-99 %).', '',
             '| bag | restarts | pooled covered | worst restart | max \\|e\\| | restarts below 90 % |',
             '|---|---|---|---|---|---|']
    for name in PLAN:
        mine = [r for r in rows if r['bag'] == name]
        share = [r['covered'] / r['samples'] for r in mine]
        pooled = sum(r['covered'] for r in mine) / sum(r['samples'] for r in mine)
        worst = int(np.argmin(share))
        below = ', '.join(f"{r['start_s']:.0f} s ({100 * s:.1f} %)" for r, s in zip(mine, share) if s < 0.9) or 'none'
        largest = max(r['max_abs_error_deg'] for r in mine)
        lines.append(f"| {name} | {len(mine)} | {100 * pooled:.1f} % | {100 * share[worst]:.1f} % at "
                     f"{mine[worst]['start_s']:.0f} s | {largest:.1f} deg | {below} |")
    each = [f"{r['bag']} {r['start_s']:.0f} s {100 * r['covered'] / r['samples']:.1f} % ({r['still_use']}, "
            f"still {r['still_s']:.1f} s)" for r in rows]
    lines += ['', 'Per restart: ' + '; '.join(each) + '.']
    return '\n'.join(lines) + '\n'


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('--no-write', action='store_true', help='print only; leave RESULTS.md as it is')
    args = p.parse_args(argv)
    t0 = time.monotonic()
    rows = [row for name, starts in PLAN.items() for row in run_bag(name, starts)]
    text = section(rows, time.monotonic() - t0)
    print(text)
    if not args.no_write:
        replace_section(TITLE, text)
    return 0


if __name__ == '__main__':
    sys.exit(main())
