"""Offline replay against the bag-I/O floor, side by side in one run.

    .venv/bin/python benchmarks/replay_floor.py                  # 60 min bags: what benchmarks/RESULTS.md reports
    .venv/bin/python benchmarks/replay_floor.py --minutes 5      # a quick look (not written to RESULTS.md)
    .venv/bin/python benchmarks/replay_floor.py --minutes 5 --profile   # + where replay's time goes (cProfile)

Two bags from the simulator CLI (kept in --bags, regenerated when the command changes):
50 Hz `vehicle_loop` (IMU 50 Hz, compass 10 Hz, temperature 1 Hz, truth 10 Hz, the bundled bag's rates)
and 1 kHz `static_ramp` (IMU 1 kHz, compass 100 Hz, temperature 10 Hz, truth 10 Hz, the soak's rates).

For each bag, in this process, one after the other (floor, replay, I/O path, floor):
- replay: `gyro_thermal_comp.nodes.replay.replay(bag, out)` (the in-process stkf node, inputs copied
  and outputs recorded into a new bag);
- floor: rosbags alone reads the same bag and deserialises every message, and its own Writer
  (mcap, zstd chunks) writes as many messages as replay wrote (each record read once under its
  topic, the rest as copies of the IMU records: about the size of the outputs);
- I/O path: the package's bulk reading and writing alone (`io_path`: raw records copied, two outputs
  per IMU sample encoded by cdr.py), no node: what replay cannot go below with these bag paths.
The floor runs before and after replay; its figure is the mean of the two (load on a shared
machine drifts). Printed: replay / floor in CPU and wall time, real-time factor (bag seconds per
wall second) and CPU us per IMU sample. A full run (60 min, both bags) writes
benchmarks/results/replay_floor.json and the replay section of benchmarks/RESULTS.md; a quick look
writes benchmarks/results/replay_floor_quick.json. Targets: replay <= 2.0x the floor
and >= 30x real time on the 1 h 1 kHz bag.
"""
from __future__ import annotations

import argparse
import cProfile
import io
import json
import os
import pstats
import shutil
import subprocess
import sys
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
os.environ.setdefault('ROS_DOMAIN_ID', str(60 + os.getpid() % 30))

import numpy as np  # noqa: E402
from rosbags.rosbag2 import CompressionFormat, CompressionMode, Reader, StoragePlugin, Writer  # noqa: E402
from rosbags.typesys import Stores, get_typestore  # noqa: E402

from gyro_thermal_comp import topics  # noqa: E402
sys.path.insert(0, str(Path(__file__).resolve().parent))   # bench_report.py beside this script
from bench_report import cpu_model, replace_section  # noqa: E402

TARGET_RATIO, TARGET_RTF = 2.0, 30.0
BAGS = {  # name -> simulate arguments (the duration is added)
    '50hz': ['vehicle_loop', '--seed', '3', '--imu-rate', '50', '--mag-rate', '10', '--temp-rate', '1',
             '--truth-rate', '10'],
    '1khz': ['static_ramp', '--seed', '1', '--imu-rate', '1000', '--mag-rate', '100', '--temp-rate', '10',
             '--truth-rate', '10'],
}


def make_bag(folder: Path, name: str, minutes: float) -> tuple[Path, str]:
    """The bag from the simulator CLI, reused while its command is unchanged."""
    args = ['simulate', *BAGS[name], '--duration', f'{minutes * 60:g}']
    command = 'gyro-thermal-comp ' + ' '.join(args)
    bag = folder / f'{name}_{minutes:g}min'
    stamp = folder / f'{bag.name}.command'
    if not (bag.is_dir() and stamp.is_file() and stamp.read_text() == command):
        print(f'generating: {command}', flush=True)
        shutil.rmtree(bag, ignore_errors=True)
        subprocess.run([sys.executable, '-m', 'gyro_thermal_comp.cli', *args, '--out', str(bag)], check=True)
        stamp.write_text(command)
    return bag, command


def timed(fn):
    """(result, CPU s of this process, wall s)."""
    cpu0, wall0 = time.process_time(), time.perf_counter()
    result = fn()
    return result, time.process_time() - cpu0, time.perf_counter() - wall0


def floor(bag: Path, writes: int, out: Path) -> dict:
    """rosbags alone: read + deserialise every message, write `writes` messages (each record once,
    the remainder spread over the IMU records as copies)."""
    store = get_typestore(Stores.ROS2_JAZZY)
    imu_topic = topics.BAG_STREAMS['imu'][0]
    shutil.rmtree(out, ignore_errors=True)
    with Reader(bag) as reader:
        n_read = sum(c.msgcount for c in reader.connections)
        n_imu = sum(c.msgcount for c in reader.connections if c.topic == imu_topic)
        extra, done_extra, seen_imu = writes - n_read, 0, 0
        writer = Writer(out, version=9, storage_plugin=StoragePlugin.MCAP)
        writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        with writer:
            conns = {c.topic: writer.add_connection(c.topic, c.msgtype, typestore=store) for c in reader.connections}
            copy = writer.add_connection('/floor/copies', 'sensor_msgs/msg/Imu', typestore=store)
            written = 0
            for conn, t_ns, raw in reader.messages():
                store.deserialize_cdr(raw, conn.msgtype)
                writer.write(conns[conn.topic], t_ns, raw)
                written += 1
                if conn.topic == imu_topic and extra > 0:
                    seen_imu += 1
                    upto = seen_imu * extra // n_imu
                    for _ in range(upto - done_extra):
                        writer.write(copy, t_ns, raw)
                    written += upto - done_extra
                    done_extra = upto
    shutil.rmtree(out, ignore_errors=True)
    return {'read': n_read, 'written': written}


def io_path(bag: Path, out: Path) -> dict:
    """What replay costs with no node at all, through the package's bulk paths: chunks read with
    their raw records (Imu/MagneticField/Temperature decoded as arrays), the records copied
    unchanged, and per IMU sample an Imu and a PoseWithCovarianceStamped encoded in bulk (cdr.py)
    and written in batches. The node's share of replay is what replay costs beyond this."""
    from gyro_thermal_comp import cdr
    from gyro_thermal_comp.bag_io import BagReader, BagWriter
    from gyro_thermal_comp.stamps import ns_at
    shutil.rmtree(out, ignore_errors=True)
    cov9, cov36 = np.diag([1e-6, 1e-6, 1e-4]).ravel(), np.diag([1e6] * 5 + [1e-3]).ravel()
    with BagReader(bag) as reader, BagWriter(out, time_origin_ns=reader.time_origin_ns) as writer:
        for chunk, raw in reader.chunks(10.0, keep_raw=True):
            writer.write_raw_records(raw)
            imu = chunk.imu
            if imu is None:
                continue
            t_ns = ns_at(imu.t, reader.time_origin_ns)
            quat = np.zeros((len(t_ns), 4))
            quat[:, 3] = 1.0
            writer.write_raw_many('/imu/data', cdr.IMU, t_ns, cdr.encode_imu(
                t_ns, 'imu_link', quat, cov9, imu.gyro, cov9, imu.accel, cov9))
            writer.write_raw_many('/imu/heading', cdr.POSE_COV_STAMPED, t_ns,
                                  cdr.encode_pose_with_covariance_stamped(t_ns, 'odom', quat, covariance=cov36))
        counts = dict(writer.counts)
    shutil.rmtree(out, ignore_errors=True)
    return counts


def run_replay(bag: Path, out: Path) -> dict:
    from gyro_thermal_comp.nodes.replay import replay
    shutil.rmtree(out, ignore_errors=True)
    counts = replay(bag, out)
    shutil.rmtree(out, ignore_errors=True)
    return counts


def measure(name: str, bag: Path, command: str, work: Path) -> dict:
    with Reader(bag) as reader:
        duration_s = (reader.end_time - reader.start_time) * 1e-9
        n_imu = sum(c.msgcount for c in reader.connections if c.topic == topics.BAG_STREAMS['imu'][0])
        n_msgs = sum(c.msgcount for c in reader.connections)
    expected = n_msgs + 2 * n_imu + int(duration_s)   # inputs, imu/data + imu/heading, diagnostics at 1 Hz
    f1, f1_cpu, f1_wall = timed(lambda: floor(bag, expected, work / 'floor'))
    counts, r_cpu, r_wall = timed(lambda: run_replay(bag, work / 'replay'))
    writes = sum(counts.values())
    io_counts, io_cpu, io_wall = timed(lambda: io_path(bag, work / 'io'))
    f2, f2_cpu, f2_wall = timed(lambda: floor(bag, writes, work / 'floor'))
    floor_cpu, floor_wall = (f1_cpu + f2_cpu) / 2, (f1_wall + f2_wall) / 2
    r = {'bag': name, 'generate': command, 'duration_s': duration_s, 'imu_samples': n_imu,
         'messages_read': n_msgs, 'messages_written_by_replay': writes,
         'floor_writes': [f1['written'], f2['written']],
         'floor_cpu_s': [f1_cpu, f2_cpu], 'floor_wall_s': [f1_wall, f2_wall],
         'replay_cpu_s': r_cpu, 'replay_wall_s': r_wall,
         'ratio_cpu': r_cpu / floor_cpu, 'ratio_wall': r_wall / floor_wall,
         'io_path_cpu_s': io_cpu, 'io_path_wall_s': io_wall, 'io_path_written': sum(io_counts.values()),
         'io_path_ratio_cpu': io_cpu / floor_cpu, 'io_path_cpu_us_per_imu_sample': 1e6 * io_cpu / n_imu,
         'real_time_factor': duration_s / r_wall,
         'replay_cpu_us_per_imu_sample': 1e6 * r_cpu / n_imu, 'floor_cpu_us_per_imu_sample': 1e6 * floor_cpu / n_imu}
    print(f"{name}: replay/floor {r['ratio_cpu']:.2f}x CPU ({r_cpu:.1f} s vs {f1_cpu:.1f}/{f2_cpu:.1f} s), "
          f"{r['ratio_wall']:.2f}x wall; {r['real_time_factor']:.1f}x real time; "
          f"{r['replay_cpu_us_per_imu_sample']:.1f} us CPU per IMU sample (floor "
          f"{r['floor_cpu_us_per_imu_sample']:.1f}); I/O path alone {r['io_path_ratio_cpu']:.2f}x the floor "
          f"({r['io_path_cpu_us_per_imu_sample']:.1f} us per IMU sample)", flush=True)
    return r


# cProfile breakdown: where a function's own time goes, by the file it is in
_PARTS = [
    ('estimator (thermal/, heading, angles)', ('/gyro_thermal_comp/thermal/', 'heading_track.py', 'angles.py')),
    ('node per-sample path (nodes/, input_guard, samples, stamps)', ('/gyro_thermal_comp/nodes/', 'input_guard.py',
                                                                    'samples.py', 'stamps.py', 'progress.py')),
    ('rclpy messages + serialize_message', ('/rclpy/', '/sensor_msgs/', '/geometry_msgs/', '/std_msgs/',
                                            '/builtin_interfaces/', '/diagnostic_msgs/', 'rclpy_serialize')),
    ('bag write (mcap writer, zstd)', ('/mcap/writer', '/mcap/_chunk_builder', '/mcap/records', '/mcap/data_stream',
                                       'bag_storage.py', '/rosbags/rosbag2/writer', 'zstandard', 'zstd')),
    ('bag read + decode (rosbags reader, cdr.py, bag_io)', ('/rosbags/', 'bag_io.py', 'bag_reader.py',
                                                           'bag_messages.py', 'bag_writer.py', 'cdr.py', '/mcap/')),
    ('numpy (called from all of the above)', ('/numpy/', "numpy.", "'numpy")),
]


def profile_replay(bag: Path, out: Path) -> dict:
    prof = cProfile.Profile()
    prof.runcall(run_replay, bag, out)
    stats = pstats.Stats(prof)
    total = sum(v[2] for v in stats.stats.values())
    parts = {name: 0.0 for name, _ in _PARTS} | {'other': 0.0}
    for (file, line, func), (_, _, tottime, _, _) in stats.stats.items():
        where = f'{file}:{func}'
        part = next((name for name, keys in _PARTS if any(k in where for k in keys)), 'other')
        parts[part] += tottime
    print(f'\nreplay under cProfile ({total:.1f} s of own time; profiling inflates per-call costs):')
    for name, t in sorted(parts.items(), key=lambda kv: -kv[1]):
        print(f'  {100 * t / total:5.1f} %  {name}')
    text = io.StringIO()
    pstats.Stats(prof, stream=text).sort_stats('tottime').print_stats(25)
    print('\n'.join(text.getvalue().splitlines()[6:]))
    return {name: t / total for name, t in parts.items()}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--minutes', type=float, default=60.0, help='bag length, min (default 60: the targets\' 1 h)')
    ap.add_argument('--bags', type=Path, default=Path(tempfile.gettempdir()) / 'gtc_replay_floor',
                    help='folder for the generated bags (kept for the next run)')
    ap.add_argument('--only', choices=sorted(BAGS), help='just one of the bags')
    ap.add_argument('--profile', action='store_true', help='then profile replay of the 1 kHz bag (cProfile)')
    args = ap.parse_args(argv)
    if not args.minutes > 0:
        print('replay_floor.py: error: --minutes must be positive', file=sys.stderr)
        return 2
    try:
        args.bags.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        print(f'replay_floor.py: error: cannot use --bags {args.bags}: {exc.strerror or exc}', file=sys.stderr)
        return 2
    names = [args.only] if args.only else list(BAGS)
    bags = {name: make_bag(args.bags, name, args.minutes) for name in names}
    load = os.getloadavg()[0]
    results = []
    with tempfile.TemporaryDirectory(dir=args.bags) as work:
        for name in names:
            results.append(measure(name, *bags[name], Path(work)))
        breakdown = profile_replay(bags['1khz'][0], Path(work) / 'profiled') if args.profile and '1khz' in bags else None
    command = '.venv/bin/python benchmarks/replay_floor.py' + ('' if args.minutes == 60 else f' --minutes {args.minutes:g}') \
        + (f' --only {args.only}' if args.only else '') + (' --profile' if args.profile else '')
    summary = {'date': datetime.now(timezone.utc).strftime('%Y-%m-%d %H:%M UTC'), 'machine': cpu_model(),
               'cpus': os.cpu_count(), 'load_average_at_start': load, 'command': command, 'minutes': args.minutes,
               'results': results, 'profile_share': breakdown}
    full = args.minutes >= 60 and not args.only
    out = HERE / 'results' / ('replay_floor.json' if full else 'replay_floor_quick.json')   # a quick look keeps the full run's
    out.parent.mkdir(exist_ok=True)
    out.write_text(json.dumps(summary, indent=1))
    print(f'written: {out}')
    if full:
        write_results_section(summary)
    return 0


def write_results_section(s: dict) -> None:
    """Replace the replay section of benchmarks/RESULTS.md (generated, never typed)."""
    title = '## Replay vs the bag-I/O floor'
    rows = ''.join(
        f"| {r['bag']} ({r['duration_s'] / 60:.0f} min, {r['imu_samples']} IMU) | {r['ratio_cpu']:.2f}x "
        f"({r['ratio_wall']:.2f}x) | {r['real_time_factor']:.1f}x | {r['replay_cpu_us_per_imu_sample']:.1f} "
        f"({r['floor_cpu_us_per_imu_sample']:.1f}) | {r['io_path_ratio_cpu']:.2f}x |\n" for r in s['results'])
    section = (f"{title}\n\n`{s['command']}` on {s['machine']} ({s['cpus']} cores, load average "
               f"{s['load_average_at_start']:.1f} at the start), {s['date']}. Floor: the same bag read and "
               f"deserialised by rosbags alone, and as many messages written by rosbags' Writer; measured "
               f"before and after replay, mean of the two. Bags: "
               + '; '.join(f"`{r['generate']}`" for r in s['results'])
               + f".\n\n| bag | replay / floor, CPU (wall) | real time | CPU us per IMU sample (floor) "
               f"| bulk I/O path alone / floor, CPU |\n|---|---|---|---|---|\n{rows}\nTargets on the 1 h 1 kHz bag: <= {TARGET_RATIO:.1f}x the floor, "
               f">= {TARGET_RTF:.0f}x real time. Raw figures: `benchmarks/results/replay_floor.json`.\n")
    replace_section(title, section)


if __name__ == '__main__':
    sys.exit(main())
