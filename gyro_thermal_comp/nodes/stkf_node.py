"""`stkf_node`: the STKF thermal-drift estimator as a ROS 2 node (node name `stkf_drift_estimator`).

Thin by design (like imu_tools' wrapper around ImuFilter): messages in, `ThermalDriftEstimator` in
the middle, messages out. Subscribes `imu/data_raw`, `imu/mag`, `imu/temperature` (sensor-data QoS);
publishes, one per IMU sample, with the input stamp:
- `imu/data` (sensor_msgs/Imu, the input frame_id): rates with the drift removed; orientation in
  `world_frame` (ENU, or NED) with REP 145 covariances. Yaw is the drift-compensated gyro heading
  corrected by the compass. Roll and pitch are NOT a real-time attitude: they are the direction of
  the mean specific force over the last `tilt_window_s` (120 s; turning samples left out), right for
  a ground vehicle whose attitude changes little, lagging on a slope or a rolling platform. Their
  variance is `tilt_floor_deg`^2 (accelerometer offset, misalignment) plus the standard error of
  that mean under the vehicle's accelerations; the yaw variance is the heading filter's plus
  `compass_deviation_sigma_deg`^2 and `declination_sigma_deg`^2, which never average down
  (orientation_uncertainty.py).
- `imu/heading` (geometry_msgs/PoseWithCovarianceStamped, frame `fixed_frame`): the same yaw, the
  levelled IMU frame's orientation, with the yaw variance (the rest marked unknown).
- `/tf` `fixed_frame` -> IMU frame (rotation only) with `publish_tf` (needs tf2_msgs).
- `/diagnostics`.
Inputs are taken and outputs published as serialized CDR (raw subscriptions and publishers,
conversions.InputSamples and RawOutputs, through cdr.OneMessage): rclpy's conversion of an Imu with
its covariance arrays to and from a message object costs more than the node's own work per sample.
Unreadable bytes are dropped and counted (`input.<stream>_dropped_malformed`). The node has no rclpy
QoS-event handlers (every executor turn walks them); `EndpointCheck` warns about incompatible
endpoints instead. Two paths (thermal/compensator.py). Each IMU sample is compensated and published in its own
callback (the fast path), from the estimator's state at its latest row at or before the stamp minus
`output_delay_s`; a steady-clock timer puts the buffered samples of all topics in stamp order and
runs the estimator on them in one batch (the slow path). Which state compensates a sample depends
on stamps only, so the node produces what an offline run over the same bag produces. At start it
says what it does, names inputs that have not arrived after a few seconds, and says when the still
period begins and ends.
"""
from __future__ import annotations

import math
import sys
import threading
import time

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus
from rcl_interfaces.msg import SetParametersResult
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from sensor_msgs.msg import Imu, MagneticField, Temperature

from .. import cdr, topics
from ..learning_status import LearningStatus, learning_line
from ..samples import SensorChunk
from ..stamps import TimeOrigin, ns_at
from ..thermal.compensator import QUEUED, ThermalCompensator
from ..thermal.fast_path import RowQueue
from ..thermal.estimator import reason_names
from . import conversions as conv
from .interface import (STKF, EndpointCheck, TFMessage, check_inputs_arrived, create_publishers, create_subscriptions,
                        input_counters, input_wait_report, output_counters, pop_chunk, sensor_qos)
from .node_health import ERROR, MOTION_REASONS, OK, WARN, NodeHealth, assess
from .output_arrays import OutputArrays
from .orientation_uncertainty import OrientationVariance, declination_sigma_deg
from .parameters import all_specs, config_from_params, with_model_file
from .ros_params import ParameterFileError, declare_parameters, first_problem, parameter_file_problems, run_node
from .stamp_merger import StampMerger, poll_gap_s
from .startup_report import StillPeriodReport
from .state_store import StateFileInUse, StateStore, StateStoreError
from .world_frame import world_quat, world_quat_one

NODE_NAME = STKF.node_name
_LEVELS = {OK: DiagnosticStatus.OK, WARN: DiagnosticStatus.WARN, ERROR: DiagnosticStatus.ERROR}


class StkfDriftEstimatorNode(Node):
    def __init__(self, node_name: str = NODE_NAME, **node_kwargs):
        super().__init__(node_name, **node_kwargs)
        self._specs = {s.name: s for s in all_specs()}
        values = declare_parameters(self, self._specs)
        self._param_file_problems = parameter_file_problems(self)   # files none of whose sections apply
        if values['publish_tf'] and TFMessage is None:
            raise ParameterFileError('publish_tf: tf2_msgs is not installed (it comes with a ROS install: '
                                     'ros-jazzy-tf2-msgs); set publish_tf false')
        self.settings = dict(values)
        self.compensator = ThermalCompensator(with_model_file(config_from_params(values), values['drift_model_file']),
                                              values['output_delay_s'],
                                              held=self._held_variances)
        self.estimator = self.compensator.estimator
        self._warm_start()
        self._lock = threading.Lock()  # timer vs. shutdown/flush from another thread
        self.merger = StampMerger([p.name for p in STKF.inputs], max_latency_s=values['max_latency_s'],
                                  max_buffered=values['buffer_max_samples'],
                                  max_poll_gap_s=poll_gap_s(values['process_period_s']),
                                  max_jump_s=self.estimator.cfg.max_time_jump_s,
                                  confirm_samples=self.estimator.cfg.time_jump_confirm_samples,
                                  first_sample_wait_s=values['first_sample_wait_s'])
        cfg = self.estimator.cfg
        self._declination_sigma_deg = declination_sigma_deg(values['declination_sigma_deg'], cfg.declination_rad)
        self.orientation_variance = OrientationVariance.from_params(values, cfg)
        self._imu_frame: str | None = None      # frame_id of the first IMU message (hardware_id default)
        self.time_origin = TimeOrigin()         # the core runs on s since the first stamp (replay sets it)
        self._pending = RowQueue()       # (header CDR bytes or None, accel) of the IMU samples the compensator queues
        self.bulk_sink = None            # replay: writes imu/data and imu/heading in bulk (output_arrays.py)
        self._samples = conv.InputSamples()
        self._raw = conv.RawOutputs(values['fixed_frame'])
        self._heading_wanted = True
        self._imu_period_s: float | None = None
        self.outputs_published = 0
        self._last_out: dict | None = None
        self._drift_var = 0.0  # (rad/s)^2, variance of the drift estimate, for the output covariance
        self._reported = {'imu_received': 0, 'published': 0, 'dropped': 0}   # at the last diagnostics report
        self._t_created = time.monotonic()
        self.learning_status = LearningStatus(cfg.window_s)   # why nothing is learned, if it is not
        self._said_not_learning: int | None = None   # filter updates when the not-learning line was logged
        self._silence_after_s = max(1.0, 2.0 * values['diagnostics_period_s'])   # a stream this quiet is named

        # Inputs in their own callback group; the lock keeps the buffer consistent (a batch holds it,
        # so under a multi-threaded executor input callbacks wait for it: DDS queues them meanwhile).
        # Raw: the callbacks read the CDR bytes themselves (conversions.InputSamples). Quiet: no
        # QoS-event handlers, which cost every executor turn; EndpointCheck says what they would.
        self._inputs_group = MutuallyExclusiveCallbackGroup()
        self._input_qos = sensor_qos(values['input_queue_depth'], reliable=values['reliable_inputs'])
        self.subscriptions_by_stream = create_subscriptions(
            self, STKF, {'imu': self._on_imu, 'mag': self._on_mag, 'temperature': self._on_temperature},
            self._input_qos, self._inputs_group, raw=True, quiet=True)
        # output name -> publisher (replay swaps in recorders); real publishers get CDR bytes
        depth = values['output_queue_depth']
        self.pubs = create_publishers(self, STKF, skip=() if values['publish_tf'] else ('tf',), quiet=True,
                                      depths={'imu': depth, 'heading': depth})
        self.endpoint_check = EndpointCheck(self.get_logger(), self, self.subscriptions_by_stream.values(),
                                            self.pubs.values())

        steady = Clock(clock_type=ClockType.STEADY_TIME)  # keeps running with use_sim_time and no /clock
        self.create_timer(values['process_period_s'], self.process_buffered, clock=steady)
        self._diag_timer = self.create_timer(values['diagnostics_period_s'], self.publish_diagnostics, clock=steady)
        self._save_timer = self.create_timer(values['state_save_period_s'], self.save_state, clock=steady)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.input_wait = input_wait_report(self, self.subscriptions_by_stream,
                                            optional=() if values['temperature_sensor'] else ('temperature',))
        self.still_report = StillPeriodReport(self.get_logger(), cfg.still_period_s)
        self._log_start()

    def _log_start(self) -> None:
        """One message: what this node does, from what, to where, and what it needs first."""
        s, cfg = self.settings, self.estimator.cfg
        inputs = ', '.join(sub.topic_name for sub in self.subscriptions_by_stream.values())
        outputs = ', '.join(pub.topic_name for pub in self.pubs.values())
        self.get_logger().info(
            f'thermal gyro-drift estimator, {self.state_status}. Inputs: {inputs}; outputs: {outputs}. '
            f'Needs {cfg.still_period_s:g} s motionless at the start (biases, compass noise). Orientation in '
            f"{s['world_frame'].upper()}, heading frame '{s['fixed_frame']}'"
            f"{', TF on' if s['publish_tf'] else ''}; 1-sigma floors: roll/pitch {s['tilt_floor_deg']:g} deg, yaw "
            f"{math.hypot(s['compass_deviation_sigma_deg'], self._declination_sigma_deg):.2g} deg (compass "
            f"deviation {s['compass_deviation_sigma_deg']:g}, declination {self._declination_sigma_deg:g}"
            f"{'' if cfg.declination_rad else ': declination_rad not set'}).")

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
    def _on_imu(self, msg: bytes | Imu) -> None:
        """imu/data_raw: serialized CDR (the subscription is raw) or an Imu (tests, tools)."""
        sample = self._read('imu', msg)
        if sample is None:
            return
        ns, frame_id, header, row = sample
        t = self.time_origin.seconds(ns)
        if self._imu_frame is None:
            self._imu_frame = frame_id
        with self._lock:
            accepted = self.merger.push('imu', t, row)
            out = self.compensator.push(ns, row[:3], row[3:])
            if out is QUEUED:   # it waits for the estimator, or behind samples that do
                queued = np.empty(1, object)
                queued[0] = header
                self._pending.append(queued, np.array([row[3:]], dtype=float))
                self._publish_ready()
            elif out is not None:
                self._publish_one(header, row[3:], out)
        if not accepted:
            self.get_logger().warning('IMU samples the estimator cannot use (NaN, repeated/out-of-order or late '
                                      'stamps); see diagnostics', throttle_duration_sec=10.0)

    def _on_mag(self, msg: bytes | MagneticField) -> None:
        self._push_slow('mag', msg)

    def _on_temperature(self, msg: bytes | Temperature) -> None:
        self._push_slow('temperature', msg)

    def _push_slow(self, stream: str, msg) -> None:
        """A sample only the estimator uses: into the stamp merger."""
        sample = self._read(stream, msg)
        if sample is not None:
            t = self.time_origin.seconds(sample[0])
            with self._lock:
                self.merger.push(stream, t, sample[3])

    def _read(self, stream: str, msg):
        """(stamp ns, frame_id, header CDR bytes, row) of an input message, or None: bytes that are
        no message of the stream's type are dropped and counted (`input.<stream>_dropped_malformed`)."""
        try:
            return getattr(self._samples, stream)(msg)
        except cdr.MalformedMessage as exc:
            with self._lock:
                self.merger.malformed(stream)
            self.get_logger().warning(f'dropped unreadable {stream} messages (see diagnostics '
                                      f'input.{stream}_dropped_malformed): {exc}', throttle_duration_sec=10.0)
            return None

    # ------------------------------------------------------------------ slow path: the estimator
    def process_buffered(self, flush: bool = False) -> None:
        with self._lock:
            self._process_buffered(flush)

    def _process_buffered(self, flush: bool) -> None:
        # imu/heading is built per sample only while somebody listens (checked here, not per sample)
        pub = self.pubs['heading']
        self._heading_wanted = pub.get_subscription_count() > 0 if isinstance(pub, Publisher) else True
        chunk = pop_chunk(self.merger, self.subscriptions_by_stream, flush)
        if chunk is not None and chunk.imu is not None:
            self._estimate(chunk)
        if flush:
            self.compensator.finish()
        self._publish_ready()

    def process_chunk(self, chunk: SensorChunk) -> None:
        """Offline (replay): what the live node does with these samples, in one go: queue the IMU
        samples, run the estimator, publish (thermal/compensator.py)."""
        self._imu_frame = self._imu_frame or topics.IMU_FRAME
        self.compensator.add_many(ns_at(chunk.imu.t, self.time_origin.ns or 0), chunk.imu.gyro, chunk.imu.accel)
        self._pending.append(np.full(chunk.imu.t.size, None, object), chunk.imu.accel)
        self._estimate(chunk)
        self._publish_ready()

    def _estimate(self, chunk: SensorChunk) -> None:
        out = self.compensator.estimate(chunk, self.time_origin.ns or 0)
        est = self.estimator
        self.still_report.update(est.t_origin, est.still.end_s, est.learner is not None)
        if len(out.track.t) > 1:
            self._imu_period_s = float(np.median(np.diff(out.track.t)))
        if len(out.track.t):
            self._last_out = {'reasons': int(out.reasons[-1]), 'gate_open': bool(out.gate_open[-1]),
                              'drift_rad_s': float(out.track.drift_rad_s[-1])}
            if np.isfinite(out.temperature_c[-1]):
                self._last_out['temperature_c'] = float(out.temperature_c[-1])
        self.learning_status.add(out.track.t, out.reasons, out.valid, est.counters().get('filter_updates', 0),
                                 est.drift_window_s)

    def _held_variances(self, out, chunk: SensorChunk) -> dict:
        return self.orientation_variance.held_tilt(out, chunk.imu.accel, self.estimator.gyro.tilt_max_rate_rad_s)

    # ------------------------------------------------------------------ fast path: one output per sample
    def _publish_ready(self) -> None:
        """Publish every queued IMU sample whose anchor is final (thermal/fast_path.py)."""
        n, out = self.compensator.take_ready()
        if n:
            headers, accel = self._pending.take(n)
            self._publish(out, headers, accel)

    def _publish(self, out, headers, accel) -> None:
        """One imu/data and one imu/heading message (and a transform) per sample out.ok marks."""
        o = self._output_arrays(out, accel)
        self.outputs_published += o.ns.size
        if self.bulk_sink is not None:   # replay: imu/data and imu/heading of the whole batch at once
            self.bulk_sink.write(o)
            if self.settings['publish_tf'] and 'tf' in self.pubs:
                for k, t_ns in enumerate(o.ns.tolist()):
                    self.pubs['tf'].publish(conv.tf_message([conv.transform_msg(
                        conv.time_msg_ns(t_ns), self.settings['fixed_frame'], o.frame_id, o.q_imu[k])]))
            return
        for k, i in enumerate(np.flatnonzero(out.ok).tolist()):
            header = headers[i] or cdr.header_cdr(int(o.ns[k]), o.frame_id)
            self._send(header, o.gyro[k].tolist(), o.accel[k].tolist(), o.q_imu[k].tolist(),
                       o.orientation_var[k].tolist(), o.gyro_var, o.accel_var, o.q_heading[k].tolist())

    def _publish_one(self, header, accel, out) -> None:
        """`_publish` for one sample from `FastPath.run_one`, in Python floats (the live path)."""
        k, wx, wy, wz, yaw, heading_var = out
        held = self.compensator.fast.anchors.held
        gyro_var, accel_var = self._noise_variances()
        frame = self.settings['world_frame']
        yaw_var = self.orientation_variance.yaw_variance(heading_var)
        q_imu = world_quat_one(float(held['roll'][k]), float(held['pitch'][k]), yaw, frame)
        self._send(header, (wx, wy, wz), accel, q_imu,
                   (float(held['roll_var'][k]), float(held['pitch_var'][k]), yaw_var), gyro_var, accel_var,
                   world_quat_one(0.0, 0.0, yaw, frame) if self._heading_wanted else None)
        self.outputs_published += 1

    def _send(self, header: bytes, gyro, accel, q_imu, orientation_var, gyro_var, accel_var, q_heading) -> None:
        """imu/data, imu/heading (while somebody listens) and the transform of one sample, with the
        header `header` (CDR bytes, the input's). Real publishers get CDR bytes (conversions.RawOutputs);
        stand-ins (replay recorders, tests) message objects with the same numbers."""
        fixed, yaw_var = self.settings['fixed_frame'], orientation_var[2]
        pub, typed_header = self.pubs['imu'], None
        if isinstance(pub, Publisher):
            pub.publish(self._raw.imu(header, gyro, accel, q_imu, gyro_var, accel_var, orientation_var))
        else:
            typed_header = conv.header_msg(header)
            pub.publish(conv.compensated_imu(typed_header, gyro, accel, q_imu, gyro_var=gyro_var,
                                             accel_var=accel_var, orientation_var=orientation_var))
        if self._heading_wanted:
            pub = self.pubs['heading']
            if isinstance(pub, Publisher):
                pub.publish(self._raw.heading(header, q_heading, yaw_var))
            else:
                typed_header = typed_header or conv.header_msg(header)
                pub.publish(conv.heading_msg(typed_header.stamp, fixed, q_heading, yaw_var))
        if self.settings['publish_tf'] and 'tf' in self.pubs:
            typed_header = typed_header or conv.header_msg(header)
            self.pubs['tf'].publish(conv.tf_message([conv.transform_msg(
                typed_header.stamp, fixed, typed_header.frame_id or topics.IMU_FRAME, q_imu)]))

    def _output_arrays(self, out, accel) -> OutputArrays:
        """The published numbers of the samples out.ok marks, as arrays (never NaN)."""
        ok = out.ok
        gyro_var, accel_var = self._noise_variances()
        h = out.held
        yaw = out.heading[ok]
        frame = self.settings['world_frame']
        zeros = np.zeros(yaw.size)
        return OutputArrays(
            ns=out.ns[ok], frame_id=self._imu_frame or topics.IMU_FRAME, gyro=out.gyro_compensated[ok],
            accel=accel[ok], q_imu=world_quat(h['roll'][ok], h['pitch'][ok], yaw, frame),
            q_heading=world_quat(zeros, zeros, yaw, frame),   # the levelled IMU frame
            orientation_var=np.column_stack((h['roll_var'][ok], h['pitch_var'][ok],
                                             self.orientation_variance.yaw_variance(out.heading_var[ok]))),
            gyro_var=gyro_var, accel_var=accel_var)

    def _noise_variances(self):
        """Rate and accelerometer variances for REP 145, from the noise model."""
        fs = 1.0 / self._imu_period_s if self._imu_period_s else 100.0
        arw = math.radians(self.estimator.cfg.arw_deg_sqrt_s)
        drift_var = self._drift_var  # refreshed with the diagnostics (1 Hz): too costly per sample
        return arw ** 2 * fs + drift_var, self.settings['accel_noise_density_m_s2_rthz'] ** 2 * fs

    @property
    def hardware_id(self) -> str:
        """The `hardware_id` parameter, else the IMU's frame_id as received, else 'imu'."""
        return self.settings['hardware_id'] or self._imu_frame or 'imu'

    # ------------------------------------------------------------------ diagnostics
    def diagnostic_values(self) -> tuple[int, str, dict]:
        """Level, message and key values (node_health.py). First the key values a robot team reads,
        each with its unit in the name: temperature (degC), drift and its sigma (deg/s), heading
        sigma (deg), time since the last compass correction (s); then the drift-model parameters
        (`param.<term> [unit]`, `sigma.<term> [unit]`), the core's counters under `core.` and the
        input layer's under `input.`, so no component hides another."""
        d = self.estimator.diagnostics()
        self._drift_var = float(np.nan_to_num(d.get('drift_sigma_rad_s', 0.0))) ** 2
        counters = self.estimator.counters()
        last = self._last_out or {}
        heading_sigma_deg = math.degrees(d['heading_sigma_rad'])
        age_s = d['temperature_age_s']
        values = {
            'temperature_c': last.get('temperature_c', 'none'),
            'temperature_age_s': age_s if math.isfinite(age_s) else 'no reading yet',
            'drift_deg_s': math.degrees(last['drift_rad_s']) if 'drift_rad_s' in last else 'none yet',
            'drift_sigma_deg_s': math.degrees(d['drift_sigma_rad_s']),
            'heading_sigma_deg': heading_sigma_deg,
            'yaw_sigma_deg': math.degrees(math.sqrt(float(
                self.orientation_variance.yaw_variance(d['heading_sigma_rad'] ** 2)))),
            'since_compass_update_s': d['coasting_for_s'],
            'gate_open': d['gate_open'],
            'gate_reasons': ','.join(d.get('gate_reasons', [])) or 'none',
            'filter_updates': counters.get('filter_updates', 0),
        }
        units = dict(zip(self.estimator.model.names, (t.unit for t in self.estimator.model.terms)))
        units['constant_at_0c'] = units.get('constant', 'rad/s')
        for name, value in d.get('params', {}).items():
            values[f'param.{name} [{units.get(name, "SI")}]'] = value
        for name, value in d.get('param_sigmas', {}).items():
            values[f'sigma.{name} [{units.get(name, "SI")}]'] = value
        for key in ('heading_sigma_rad', 'drift_sigma_rad_s', 'temperature_stuck', 'temperature_stuck_for_s',
                    'window_r_scale'):
            values[key] = d[key]
        values.update({f'core.{k}': v for k, v in counters.items()})
        values.update(input_counters(self.merger, self.subscriptions_by_stream))
        values.update(output_counters(self.pubs))
        values['outputs_published'] = self.outputs_published
        comp = self.compensator
        values['outputs_not_published'] = comp.fast.dropped    # the input guard's drops, NaN
        values['outputs_waited'] = comp.waited   # the estimator lagged more than output_delay_s
        values['incompatible_endpoints'] = self.endpoint_check.incompatible   # named in the log
        values['state_file'] = self.state_status
        values['still_period'] = self.estimator.still_use or 'running'
        if 'reasons' in last:
            values['last_sample_reasons'] = ','.join(reason_names(last['reasons'])) or 'none'
        dropped = sum(v for k, v in values.items() if 'dropped' in k and isinstance(v, int))
        values['input_samples_dropped'] = dropped
        learn = self.estimator.cfg.learn
        est = self.estimator
        imu_received = values.get('input.imu_received', 0)
        health = NodeHealth(
            imu_topic=self.subscriptions_by_stream['imu'].topic_name,
            imu_received=imu_received + int(est.t_origin is not None),
            imu_received_new=imu_received - self._reported['imu_received'],
            published_new=self.outputs_published - self._reported['published'],
            node_age_s=time.monotonic() - self._t_created, silence_after_s=self._silence_after_s,
            silent=self.merger.silent_streams(self._silence_after_s),
            started=bool(d.get('started')), waiting=self._waiting_status(),
            gate_open=bool(d['gate_open']), gate_reasons=tuple(d.get('gate_reasons', [])),
            since_compass_s=float(d['coasting_for_s']), heading_sigma_deg=heading_sigma_deg,
            heading_sigma_limit_deg=self.settings['compass_deviation_sigma_deg'],
            temperature_sensor=self.settings['temperature_sensor'], temperature_age_s=age_s,
            temperature_timeout_s=est.cfg.temperature_timeout_s, temperature_stuck=bool(d.get('temperature_stuck')),
            imu_for_s=est.gyro.t_last - est.t_origin if est.t_origin is not None else 0.0,
            learn=learn, filter_updates=int(counters.get('filter_updates', 0)),
            not_learning=self.learning_status.verdict(counters) if learn else None,
            stalled=(self.learning_status.verdict(counters, since_update=True, by_design=MOTION_REASONS)
                     if learn else None),
            state_rejected=self.state_rejected, parameter_files=tuple(self._param_file_problems),
            dropped_new=max(dropped - self._reported['dropped'], 0), dropped_total=dropped,
            incompatible_endpoints=self.endpoint_check.incompatible)
        self._reported = {'imu_received': imu_received, 'published': self.outputs_published, 'dropped': dropped}
        level, message = assess(health)
        said = health.not_learning or (health.stalled if health.gate_open else None)
        if said and self._said_not_learning is None:   # once in the log; again only after it learned since
            self.get_logger().warning(said)
            self._said_not_learning = health.filter_updates
        elif self._said_not_learning is not None and health.filter_updates > self._said_not_learning:
            self._said_not_learning = None
        return _LEVELS[level], message, values

    def _waiting_status(self) -> str:
        est = self.estimator
        if est.t_origin is None or est.still.end_s is None:
            return 'waiting for the still period: no data yet'
        left = est.still.end_s - max(est.gyro.t_last, est.t_origin)
        return f'waiting for the still period to end: {max(left, 0.0):.0f} s left (keep the unit motionless)'

    def publish_diagnostics(self) -> None:
        check_inputs_arrived(self.input_wait, self.merger, self.subscriptions_by_stream, self._lock)
        self.endpoint_check.check()
        level, message, values = self.diagnostic_values()
        self.pubs['diagnostics'].publish(conv.diagnostic_array(self.get_clock().now().to_msg(),
                                                    f'{self.get_name()}: thermal drift', self.hardware_id,
                                                    level, message, values))

    def learning_summary(self) -> str:
        """One line: the filter's updates so far, or why it made none (learning_status.py)."""
        return learning_line(self.learning_status, self.estimator.counters(), self.estimator.cfg.learn)

    def shutdown(self) -> None:
        """Process what is buffered and save the learned state (call before destroy_node)."""
        self.process_buffered(flush=True)
        self.save_state()
        self.get_logger().info(f'stopped: {self.outputs_published} outputs published; {self.learning_summary()}')


def main(args=None) -> int:
    return run_node(StkfDriftEstimatorNode, 'stkf_node', args)


if __name__ == '__main__':
    sys.exit(main())
