"""Soak: the live stkf_node for 30 min of wall time at 1 kHz, with a fault every minute.

    .venv/bin/python benchmarks/soak.py                  # 30 min: what benchmarks/RESULTS.md reports
    .venv/bin/python benchmarks/soak.py --minutes 4      # a quick look (not written to RESULTS.md)

The node runs as its own process (`python -m gyro_thermal_comp.nodes.stkf_node`, reliable inputs), fed
over loopback DDS by this process with the static_ramp scenario streamed from the simulator at real
time (IMU 1 kHz, compass 100 Hz, temperature 10 Hz). From minute 2 on, one fault a minute, in turn:
IMU stamped an hour ahead, a dead (all-zero) magnetometer for 10 s, a runtime `gate.reference_memory_s
= 0` (must be refused), gyro 1e30, temperature 1e30, a +80 degC temperature spike, a 60 s temperature
dropout, NaN IMU samples. Every /imu/data is received and checked; the node's RSS is sampled every 10 s.

Pass: the node is alive at the end and exits 0 on SIGINT; no non-finite output; RSS growth after the
5 min warm-up < 5 %; final heading error (design section 5: relative to the first minute after the
still period) <= that of the same data without faults, run through the core offline, + 0.5 deg.
Writes benchmarks/results/soak.json and, for a full run, the soak section of benchmarks/RESULTS.md.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import signal
import subprocess
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
os.environ.setdefault('ROS_DOMAIN_ID', str(60 + os.getpid() % 30))

import rclpy  # noqa: E402  (after the DDS environment is set)
from rcl_interfaces.msg import Parameter as ParameterMsg, ParameterType, ParameterValue  # noqa: E402
from rcl_interfaces.srv import SetParameters  # noqa: E402
from rclpy.qos import QoSProfile  # noqa: E402
from sensor_msgs.msg import Imu, MagneticField, Temperature  # noqa: E402
from std_msgs.msg import Header  # noqa: E402

from gyro_thermal_comp import sim, topics  # noqa: E402
from gyro_thermal_comp.angles import wrap_angle, yaw_from_quat  # noqa: E402
from gyro_thermal_comp.nodes import conversions as conv  # noqa: E402
from gyro_thermal_comp.samples import SensorChunk, concat_samples, slice_samples  # noqa: E402
from gyro_thermal_comp.thermal.estimator import ThermalDriftEstimator  # noqa: E402
sys.path.insert(0, str(Path(__file__).resolve().parent))   # bench_report.py beside this script
from bench_report import cpu_model, replace_section  # noqa: E402

FAULTS = ('imu_future', 'mag_zero', 'param_zero', 'gyro_huge', 'temp_huge', 'temp_spike', 'temp_dropout', 'imu_nan')
WARMUP_S = 300.0


def scenario(minutes: float):
    return sim.make_config('static_ramp', seed=11, duration_s=minutes * 60.0 + 30.0, imu_rate_hz=1000.0,
                           mag_rate_hz=100.0, temp_rate_hz=10.0, truth_rate_hz=10.0)


def fault_at(t_s: float, t0_s: float) -> tuple[str, float] | None:
    """(fault, seconds into its minute) from minute 2 on."""
    k = int((t_s - t0_s) // 60.0) - 2
    return None if k < 0 else (FAULTS[k % len(FAULTS)], (t_s - t0_s) % 60.0)


class Player:
    def __init__(self, node):
        qos = QoSProfile(depth=10000)
        self.node = node
        self.imu = node.create_publisher(Imu, topics.IMU_RAW, qos)
        self.mag = node.create_publisher(MagneticField, topics.MAG, qos)
        self.temp = node.create_publisher(Temperature, topics.TEMPERATURE, qos)
        self.outputs = []   # (t, yaw, finite) of every 100th output and of any non-finite one
        self.received = 0
        self.published = 0
        node.create_subscription(Imu, topics.IMU_COMPENSATED, self._on_output, QoSProfile(depth=10000))
        self.param_client = node.create_client(SetParameters, '/stkf_drift_estimator/set_parameters')
        self.param_results: list[bool] = []
        self.done_param = set()

    def _on_output(self, msg: Imu) -> None:
        q = [msg.orientation.x, msg.orientation.y, msg.orientation.z, msg.orientation.w]
        values = [msg.angular_velocity.x, msg.angular_velocity.y, msg.angular_velocity.z, *q,
                  *msg.orientation_covariance, *msg.angular_velocity_covariance]
        finite = all(math.isfinite(v) for v in values)
        if self.received % 100 == 0 or not finite:
            self.outputs.append((conv.stamp_s(msg.header.stamp), float(yaw_from_quat(np.array(q))), finite))
        self.received += 1

    def publish_chunk(self, chunk: SensorChunk, t0: float, t_wall0: float) -> None:
        """Every sample at its time (real time from t0 at wall time t_wall0), faults put in."""
        events = []
        for name, s in (('imu', chunk.imu), ('mag', chunk.mag), ('temperature', chunk.temperature)):
            events += [(float(t), name, i) for i, t in enumerate(s.t)]
        events.sort()
        for t, name, i in events:
            delay = t_wall0 + (t - t0) - time.monotonic()
            if delay > 0.005:   # publish in bursts of 5 ms, as a driver does
                time.sleep(delay)
            fault = fault_at(t, t0)
            kind, into = fault if fault else (None, 0.0)
            stamp = t
            if name == 'imu':
                gyro, accel = chunk.imu.gyro[i], chunk.imu.accel[i]
                if kind == 'imu_future' and into < 0.005:
                    stamp = t + 3600.0
                elif kind == 'gyro_huge' and into < 0.005:
                    gyro = np.full(3, 1e30)
                elif kind == 'imu_nan' and into < 0.005:
                    gyro = np.full(3, np.nan)
                self.imu.publish(conv.imu_msg(Header(stamp=conv.time_msg(stamp), frame_id='imu_link'), gyro, accel))
                self.published += 1
            elif name == 'mag':
                field = np.zeros(3) if kind == 'mag_zero' and into < 10.0 else chunk.mag.field[i]
                msg = MagneticField(header=Header(stamp=conv.time_msg(stamp), frame_id='imu_link'))
                msg.magnetic_field.x, msg.magnetic_field.y, msg.magnetic_field.z = map(float, field)
                self.mag.publish(msg)
            else:
                value = float(chunk.temperature.temp_c[i])
                if kind == 'temp_dropout':
                    continue
                if kind == 'temp_huge' and into < 0.1:
                    value = 1e30
                elif kind == 'temp_spike' and into < 0.1:
                    value += 80.0
                self.temp.publish(Temperature(header=Header(stamp=conv.time_msg(stamp), frame_id='imu_link'),
                                              temperature=value))
            if kind == 'param_zero' and int(t // 60) not in self.done_param:
                self.done_param.add(int(t // 60))
                self._set_zero_memory()

    def _set_zero_memory(self) -> None:
        request = SetParameters.Request(parameters=[ParameterMsg(
            name='gate.reference_memory_s',
            value=ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=0.0))])
        future = self.param_client.call_async(request)
        future.add_done_callback(lambda f: self.param_results.append(bool(f.result().results[0].successful)))


def rss_mb(pid: int) -> float:
    for line in Path(f'/proc/{pid}/status').read_text().splitlines():
        if line.startswith('VmRSS:'):
            return int(line.split()[1]) / 1024.0
    return math.nan


def heading_error_at(t_end: float, t_out, yaw_out, odom, still_s: float) -> float:
    """|e| over the 10 s before t_end, deg: e = wrap(yaw - yaw_true) - its mean over the first
    minute after the still period (design section 5)."""
    yaw_true = np.interp(t_out, odom.t, np.unwrap(yaw_from_quat(odom.quat)))
    e = np.unwrap(wrap_angle(yaw_out - yaw_true))
    ref = (t_out > t_out[0] + still_s) & (t_out < t_out[0] + still_s + 60.0)
    e = e - np.mean(e[ref])
    return float(np.degrees(abs(np.mean(e[(t_out > t_end - 10.0) & (t_out <= t_end)]))))


def offline_clean(cfg):
    """The same data without faults through the core: (t, heading) every 100th sample, and the truth."""
    est = ThermalDriftEstimator()
    t, yaw, odom = [], [], []
    for chunk in sim.simulate(cfg):
        out = est.process(SensorChunk(imu=chunk.imu, mag=chunk.mag, temperature=chunk.temperature))
        t.append(out.track.t[::100])
        yaw.append(out.track.heading_rad[::100])
        odom.append(chunk.odom)
    return np.concatenate(t), np.concatenate(yaw), concat_samples(odom)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--minutes', type=float, default=30.0)
    args = parser.parse_args()
    cfg = scenario(args.minutes)
    t_clean, yaw_clean, odom = offline_clean(cfg)
    node_proc = subprocess.Popen([sys.executable, '-m', 'gyro_thermal_comp.nodes.stkf_node', '--ros-args',
                                  '-p', 'reliable_inputs:=true', '-p', 'input_queue_depth:=10000'],
                                 stderr=subprocess.PIPE, text=True)
    rclpy.init()
    node = rclpy.create_node('gtc_soak_player')
    player = Player(node)
    executor = rclpy.executors.SingleThreadedExecutor()
    executor.add_node(node)
    import threading
    threading.Thread(target=executor.spin, daemon=True).start()
    deadline = time.monotonic() + 30.0
    while player.imu.get_subscription_count() == 0 or player.temp.get_subscription_count() == 0 or \
            player.mag.get_subscription_count() == 0:
        if time.monotonic() > deadline or node_proc.poll() is not None:
            print('soak: the node did not come up', file=sys.stderr)
            return 1
        time.sleep(0.1)
    time.sleep(1.0)
    rss, t_wall0, t0 = [], time.monotonic(), None
    next_rss = 0.0
    for chunk in sim.simulate(cfg):
        t0 = float(chunk.imu.t[0]) if t0 is None else t0
        for lo in np.arange(chunk.imu.t[0], chunk.imu.t[-1] + 1e-9, 1.0):   # 1 s slices
            part = SensorChunk(**{n: slice_samples(s, (s.t >= lo) & (s.t < lo + 1.0))
                                  for n, s in (('imu', chunk.imu), ('mag', chunk.mag),
                                               ('temperature', chunk.temperature))})
            player.publish_chunk(part, t0, t_wall0)
            if time.monotonic() - t_wall0 >= next_rss:
                if node_proc.poll() is None:
                    rss.append((time.monotonic() - t_wall0, rss_mb(node_proc.pid)))
                next_rss += 10.0
            if node_proc.poll() is not None:
                break
        if node_proc.poll() is not None:
            break
    alive = node_proc.poll() is None
    time.sleep(3.0)
    node_proc.send_signal(signal.SIGINT)
    try:
        code = node_proc.wait(timeout=60.0)
    except subprocess.TimeoutExpired:
        node_proc.kill()
        code = -9
    log = node_proc.stderr.read()
    executor.shutdown(timeout_sec=2.0)
    rclpy.try_shutdown()
    rss = np.array(rss)
    warm = rss[rss[:, 0] >= min(WARMUP_S, rss[-1, 0] / 2)]
    growth = float(warm[-1, 1] / warm[0, 1] - 1.0)
    outs = np.array([(t, y) for t, y, ok in player.outputs if ok])
    nonfinite = sum(1 for *_, ok in player.outputs if not ok)
    t_end = float(outs[-1, 0])   # the node's last output: compare both at the same data time
    error_deg = heading_error_at(t_end, outs[:, 0], outs[:, 1], odom, 30.0)
    clean_error_deg = heading_error_at(t_end, t_clean, yaw_clean, odom, 30.0)
    result = {
        'date': datetime.now(timezone.utc).strftime('%Y-%m-%d %H:%M UTC'), 'machine': cpu_model(),
        'cpus': os.cpu_count(), 'minutes': args.minutes,
        'command': f'.venv/bin/python benchmarks/soak.py --minutes {args.minutes:g}',
        'node_alive_at_end': alive, 'node_exit_code': code, 'nonfinite_outputs': nonfinite,
        'imu_published': player.published, 'outputs_received': player.received,
        'data_s': float(outs[-1, 0] - outs[0, 0]), 'wall_s': time.monotonic() - t_wall0,
        'outputs_kept_for_heading': len(player.outputs),
        'rss_mb_after_warmup': [float(warm[0, 1]), float(warm[-1, 1])],
        'rss_growth': growth, 'param_zero_refused': [not ok for ok in player.param_results],
        'final_heading_error_deg': error_deg, 'clean_offline_final_heading_error_deg': clean_error_deg,
    }
    result['passed'] = bool(alive and code == 0 and nonfinite == 0 and growth < 0.05
                            and all(result['param_zero_refused']) and error_deg <= clean_error_deg + 0.5)
    (HERE / 'results').mkdir(exist_ok=True)
    (HERE / 'results' / 'soak.json').write_text(json.dumps(result, indent=1))
    print(json.dumps(result, indent=1))
    if not result['passed']:
        print(log[-3000:], file=sys.stderr)
    if args.minutes >= 30.0:
        write_results_section(result)
    return 0 if result['passed'] else 1


def write_results_section(r: dict) -> None:
    """Replace the soak section of benchmarks/RESULTS.md (generated, never typed)."""
    section = (f"## Soak\n\n`{r['command']}` on {r['machine']} ({r['cpus']} cores), {r['date']}: "
               f"{'PASS' if r['passed'] else 'FAIL'}.\n\n"
               f"| measure | result | target |\n|---|---|---|\n"
               f"| node alive at the end, exit code on SIGINT | {r['node_alive_at_end']}, {r['node_exit_code']} "
               f"| True, 0 |\n"
               f"| non-finite outputs (every output checked) | {r['nonfinite_outputs']} | 0 |\n"
               f"| outputs received / IMU samples published | {r['outputs_received']} / {r['imu_published']} | "
               f"(throughput: a target of live_latency.py, not here) |\n"
               f"| RSS after warm-up, MB | {r['rss_mb_after_warmup'][0]:.1f} -> {r['rss_mb_after_warmup'][1]:.1f} "
               f"({100 * r['rss_growth']:+.1f} %) | < +5 % |\n"
               f"| runtime gate.reference_memory_s = 0 refused | {r['param_zero_refused']} | all True |\n"
               f"| final heading error, deg | {r['final_heading_error_deg']:.2f} (clean, offline: "
               f"{r['clean_offline_final_heading_error_deg']:.2f}) | <= clean + 0.5 |\n")
    replace_section('## Soak', section)


if __name__ == '__main__':
    sys.exit(main())
