"""Acceptance: `examples/compose_nodes.py`, run as a user runs it, over loopback DDS.

Every IMU sample published at 250 Hz comes out compensated, and Ctrl-C (or SIGTERM) while data
flows ends the process with exit code 0, no traceback, the last batch published and the STKF's
state file written. The run is fenced by conditions (the node's diagnostics, the outputs counted);
the time limits only turn a hang into a failure, so a loaded machine makes it slower, not red.
"""
import json
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time

import pytest
import rclpy
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Imu, MagneticField, Temperature

from conftest import REPO

RATE_HZ = 250.0
STAMP0_S = 1000.0
START_TIMEOUT_S = 90.0     # the example imports numpy/scipy and matches DDS readers: slow when loaded
DELIVERY_TIMEOUT_S = 120.0
EXIT_TIMEOUT_S = 180.0    # hang guard only: a starved process flushes, saves and waits for acks

# Reliable inputs with a queue for 40 s of 250 Hz: the count must be exact even when the node is
# starved of CPU for a while (the default best effort matches every driver but may lose samples).
# A 1 s still period lets the STKF start learning, so there is a state to save; a 30 s
# max_latency_s keeps a topic a reliable writer resends late from being dropped as late (every
# topic flows until the end here, so nothing waits on it).
PARAMS = """\
/stkf_drift_estimator:
  ros__parameters:
    reliable_inputs: true
    input_queue_depth: 10000
    max_latency_s: 30.0
    still_period_s: 1.0
"""


class Probe:
    """Our side of the wire: a driver publishing at 250 Hz and a subscriber counting the outputs."""

    def __init__(self, context: Context):
        self.node = rclpy.create_node('gtc_composition_probe', context=context)
        qos = QoSProfile(depth=100_000, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST)
        self.pubs = {'imu': self.node.create_publisher(Imu, '/vehicle/imu/data_raw', qos),
                     'mag': self.node.create_publisher(MagneticField, '/imu/mag', qos),
                     'temperature': self.node.create_publisher(Temperature, '/imu/temperature', qos)}
        self.out_stamps: list[int] = []        # ns, of every /imu/data output, in arrival order
        self.node_values: dict[str, str] = {}  # the STKF node's latest diagnostic values
        self.node.create_subscription(Imu, '/imu/data', self._on_output, QoSProfile(depth=100_000))
        self.node.create_subscription(DiagnosticArray, '/diagnostics', self._on_diagnostics, QoSProfile(depth=100))
        self.published = 0
        self._stop = threading.Event()

    def _on_output(self, msg: Imu) -> None:
        self.out_stamps.append(msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec)

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        for status in msg.status:
            if 'stkf_drift_estimator' in status.name:
                self.node_values = {kv.key: kv.value for kv in status.values}

    def node_count(self, key: str) -> int:
        try:
            return int(self.node_values.get(key, -1))
        except ValueError:
            return -1

    def matched(self) -> bool:
        """Both ends see each other (samples published before the node's reader matched are lost)."""
        return (all(p.get_subscription_count() > 0 for p in self.pubs.values())
                and all(self.node_count(f'input.{s}_publishers') > 0 for s in self.pubs))

    @staticmethod
    def stamp_ns(i: int) -> int:
        return round((STAMP0_S + i / RATE_HZ) * 1e9)

    def play(self) -> None:
        """IMU at 250 Hz, magnetometer every 5th and temperature every 25th sample (same stamps),
        until stopped. Paced on a schedule: a late tick is caught up, so the mean rate stays 250 Hz."""
        start = time.monotonic()
        i = 0
        while not self._stop.is_set():
            ns = self.stamp_ns(i)
            stamp = Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)
            if i % 25 == 0:
                temperature = Temperature(temperature=25.0 + 0.002 * i)
                temperature.header.stamp, temperature.header.frame_id = stamp, 'imu_link'
                self.pubs['temperature'].publish(temperature)
            if i % 5 == 0:
                mag = MagneticField()
                mag.header.stamp, mag.header.frame_id = stamp, 'imu_link'
                mag.magnetic_field.x, mag.magnetic_field.z = 2.0e-5, -4.0e-5
                self.pubs['mag'].publish(mag)
            imu = Imu()
            imu.header.stamp, imu.header.frame_id = stamp, 'imu_link'
            imu.angular_velocity.z, imu.linear_acceleration.z = 1e-3, 9.80665
            self.pubs['imu'].publish(imu)
            i += 1
            self.published = i
            self._stop.wait(max(0.0, start + i / RATE_HZ - time.monotonic()))

    def stop(self) -> None:
        self._stop.set()


def wait_until(condition, proc, timeout_s: float, failure: str) -> None:
    end = time.monotonic() + timeout_s
    while not condition():
        assert proc.poll() is None, f'the example exited ({proc.returncode}) before: {failure}'
        assert time.monotonic() < end, f'{failure} within {timeout_s:.0f} s'
        time.sleep(0.05)


@pytest.mark.parametrize('signum, samples, executor', [(signal.SIGINT, 2250, 'single'), (signal.SIGTERM, 500, 'single'),
                                                       (signal.SIGTERM, 500, 'events')],
                         ids=['ctrl_c', 'sigterm', 'sigterm_events_executor'])
def test_composition_example_loses_nothing_and_stops_cleanly(tmp_path, signum, samples, executor):
    params, state_file = tmp_path / 'params.yaml', tmp_path / 'stkf_state.json'
    params.write_text(PARAMS)
    log = tempfile.TemporaryFile(mode='w+')
    proc = subprocess.Popen([sys.executable, str(REPO / 'examples' / 'compose_nodes.py'), '--state-file',
                             str(state_file), '--executor', executor, '--ros-args', '--params-file', str(params)],
                            cwd=REPO, stdout=subprocess.PIPE, stderr=log, text=True)
    context = Context()
    rclpy.init(context=context)
    probe = Probe(context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(probe.node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    player = threading.Thread(target=probe.play, daemon=True)
    try:
        wait_until(probe.matched, proc, START_TIMEOUT_S, 'the example did not match our topics')
        player.start()
        wanted = {probe.stamp_ns(i) for i in range(samples)}
        wait_until(lambda: wanted <= set(probe.out_stamps), proc, DELIVERY_TIMEOUT_S,
                   f'not every one of the first {samples} samples came out compensated')
        # Data still flows (the player runs on): stop the example as a user or a service manager does.
        received = probe.node_count('input.imu_received')
        wait_until(lambda: probe.node_count('input.imu_received') > received, proc, DELIVERY_TIMEOUT_S,
                   'the node stopped receiving')
        proc.send_signal(signum)
        try:
            stdout, _ = proc.communicate(timeout=EXIT_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            proc.send_signal(signal.SIGUSR1)   # compose.init: every thread's stack to stderr
            time.sleep(2.0)
            log.seek(0)
            pytest.fail(f'still running {EXIT_TIMEOUT_S:.0f} s after the signal; its stacks:\n{log.read()[-8000:]}')
        probe.stop()
        player.join()
        log.seek(0)
        stderr = log.read()
        assert proc.returncode == 0, stderr[-3000:]
        assert 'Traceback' not in stderr and 'context is invalid' not in stderr, stderr[-3000:]
        assert '/stkf_drift_estimator' in stdout and '/wheel/carousel_demodulator' in stdout
        assert 'stopped: 0 outputs published' in stderr   # the carousel, which nothing fed, stopped too
        published = [int(n) for n in re.findall(r'\[stkf_drift_estimator\]: stopped: (\d+)', stderr)]
        assert len(published) == 1 and published[0] >= samples, stderr[-3000:]
        # The node waited for our acknowledgements before it exited: we hold everything it published,
        # one output per IMU sample, in order and without a gap, up to where it stopped.
        assert probe.out_stamps == [probe.stamp_ns(i) for i in range(published[0])]
        state = json.loads(state_file.read_text())
        assert state['format'] == 'gyro_thermal_comp/stkf_state/1' and len(state['x']) >= 3
    finally:
        probe.stop()
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        executor.shutdown()
        probe.node.destroy_node()
        rclpy.try_shutdown(context=context)
        log.close()
