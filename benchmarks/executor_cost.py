"""CPU per input message of rclpy's SingleThreadedExecutor vs MultiThreadedExecutor around the STKF node.

    .venv/bin/python benchmarks/executor_cost.py [--seconds 12]

Backs the docstring of gyro_thermal_comp/nodes/compose.py (why spin_together defaults to a SingleThreadedExecutor).
Each executor runs in its own subprocess (clean rclpy state and CPU accounting) with the node from make_stkf_node
(reliable inputs, queues deep enough for everything) and a publisher: N seconds of 250 Hz IMU + 50 Hz mag + 10 Hz
temperature are published and acknowledged while nothing spins, then the executor spins until every message has
been through its callback. Process CPU (user + system) over the spin is split into CPU inside the node's callbacks
(thread_time around each subscription and timer callback) and the rest: executor dispatch (wait sets, take,
deserialization, hand-off to pool threads) and DDS. Prints us/msg for both side by side with the multi/single ratio;
writes benchmarks/results/executor_cost.json.
"""
import argparse
import json
import os
import resource
import subprocess
import sys
import threading
import time
from datetime import datetime, timezone
from pathlib import Path
sys.path.insert(0, str(Path(__file__).resolve().parent))   # bench_report.py beside this script
from bench_report import cpu_model  # noqa: E402

# Loopback only, a domain of our own: no traffic to or from other ROS processes on this machine.
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
os.environ.setdefault('ROS_DOMAIN_ID', '61')

RESULTS_JSON = Path(__file__).resolve().parent / 'results' / 'executor_cost.json'
EXECUTORS = ('single', 'multi')
IMU_HZ, MAG_EVERY, TEMP_EVERY = 250, 5, 25     # mag and temperature every 5th / 25th IMU stamp: 50 Hz, 10 Hz
MAX_SECONDS = 400                               # 250 Hz * 400 s = input_queue_depth's maximum (100000)
SPIN_POLL_S = 0.1                               # as spin_together's


def measure(executor_name: str, seconds: int) -> dict:
    """One executor, in this process: queue everything, then spin until every message is taken."""
    import rclpy   # here, not at the top: the parent process never needs rclpy
    from builtin_interfaces.msg import Time
    from rclpy.duration import Duration
    from rclpy.executors import MultiThreadedExecutor, SingleThreadedExecutor
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from gyro_thermal_comp.nodes.compose import make_stkf_node

    depth = IMU_HZ * seconds   # the IMU queue must hold all of its messages: none may be lost before the spin
    rclpy.init()
    node = make_stkf_node({'reliable_inputs': True, 'input_queue_depth': depth})
    cb_cpu_s, msgs_done, lock = [0.0], [0], threading.Lock()

    def timed(callback, counts_message: bool):
        def wrapper(*args):   # one argument (a message) or none (a timer)
            t_s = time.thread_time()   # this thread's CPU only: right in pool threads too
            result = callback(*args)
            with lock:
                cb_cpu_s[0] += time.thread_time() - t_s
                msgs_done[0] += counts_message   # counted once done: spinning stops after the last one
            return result
        return wrapper

    # The entities' callbacks, swapped on this node only: the executor calls entity.callback at dispatch.
    inputs = list(node.subscriptions_by_stream.values())
    for entity in [*node.subscriptions, *node.timers]:
        entity.callback = timed(entity.callback, entity in inputs)

    pub_node = rclpy.create_node('executor_cost_pub')
    qos = QoSProfile(depth=depth, reliability=ReliabilityPolicy.RELIABLE)
    pubs = {s: pub_node.create_publisher(sub.msg_type, sub.topic_name, qos)
            for s, sub in node.subscriptions_by_stream.items()}
    deadline = time.monotonic() + 30.0
    while not all(p.get_subscription_count() for p in pubs.values()):
        if time.monotonic() > deadline:
            raise RuntimeError('the node\'s subscriptions were not matched within 30 s (DDS discovery)')
        time.sleep(0.01)

    msgs = {s: p.msg_type() for s, p in pubs.items()}   # one message per stream, restamped each time
    msgs['imu'].linear_acceleration.z = 9.80665           # level and still: input the node accepts
    msgs['mag'].magnetic_field.x, msgs['mag'].magnetic_field.z = 2e-5, -4e-5
    msgs['temperature'].temperature = 25.0
    every = {'imu': 1, 'mag': MAG_EVERY, 'temperature': TEMP_EVERY}
    sent = 0
    for i in range(IMU_HZ * seconds):
        stamp = Time(sec=1000 + i // IMU_HZ, nanosec=(i % IMU_HZ) * (1_000_000_000 // IMU_HZ))
        for stream, msg in msgs.items():
            if i % every[stream] == 0:
                msg.header.stamp = stamp
                pubs[stream].publish(msg)
                sent += 1
    # Acknowledged = in the node's reader queue: the spin then starts with everything there.
    if not all(p.wait_for_all_acked(Duration(seconds=30)) for p in pubs.values()):
        raise RuntimeError('published messages not acknowledged within 30 s')

    threads = len(os.sched_getaffinity(0)) if executor_name == 'multi' else 1   # multi: rclpy's default count
    ex = MultiThreadedExecutor(threads) if executor_name == 'multi' else SingleThreadedExecutor()
    ex.add_node(node)
    r0, t0_s, cb0_s = resource.getrusage(resource.RUSAGE_SELF), time.monotonic(), cb_cpu_s[0]
    while msgs_done[0] < sent and time.monotonic() - t0_s < 60.0 + 5.0 * seconds:
        ex.spin_once(timeout_sec=SPIN_POLL_S)
    wall_s, r1 = time.monotonic() - t0_s, resource.getrusage(resource.RUSAGE_SELF)
    cpu_s = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
    cb_s, done = cb_cpu_s[0] - cb0_s, msgs_done[0]
    if done < sent:
        raise RuntimeError(f'only {done} of {sent} messages taken within the time limit')
    result = {'executor': type(ex).__name__, 'threads': threads,
              'messages_sent': sent, 'messages_taken': done, 'spin_wall_s': wall_s,
              'cpu_us_per_msg': 1e6 * cpu_s / done, 'callback_us_per_msg': 1e6 * cb_s / done,
              'dispatch_us_per_msg': 1e6 * (cpu_s - cb_s) / done, 'outputs_published': node.outputs_published}
    ex.shutdown()
    node.destroy_node()
    pub_node.destroy_node()
    rclpy.try_shutdown()
    return result


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    p.error = lambda message: sys.exit(f'executor_cost: {message}')   # one line, exit status 1
    p.add_argument('--seconds', type=int, default=12, help=f'seconds of sensor data queued, 1..{MAX_SECONDS}')
    p.add_argument('--child', choices=EXECUTORS, help=argparse.SUPPRESS)   # internal: one executor's run
    a = p.parse_args()
    if not 1 <= a.seconds <= MAX_SECONDS:
        p.error(f'--seconds must be 1..{MAX_SECONDS} (input_queue_depth = 250 * seconds <= 100000), not {a.seconds}')
    if a.child:
        print(json.dumps(measure(a.child, a.seconds)))
        return 0

    load_1min = os.getloadavg()[0]
    runs = {}
    for name in EXECUTORS:   # one after the other: they would compete for the cores
        proc = subprocess.run([sys.executable, __file__, '--seconds', str(a.seconds), '--child', name],
                              capture_output=True, text=True)
        if proc.returncode != 0:
            last = (proc.stderr.strip().splitlines() or [f'exit status {proc.returncode}'])[-1]
            sys.exit(f'executor_cost: the {name} run failed: {last}')
        runs[name] = json.loads(proc.stdout.strip().splitlines()[-1])
    s, m = runs['single'], runs['multi']
    print(f'{a.seconds} s of 250 Hz IMU + 50 Hz mag + 10 Hz temperature: {s["messages_taken"]} messages per executor '
          f'({os.cpu_count()} CPUs, load {load_1min:.2f} at start; multi: {m["threads"]} threads)')
    print(f'{"":26s}{"single":>9s}{"multi":>9s}{"multi/single":>14s}')
    for key, label in (('cpu_us_per_msg', 'process CPU, us/msg'), ('callback_us_per_msg', '  in callbacks, us/msg'),
                       ('dispatch_us_per_msg', '  rest (dispatch), us/msg'), ('spin_wall_s', 'wall to take all, s')):
        print(f'{label:26s}{s[key]:9.1f}{m[key]:9.1f}{m[key] / s[key]:13.2f}x')
    print(f'{"outputs published":26s}{s["outputs_published"]:9d}{m["outputs_published"]:9d}')

    RESULTS_JSON.parent.mkdir(exist_ok=True)
    RESULTS_JSON.write_text(json.dumps({
        'date': datetime.now(timezone.utc).strftime('%Y-%m-%d %H:%M UTC'), 'machine': cpu_model(),
        'cpus': os.cpu_count(), 'load_1min_at_start': load_1min, 'seconds': a.seconds,
        'command': f'.venv/bin/python benchmarks/executor_cost.py --seconds {a.seconds}', 'runs': runs,
        'ratio_multi_over_single': {k: m[k] / s[k] for k in ('cpu_us_per_msg', 'callback_us_per_msg',
                                                             'dispatch_us_per_msg', 'spin_wall_s')}}, indent=1) + '\n')
    print(f'written: {RESULTS_JSON}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
