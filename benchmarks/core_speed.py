"""The pure core on arrays (no ROS) vs imufusion's C AHRS loop, on the same samples.

    .venv/bin/python benchmarks/core_speed.py                 # 100 Hz and 1 kHz: RESULTS.md section
    .venv/bin/python benchmarks/core_speed.py --profile       # + cProfile of the core at 100 Hz
    .venv/bin/python benchmarks/core_speed.py --duration 60 --repeats 1   # a quick look (not written to RESULTS.md)
    .venv/bin/python benchmarks/core_speed.py --against HEAD   # + the estimator of a git revision, interleaved

Samples: the simulator's `vehicle_loop` scenario (driving, turning, magnetic disturbances: the gate
and the filter work) at 100 Hz and 1 kHz IMU (mag 100 Hz, temperature 10 Hz), or `--bag` (its own
rate), held in memory and cut by stamp into chunks of `--chunks` seconds: 0.02 s is the live node's
batch (`process_period_s`), 10 s what `replay` reads, 60 s what `evaluate` reads. Timed, in turn on
the same chunks, each from a fresh object:
- `estimator`: `ThermalDriftEstimator.process` per chunk (the slow path);
- `compensator`: `ThermalCompensator.run` per chunk (estimator + fast path: one output per sample);
- `fusion_loop`: imufusion's `Ahrs.update` (C) per sample in a Python loop with the latest
  magnetometer sample, inputs converted per chunk (deg/s, g, uT) and handed over as lists of
  `FUSION_BLOCK` rows (its fastest call),
  reading the quaternion after each sample (an output per sample, as the core gives);
- `fusion_update_only`: the same without reading the quaternion (the bare C loop: the hardest bar);
- `fusion_peer`: `FusionPeer.update`, as `evaluate` runs imufusion (with its gyro bias tracker).
Samples/s = IMU samples / process CPU time (user + system: the machine's other load does not count);
best of `--repeats` (the least disturbed run), median beside it. Ratios are core / imufusion.
The per-block loops (the heading filter and the magnetic gate run once per compass block, in Python,
whatever the IMU rate) are timed apart in extra passes over the largest chunks of the first
record, CPU per block, beside imufusion's CPU for the IMU samples of one block: above 1x, the core
cannot reach imufusion's rate at that IMU rate however fast the rest is.
`--against REV`: the estimator of git revision REV (its package imported under another name) and
this one, each chunk through one then the other, alternating which goes first, best of `--repeats`:
CPU per chunk and the ratio this / REV, the same load on both (a change's speed-up in one run).
Writes benchmarks/results/core_speed.json and, for the default run, its section of benchmarks/RESULTS.md.
"""
from __future__ import annotations

import argparse
import cProfile
import importlib
import importlib.util
import io
import json
import os
import pstats
import re
import subprocess
import sys
import tarfile
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from gyro_thermal_comp import sim
from gyro_thermal_comp.constants import STANDARD_GRAVITY_M_S2
from gyro_thermal_comp.evaluation.peers import FusionPeer
from gyro_thermal_comp.samples import SensorChunk, concat_chunks, slice_samples
from gyro_thermal_comp.thermal.compensator import ThermalCompensator
from gyro_thermal_comp.thermal.estimator import EstimatorConfig, ThermalDriftEstimator
from gyro_thermal_comp.thermal.heading_filter import HeadingFilter
from gyro_thermal_comp.thermal.magnetic_gate import MagneticGate
sys.path.insert(0, str(Path(__file__).resolve().parent))   # bench_report.py beside this script
from bench_report import cpu_model, code_state, replace_section  # noqa: E402

HERE = Path(__file__).resolve().parent
RESULTS_JSON = HERE / 'results' / 'core_speed.json'
REPO = HERE.parent
PRIME_S = 60.0       # untimed start of every pass: the 30 s still period and the first update windows
MAX_CHUNKS = 3000    # timed chunks per pass at most (0.02 s chunks: 60 s of data)
FUSION_BLOCK = 256   # imufusion inputs as Python lists this many rows at a time: lists of a whole chunk cost GC time
METHODS = ('estimator', 'compensator', 'fusion_loop', 'fusion_update_only', 'fusion_peer')
CORE, FUSION = ('estimator', 'compensator'), ('fusion_loop', 'fusion_update_only', 'fusion_peer')
LOAD_AT_START = os.getloadavg()[0]   # the machine's other work when this started
DEFAULTS = {'rates': '100,1000', 'chunks': '0.02,10,60', 'duration': 600.0, 'repeats': 3}
_TEMP_DIRS: list = []   # the packages of `--against` revisions


def simulated(rate_hz: float, duration_s: float) -> SensorChunk:
    cfg = sim.make_config('vehicle_loop', seed=13, duration_s=duration_s, imu_rate_hz=rate_hz, mag_rate_hz=100.0,
                          temp_rate_hz=10.0)
    return concat_chunks(SensorChunk(imu=c.imu, mag=c.mag, temperature=c.temperature) for c in sim.simulate(cfg))


def from_bag(path: str) -> SensorChunk:
    from gyro_thermal_comp.bag_io import read_chunks
    chunk = concat_chunks(read_chunks(path, 60.0, streams=('imu', 'mag', 'temperature')))
    return SensorChunk(imu=chunk.imu, mag=chunk.mag, temperature=chunk.temperature)


def split(record: SensorChunk, chunk_s: float) -> list[SensorChunk]:
    """Consecutive chunks of `chunk_s` of stamps (every stream cut at the same times)."""
    t0, t1 = float(record.imu.t[0]), float(record.imu.t[-1])
    edges = t0 + chunk_s * np.arange(int(np.floor((t1 - t0) / chunk_s)) + 2)
    cut = {n: np.searchsorted(s.t, edges) for n, s in record.streams().items()}
    return [SensorChunk(**{n: slice_samples(s, slice(cut[n][i], cut[n][i + 1])) for n, s in record.streams().items()})
            for i in range(edges.size - 1)]


# ------------------------------------------------------------------ the methods
# Each is (make, step): a fresh object, then one call per chunk. Passes are primed untimed.
def make_estimator(rate_hz):
    est = ThermalDriftEstimator(EstimatorConfig())
    return est.process


def make_compensator(rate_hz):
    comp = ThermalCompensator(EstimatorConfig())
    return lambda c: comp.run(c, 0)


def make_fusion(read_output: bool):
    def make(rate_hz):
        import imufusion
        settings = imufusion.AhrsSettings()
        settings.sample_rate = rate_hz
        settings.convention = imufusion.CONVENTION_ENU
        ahrs = imufusion.Ahrs()
        ahrs.set_settings(settings)
        last_mag = [np.empty(0), np.empty((0, 3))]

        def step(c):
            mag_t, mag_f = last_mag
            if c.mag.t.size:   # the latest magnetometer sample at or before each IMU sample
                mag_t, mag_f = np.concatenate((mag_t[-1:], c.mag.t)), np.concatenate((mag_f[-1:], c.mag.field))
                last_mag[:] = mag_t, mag_f
            i = np.maximum(np.searchsorted(mag_t, c.imu.t, side='right') - 1, 0)
            gyro, accel = np.degrees(c.imu.gyro), c.imu.accel / STANDARD_GRAVITY_M_S2
            mag = mag_f[i] * 1e6 if mag_t.size else np.zeros_like(gyro)
            update, get_q, out = ahrs.update, ahrs.get_quaternion, []
            for b in range(0, gyro.shape[0], FUSION_BLOCK):   # small lists: a big list of lists costs GC time
                rows = zip(*(v[b:b + FUSION_BLOCK].tolist() for v in (gyro, accel, mag)))
                if read_output:
                    for g, a, m in rows:
                        update(g, a, m)
                        out.append(get_q())
                else:
                    for g, a, m in rows:
                        update(g, a, m)
        return step
    return make


def make_fusion_peer(rate_hz):
    return FusionPeer(sample_rate_hz=rate_hz).update


MAKE = {'estimator': make_estimator, 'compensator': make_compensator, 'fusion_loop': make_fusion(True),
        'fusion_update_only': make_fusion(False), 'fusion_peer': make_fusion_peer}


def time_method(name: str, rate_hz: float, prime: SensorChunk, chunks) -> tuple[float, float]:
    """(process CPU s, wall s) of one pass over `chunks`, by a fresh object primed with `prime`."""
    step = MAKE[name](rate_hz)
    step(prime)
    c0, w0 = time.process_time(), time.perf_counter()
    for c in chunks:
        step(c)
    return time.process_time() - c0, time.perf_counter() - w0


def prepared(record: SensorChunk, chunk_s: float):
    """(IMU rate Hz, the priming chunk, the timed chunks)."""
    t0, t1 = float(record.imu.t[0]), float(record.imu.t[-1])
    t_prime = t0 + min(PRIME_S, 0.5 * (t1 - t0))   # a short record: its first half
    streams = record.streams()
    prime = SensorChunk(**{k: slice_samples(s, s.t < t_prime) for k, s in streams.items()})
    rest = SensorChunk(**{k: slice_samples(s, s.t >= t_prime) for k, s in streams.items()})
    return float(1.0 / np.median(np.diff(record.imu.t))), prime, split(rest, chunk_s)[:MAX_CHUNKS]


def measure(record: SensorChunk, chunk_s: float, repeats: int) -> dict:
    """Every method on the same chunks: the first PRIME_S of the record untimed in one chunk (the
    still period and the first windows are behind), then at most MAX_CHUNKS chunks of `chunk_s`."""
    rate_hz, prime, chunks = prepared(record, chunk_s)
    n = sum(int(c.imu.t.size) for c in chunks)
    cpu = {m: [] for m in METHODS}
    wall = {m: [] for m in METHODS}
    for _ in range(repeats):   # interleaved: a burst of load hits every method alike
        for m in METHODS:
            c, w = time_method(m, rate_hz, prime, chunks)
            cpu[m].append(c)
            wall[m].append(w)
    res = {'chunk_s': chunk_s, 'chunks': len(chunks), 'imu_samples': n, 'timed_s': n / rate_hz, 'methods': {}}
    for m in METHODS:
        res['methods'][m] = {'samples_per_s_cpu_best': n / min(cpu[m]),
                             'samples_per_s_cpu_median': n / float(np.median(cpu[m])),
                             'samples_per_s_wall_best': n / min(wall[m]), 'cpu_s': cpu[m], 'wall_s': wall[m],
                             'us_per_chunk_cpu_best': 1e6 * min(cpu[m]) / len(chunks)}
    return res


def ratios(res: dict) -> dict:
    m = res['methods']
    return {f'{c}/{f}': m[c]['samples_per_s_cpu_best'] / m[f]['samples_per_s_cpu_best']
            for c in CORE for f in FUSION if c in m and f in m}


def per_call(results: list[dict], method: str = 'estimator') -> dict:
    """CPU per call at the smallest chunk (its overhead: a few samples each) and the marginal cost per
    sample between the smallest and the largest chunk of the same record."""
    small = min(results, key=lambda r: r['imu_samples'] / r['chunks'])
    same = [r for r in results if r['record'] == small['record']]
    big = max(same, key=lambda r: r['imu_samples'] / r['chunks'])
    n_s, n_b = small['imu_samples'] / small['chunks'], big['imu_samples'] / big['chunks']
    t_s, t_b = (r['methods'][method]['us_per_chunk_cpu_best'] for r in (small, big))
    per_sample = (t_b - t_s) / (n_b - n_s) if n_b > n_s else float('nan')
    return {'method': method, 'record': small['record'], 'samples_per_call_small': n_s,
            'us_per_call_small': t_s, 'samples_per_call_big': n_b, 'us_per_sample_marginal': per_sample,
            'overhead_us_per_call': t_s - per_sample * n_s}


def block_loops(record: SensorChunk, chunk_s: float, repeats: int) -> dict | None:
    """CPU per compass block of `HeadingFilter.run` and `MagneticGate.update` inside the estimator
    (chunks of `chunk_s`), best of `repeats` passes, and their share of the estimator's CPU; None
    when no block closed (no compass)."""
    rate_hz, prime, chunks = prepared(record, chunk_s)
    cpu = {'heading_filter': [], 'gate': [], 'estimator': []}
    for _ in range(repeats):
        step = MAKE['estimator'](rate_hz)
        step(prime)
        spent, blocks = {'heading_filter': 0.0, 'gate': 0.0}, [0]

        def timed(method, name):
            def call(self, t, *args, **kwargs):   # both run once on every closed block
                c0 = time.process_time()
                out = method(self, t, *args, **kwargs)
                spent[name] += time.process_time() - c0
                blocks[0] += len(t) if name == 'gate' else 0
                return out
            return call
        saved = HeadingFilter.run, MagneticGate.update
        HeadingFilter.run, MagneticGate.update = timed(saved[0], 'heading_filter'), timed(saved[1], 'gate')
        try:
            c0 = time.process_time()
            for c in chunks:
                step(c)
            cpu['estimator'].append(time.process_time() - c0)
        finally:
            HeadingFilter.run, MagneticGate.update = saved
        for name, v in spent.items():
            cpu[name].append(v)
    if not blocks[0]:
        return None
    best = {k: min(v) for k, v in cpu.items()}
    return {'rate_hz': rate_hz, 'chunk_s': chunk_s, 'blocks': blocks[0], 'block_s': EstimatorConfig().compass_block_s,
            'us_per_block': {k: 1e6 * best[k] / blocks[0] for k in ('heading_filter', 'gate')},
            'share_of_estimator': (best['heading_filter'] + best['gate']) / best['estimator']}


def loops_vs_fusion(loops: dict, results: list[dict]) -> float:
    """(heading filter + gate) CPU per block / imufusion's CPU for one block's IMU samples (`results`:
    the same record's)."""
    res = next(r for r in results if r['chunk_s'] == loops['chunk_s'])
    fusion_us_per_sample = 1e6 / res['methods']['fusion_loop']['samples_per_s_cpu_best']
    return sum(loops['us_per_block'].values()) / (fusion_us_per_sample * loops['rate_hz'] * loops['block_s'])


def estimator_at(rev: str):
    """ThermalDriftEstimator of this package at git revision `rev`, imported as a package of another
    name (its modules import each other relatively). Raises CalledProcessError for an unknown rev."""
    archive = subprocess.run(['git', 'archive', rev, 'gyro_thermal_comp'], cwd=REPO, capture_output=True,
                             check=True).stdout
    _TEMP_DIRS.append(tempfile.TemporaryDirectory(prefix='core_speed_'))   # removed at exit
    where = Path(_TEMP_DIRS[-1].name) / 'gyro_thermal_comp'
    tarfile.open(fileobj=io.BytesIO(archive)).extractall(where.parent, filter='data')
    name = 'gyro_thermal_comp_' + re.sub(r'\W', '_', rev)
    spec = importlib.util.spec_from_file_location(name, where / '__init__.py', submodule_search_locations=[str(where)])
    sys.modules[name] = package = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(package)
    return importlib.import_module(name + '.thermal.estimator').ThermalDriftEstimator


def against(record: SensorChunk, chunk_s: float, repeats: int, old_estimator, rev: str) -> dict:
    """CPU per chunk of this estimator and `old_estimator` (git `rev`), chunk by chunk in turn."""
    rate_hz, prime, chunks = prepared(record, chunk_s)
    best = {'this': np.inf, rev: np.inf}
    for r in range(repeats):
        ests = {'this': ThermalDriftEstimator(EstimatorConfig()), rev: old_estimator(EstimatorConfig())}
        for est in ests.values():
            est.process(prime)
        cpu = dict.fromkeys(ests, 0.0)
        order = list(ests) if r % 2 == 0 else list(ests)[::-1]
        for c in chunks:
            for k in order:
                c0 = time.process_time()
                ests[k].process(c)
                cpu[k] += time.process_time() - c0
        best = {k: min(best[k], cpu[k]) for k in best}
    return {'rev': rev, 'rate_hz': rate_hz, 'chunk_s': chunk_s, 'chunks': len(chunks),
            'us_per_chunk_cpu_best': {k: 1e6 * v / len(chunks) for k, v in best.items()},
            'this_over_rev': best['this'] / best[rev]}


def profile(record: SensorChunk, chunk_s: float, top: int, method: str = 'estimator') -> dict:
    """cProfile of `method` per chunk (primed as timed): the `top` functions by own time, and this
    package's by cumulative time. (cProfile inflates small calls: shares, not absolute times.)"""
    rate_hz, prime, chunks = prepared(record, chunk_s)
    step = MAKE[method](rate_hz)
    step(prime)
    prof = cProfile.Profile()
    prof.enable()
    for c in chunks:
        step(c)
    prof.disable()
    stats = pstats.Stats(prof)
    total, rows = stats.total_tt, []
    for (path, line, func), (cc, nc, tt, ct, _) in stats.stats.items():
        ours = path.startswith(str(REPO))
        rel = os.path.relpath(path, REPO) if ours else path.replace(sys.prefix, '<venv>')
        rows.append({'where': f'{rel}:{line}', 'function': func, 'calls': nc, 'own_s': tt, 'cum_s': ct, 'ours': ours,
                     'own_us_per_process_call': 1e6 * tt / len(chunks),
                     'cum_us_per_process_call': 1e6 * ct / len(chunks)})
    own = sorted(rows, key=lambda r: -r['own_s'])[:top]
    cum = sorted((r for r in rows if r['ours']), key=lambda r: -r['cum_s'])[:top]
    print(f'\ncProfile: {method} at {rate_hz:g} Hz, {len(chunks)} chunks of {chunk_s:g} s, '
          f'{1e6 * total / len(chunks):.0f} us per call under the profiler')
    for title, sel, key in (('own time', own, 'own_us_per_process_call'),
                            ('cumulative time, this package', cum, 'cum_us_per_process_call')):
        print(f"top {top} by {title}:\n{'us/call':>8s} {'%':>5s} {'calls':>8s}  where")
        for r in sel:
            print(f"{r[key]:8.1f} {100 * r[key] * len(chunks) / 1e6 / total:5.1f} {r['calls']:8d}  "
                  f"{r['where']} {r['function']}")
    return {'method': method, 'rate_hz': rate_hz, 'chunk_s': chunk_s, 'chunks': len(chunks),
            'us_per_call_profiled': 1e6 * total / len(chunks), 'by_own_time': own, 'by_cumulative_time': cum}


def parse_floats(p, text: str, what: str) -> list[float]:
    try:
        values = [float(x) for x in text.split(',')]
    except ValueError:
        p.error(f'{what} must be numbers separated by commas, not {text!r}')
    if not values or not all(v > 0 and np.isfinite(v) for v in values):
        p.error(f'{what} must be positive numbers, not {text!r}')
    return values


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    p.error = lambda message: sys.exit(f'core_speed: {message}')   # one line, exit status 1
    p.add_argument('--rates', default=DEFAULTS['rates'], help='simulated IMU rates, Hz, comma-separated (10..5000)')
    p.add_argument('--chunks', default=DEFAULTS['chunks'], help='chunk lengths, s, comma-separated')
    p.add_argument('--duration', type=float, default=DEFAULTS['duration'], help='simulated record, s (40..7200)')
    p.add_argument('--repeats', type=int, default=DEFAULTS['repeats'], help='timed passes per method (1..20)')
    p.add_argument('--bag', help='a bag to read instead of simulating (its own rates)')
    p.add_argument('--json', default=str(RESULTS_JSON), help='where the results go (default: %(default)s)')
    p.add_argument('--profile', action='store_true',
                   help='also cProfile the estimator at 100 Hz (0.02 s, 10 s chunks) and the compensator (10 s)')
    p.add_argument('--against', metavar='REV', help="also time the estimator of git revision REV (e.g. HEAD) "
                   "interleaved with this one, chunk by chunk: CPU ratio this / REV")
    a = p.parse_args()
    rates, chunk_lengths = parse_floats(p, a.rates, '--rates'), parse_floats(p, a.chunks, '--chunks')
    if not all(10 <= r <= 5000 for r in rates) or not 40 <= a.duration <= 7200 or not 1 <= a.repeats <= 20:
        p.error('out of range: --rates 10..5000 Hz, --duration 40..7200 s, --repeats 1..20')
    old_estimator = None
    if a.against:
        try:
            old_estimator = estimator_at(a.against)
        except subprocess.CalledProcessError as exc:
            p.error(f'--against {a.against}: {exc.stderr.decode(errors="replace").strip().splitlines()[-1]}')
    if a.bag:
        from gyro_thermal_comp.bag_io import BagError
        try:
            records = {'bag': from_bag(a.bag)}
        except (BagError, OSError, ValueError) as exc:
            p.error(f'cannot read {a.bag}: {str(exc).splitlines()[0] if str(exc) else type(exc).__name__}')
        if records['bag'].imu is None or records['bag'].imu.t.size < 2:
            p.error(f'{a.bag} has no IMU samples')
    else:
        records = {f'{r:g} Hz': simulated(r, a.duration) for r in rates}
    results = []
    for label, record in records.items():
        for chunk_s in chunk_lengths:
            res = measure(record, chunk_s, a.repeats)
            res['record'] = label
            res['ratios_cpu_best'] = ratios(res)
            results.append(res)
            print_result(res)
    out = {'date': datetime.now(timezone.utc).strftime('%Y-%m-%d %H:%M UTC'), 'machine': cpu_model(),
           'cpus': os.cpu_count(), 'load_1min_at_start': LOAD_AT_START,
           'command': ' '.join(['.venv/bin/python benchmarks/core_speed.py'] + sys.argv[1:]),
           'source': a.bag or 'simulated vehicle_loop, seed 13', 'duration_s': None if a.bag else a.duration,
           'repeats': a.repeats, **code_state(), 'results': results}
    if len(chunk_lengths) >= 2:
        f = out['estimator_per_call'] = per_call(results)
        print(f"\nestimator ({f['record']}): {f['us_per_call_small']:.0f} us CPU per process() call of "
              f"{f['samples_per_call_small']:g} samples, {f['us_per_sample_marginal']:.3f} us per further sample "
              f"(up to {f['samples_per_call_big']:g} per call): overhead ~ {f['overhead_us_per_call']:.0f} us per call")
    first = next(iter(records))
    loops = out['block_loops'] = block_loops(records[first], max(chunk_lengths), a.repeats)
    if loops is not None:
        loops['vs_fusion_loop'] = loops_vs_fusion(loops, [r for r in results if r['record'] == first])
        us = loops['us_per_block']
        print(f"\nper-block loops ({first}, {loops['chunk_s']:g} s chunks, {loops['blocks']} blocks of "
              f"{loops['block_s']:g} s): heading filter {us['heading_filter']:.1f} us + gate {us['gate']:.1f} us "
              f"CPU per block ({100 * loops['share_of_estimator']:.0f} % of the estimator) = "
              f"{loops['vs_fusion_loop']:.2f}x imufusion's CPU for the block's "
              f"{loops['rate_hz'] * loops['block_s']:g} IMU samples")
    if old_estimator is not None:
        out['against'] = []
        for label, record in records.items():
            for chunk_s in chunk_lengths:
                r = against(record, chunk_s, a.repeats, old_estimator, a.against)
                r['record'] = label
                out['against'].append(r)
                us = r['us_per_chunk_cpu_best']
                print(f"against {a.against} ({label}, {chunk_s:g} s chunks, {r['chunks']} chunks): this "
                      f"{us['this']:.0f} us, {a.against} {us[a.against]:.0f} us CPU per chunk: this / {a.against} "
                      f"{r['this_over_rev']:.3f}")
    if a.profile:
        rec = records.get('100 Hz') or next(iter(records.values()))
        out['profile'] = [profile(rec, chunk_s, 25) for chunk_s in (0.02, 10.0)] + \
            [profile(rec, 10.0, 12, 'compensator')]
    path = Path(a.json)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(out, indent=1) + '\n')
    except OSError as exc:
        sys.exit(f'core_speed: cannot write {path}: {exc.strerror or exc}')
    print(f'written: {path}')
    if not a.bag and path.resolve() == RESULTS_JSON and all(getattr(a, k) == v for k, v in DEFAULTS.items()):
        write_results_section(out)
    return 0


def print_result(res: dict) -> None:
    print(f"\n{res['record']}, {res['chunk_s']:g} s chunks ({res['chunks']} chunks, {res['imu_samples']} IMU samples):")
    print(f"{'':20s}{'M samples/s (CPU, best)':>25s}{'median':>9s}{'us/chunk':>10s}")
    for m, v in res['methods'].items():
        print(f"{m:20s}{v['samples_per_s_cpu_best'] / 1e6:25.3f}{v['samples_per_s_cpu_median'] / 1e6:9.3f}"
              f"{v['us_per_chunk_cpu_best']:10.1f}")
    print('  ratios: ' + ', '.join(f'{k} {v:.2f}x' for k, v in res['ratios_cpu_best'].items()))


def target_status(results: list[dict]) -> str:
    """The speed target from this run: estimator / fusion_loop at 100 Hz, chunks of 10 s and more
    (what replay and evaluate hand the core; the live node's 0.02 s batches are a per-call cost)."""
    got = [(res['chunk_s'], res['ratios_cpu_best']['estimator/fusion_loop']) for res in results
           if res['record'] == '100 Hz' and res['chunk_s'] >= 10.0]
    if not got:
        return 'not measured'
    worst = min(q for _, q in got)
    return ('met' if worst >= 1.0 else 'NOT met') + ' (' + ', '.join(f'{c:g} s chunks {q:.2f}x' for c, q in got) + ')'


def write_results_section(r: dict) -> None:
    """Replace the core-speed section of benchmarks/RESULTS.md (generated, never typed)."""
    title = '## Core on arrays vs imufusion'
    rows = []
    for res in r['results']:
        m, q = res['methods'], res['ratios_cpu_best']
        rows.append(f"| {res['record']} | {res['chunk_s']:g} s | "
                    + ' | '.join(f"{m[k]['samples_per_s_cpu_best'] / 1e6:.3f}" for k in METHODS)
                    + f" | {q['estimator/fusion_loop']:.2f}x | {q['estimator/fusion_update_only']:.2f}x "
                      f"| {q['compensator/fusion_loop']:.2f}x |")
    f, b = r.get('estimator_per_call', {}), r.get('block_loops', {})
    section = (f"{title}\n\n`{r['command']}` on {r['machine']} ({r['cpus']} cores, load average "
               f"{r['load_1min_at_start']:.2f} at start), {r['date']}. {r['source']}, {r['duration_s']:g} s; "
               f"M IMU samples per CPU second, best of {r['repeats']}:\n\n"
               '| IMU | chunk | estimator | compensator | fusion_loop | fusion_update_only | fusion_peer '
               '| estimator / fusion_loop | estimator / fusion_update_only | compensator / fusion_loop |\n'
               '|---|---|---|---|---|---|---|---|---|---|\n' + '\n'.join(rows) +
               (f"\n\nEstimator ({f['record']}): {f['us_per_call_small']:.0f} us CPU per `process()` call of "
                f"{f['samples_per_call_small']:g} samples, {f['us_per_sample_marginal']:.3f} us per further sample: "
                f"~{f['overhead_us_per_call']:.0f} us overhead per call." if f else '') +
               (f"\n\nPer-block loops ({b['rate_hz']:g} Hz, {b['chunk_s']:g} s chunks): the heading filter "
                f"{b['us_per_block']['heading_filter']:.1f} us and the gate {b['us_per_block']['gate']:.1f} us CPU per "
                f"{b['block_s']:g} s compass block, {100 * b['share_of_estimator']:.0f} % of the estimator's CPU: "
                f"{b['vs_fusion_loop']:.2f}x imufusion's CPU for the block's {b['rate_hz'] * b['block_s']:g} IMU "
                "samples "
                "(above 1x these Python loops alone are slower than imufusion's C loop)." if b else '') +
               f"\n\nTarget: estimator at 100 Hz >= imufusion's C loop: {target_status(r['results'])}. "
               'Raw figures and the profile: `benchmarks/results/core_speed.json`.\n')
    replace_section(title, section)


if __name__ == '__main__':
    sys.exit(main())
