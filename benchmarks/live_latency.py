"""Live stkf_node vs a pass-through relay, side by side: stamp-to-output latency, drops, CPU.

    .venv/bin/python benchmarks/live_latency.py                         # 200 Hz, 1 kHz, 2 kHz: RESULTS.md
    .venv/bin/python benchmarks/live_latency.py --rates 200 --seconds 3 # a quick look (not written to RESULTS.md)
    .venv/bin/python benchmarks/live_latency.py --executor events       # every process on rclpy's EventsExecutor

Per IMU rate, two passes on loopback DDS (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST, ROS_DOMAIN_ID from
the environment, else 64), each with fresh processes and the same publisher schedule: the node beside
the relay (five processes, the targets' comparison), then the relay beside the raw relay (a sixth
process in the first pass would load the two cores the comparison runs on). The processes:
- the node: `python -m gyro_thermal_comp.nodes.stkf_node` (what `ros2 run gyro_thermal_comp stkf_node`
  starts) with its defaults (best-effort inputs, depth `input_queue_depth`) but `still_period_s`
  (`--still-s`, 5 s) so the measured window runs the learning slow path, not the start-up still period;
- the relay (the targets' reference): a minimal rclpy node that subscribes `imu/data_raw` with the
  node's input QoS and republishes each sensor_msgs/Imu unchanged on `relay/imu/data` with the node's
  output QoS, as message objects (rclpy converts each one from and to CDR);
- the raw relay: the same, but it takes the serialized CDR and publishes those bytes
  (`relay_raw/imu/data`): what DDS and the rclpy executor alone cost, as the node's raw subscriptions
  and publishers do. Both relays spin as the node does (one executor, `spin_once()` in a loop) and
  keep rclpy's defaults otherwise, its QoS-event handlers included (the node has none: interface.py);
- a publisher: IMU at the rate, MagneticField 100 Hz, Temperature 10 Hz (a level, still unit) on the
  node's input topics, best effort. Each stamp is the system clock when the sample is published minus
  a random 0..`--jitter-us` (a driver stamps before it publishes); `--bunch` of the IMU samples are held
  and published together with the next one (a driver reading two from its buffer at once). Stamps of a
  topic stay increasing (a real driver's clock does not go back within a topic);
- a recorder: the outputs of the pass (raw CDR, reliable as the outputs are), `/diagnostics`.
  Latency = the recorder's wall clock in its callback - header stamp (and, beside it, the
  middleware's reception time from the message info, which excludes the recorder's own queueing).

Measured: the IMU samples stamped within `--seconds` after `--still-s` + 2 s of publishing (the
estimator past its still period). CPU = utime + stime from /proc/<pid>/stat over that window. Drops:
published vs received by the recorder, and the node's own counters (`outputs_published`, its
diagnostics `input.*`/`core.*`), which say whether the node or DDS lost a sample.
Writes benchmarks/results/live_latency.json and, for the full run (all three rates, >= 20 s each),
the live-latency section of benchmarks/RESULTS.md.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import signal
import struct
import subprocess
import sys
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
sys.path.insert(0, str(Path(__file__).resolve().parent))   # bench_report.py beside this script
from bench_report import cpu_model, code_state, replace_section  # noqa: E402
from gyro_thermal_comp.nodes.executors import EXECUTORS, make_executor, spin_once_args  # noqa: E402

HERE = Path(__file__).resolve().parent
RESULTS_JSON = HERE / 'results' / 'live_latency.json'
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
os.environ.setdefault('ROS_DOMAIN_ID', '64')

RELAY_TOPICS = {'relay': 'relay/imu/data', 'relay_raw': 'relay_raw/imu/data'}
MAG_HZ, TEMP_HZ = 100.0, 10.0
SYSTEMS = ('node', 'relay', 'relay_raw')
SETTLE_S = 3.0          # after the last sample: outputs drain, the node's 1 Hz diagnostics report all
START_TIMEOUT_S = 90.0  # only turns a hang (discovery, a starved machine) into an error
CLK_TCK = os.sysconf('SC_CLK_TCK')


# ---------------------------------------------------------------- child processes (--role)
class _Stop:
    """SIGINT/SIGTERM end a child's spin loop (whatever disposition it inherited)."""
    def __init__(self):
        self.now = False
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, self._set)

    def _set(self, *_):
        self.now = True


def _init_ros():
    import rclpy
    from rclpy.signals import SignalHandlerOptions
    stop = _Stop()
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    return rclpy, stop


def make_relay(rclpy, depth: int, raw: bool):
    """A node that republishes imu/data_raw: message objects, or (`raw`) the serialized bytes as
    received; rclpy's defaults otherwise. Returns (node, [how many it relayed])."""
    from rclpy.qos import QoSProfile
    from sensor_msgs.msg import Imu
    from gyro_thermal_comp import topics
    from gyro_thermal_comp.nodes.interface import STKF, sensor_qos
    system = 'relay_raw' if raw else 'relay'
    node = rclpy.create_node(f'gtc_latency_{system}')
    pub = node.create_publisher(Imu, RELAY_TOPICS[system], QoSProfile(depth=STKF.output('imu').depth))
    count = [0]

    def relay(msg):
        pub.publish(msg)
        count[0] += 1
    node.create_subscription(Imu, topics.IMU_RAW, relay, sensor_qos(depth), raw=raw)
    return node, count


def run_relay(depth: int, raw: bool, executor_kind: str) -> int:
    rclpy, stop = _init_ros()
    node, count = make_relay(rclpy, depth, raw)
    # Spun as rclpy.spin(node) spins the node: one executor, `spin_once()` without a timeout.
    # rclpy.spin_once(node, timeout_sec=...) would add and remove the node (an extra wait) and create
    # a timeout timer every turn, costs the node does not pay. A timer wakes it to see a stop request.
    node.create_timer(0.1, lambda: None)
    executor = make_executor(executor_kind)
    executor.add_node(node)
    print('ready', flush=True)
    while not stop.now:
        executor.spin_once(**spin_once_args(executor_kind))
    print(json.dumps({'relayed': count[0]}), flush=True)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


def run_recorder(out_path: str, systems, executor_kind: str) -> int:
    rclpy, stop = _init_ros()
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.qos import QoSProfile
    from sensor_msgs.msg import Imu
    from gyro_thermal_comp import topics
    from gyro_thermal_comp.nodes.stkf_node import NODE_NAME
    node = rclpy.create_node('gtc_latency_recorder')
    rows = {s: [] for s in systems}   # (stamp ns, callback wall ns, middleware reception ns)
    diag = {}

    def recorder(system):
        out = rows[system]

        def on_msg(data: bytes, info) -> None:
            now = time.time_ns()
            sec, nsec = struct.unpack_from('<iI', data, 4)   # CDR little endian: header.stamp first
            out.append((sec * 1_000_000_000 + nsec, now, info['received_timestamp']))

        def on_msg_no_info(data: bytes) -> None:
            now = time.time_ns()
            sec, nsec = struct.unpack_from('<iI', data, 4)
            out.append((sec * 1_000_000_000 + nsec, now, now))
        # Jazzy's EventsExecutor fails on a callback that takes the message info ("null argument to
        # internal routine"): there the middleware reception time is the callback's
        return on_msg if executor_kind == 'single' else on_msg_no_info

    def on_diag(msg) -> None:
        for st in msg.status:
            if st.name.startswith(NODE_NAME):
                diag.update({kv.key: kv.value for kv in st.values}, message=st.message)
    qos = QoSProfile(depth=10000)
    topic_of = {'node': topics.IMU_COMPENSATED, **RELAY_TOPICS}
    subs = [node.create_subscription(Imu, topic_of[s], recorder(s), qos, raw=True) for s in systems]
    node.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, on_diag, QoSProfile(depth=100))
    ready = [False]

    def say_ready() -> None:
        if not ready[0] and all(s.get_publisher_count() for s in subs):
            ready[0] = True
            print('ready', flush=True)
    node.create_timer(0.05, say_ready)   # also wakes the loop to see a stop request
    # one executor, no timeout: the recorder takes two outputs per IMU sample and must not be the
    # slowest process (its queueing would count as latency)
    executor = make_executor(executor_kind)
    executor.add_node(node)
    while not stop.now:
        executor.spin_once(**spin_once_args(executor_kind))
    np.savez(out_path, **{s: np.array(r, dtype=np.int64).reshape(-1, 3) for s, r in rows.items()},
             diag=np.array(json.dumps(diag)))
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


def schedule(rate_hz: float, seconds: float, jitter_us: float, bunch: float, seed: int):
    """(due s after start, stream, jitter s, held-with-next) per sample, in publishing order."""
    rng = np.random.default_rng(seed)
    events = []
    for stream, hz in (('imu', rate_hz), ('mag', MAG_HZ), ('temperature', TEMP_HZ)):
        due = np.arange(int(seconds * hz)) / hz
        jit = rng.uniform(0.0, jitter_us * 1e-6, due.size)
        held = (rng.random(due.size) < bunch) if stream == 'imu' else np.zeros(due.size, bool)
        held[-1:] = False
        events += list(zip(due.tolist(), [stream] * due.size, jit.tolist(), held.tolist()))
    events.sort(key=lambda e: e[0])
    return events


def run_publisher(rate_hz: float, seconds: float, jitter_us: float, bunch: float, seed: int, out_path: str,
                  systems) -> int:
    rclpy, stop = _init_ros()
    from rclpy.qos import qos_profile_sensor_data, QoSProfile
    from sensor_msgs.msg import Imu, MagneticField, Temperature
    from gyro_thermal_comp import topics
    node = rclpy.create_node('gtc_latency_driver')
    qos = QoSProfile(depth=1000, reliability=qos_profile_sensor_data.reliability,
                     durability=qos_profile_sensor_data.durability)
    msgs = {'imu': Imu(), 'mag': MagneticField(), 'temperature': Temperature()}
    pubs = {'imu': node.create_publisher(Imu, topics.IMU_RAW, qos),
            'mag': node.create_publisher(MagneticField, topics.MAG, qos),
            'temperature': node.create_publisher(Temperature, topics.TEMPERATURE, qos)}
    for m in msgs.values():
        m.header.frame_id = 'imu_link'
    need = {'imu': len(systems), 'mag': int('node' in systems), 'temperature': int('node' in systems)}
    deadline = time.monotonic() + START_TIMEOUT_S
    while any(pubs[s].get_subscription_count() < n for s, n in need.items()):
        if time.monotonic() > deadline or stop.now:
            print('publisher: subscribers not matched', file=sys.stderr)
            return 1
        time.sleep(0.05)
    time.sleep(0.5)   # the subscribers' side of the match (best effort: no handshake to wait for)
    rng = np.random.default_rng(seed + 1)
    events = schedule(rate_hz, seconds, jitter_us, bunch, seed)
    n_imu = sum(e[1] == 'imu' for e in events)
    gyro = np.array([0.002, -0.001, 0.003]) + 2e-3 * rng.standard_normal((n_imu, 3))   # rad/s
    accel = np.array([0.0, 0.0, 9.80665]) + 0.01 * rng.standard_normal((n_imu, 3))     # m/s^2
    imu_stamps, last = [], {s: 0 for s in msgs}
    held: list = []
    i_imu, i_other = 0, 0
    t0 = time.monotonic()
    print(f'start {time.time_ns()}', flush=True)
    for due, stream, jit, hold in events:
        if stop.now:
            break
        delay = t0 + due - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        stamp = max(time.time_ns() - int(jit * 1e9), last[stream] + 1000)   # >= 1 us after the previous
        last[stream] = stamp
        m = msgs[stream]
        if stream == 'imu':
            held.append((stamp, gyro[i_imu], accel[i_imu]))
            i_imu += 1
            if hold:
                continue   # published with the next IMU sample
            for s, g, a in held:
                m.header.stamp.sec, m.header.stamp.nanosec = divmod(s, 1_000_000_000)
                m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z = g.tolist()
                m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z = a.tolist()
                pubs['imu'].publish(m)
                imu_stamps.append(s)
            held.clear()
            continue
        m.header.stamp.sec, m.header.stamp.nanosec = divmod(stamp, 1_000_000_000)
        i_other += 1
        if stream == 'mag':
            m.magnetic_field.x, m.magnetic_field.y, m.magnetic_field.z = 2.0e-5, 1e-8 * (i_other % 7), -4.0e-5
        else:
            m.temperature = 25.0 + 1e-3 * i_other   # a slow warm-up, degC
        pubs[stream].publish(m)
    np.save(out_path, np.array(imu_stamps, np.int64))
    time.sleep(0.5)   # best effort: let the last samples leave before the writer goes
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


def profile_node(rate_hz: float, seconds: float, still_s: float, top: int = 20) -> dict:
    """The node's own CPU per IMU sample without DDS: its callbacks called directly in this process
    with serialized messages, as its raw subscriptions hand them over (mag 100 Hz, temperature 10 Hz,
    the batch timer every `process_period_s` and diagnostics every `diagnostics_period_s` of stamps),
    first without, then with cProfile. Outputs go to publishers nobody subscribes (still serialised).
    Also what may hold a single-threaded executor while IMU samples wait: the CPU of each slow-path
    batch and of each diagnostics message, and the garbage collector's pauses."""
    import cProfile
    import gc
    import pstats
    rclpy, _ = _init_ros()
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import Imu, MagneticField, Temperature
    from gyro_thermal_comp.nodes.compose import make_stkf_node
    node = make_stkf_node({'still_period_s': still_s})
    base = time.time_ns()
    period = int(1e9 / rate_hz)
    mag_every, temp_every, batch_every, diag_every = (
        max(1, round(rate_hz / hz)) for hz in (MAG_HZ, TEMP_HZ, 1.0 / node.settings['process_period_s'],
                                               1.0 / node.settings['diagnostics_period_s']))
    n_warm, n = int((still_s + 2.0) * rate_hz), int(seconds * rate_hz)
    rng = np.random.default_rng(13)
    messages = []   # serialized before the clock runs: a driver's cost, not the node's
    for k in range(n_warm + 2 * n):
        m = Imu()
        m.header.frame_id = 'imu_link'
        m.header.stamp.sec, m.header.stamp.nanosec = divmod(base + k * period, 1_000_000_000)
        gyro = 0.003 + 2e-3 * rng.standard_normal(3)   # rad/s
        m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z = gyro.tolist()
        m.linear_acceleration.z = 9.80665
        g = MagneticField(header=m.header)
        g.magnetic_field.x, g.magnetic_field.z = 2e-5, -4e-5
        messages.append((serialize_message(m), serialize_message(g),
                         serialize_message(Temperature(header=m.header, temperature=25.0 + 1e-4 * k))))
    held_us = {'batch': [], 'diagnostics': [], 'gc': []}   # CPU of each, us
    gc_start = []

    def on_gc(phase, info) -> None:
        if phase == 'start':
            gc_start.append(time.thread_time_ns())
        elif gc_start:
            held_us['gc'].append(1e-3 * (time.thread_time_ns() - gc_start.pop()))

    def timed(kind: str, call) -> None:
        c = time.thread_time_ns()
        call()
        held_us[kind].append(1e-3 * (time.thread_time_ns() - c))

    def feed(k0: int, k1: int) -> None:
        for k in range(k0, k1):
            imu, mag, temperature = messages[k]
            if k % mag_every == 0:
                node._on_mag(mag)
            if k % temp_every == 0:
                node._on_temperature(temperature)
            node._on_imu(imu)
            if k % batch_every == 0:
                timed('batch', node.process_buffered)
            if k % diag_every == 0:
                timed('diagnostics', node.publish_diagnostics)
    feed(0, n_warm)
    for v in held_us.values():
        v.clear()
    gc.callbacks.append(on_gc)
    c0 = time.process_time()
    feed(n_warm, n_warm + n)
    cpu_us = 1e6 * (time.process_time() - c0) / n
    gc.callbacks.remove(on_gc)
    held = {k: np.array(v) for k, v in held_us.items()}
    prof = cProfile.Profile()
    prof.enable()
    feed(n_warm + n, n_warm + 2 * n)
    prof.disable()
    published = node.outputs_published
    relay, _ = make_relay(rclpy, node.settings['input_queue_depth'], raw=False)
    turns = {'node': empty_turn_us(node), 'relay': empty_turn_us(relay)}
    relay.destroy_node()
    node.destroy_node()
    rclpy.try_shutdown()
    stats = pstats.Stats(prof)
    rows = []
    for (path, line, func), (_, nc, tt, ct, _) in stats.stats.items():
        where = os.path.relpath(path, HERE.parent) if path.startswith(str(HERE.parent)) else Path(path).name
        rows.append({'where': f'{where}:{line}', 'function': func, 'calls': nc,
                     'own_us_per_sample': 1e6 * tt / n, 'cum_us_per_sample': 1e6 * ct / n,
                     'ours': path.startswith(str(HERE.parent / 'gyro_thermal_comp'))})
    own = sorted(rows, key=lambda r: -r['own_us_per_sample'])[:top]
    cum = sorted((r for r in rows if r['ours']), key=lambda r: -r['cum_us_per_sample'])[:top]
    print(f'node callbacks in process, {rate_hz:g} Hz IMU, {seconds:g} s of stamps: {cpu_us:.0f} us CPU per IMU '
          f'sample without the profiler ({published} outputs published); under cProfile {1e6 * stats.total_tt / n:.0f}')
    for kind, label in (('batch', f'slow-path batch (every {batch_every} IMU samples)'),
                        ('diagnostics', f'diagnostics (every {diag_every})'), ('gc', 'garbage collection')):
        v = held[kind]
        cpu = f', CPU mean {v.mean():.0f}, max {v.max():.0f} us' if v.size else ''
        print(f'{label}: {v.size} in the window{cpu}')
    print(f"an executor turn with nothing ready (the wait-set overhead every callback pays): node {turns['node']:.0f}, "
          f"relay {turns['relay']:.0f} us CPU")
    for title, sel, key in (('own time', own, 'own_us_per_sample'), ('cumulative time, this package', cum,
                                                                     'cum_us_per_sample')):
        print(f"top {top} by {title} (us per IMU sample, profiled):")
        for r in sel:
            print(f"{r[key]:8.1f} {r['calls']:8d}  {r['where']} {r['function']}")
    return {'rate_hz': rate_hz, 'seconds': seconds, 'cpu_us_per_imu_sample': cpu_us,
            'held_cpu_us': {k: {'count': int(v.size), 'mean': float(v.mean()) if v.size else None,
                                'max': float(v.max()) if v.size else None} for k, v in held.items()},
            'empty_turn_cpu_us': turns, 'by_own_time': own,
            'by_cumulative_time': cum}


def empty_turn_us(node, turns: int = 2000) -> float:
    """CPU per `spin_once` of a SingleThreadedExecutor holding only `node` when nothing is ready, us:
    rclpy rebuilds and walks the wait set each turn, so every callback pays this once."""
    from rclpy.executors import SingleThreadedExecutor
    executor = SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    c0 = time.process_time()
    for _ in range(turns):
        executor.spin_once(timeout_sec=0.0)
    cpu = time.process_time() - c0
    executor.remove_node(node)
    executor.shutdown()
    return 1e6 * cpu / turns


# ---------------------------------------------------------------- the harness
def cpu_s(pid: int) -> float:
    """utime + stime of a process, s (/proc/<pid>/stat fields 14, 15)."""
    fields = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / CLK_TCK


def _child(args: list[str], **kw) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, *args], text=True, **kw)


def _wait_line(proc: subprocess.Popen, prefix: str, what: str) -> str:
    """The child's first stdout line starting with `prefix` (readline blocks: a dead child gives '')."""
    while True:
        line = proc.stdout.readline()
        if not line:
            raise RuntimeError(f'{what} exited (code {proc.wait()}) before saying {prefix!r}')
        if line.startswith(prefix):
            return line.strip()


def _stop(proc: subprocess.Popen, timeout_s: float = 60.0) -> str:
    """SIGINT, then the rest of its stdout; a child that does not stop is killed and named."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
    try:
        out, _ = proc.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, _ = proc.communicate()
        raise RuntimeError(f'process {proc.args[1:3]} did not stop within {timeout_s:g} s of SIGINT')
    return out or ''


def latency_stats(rows: np.ndarray, col: int) -> dict:
    lat_ms = (rows[:, col] - rows[:, 0]) * 1e-6
    if lat_ms.size == 0:
        return {'p50_ms': None, 'p99_ms': None, 'max_ms': None}
    p50, p99 = np.percentile(lat_ms, [50, 99])
    return {'p50_ms': float(p50), 'p99_ms': float(p99), 'max_ms': float(lat_ms.max())}


def measure_rate(rate_hz: float, a, tmp: Path) -> dict:
    """Two passes, each with fresh processes and the same publisher schedule: the node beside the
    typed relay (the targets' comparison, five processes), then the typed relay
    beside the raw relay (a sixth process in the first pass would load the two cores the comparison
    runs on). The raw relay's figures come from the second pass, with the typed relay's there."""
    result = measure_pass(rate_hz, a, tmp, ('node', 'relay'))
    relays = measure_pass(rate_hz, a, tmp, ('relay', 'relay_raw'))
    result['relay_raw'] = relays['relay_raw']
    result['relay_in_raw_pass'] = relays['relay']
    for key in ('cpu_s', 'cpu_percent', 'cpu_us_per_output'):
        result[key]['relay_raw'] = relays[key]['relay_raw']
        result[key]['relay_in_raw_pass'] = relays[key]['relay']
    result['relay_raw_relayed'] = relays['relay_raw_relayed']
    result['cpu_ratio_node_over_relay_raw'] = result['cpu_s']['node'] / max(relays['cpu_s']['relay_raw'], 1e-9)
    result['cpu_ratio_relay_over_relay_raw'] = relays['cpu_s']['relay'] / max(relays['cpu_s']['relay_raw'], 1e-9)
    result['load_1min_at_end'] = relays['load_1min_at_end']
    return result


def measure_pass(rate_hz: float, a, tmp: Path, systems: tuple[str, ...]) -> dict:
    """One run of the publisher into `systems` (node, relay, relay_raw) and the recorder."""
    warm_s = a.still_s + 2.0
    tag = f"{rate_hz:g}_{'_'.join(systems)}"
    node_log = open(tmp / f'node_{tag}.log', 'w+')
    relays = [s for s in systems if s in RELAY_TOPICS]
    procs = {}
    try:
        if 'node' in systems:
            procs['node'] = _child(['-m', 'gyro_thermal_comp.nodes.stkf_node', '--executor', a.executor,
                                    '--ros-args', '-p',
                                    f'still_period_s:={a.still_s}'], stdout=node_log, stderr=subprocess.STDOUT)
        for relay in relays:
            procs[relay] = _child([__file__, '--role', 'relay', '--executor', a.executor]
                                  + (['--raw'] if relay == 'relay_raw' else []),
                                  stdout=subprocess.PIPE)
        procs['recorder'] = _child([__file__, '--role', 'recorder', '--executor', a.executor,
                                    '--out', str(tmp / f'rec_{tag}.npz'),
                                    '--systems', ','.join(systems)], stdout=subprocess.PIPE)
        for relay in relays:
            _wait_line(procs[relay], 'ready', f'the {relay}')
        _wait_line(procs['recorder'], 'ready', 'the recorder')
        stamps_path = tmp / f'pub_{tag}.npy'
        procs['publisher'] = _child([__file__, '--role', 'publisher', '--rate-hz', str(rate_hz),
                                     '--seconds', str(warm_s + a.seconds), '--jitter-us', str(a.jitter_us),
                                     '--bunch', str(a.bunch), '--out', str(stamps_path),
                                     '--systems', ','.join(systems)], stdout=subprocess.PIPE)
        start_ns = int(_wait_line(procs['publisher'], 'start', 'the publisher').split()[1])
        lo_ns, hi_ns = start_ns + int(warm_s * 1e9), start_ns + int((warm_s + a.seconds) * 1e9)
        pids = {name: p.pid for name, p in procs.items()}
        time.sleep(max(0.0, lo_ns * 1e-9 - time.time()))
        c0, w0 = {n: cpu_s(pid) for n, pid in pids.items()}, time.monotonic()
        time.sleep(max(0.0, hi_ns * 1e-9 - time.time()))
        c1, w1 = {n: cpu_s(pid) for n, pid in pids.items()}, time.monotonic()
        if procs['publisher'].wait() != 0:
            raise RuntimeError('the publisher failed')
        time.sleep(SETTLE_S)
        _stop(procs.pop('recorder'))
        node_code = procs['node'].poll() if 'node' in procs else None
        if 'node' in procs:
            _stop(procs.pop('node'), 180.0)
        relayed = {relay: json.loads(_stop(procs.pop(relay)).strip().splitlines()[-1])['relayed'] for relay in relays}
    finally:
        for p in procs.values():   # an error above: leave nothing running
            if p.poll() is None:
                p.kill()
                p.wait()
    node_log.seek(0)
    log = node_log.read()
    stopped = re.search(r'stopped: (\d+) outputs published', log)
    rec = np.load(tmp / f'rec_{tag}.npz')
    diag = json.loads(str(rec['diag']))
    published = np.load(stamps_path)
    in_window = (published >= lo_ns) & (published < hi_ns)
    wall = w1 - w0
    result = {'rate_hz': rate_hz, 'window_s': wall, 'imu_published_total': int(published.size),
              'imu_published_in_window': int(in_window.sum()), 'node_alive_before_stop': node_code is None,
              'node_outputs_published_at_stop': int(stopped.group(1)) if stopped else None,
              **{f'{relay}_relayed': n for relay, n in relayed.items()},
              'cpu_s': {n: c1[n] - c0[n] for n in c0}, 'cpu_percent': {n: 100.0 * (c1[n] - c0[n]) / wall for n in c0},
              'node_diagnostics': {k: v for k, v in diag.items()
                                   if k == 'message' or k == 'outputs_published' or k.startswith(('input.', 'core.'))}}
    for s in systems:
        rows = rec[s]
        win = rows[(rows[:, 0] >= lo_ns) & (rows[:, 0] < hi_ns)]
        result[s] = {'received_total': int(rows.shape[0]), 'received_in_window': int(win.shape[0]),
                     'missing_in_window': int(np.setdiff1d(published[in_window], win[:, 0]).size),
                     'latency': latency_stats(win, 1), 'latency_middleware': latency_stats(win, 2)}
    if 'node' in systems and 'relay' in systems:
        result['cpu_ratio_node_over_relay'] = result['cpu_s']['node'] / max(result['cpu_s']['relay'], 1e-9)
    # per output received: a node that falls behind (and loses input) also spends less in all
    result['cpu_us_per_output'] = {s: 1e6 * result['cpu_s'][s] / max(result[s]['received_in_window'], 1)
                                   for s in systems}
    result['load_1min_at_end'] = os.getloadavg()[0]
    return result


def report(r: dict) -> None:
    """The node beside the typed relay (the targets' reference) and the raw relay, with the ratios."""
    n, y, w = r['node'], r['relay'], r['relay_raw']
    print(f"\n{r['rate_hz']:g} Hz IMU: {r['imu_published_in_window']} published in the {r['window_s']:.1f} s window")
    print(f"{'':34s}{'node':>10s}{'relay':>10s}{'raw relay':>10s}{'node/relay':>12s}{'node/raw':>10s}")

    def row(label, a, b, c, fmt='10.2f'):
        if None in (a, b, c):
            return
        print(f'{label:34s}{a:{fmt}}{b:{fmt}}{c:{fmt}}{a / max(b, 1e-9):11.2f}x{a / max(c, 1e-9):9.2f}x')
    for key, label in (('p50_ms', 'latency p50, ms'), ('p99_ms', 'latency p99, ms'), ('max_ms', 'latency max, ms')):
        row(label, n['latency'][key], y['latency'][key], w['latency'][key])
    row('  (middleware reception) p99, ms', *(s['latency_middleware']['p99_ms'] for s in (n, y, w)))
    print(f"{'received in window':34s}{n['received_in_window']:10d}{y['received_in_window']:10d}"
          f"{w['received_in_window']:10d}")
    print(f"{'missing in window':34s}{n['missing_in_window']:10d}{y['missing_in_window']:10d}"
          f"{w['missing_in_window']:10d}")
    row('CPU, % of one core', *(r['cpu_percent'][s] for s in SYSTEMS), fmt='10.1f')
    row('CPU per output received, us', *(r['cpu_us_per_output'][s] for s in SYSTEMS), fmt='10.0f')
    u = r['cpu_us_per_output']
    print(f"(raw relay: second pass, beside the relay, which took {u['relay_in_raw_pass']:.0f} us per output there: "
          f"{u['relay_in_raw_pass'] / max(u['relay_raw'], 1e-9):.2f}x the raw relay)")
    d = r['node_diagnostics']
    drops = {k: v for k, v in d.items() if ('dropped' in k or 'rejected' in k) and v not in ('0', 0)}
    print(f"node: input.imu_received {d.get('input.imu_received')}, outputs_published {d.get('outputs_published')} "
          f"(at stop {r['node_outputs_published_at_stop']}), non-zero drop counters: {drops or 'none'}; "
          f"relays relayed {r['relay_relayed']} and {r['relay_raw_relayed']} of {r['imu_published_total']}")


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    p.error = lambda message: sys.exit(f'live_latency: {message}')   # one line, exit status 1
    p.add_argument('--rates', default='200,1000,2000', help='IMU rates, Hz, comma-separated (50..5000)')
    p.add_argument('--seconds', type=float, default=25.0, help='measured window per rate, s (1..600)')
    p.add_argument('--still-s', type=float, default=5.0, help="the node's still_period_s, s (0..60)")
    p.add_argument('--jitter-us', type=float, default=300.0, help='stamp taken up to this long before publishing, us')
    p.add_argument('--bunch', type=float, default=0.01, help='share of IMU samples published with the next one')
    p.add_argument('--executor', choices=EXECUTORS, default='single',
                   help="the rclpy executor of the node, the relays and the recorder (the node's --executor)")
    p.add_argument('--json', default=None, help='where the results go (default: benchmarks/results/'
                   'live_latency.json, live_latency_events.json with --executor events)')
    p.add_argument('--profile-node', type=float, metavar='HZ',
                   help="instead: the node's callbacks in this process at this IMU rate, with cProfile (no DDS)")
    p.add_argument('--role', choices=('relay', 'recorder', 'publisher'), help=argparse.SUPPRESS)
    p.add_argument('--raw', action='store_true', help=argparse.SUPPRESS)
    p.add_argument('--systems', default=','.join(SYSTEMS), help=argparse.SUPPRESS)
    p.add_argument('--out', help=argparse.SUPPRESS)
    p.add_argument('--rate-hz', type=float, help=argparse.SUPPRESS)
    p.add_argument('--seed', type=int, default=13, help=argparse.SUPPRESS)
    a = p.parse_args()
    if a.role == 'relay':
        from gyro_thermal_comp.nodes.parameters import all_specs
        return run_relay(next(s.default for s in all_specs() if s.name == 'input_queue_depth'), a.raw, a.executor)
    if a.role == 'recorder':
        return run_recorder(a.out, a.systems.split(','), a.executor)
    if a.role == 'publisher':
        return run_publisher(a.rate_hz, a.seconds, a.jitter_us, a.bunch, a.seed, a.out, a.systems.split(','))
    try:
        rates = [float(x) for x in a.rates.split(',')]
    except ValueError:
        p.error(f'--rates must be numbers separated by commas, not {a.rates!r}')
    if not all(50 <= r <= 5000 for r in rates) or not 1 <= a.seconds <= 600 or not 0 <= a.still_s <= 60 \
            or not 0 <= a.jitter_us <= 100000 or not 0 <= a.bunch < 0.5:
        p.error('out of range: --rates 50..5000 Hz, --seconds 1..600, --still-s 0..60, --jitter-us 0..1e5, '
                '--bunch 0..0.5')
    if a.profile_node is not None:
        if not 50 <= a.profile_node <= 5000:
            p.error('--profile-node: 50..5000 Hz')
        profile_node(a.profile_node, a.seconds, a.still_s)
        return 0
    load = os.getloadavg()[0]
    runs = []
    with tempfile.TemporaryDirectory(prefix='gtc_live_latency_') as tmp:
        for rate in rates:   # one after the other, each with fresh processes
            try:
                runs.append(measure_rate(rate, a, Path(tmp)))
            except RuntimeError as exc:
                sys.exit(f'live_latency: {rate:g} Hz: {exc}')
            report(runs[-1])
    command = ' '.join(['.venv/bin/python benchmarks/live_latency.py'] + sys.argv[1:])
    result = {'date': datetime.now(timezone.utc).strftime('%Y-%m-%d %H:%M UTC'), 'machine': cpu_model(),
              'cpus': os.cpu_count(), 'load_1min_at_start': load, 'command': command,
              'ros_domain_id': os.environ['ROS_DOMAIN_ID'], **code_state(), 'seconds': a.seconds, 'still_s': a.still_s,
              'jitter_us': a.jitter_us, 'bunch': a.bunch, 'executor': a.executor, 'runs': runs}
    default_json = RESULTS_JSON if a.executor == 'single' else RESULTS_JSON.with_name(f'live_latency_{a.executor}.json')
    path = Path(a.json) if a.json else default_json
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(result, indent=1) + '\n')
    except OSError as exc:
        sys.exit(f'live_latency: cannot write {path}: {exc.strerror or exc}')
    print(f'\nwritten: {path}')
    if sorted(rates) == [200.0, 1000.0, 2000.0] and a.seconds >= 20 and path.resolve() == default_json:
        write_results_section(result)
    return 0


def write_results_section(r: dict) -> None:
    """Replace the live-latency section of benchmarks/RESULTS.md (generated, never typed)."""
    json_name = 'live_latency.json' if r['executor'] == 'single' else f"live_latency_{r['executor']}.json"
    title = ('## Live latency and CPU vs a relay (single executor)' if r['executor'] == 'single' else
             f"## Live latency and CPU vs a relay, --executor {r['executor']}")
    rows = []
    for run in r['runs']:
        n, y, w = run['node'], run['relay'], run['relay_raw']
        lat, rlat, wlat = (' / '.join('-' if s['latency'][k] is None else f"{s['latency'][k]:.2f}"
                                      for k in ('p50_ms', 'p99_ms', 'max_ms')) for s in (n, y, w))
        d = run['node_diagnostics']
        a, b, c = n['latency']['p99_ms'], y['latency']['p99_ms'], w['latency']['p99_ms']
        p99_ratio = '-' if a is None or b is None else f'{a / b:.2f}x'
        p99_raw_ratio = '-' if a is None or c is None else f'{a / c:.2f}x'
        rows.append(f"| {run['rate_hz']:g} Hz | {lat} | {rlat} | {p99_ratio} "
                    f"| {n['received_in_window']} / {y['received_in_window']} / {run['imu_published_in_window']} "
                    f"| {d.get('input.imu_received')} / {d.get('outputs_published')} "
                    f"| {run['cpu_percent']['node']:.1f} / {run['cpu_percent']['relay']:.1f} "
                    f"| {run['cpu_ratio_node_over_relay']:.2f}x "
                    f"| {run['cpu_us_per_output']['node']:.0f} / {run['cpu_us_per_output']['relay']:.0f} "
                    f"| {wlat} | {p99_raw_ratio} | {w['received_in_window']} "
                    f"| {run['cpu_percent']['relay_raw']:.1f} / {run['cpu_us_per_output']['relay_raw']:.0f} "
                    f"| {run['cpu_ratio_node_over_relay_raw']:.2f}x | {run['cpu_ratio_relay_over_relay_raw']:.2f}x "
                    f"| {run['load_1min_at_end']:.2f} |")
    section = (f"{title}\n\n`{r['command']}` on {r['machine']} ({r['cpus']} cores, load average "
               f"{r['load_1min_at_start']:.2f} at start), {r['date']}. IMU + 100 Hz mag + 10 Hz temperature, "
               f"stamps jittered up to {r['jitter_us']:g} us, {100 * r['bunch']:g} % of IMU samples bunched; "
               f"{r['seconds']:g} s measured per rate, after the node's {r['still_s']:g} s still period.\n\n"
               '| IMU rate | node latency p50 / p99 / max, ms | relay p50 / p99 / max, ms | p99 node/relay '
               '| received in window: node / relay / published | node input.imu_received / outputs_published '
               '| CPU % node / relay | CPU node/relay | CPU us per output node / relay '
               '| raw relay p50 / p99 / max, ms | p99 node/raw relay | raw relay received '
               '| raw relay CPU % / us per output | CPU node/raw relay | CPU relay/raw relay (2nd pass) '
               '| load at end |\n'
               '|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n'
               + '\n'.join(rows) + '\n\nTargets (1 kHz): zero dropped IMU samples, p99 <= 2 ms, CPU <= 1.3x '
               'the relay (the typed relay, rclpy message objects in and out). The raw relay republishes the '
               'serialized bytes: what DDS and the rclpy executor alone cost; it runs in a second pass beside the '
               'relay (the ratio of the two is from that pass). The node, the relays and the recorder spin the '
               f"`{r['executor']}` executor (`--executor`: gyro_thermal_comp/nodes/executors.py). Raw figures: "
               f"`benchmarks/results/{json_name}`.\n")
    replace_section(title, section)


if __name__ == '__main__':
    sys.exit(main())
