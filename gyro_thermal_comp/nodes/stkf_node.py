"""`stkf_node`: the STKF thermal-drift estimator as a ROS 2 node (node name `stkf_drift_estimator`).

Thin by design (like imu_tools' wrapper around ImuFilter): messages in, `ThermalDriftEstimator` in
the middle, messages out. Subscribes `imu/data_raw`, `imu/mag`, `imu/temperature` (sensor-data QoS);
publishes `imu/data` (compensated, REP 145 covariances, input stamp and frame_id), `imu/heading`
and `diagnostics`. Callbacks only buffer; a steady-clock timer puts the buffered samples in stamp
order and runs the estimator on them in one batch, so the node keeps up at 1 kHz and produces what
an offline run over the same bag produces.
"""
from __future__ import annotations

import math
import sys
import threading
from collections import deque

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus
from rcl_interfaces.msg import SetParametersResult
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from sensor_msgs.msg import Imu, MagneticField, Temperature
from std_msgs.msg import Header

from .. import topics
from ..samples import SensorChunk
from ..thermal.estimator import ThermalDriftEstimator, reason_names
from . import conversions as conv
from .interface import STKF, create_publishers, create_subscriptions, input_counters, pop_chunk, sensor_qos
from .parameters import all_specs, config_from_params
from .ros_params import ParameterFileError, declare_parameters, run_node, first_problem
from .stamp_merger import StampMerger, poll_gap_s
from .state_store import StateFileInUse, StateStore, StateStoreError

NODE_NAME = STKF.node_name


class StkfDriftEstimatorNode(Node):
    def __init__(self, node_name: str = NODE_NAME, **node_kwargs):
        super().__init__(node_name, **node_kwargs)
        self._specs = {s.name: s for s in all_specs()}
        values = declare_parameters(self, self._specs)
        self.settings = dict(values)
        self.estimator = ThermalDriftEstimator(config_from_params(values))
        self._warm_start()
        self._lock = threading.Lock()  # timer vs. shutdown/flush from another thread
        self.merger = StampMerger([p.name for p in STKF.inputs], max_latency_s=values['max_latency_s'],
                                  max_buffered=values['buffer_max_samples'],
                                  max_poll_gap_s=poll_gap_s(values['process_period_s']),
                                  max_jump_s=self.estimator.cfg.max_time_jump_s,
                                  confirm_samples=self.estimator.cfg.time_jump_confirm_samples)
        self._headers: deque = deque()          # (stamp, frame_id) of buffered IMU samples, in order
        self._imu_period_s: float | None = None
        self.outputs_published = 0
        self._last_out: dict | None = None
        self._drift_var = 0.0  # (rad/s)^2, variance of the drift estimate, for the output covariance
        self._dropped_reported = 0   # dropped input samples already reported in diagnostics
        self._silence_after_s = max(1.0, 2.0 * values['diagnostics_period_s'])   # a stream this quiet is named

        # Inputs in their own callback group: under a multi-threaded executor they keep being received
        # while a batch is processed; the lock keeps the buffer consistent.
        self._inputs_group = MutuallyExclusiveCallbackGroup()
        self._input_qos = sensor_qos(values['input_queue_depth'], reliable=values['reliable_inputs'])
        self.subscriptions_by_stream = create_subscriptions(
            self, STKF, {'imu': self._on_imu, 'mag': self._on_mag, 'temperature': self._on_temperature},
            self._input_qos, self._inputs_group)
        self.pubs = create_publishers(self, STKF)   # output name -> publisher (replay swaps in recorders)

        steady = Clock(clock_type=ClockType.STEADY_TIME)  # keeps running with use_sim_time and no /clock
        self.create_timer(values['process_period_s'], self.process_buffered, clock=steady)
        self._diag_timer = self.create_timer(values['diagnostics_period_s'], self.publish_diagnostics, clock=steady)
        self._save_timer = self.create_timer(values['state_save_period_s'], self.save_state, clock=steady)
        self.add_on_set_parameters_callback(self._on_set_parameters)

    # ------------------------------------------------------------------ parameters
    def _on_set_parameters(self, params) -> SetParametersResult:
        problem = first_problem(self._specs, params, self.settings)
        if problem:
            return SetParametersResult(successful=False, reason=problem)
        gate_changes = {p.name.split('.', 1)[1]: p.value for p in params if p.name.startswith('gate.')}
        if gate_changes:
            try:
                self.estimator.set_gate_config(**gate_changes)
            except (TypeError, ValueError) as exc:
                return SetParametersResult(successful=False, reason=str(exc))
        for p in params:
            if p.name in ('diagnostics_period_s', 'state_save_period_s'):
                timer = self._diag_timer if p.name == 'diagnostics_period_s' else self._save_timer
                timer.timer_period_ns = int(p.value * 1e9)
                timer.reset()
            if p.name in self.settings:
                self.settings[p.name] = p.value
        return SetParametersResult(successful=True)

    # ------------------------------------------------------------------ persistence
    def _warm_start(self) -> None:
        """Own the state file and load it; a file that does not fit is moved aside (cold start, said
        in diagnostics). A state file in use by another node is a configuration error (exit 2)."""
        path = self.get_parameter('state_file').value
        self.state_store: StateStore | None = None
        self.state_status, self.state_rejected = 'cold start: no state_file parameter', False
        if not path:
            return
        store = StateStore(path)
        try:
            result = store.load(self.estimator.set_state)   # validates before it changes anything
        except StateFileInUse as exc:
            raise ParameterFileError(f'state_file: {exc}') from None
        except OSError as exc:   # folder missing/read-only: run, but without persistence
            self.state_status = f'cold start: cannot use state file {path} ({exc}); not saving'
            self.get_logger().error(self.state_status)
            return
        self.state_store = store
        self.state_status, self.state_rejected = result.status, result.moved_to is not None
        (self.get_logger().info if result.warm else self.get_logger().warning)(result.status)

    def save_state(self) -> None:
        state = self.estimator.get_state()
        if self.state_store is None or 'x' not in state:
            return
        try:
            self.state_store.save(state)
        except (OSError, StateStoreError) as exc:
            self.get_logger().error(f'cannot save state: {exc}', throttle_duration_sec=60.0)

    def destroy_node(self):
        if getattr(self, 'state_store', None) is not None:
            self.state_store.release()
        return super().destroy_node()

    # ------------------------------------------------------------------ input
    def _on_imu(self, msg: Imu) -> None:
        t, row = conv.imu_row(msg)
        with self._lock:
            accepted = self.merger.push('imu', t, row)
            if accepted:
                self._headers.append(msg.header)
        if not accepted:
            self.get_logger().warning('dropping IMU samples (NaN, repeated/out-of-order or late stamps); '
                                      'see diagnostics', throttle_duration_sec=10.0)

    def _on_mag(self, msg: MagneticField) -> None:
        with self._lock:
            self.merger.push('mag', *conv.mag_row(msg))

    def _on_temperature(self, msg: Temperature) -> None:
        with self._lock:
            self.merger.push('temperature', *conv.temperature_row(msg))

    # ------------------------------------------------------------------ processing
    def process_buffered(self, flush: bool = False) -> None:
        with self._lock:
            self._process_buffered(flush)

    def _process_buffered(self, flush: bool) -> None:
        chunk = pop_chunk(self.merger, self.subscriptions_by_stream, flush)
        if chunk is None:
            return
        headers = [self._headers.popleft() for _ in range(len(chunk.imu.t))] if chunk.imu is not None else []
        self.process_chunk(chunk, headers)

    def process_chunk(self, chunk: SensorChunk, headers=None) -> None:
        """Run the estimator on stamp-ordered samples and publish one output per IMU sample.

        `headers` are the input headers (stamp + frame_id) of the IMU samples; replay passes None and
        the stamps are rebuilt from the sample times with the IMU frame id.
        """
        out = self.estimator.process(chunk)
        n = len(out.track.t)
        if n == 0:
            return
        if headers is None:
            headers = [Header(stamp=conv.time_msg(t), frame_id=topics.IMU_FRAME) for t in out.track.t.tolist()]
        if n > 1:
            self._imu_period_s = float(np.median(np.diff(out.track.t)))
        gyro_var, accel_var, tilt_var = self._noise_variances(out)
        heading_var = np.square(out.track.heading_sigma_rad)
        for i in np.flatnonzero(out.valid).tolist():
            if not (np.all(np.isfinite(out.gyro_compensated[i])) and math.isfinite(out.track.heading_rad[i])):
                continue  # never publish NaN (e.g. before the first temperature): said in diagnostics
            roll, pitch = out.roll_rad[i], out.pitch_rad[i]
            if not (math.isfinite(roll) and math.isfinite(pitch)):
                roll = pitch = 0.0
            h_var = heading_var[i] if math.isfinite(heading_var[i]) else math.pi ** 2
            self.pubs['imu'].publish(conv.compensated_imu(
                headers[i], out.gyro_compensated[i], chunk.imu.accel[i], roll, pitch, out.track.heading_rad[i],
                gyro_var=gyro_var[i], accel_var=accel_var, tilt_var=tilt_var, heading_var=h_var))
            self.pubs['heading'].publish(conv.heading_msg(headers[i], out.track.heading_rad[i]))
            self.outputs_published += 1
        self._last_out = {'reasons': int(out.reasons[-1]), 'gate_open': bool(out.gate_open[-1]),
                          'temperature_c': float(out.temperature_c[-1])}

    def _noise_variances(self, out):
        """Per-sample variances for REP 145 covariances from the sensor noise model."""
        fs = 1.0 / self._imu_period_s if self._imu_period_s else 100.0
        arw = math.radians(self.estimator.cfg.arw_deg_sqrt_s)
        drift_var = self._drift_var  # refreshed with the diagnostics (1 Hz): too costly per batch
        gyro_var = np.full(len(out.track.t), arw ** 2 * fs + drift_var)
        accel_var = self.settings['accel_noise_density_m_s2_rthz'] ** 2 * fs
        n_tilt = max(1.0, fs * self.estimator.cfg.tilt_window_s)
        tilt_var = accel_var / n_tilt / 9.80665 ** 2
        return gyro_var, accel_var, tilt_var

    # ------------------------------------------------------------------ diagnostics
    def diagnostic_values(self) -> tuple[int, str, dict]:
        """Level, message and key values: the estimate (plain keys, `param.*`, `sigma.*`), the core's
        counters under `core.` and the input layer's under `input.`, so no component hides another."""
        d = self.estimator.diagnostics()
        self._drift_var = float(np.nan_to_num(d.get('drift_sigma_rad_s', 0.0))) ** 2
        values = {}
        for name, value in d.get('params', {}).items():
            values[f'param.{name}'] = value
        for name, value in d.get('param_sigmas', {}).items():
            values[f'sigma.{name}'] = value
        for key in ('gate_open', 'coasting_for_s', 'heading_sigma_rad', 'drift_sigma_rad_s', 'temperature_stuck',
                    'temperature_stuck_for_s'):
            values[key] = d[key]
        values['gate_reasons'] = ','.join(d.get('gate_reasons', [])) or 'none'
        values.update({f'core.{k}': v for k, v in self.estimator.counters().items()})
        values.update(input_counters(self.merger, self.subscriptions_by_stream))
        values['outputs_published'] = self.outputs_published
        values['state_file'] = self.state_status
        if self._last_out is not None:
            values['last_sample_reasons'] = ','.join(reason_names(self._last_out['reasons'])) or 'none'
        status = 'learning: gate open'
        if not d.get('started'):
            status = 'waiting for the still period / first data'
        elif not d.get('gate_open'):
            status = f'coasting on the model: {values["gate_reasons"]}'
        problems = self._problems(d, values)
        level = DiagnosticStatus.WARN if problems or status != 'learning: gate open' else DiagnosticStatus.OK
        return level, '; '.join([status] + problems), values

    def _problems(self, d: dict, values: dict) -> list[str]:
        """What a robot operator must hear about, beyond the gate: each makes the status WARN."""
        problems = []
        age_s = d['temperature_age_s']
        values['temperature_age_s'] = age_s
        if d.get('started') and age_s == math.inf:
            problems.append('no temperature readings: the model runs at its reference temperature')
        elif age_s > self.estimator.cfg.temperature_timeout_s:
            problems.append(f'temperature stale for {age_s:.0f} s: not learning, drift uncertainty growing')
        if d.get('temperature_stuck'):
            problems.append('temperature stuck')
        if self.state_rejected:
            problems.append('state file rejected (see state_file)')
        silent = self.merger.silent_streams(self._silence_after_s)
        if silent:
            problems.append('no input on ' + ', '.join(f'{k} for {v:.0f} s' for k, v in silent.items()))
        dropped = sum(v for k, v in values.items() if 'dropped' in k and isinstance(v, int))
        values['input_samples_dropped'] = dropped
        if dropped > self._dropped_reported:
            problems.append(f'{dropped - self._dropped_reported} input samples dropped since the last report '
                            f'({dropped} in all: see core.* and input.*)')
        self._dropped_reported = dropped
        return problems

    def publish_diagnostics(self) -> None:
        level, message, values = self.diagnostic_values()
        self.pubs['diagnostics'].publish(conv.diagnostic_array(self.get_clock().now().to_msg(),
                                                    f'{self.get_name()}: thermal drift', topics.IMU_FRAME,
                                                    level, message, values))

    def shutdown(self) -> None:
        """Process what is buffered and save the learned state (call before destroy_node)."""
        self.process_buffered(flush=True)
        self.save_state()
        self.get_logger().info(f'stopped: {self.outputs_published} outputs published')


def main(args=None) -> int:
    return run_node(StkfDriftEstimatorNode, 'stkf_node', args)


if __name__ == '__main__':
    sys.exit(main())
