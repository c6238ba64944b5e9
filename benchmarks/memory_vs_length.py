"""Peak RSS of `replay`, `evaluate` and `discover` against the bag's length.

    .venv/bin/python benchmarks/memory_vs_length.py                      # 2 h and 8 h, IMU 100 Hz
    .venv/bin/python benchmarks/memory_vs_length.py --hours 0.5 2 --commands discover   # a quick look

Bags of one scenario (static_ramp, seed 1; IMU `--imu-rate` Hz, compass 10 Hz, temperature 1 Hz,
truth 10 Hz) are written by `gyro-thermal-comp simulate` (it streams: memory bounded by one chunk)
into `--bag-dir` and reused when already there. Each command runs as its own process under a fresh
wrapper process whose `resource.getrusage(RUSAGE_CHILDREN).ru_maxrss` is that command's peak RSS
alone. Prints, per command, the peak at each length and the ratio longest/shortest (target <= 1.2).

Writes benchmarks/results/memory_vs_length.json (one entry per command, each with the command line,
machine and date of the run that measured it: re-running some commands with the same settings
replaces only theirs) and, once 2 h and 8 h figures of all three commands are there, the memory
section of benchmarks/RESULTS.md.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path
sys.path.insert(0, str(Path(__file__).resolve().parent))   # bench_report.py beside this script
from bench_report import cpu_model, replace_section  # noqa: E402

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
CLI = str(ROOT / '.venv' / 'bin' / 'gyro-thermal-comp')
COMMANDS = ('replay', 'evaluate', 'discover')
TARGET_RATIO = 1.2
SECTION = '## Memory vs bag length'
# runs CMD (argv after the wrapper's) and prints its peak RSS (KiB on Linux) as the last line
_WRAPPER = ('import resource, subprocess, sys\n'
            'code = subprocess.run(sys.argv[1:], stdout=subprocess.DEVNULL).returncode\n'
            'print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss, code)\n')


def bag_for(hours: float, rate_hz: float, bag_dir: Path) -> Path:
    """The scenario's bag of this length and IMU rate, written once and reused."""
    path = bag_dir / f'static_ramp_s1_imu{rate_hz:g}_{hours:g}h'
    if (path / 'metadata.yaml').exists():
        return path
    cmd = [CLI, 'simulate', 'static_ramp', '--seed', '1', '--duration', f'{hours * 3600:g}',
           '--imu-rate', f'{rate_hz:g}', '--mag-rate', '10', '--temp-rate', '1', '--truth-rate', '10',
           '--out', str(path), '--force']
    print('writing', path, flush=True)
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    return path


def peak_rss_mb(argv: list[str]) -> tuple[float, float]:
    """(peak RSS of `argv` in MB, wall time s), run under a fresh wrapper process."""
    t0 = time.monotonic()
    out = subprocess.run([sys.executable, '-c', _WRAPPER, *argv], capture_output=True, text=True, check=True)
    kib, code = out.stdout.split()[-2:]
    if int(code) != 0:
        raise RuntimeError(f'{" ".join(argv)} exited {code}')
    return int(kib) / 1024.0, time.monotonic() - t0


def command_argv(cmd: str, bag: Path, work: Path, args) -> list[str]:
    if cmd == 'replay':
        return [CLI, 'replay', str(bag), '--out', str(work / f'replay_{bag.name}'), '--force']
    if cmd == 'evaluate':
        return [CLI, 'evaluate', str(bag)] + (['--no-peers'] if args.no_peers else [])
    return [CLI, 'discover', str(bag), '--reference', args.reference]


class _Parser(argparse.ArgumentParser):
    def error(self, message):   # one line, no usage block
        self.exit(2, f'memory_vs_length.py: {message}\n')


def main() -> int:
    ap = _Parser(description=__doc__.splitlines()[0])
    ap.add_argument('--hours', type=float, nargs='+', default=[2.0, 8.0], help='bag lengths, h (default 2 8)')
    ap.add_argument('--imu-rate', type=float, default=100.0, help='IMU rate, Hz (default 100)')
    ap.add_argument('--commands', nargs='+', choices=COMMANDS, default=list(COMMANDS))
    ap.add_argument('--bag-dir', type=Path, default=Path(tempfile.gettempdir()) / 'gtc_memory_bags',
                    help='where the bags are written and reused (default: a folder under the temp dir)')
    ap.add_argument('--reference', choices=('static', 'odom'), default='static', help='discover --reference')
    ap.add_argument('--no-peers', action='store_true', help='evaluate --no-peers (faster)')
    args = ap.parse_args()
    if any(h <= 0 for h in args.hours) or args.imu_rate <= 0:
        ap.error('--hours and --imu-rate must be > 0')
    hours = sorted(set(args.hours))
    args.bag_dir.mkdir(parents=True, exist_ok=True)
    bags = {h: bag_for(h, args.imu_rate, args.bag_dir) for h in hours}
    runs: dict[str, dict[str, dict]] = {c: {} for c in args.commands}
    with tempfile.TemporaryDirectory() as work:
        for cmd in args.commands:
            for h in hours:
                mb, wall = peak_rss_mb(command_argv(cmd, bags[h], Path(work), args))
                runs[cmd][f'{h:g}'] = {'peak_rss_mb': mb, 'wall_s': wall}
                print(f'{cmd:9s} {h:5g} h  peak RSS {mb:8.1f} MB  ({wall:.0f} s)', flush=True)
    lo, hi = f'{hours[0]:g}', f'{hours[-1]:g}'
    argv = ' '.join(sys.argv[1:])
    settings = {'hours': hours, 'imu_rate_hz': args.imu_rate, 'discover_reference': args.reference,
                'evaluate_peers': not args.no_peers, 'target_ratio': TARGET_RATIO}
    this_run = {'date': datetime.now(timezone.utc).strftime('%Y-%m-%d %H:%M UTC'), 'machine': cpu_model(),
                'cpus': os.cpu_count(), 'load_average_at_end': os.getloadavg()[0],
                'command': '.venv/bin/python benchmarks/memory_vs_length.py' + (f' {argv}' if argv else '')}
    # one entry per command, each with the run that measured it: a later run of some commands with
    # the same settings replaces only theirs
    path = HERE / 'results' / 'memory_vs_length.json'
    result = {**settings, 'commands': {}}
    if path.exists():
        old = json.loads(path.read_text())
        if all(old.get(k) == v for k, v in settings.items()):
            result['commands'] = old.get('commands', {})
    for c in args.commands:
        ratio = runs[c][hi]['peak_rss_mb'] / runs[c][lo]['peak_rss_mb']
        result['commands'][c] = {**this_run, 'peak_rss_mb': {h: r['peak_rss_mb'] for h, r in runs[c].items()},
                                 'wall_s': {h: r['wall_s'] for h, r in runs[c].items()},
                                 'ratio_longest_to_shortest': ratio}
        print(f'{c:9s} peak RSS {hi} h / {lo} h = {ratio:.3f}x  (target <= {TARGET_RATIO}x)')
    path.parent.mkdir(exist_ok=True)
    path.write_text(json.dumps(result, indent=1))
    if hours[0] == 2.0 and hours[-1] == 8.0 and set(result['commands']) == set(COMMANDS):
        write_results_section(result)
    return 0 if all(result['commands'][c]['ratio_longest_to_shortest'] <= TARGET_RATIO for c in args.commands) else 1


def write_results_section(r: dict) -> None:
    """Replace the memory section of benchmarks/RESULTS.md (generated, never typed)."""
    lo, hi = f"{r['hours'][0]:g}", f"{r['hours'][-1]:g}"
    rows = ''.join(f"| `{c}` | {e['peak_rss_mb'][lo]:.1f} | {e['peak_rss_mb'][hi]:.1f} | "
                   f"{e['ratio_longest_to_shortest']:.3f}x | <= {r['target_ratio']}x | `{e['command']}`, "
                   f"{e['machine']} ({e['cpus']} cores, load {e['load_average_at_end']:.1f}), {e['date']} |\n"
                   for c, e in ((c, r['commands'][c]) for c in COMMANDS))
    section = (f"{SECTION}\n\nstatic_ramp bags (seed 1), IMU {r['imu_rate_hz']:g} Hz; `discover --reference "
               f"{r['discover_reference']}`, `evaluate` {'with' if r['evaluate_peers'] else 'without'} peers, "
               f"`replay` in-process. Peak RSS of each command's own process, MB:\n\n"
               f"| command | {lo} h | {hi} h | {hi} h / {lo} h | target | measured by |\n"
               f"|---|---|---|---|---|---|\n{rows}\nRaw figures: `benchmarks/results/memory_vs_length.json`.\n")
    replace_section(SECTION, section)


if __name__ == '__main__':
    sys.exit(main())
