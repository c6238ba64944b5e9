"""`stkf_node`: the STKF thermal-drift estimator as a ROS 2 node (node name `stkf_drift_estimator`).

Thin by design (like imu_tools' wrapper around ImuFilter): messages in, `ThermalDriftEstimator` in
the middle, messages out. Subscribes `imu/data_raw`, `imu/mag`, `imu/temperature` (sensor-data QoS);
publishes, one per IMU sample, with the input stamp:
- `imu/data` (sensor_msgs/Imu, the input frame_id): rates with the drift removed; orientation in
  `world_frame` (ENU, or NED) with REP 145 covariances. Yaw is the drift-compensated gyro heading
  corrected by the compass. Roll and pitch are NOT a real-time attitude: they are the direction of
  the mean specific force over the last `tilt_window_s` (120 s; turning samples left out), right for
  a ground vehicle whose attitude changes little, lagging on a slope or a rolling platform. Their
  variance is `tilt_floor_rad`^2 (accelerometer offset, misalignment) plus the standard error of
  that mean under the vehicle's accelerations; the yaw variance is the heading filter's plus
  `compass_deviation_sigma_rad`^2 and `declination_sigma_rad`^2, which never average down
  (orientation_uncertainty.py).
- `imu/heading` (geometry_msgs/PoseWithCovarianceStamped, frame `fixed_frame`): the same yaw, the
  levelled IMU frame's orientation, with the yaw variance (the rest marked unknown).
- `/tf` `fixed_frame` -> IMU frame (rotation only) with `publish_tf` (needs tf2_msgs).
- `/diagnostics`.
Inputs are taken and outputs published as serialized CDR (raw subscriptions and publishers,
conversions.InputSamples and output_sinks.CdrSink, through cdr.OneMessage): rclpy's conversion of an
Imu with its covariance arrays to and from a message object costs more than the node's own work per
sample; where the outputs go (live publishers, stand-ins, replay's bulk recorder) is one
output_sinks.OutputSink, chosen whenever the publishers change.
Unreadable bytes are dropped and counted (`input.<stream>_dropped_malformed`). The node has no rclpy
QoS-event handlers (every executor turn walks them); `EndpointCheck` warns about incompatible
endpoints instead. The numbers come from `StkfPipeline` (stkf_pipeline.py, no ROS): each IMU sample
is pushed, compensated and published in its own callback (the fast path), from the estimator's state
at its latest row at or before the stamp minus `output_delay_s`; a steady-clock timer polls the
pipeline, which runs the estimator on the samples of all topics in stamp order (the slow path) and
hands back the samples that waited for it. Which state compensates a sample depends on stamps only,
so the node produces what an offline run over the same bag produces. This module holds the ROS side:
parameters, subscriptions and publishers, the state file, diagnostics and the start-up messages (it
says what it does, names inputs that have not arrived after a few seconds, and says when the still
period begins and ends).
"""
from __future__ import annotations

import math
import sys
import threading
import time
from types import MappingProxyType

from diagnostic_msgs.msg import DiagnosticStatus
from rcl_interfaces.msg import SetParametersResult
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from sensor_msgs.msg import Imu, MagneticField, Temperature

from .. import cdr
from ..samples import SensorChunk
from . import conversions as conv
from .interface import (STKF, EndpointCheck, TFMessage, check_inputs_arrived, create_publishers, create_subscriptions,
                        input_counters, input_wait_report, output_counters, pipeline_time_origin, sensor_qos,
                        unpublished)
from .node_health import ERROR, OK, WARN, NodeHealth, NotLearningNotice, assess
from .output_sinks import OutputSink, output_sink
from .parameters import all_specs, config_from_params, with_model_file
from .ros_params import ParameterFileError, declare_parameters, first_problem, parameter_file_problems, run_node
from .startup_report import StillPeriodReport, stkf_start_message
from .state_store import StateFileInUse, StateStoreError, warm_start
from .stkf_outputs import OneOutput, OutputArrays
from .stkf_pipeline import StkfPipeline

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
        self.pipeline = StkfPipeline(with_model_file(config_from_params(values), values['drift_model_file']),
                                     values, [p.name for p in STKF.inputs])
        self.estimator, self.merger = self.pipeline.estimator, self.pipeline.merger
        try:   # own the state file and load it; one in use by another node is a configuration error
            start = warm_start(values['state_file'], self.estimator.set_state)
        except StateFileInUse as exc:
            raise ParameterFileError(f'state_file: {exc}') from None
        self.state_store, self.state_status, self.state_rejected = start.store, start.status, start.rejected
        if start.level:
            getattr(self.get_logger(), start.level)(start.status)
        self._lock = threading.Lock()  # timer vs. shutdown/flush from another thread
        self._bulk_sink = None   # replay's bulk recorder (output_arrays.py)
        self._samples = conv.InputSamples()
        self.outputs_published = 0
        self._reported = {'imu_received': 0, 'published': 0, 'dropped': 0}   # at the last diagnostics report
        self._t_created = time.monotonic()
        self._not_learning_notice = NotLearningNotice()
        self._silence_after_s = max(1.0, 2.0 * values['diagnostics_period_s'])   # a stream this quiet is named

        # Inputs in their own callback group; the lock keeps the pipeline consistent (a batch holds it, so
        # under a multi-threaded executor input callbacks wait for it: DDS queues them meanwhile). Raw: the
        # callbacks read the CDR bytes (conversions.InputSamples). Quiet: no QoS-event handlers (EndpointCheck).
        self._inputs_group = MutuallyExclusiveCallbackGroup()
        self._input_qos = sensor_qos(values['input_queue_depth'], reliable=values['reliable_inputs'])
        self.subscriptions_by_stream = create_subscriptions(
            self, STKF, {'imu': self._on_imu, 'mag': self._on_mag, 'temperature': self._on_temperature},
            self._input_qos, self._inputs_group, raw=True, quiet=True)
        # output name -> publisher (replay swaps in recorders); setting it chooses the sink (output_sinks.py)
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
        self.still_report = StillPeriodReport(self.get_logger(), self.estimator.cfg.still_period_s)
        self.get_logger().info(stkf_start_message(self.settings, self.estimator.cfg, self.state_status,
                                                  self.subscriptions_by_stream.values(), self.pubs.values()))

    # ------------------------------------------------------------------ where the outputs go
    @property
    def pubs(self) -> MappingProxyType:
        """Output name -> publisher or stand-in, read-only: replay and tests assign a whole new dict,
        and the node chooses its output sink again."""
        return self._pubs

    @pubs.setter
    def pubs(self, pubs) -> None:
        self._pubs = MappingProxyType(dict(pubs))
        self._choose_sink()

    @property
    def bulk_sink(self):
        """Replay's recorder of imu/data and imu/heading batches (output_arrays.BulkRecorder), or None."""
        return self._bulk_sink

    @bulk_sink.setter
    def bulk_sink(self, recorder) -> None:
        self._bulk_sink = recorder
        self._choose_sink()

    def _choose_sink(self) -> None:
        self.sink: OutputSink = output_sink(self._pubs, self._bulk_sink, fixed_frame=self.settings['fixed_frame'],
                                            publish_tf=self.settings['publish_tf'],
                                            heading_built=lambda: self.pipeline.build_heading)

    time_origin = pipeline_time_origin

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
        with self._lock:
            accepted, ready = self.pipeline.push_imu(*sample)
            self._publish(ready)
        if not accepted:
            self.get_logger().warning('IMU samples the estimator cannot use (NaN, repeated/out-of-order or late '
                                      'stamps); see diagnostics', throttle_duration_sec=10.0)

    def _on_mag(self, msg: bytes | MagneticField) -> None:
        sample = self._read('mag', msg)
        if sample is not None:
            with self._lock:
                self.pipeline.push_mag(sample[0], sample[3])

    def _on_temperature(self, msg: bytes | Temperature) -> None:
        sample = self._read('temperature', msg)
        if sample is not None:
            with self._lock:
                self.pipeline.push_temperature(sample[0], sample[3])

    def _read(self, stream: str, msg):
        """(stamp ns, frame_id, header CDR bytes, row) of an input message, or None: bytes that are
        no message of the stream's type are dropped and counted (`input.<stream>_dropped_malformed`)."""
        try:
            return getattr(self._samples, stream)(msg)
        except cdr.MalformedMessage as exc:
            with self._lock:
                self.pipeline.malformed(stream)
            self.get_logger().warning(f'dropped unreadable {stream} messages (see diagnostics '
                                      f'input.{stream}_dropped_malformed): {exc}', throttle_duration_sec=10.0)
            return None

    # ------------------------------------------------------------------ slow path: the estimator
    def process_buffered(self, flush: bool = False) -> None:
        with self._lock:
            # imu/heading is built per sample only while somebody listens (checked here, not per sample)
            self.pipeline.build_heading = self.sink.heading_wanted()
            self._publish(self.pipeline.poll(flush, unpublished(self.subscriptions_by_stream)))
            self.still_report.update(self.estimator)

    def process_chunk(self, chunk: SensorChunk) -> None:
        """Offline (replay): what the live node does with these samples, in one go (StkfPipeline.push_chunk)."""
        self._publish(self.pipeline.push_chunk(chunk))
        self.still_report.update(self.estimator)

    # ------------------------------------------------------------------ output
    def _publish(self, o: OneOutput | OutputArrays | None) -> None:
        """One imu/data and one imu/heading message (and a transform) per sample the pipeline hands out."""
        if o is None:
            return
        if isinstance(o, OneOutput):
            self.sink.one(o)
            self.outputs_published += 1
        else:
            self.outputs_published += o.ns.size
            self.sink.many(o)

    @property
    def hardware_id(self) -> str:
        """The `hardware_id` parameter, else the IMU's frame_id as received, else 'imu'."""
        return self.settings['hardware_id'] or self.pipeline.imu_frame or 'imu'

    # ------------------------------------------------------------------ diagnostics
    def diagnostic_values(self) -> tuple[int, str, dict]:
        """Level, message and key values (node_health.py): the pipeline's (StkfPipeline.diagnostics),
        the input layer's under `input.` and the outputs', so no component hides another."""
        core = self.pipeline.diagnostics()
        values = {**core.values, **input_counters(self.merger, self.subscriptions_by_stream),
                  **output_counters(self.pubs), 'outputs_published': self.outputs_published, **core.outputs,
                  'incompatible_endpoints': self.endpoint_check.incompatible,   # named in the log
                  'state_file': self.state_status, **core.status}
        dropped = sum(v for k, v in values.items() if 'dropped' in k and isinstance(v, int))
        values['input_samples_dropped'] = dropped
        imu_received = values.get('input.imu_received', 0)
        health = NodeHealth(
            imu_topic=self.subscriptions_by_stream['imu'].topic_name,
            imu_received=imu_received + int(self.estimator.t_origin is not None),
            imu_received_new=imu_received - self._reported['imu_received'],
            published_new=self.outputs_published - self._reported['published'],
            node_age_s=time.monotonic() - self._t_created, silence_after_s=self._silence_after_s,
            silent=self.merger.silent_streams(self._silence_after_s),
            heading_sigma_limit_deg=math.degrees(self.settings['compass_deviation_sigma_rad']),
            temperature_sensor=self.settings['temperature_sensor'], state_rejected=self.state_rejected,
            parameter_files=tuple(self._param_file_problems),
            dropped_new=max(dropped - self._reported['dropped'], 0), dropped_total=dropped,
            incompatible_endpoints=self.endpoint_check.incompatible, **core.health)
        self._reported = {'imu_received': imu_received, 'published': self.outputs_published, 'dropped': dropped}
        level, message = assess(health)
        said = self._not_learning_notice.due(health)
        if said:   # once in the log; again only after it learned since
            self.get_logger().warning(said)
        return _LEVELS[level], message, values

    def publish_diagnostics(self) -> None:
        check_inputs_arrived(self.input_wait, self.merger, self.subscriptions_by_stream, self._lock)
        self.endpoint_check.check()
        level, message, values = self.diagnostic_values()
        self.pubs['diagnostics'].publish(conv.diagnostic_array(self.get_clock().now().to_msg(),
                                                    f'{self.get_name()}: thermal drift', self.hardware_id,
                                                    level, message, values))

    def learning_summary(self) -> str:   # one line: the filter's updates so far, or why it made none
        return self.pipeline.learning_summary()

    def shutdown(self) -> None:
        """Process what is buffered and save the learned state (call before destroy_node)."""
        self.process_buffered(flush=True)
        self.save_state()
        self.get_logger().info(f'stopped: {self.outputs_published} outputs published; {self.learning_summary()}')


def main(args=None) -> int:
    return run_node(StkfDriftEstimatorNode, 'stkf_node', args)


if __name__ == '__main__':
    sys.exit(main())
