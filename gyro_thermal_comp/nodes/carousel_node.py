"""`carousel_node`: the carousel demodulator as a ROS 2 node (node name `carousel_demodulator`).

Subscribes `imu/data_raw` and, when present, `carousel/joint_states` (encoder), `imu_aux/data_raw`
(auxiliary IMU of the flip mechanism), `imu/temperature` and `imu/mag` (the magnetometer: the angle
reference without an encoder and with the spin axis vertical, `angle_reference: gravity_mag`; on a wheel
without an encoder set `wheel_radius_m`: gravity less the road acceleration is the reference);
publishes `imu/demodulated` (one body-frame Imu per revolution, stamped at the revolution end),
`carousel/gyro_bias` (imu_link frame: x, y the in-plane bias estimates; z without an encoder the axial gyro's
drift learnt by the gravity or magnetometer angle reference, else 0), `carousel/gyro_bias_sigma` (the same
stamp and frame: their 1-sigma; an axis without an estimate carries `gyro_bias_sigma_rad_s`, the offset nothing
has removed) and `diagnostics`. All physics is in `gyro_thermal_comp.carousel`; the numbers the node
publishes come from `CarouselPipeline` (carousel_pipeline.py, no ROS): the node decodes each message
into a sample and pushes it there, its timer polls the pipeline for the revolutions that closed, and
it encodes and publishes them; replay pushes whole chunks (`process_chunk`). This module holds the
ROS side: parameters, subscriptions and publishers, and the diagnostics message.

Rate covariance (REP 145): the gyro's white noise over each interval, the lock-in estimate's variance
in-plane, the spin-axis gyro's offset and scale-factor error (carousel_pipeline.py).
"""
from __future__ import annotations

import math
import sys
import threading

from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import Vector3Stamped
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from sensor_msgs.msg import Imu, JointState, MagneticField
from std_msgs.msg import Header

from .. import topics
from ..carousel import CarouselConfig
from ..samples import SensorChunk
from . import conversions as conv
from .carousel_pipeline import CarouselPipeline
from .interface import (CAROUSEL, check_inputs_arrived, create_publishers, create_subscriptions, input_counters,
                        input_wait_report, output_counters, pipeline_time_origin, sensor_qos, unpublished)
from .parameters import INPUT_PARAMS, ParamSpec, config_from_params, config_specs
from .ros_params import ParameterFileError, declare_parameters, parameter_file_problems, run_node

NODE_NAME = CAROUSEL.node_name

NODE_PARAMS = (
    ParamSpec('joint_name', '', 'JointState entry to use (empty = the first one)'),
    ParamSpec('body_frame_id', topics.BODY_FRAME, 'frame of the demodulated output (the non-rotating body)'),
    ParamSpec('process_period_s', 0.01, 'inputs are buffered and processed in batches this often, s', True, 0.0005, 1.0),
    *INPUT_PARAMS,
    ParamSpec('diagnostics_period_s', 1.0, 'diagnostics publication period, s', True, 0.1, 60.0),
    ParamSpec('gyro_bias_sigma_rad_s', math.radians(0.5), 'zero-rate offset of the gyro the demodulator cannot '
              'remove (spin axis; in-plane axes before the first estimate), 1-sigma; MEMS datasheets: 0.2-1 deg/s '
              'over temperature, rad/s', True, 0.0, math.radians(100.0)),
    ParamSpec('gyro_scale_factor_sigma', 0.005, 'scale-factor error of the spin-axis gyro, 1-sigma fraction '
              '(times the spin rate it stays in the output); MEMS datasheets: 0.5-1 %', True, 0.0, 0.5),
    ParamSpec('gyro_noise_density_rad_s_rthz', math.radians(0.01), 'gyro white noise, averaged over each output '
              'interval; MEMS datasheets: 0.004-0.015 deg/s/sqrt(Hz), rad/s/sqrt(Hz)', True, 0.0, math.radians(1.0)),
)


def carousel_specs(base: CarouselConfig | None = None) -> tuple[ParamSpec, ...]:
    """Node parameters + every CarouselConfig field (defaults of `base`, the turntable preset if None;
    config/carousel_wheel.yaml holds the wheel preset)."""
    return NODE_PARAMS + config_specs(base or CarouselConfig.turntable())


class CarouselDemodulatorNode(Node):
    def __init__(self, node_name: str = NODE_NAME, **node_kwargs):
        super().__init__(node_name, **node_kwargs)
        self._specs = {s.name: s for s in carousel_specs()}
        values = declare_parameters(self, self._specs)
        parameter_file_problems(self)
        try:
            config = config_from_params(values, CarouselConfig.turntable())
        except (TypeError, ValueError) as exc:  # the core's own consistency checks
            raise ParameterFileError(f'inconsistent carousel parameters: {exc}') from None
        self.settings = values
        self.pipeline = CarouselPipeline(config, values, [p.name for p in CAROUSEL.inputs])
        self.demodulator, self.merger = self.pipeline.demodulator, self.pipeline.merger
        self._lock = threading.Lock()  # timer vs. shutdown/flush from another thread
        self.records_published = 0

        self._inputs_group = MutuallyExclusiveCallbackGroup()  # the lock, not the group, orders input vs batch
        self._input_qos = sensor_qos(values['input_queue_depth'], reliable=values['reliable_inputs'])
        self.subscriptions_by_stream = create_subscriptions(
            self, CAROUSEL, {'imu': lambda m: self._push_imu('imu', m),
                              'imu_aux': lambda m: self._push_imu('imu_aux', m),
                              'joint': self._on_joint,
                              'temperature': lambda m: self._push('temperature',
                                                                  *conv.temperature_row(m, self.time_origin)),
                              'mag': self._on_mag},
            self._input_qos, self._inputs_group)
        self.pubs = create_publishers(self, CAROUSEL)   # output name -> publisher (replay swaps in recorders)
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.create_timer(values['process_period_s'], self.process_buffered, clock=steady)
        self.create_timer(values['diagnostics_period_s'], self.publish_diagnostics, clock=steady)
        # the encoder, the aux IMU, the temperature and the magnetometer are optional: waited for only when published
        self.input_wait = input_wait_report(self, self.subscriptions_by_stream,
                                            optional=('joint', 'imu_aux', 'temperature', 'mag'))
        inputs = ', '.join(sub.topic_name for sub in self.subscriptions_by_stream.values())
        self.get_logger().info(
            f'carousel demodulator ({config.angle_source} angle source): inputs {inputs} '
            f"(only {self.subscriptions_by_stream['imu'].topic_name} is required); one body-frame Imu per "
            f"revolution on {self.pubs['imu'].topic_name} "
            f"(frame '{values['body_frame_id']}'), in-plane biases on {self.pubs['gyro_bias'].topic_name}; "
            'needs a still start and a steady spin to learn the biases.')

    time_origin = pipeline_time_origin

    @property
    def hardware_id(self) -> str:
        """The `hardware_id` parameter, else the IMU's frame_id as received, else 'imu'."""
        return self.settings['hardware_id'] or self.pipeline.imu_frame or 'imu'

    # ------------------------------------------------------------------ input
    def _push(self, stream: str, t: float, row, frame_id: str | None = None) -> bool:
        """One decoded sample into the pipeline (its stream's guard, then the stamp merger)."""
        with self._lock:
            return self.pipeline.push(stream, t, row, frame_id)

    def _push_imu(self, stream: str, msg: Imu) -> None:
        if not self._push(stream, *conv.imu_row(msg, self.time_origin), msg.header.frame_id):
            self.get_logger().warning(f'dropping {stream} samples (NaN, repeated/out-of-order or late stamps)',
                                      throttle_duration_sec=10.0)

    def _on_mag(self, msg: MagneticField) -> None:
        # NaN, repeated or out-of-order stamps: dropped and counted by the core's guard
        # (core.mag_dropped_*) in /diagnostics, and said once per 10 s in the log
        if not self._push('mag', *conv.mag_row(msg, self.time_origin)):
            self.get_logger().warning('dropping magnetometer samples (NaN, repeated/out-of-order or late stamps)',
                                      throttle_duration_sec=10.0)

    def _on_joint(self, msg: JointState) -> None:
        name = self.settings['joint_name']
        i = list(msg.name).index(name) if name and name in msg.name else 0
        if len(msg.position) <= i:
            self.get_logger().warning('joint_states without a position for the carousel joint',
                                      throttle_duration_sec=10.0)
            return
        velocity = msg.velocity[i] if len(msg.velocity) > i else math.nan
        self._push('joint', conv.stamp_s(msg.header.stamp, self.time_origin), [msg.position[i], velocity])

    # ------------------------------------------------------------------ processing
    def process_buffered(self, flush: bool = False) -> None:
        """Demodulate what the stamp merger releases (everything with `flush`) and publish the records."""
        with self._lock:
            self._publish(self.pipeline.poll(flush, unpublished(self.subscriptions_by_stream)))

    def process_chunk(self, chunk: SensorChunk) -> None:
        """Demodulate stamp-ordered samples; publish one Imu per finished revolution (or interval)."""
        self._publish(self.pipeline.push_chunk(chunk))

    def _publish(self, out) -> None:
        """imu/demodulated, carousel/gyro_bias and carousel/gyro_bias_sigma for each record of `out`."""
        frame = self.settings['body_frame_id']
        for o in self.pipeline.outputs(out):
            header = Header(stamp=conv.time_msg(o.t_s, self.time_origin), frame_id=frame)
            # no orientation from the demodulator
            self.pubs['imu'].publish(conv.imu_msg(header, o.rate_body_rad_s, o.specific_force_body_m_s2,
                                                  gyro_var=o.rate_variances))
            bias = Vector3Stamped(header=Header(stamp=header.stamp, frame_id=topics.IMU_FRAME))
            sigma = Vector3Stamped(header=Header(stamp=header.stamp, frame_id=topics.IMU_FRAME))
            bias.vector.x, bias.vector.y, bias.vector.z = o.gyro_bias_rad_s
            sigma.vector.x, sigma.vector.y, sigma.vector.z = o.gyro_bias_sigma_rad_s
            self.pubs['gyro_bias'].publish(bias)
            self.pubs['gyro_bias_sigma'].publish(sigma)
            self.records_published += 1

    # ------------------------------------------------------------------ diagnostics
    def diagnostic_values(self) -> tuple[int, str, dict]:
        """Level, message and key values: the pipeline's (CarouselPipeline.diagnostics), the records
        published, the input layer's under `input.` and the outputs'."""
        core = self.pipeline.diagnostics()
        values = {**core.state, 'records_published': self.records_published, **core.values,
                  **input_counters(self.merger, self.subscriptions_by_stream), **output_counters(self.pubs)}
        return (DiagnosticStatus.OK if core.demodulating else DiagnosticStatus.WARN), core.message, values

    def publish_diagnostics(self) -> None:
        check_inputs_arrived(self.input_wait, self.merger, self.subscriptions_by_stream, self._lock)
        level, message, values = self.diagnostic_values()
        self.pubs['diagnostics'].publish(conv.diagnostic_array(self.get_clock().now().to_msg(),
                                                    f'{self.get_name()}: carousel', self.hardware_id,
                                                    level, message, values))

    def shutdown(self) -> None:
        with self._lock:
            self._publish(self.pipeline.poll(flush=True, unpublished=unpublished(self.subscriptions_by_stream)))
            self._publish(self.pipeline.finish())
        self.get_logger().info(f'stopped: {self.records_published} outputs published')


def main(args=None) -> int:
    return run_node(CarouselDemodulatorNode, 'carousel_node', args)


if __name__ == '__main__':
    sys.exit(main())
