"""`carousel_node`: the carousel demodulator as a ROS 2 node (node name `carousel_demodulator`).

Subscribes `imu/data_raw` and, when present, `carousel/joint_states` (encoder), `imu_aux/data_raw`
(auxiliary IMU of the flip mechanism), `imu/temperature` and `imu/mag` (the magnetometer: the angle
reference without an encoder and with the spin axis vertical, `angle_reference: gravity_mag`; on a wheel
without an encoder set `wheel_radius_m`: gravity less the road acceleration is the reference);
publishes `imu/demodulated` (one body-frame Imu per revolution, stamped at the revolution end),
`carousel/gyro_bias` (imu_link frame: x, y the in-plane bias estimates; z without an encoder the axial gyro's
drift learnt by the gravity or magnetometer angle reference, else 0), `carousel/gyro_bias_sigma` (the same
stamp and frame: their 1-sigma; an axis without an estimate carries `gyro_bias_sigma_deg_s`, the offset nothing
has removed) and `diagnostics`. All physics is in `gyro_thermal_comp.carousel`.

Rate covariance (REP 145): every axis carries the gyro's white noise averaged over the interval
(`gyro_noise_density_deg_s_rthz`); the in-plane axes the variance of the lock-in bias estimate; the
spin axis is not modulated, so its gyro's zero-rate offset and its scale-factor error times the
spin rate stay in the output (`gyro_bias_sigma_deg_s`, `gyro_scale_factor_sigma`: datasheet
values); before the first lock-in estimate the in-plane axes carry the offset too. Not covered: a
vehicle's own rate changing within a wheel revolution (demodulation residual).
"""
from __future__ import annotations

import math
import sys
import threading

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import Vector3Stamped
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from sensor_msgs.msg import Imu, JointState, MagneticField
from std_msgs.msg import Header

from .. import topics
from ..carousel import CarouselConfig, CarouselDemodulator
from ..samples import SensorChunk
from ..stamps import TimeOrigin
from . import conversions as conv
from .interface import (CAROUSEL, check_inputs_arrived, create_publishers, create_subscriptions, input_counters,
                        input_wait_report, output_counters, pop_chunk, sensor_qos)
from .parameters import INPUT_PARAMS, ParamSpec, config_from_params, config_specs
from .ros_params import ParameterFileError, declare_parameters, parameter_file_problems, run_node
from .stamp_merger import StampMerger, poll_gap_s

NODE_NAME = CAROUSEL.node_name

NODE_PARAMS = (
    ParamSpec('joint_name', '', 'JointState entry to use (empty = the first one)'),
    ParamSpec('body_frame_id', topics.BODY_FRAME, 'frame of the demodulated output (the non-rotating body)'),
    ParamSpec('process_period_s', 0.01, 'inputs are buffered and processed in batches this often, s', True, 0.0005, 1.0),
    *INPUT_PARAMS,
    ParamSpec('diagnostics_period_s', 1.0, 'diagnostics publication period, s', True, 0.1, 60.0),
    ParamSpec('gyro_bias_sigma_deg_s', 0.5, 'zero-rate offset of the gyro the demodulator cannot remove (spin axis; '
              'in-plane axes before the first estimate), 1-sigma; MEMS datasheets: 0.2-1 over temperature, deg/s',
              True, 0.0, 100.0),
    ParamSpec('gyro_scale_factor_sigma', 0.005, 'scale-factor error of the spin-axis gyro, 1-sigma fraction '
              '(times the spin rate it stays in the output); MEMS datasheets: 0.5-1 %', True, 0.0, 0.5),
    ParamSpec('gyro_noise_density_deg_s_rthz', 0.01, 'gyro white noise, averaged over each output interval; MEMS '
              'datasheets: 0.004-0.015, deg/s/sqrt(Hz)', True, 0.0, 1.0),
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
        self.demodulator = CarouselDemodulator(config)
        self.settings = values
        self._lock = threading.Lock()  # timer vs. shutdown/flush from another thread
        self.merger = StampMerger([p.name for p in CAROUSEL.inputs], max_latency_s=values['max_latency_s'],
                                  max_poll_gap_s=poll_gap_s(values['process_period_s']),
                                  first_sample_wait_s=values['first_sample_wait_s'])
        self.records_published = 0
        self.time_origin = TimeOrigin()   # the core runs on s since the first stamp (replay sets it)
        self._imu_frame: str | None = None   # frame_id of the first IMU message (hardware_id default)

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

    @property
    def hardware_id(self) -> str:
        """The `hardware_id` parameter, else the IMU's frame_id as received, else 'imu'."""
        return self.settings['hardware_id'] or self._imu_frame or 'imu'

    # ------------------------------------------------------------------ input
    def _push(self, stream: str, t: float, row) -> bool:
        """One sample past its stream's guard (the demodulator's) into the stamp merger."""
        with self._lock:
            self.merger.arrived(stream)
            return self.demodulator.admit(stream, t, row) and self.merger.push(stream, t, row)

    def _push_imu(self, stream: str, msg: Imu) -> None:
        if stream == 'imu' and self._imu_frame is None:
            self._imu_frame = msg.header.frame_id
        if not self._push(stream, *conv.imu_row(msg, self.time_origin)):
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
        with self._lock:
            self._process_buffered(flush)

    def _process_buffered(self, flush: bool) -> None:
        chunk = pop_chunk(self.merger, self.subscriptions_by_stream, flush)
        if chunk is not None:   # each sample passed its guard in `_push`
            self._publish(self.demodulator.update(chunk, admitted=True))

    def process_chunk(self, chunk: SensorChunk) -> None:
        """Demodulate stamp-ordered samples; publish one Imu per finished revolution (or interval)."""
        self._publish(self.demodulator.update(chunk))

    def _rate_variances(self, rec) -> np.ndarray:
        """Body-frame rate variances, (rad/s)^2: the gyro's white noise over the interval, plus in-plane
        the lock-in estimate's (the unremoved offset before there is one), on the spin axis its offset
        and scale-factor error times the spin rate."""
        offset_var = math.radians(self.settings['gyro_bias_sigma_deg_s']) ** 2
        noise_var = math.radians(self.settings['gyro_noise_density_deg_s_rthz']) ** 2 / max(rec.duration_s, 1e-3)
        inplane = noise_var + (rec.gyro_bias_variance if math.isfinite(rec.gyro_bias_variance) else offset_var)
        spin = rec.spin_rate_rad_s if math.isfinite(rec.spin_rate_rad_s) else 0.0
        axial = noise_var + offset_var + (self.settings['gyro_scale_factor_sigma'] * spin) ** 2
        # carousel axes -> body axes (the spin axis is carousel z): diag(M D M^T)
        m = np.asarray(self.demodulator.config.carousel_to_body, dtype=float)
        return np.square(m) @ np.array([inplane, inplane, axial])

    def _bias_estimates(self, rec) -> tuple[tuple, tuple]:
        """((x, y, z) gyro bias estimates, (x, y, z) their 1-sigma), rad/s, imu_link: in-plane the lock-in's, axial
        the angle reference's learnt drift; an axis without an estimate 0 with the unremoved offset's sigma
        (`gyro_bias_sigma_deg_s`). Never NaN or inf."""
        offset = math.radians(self.settings['gyro_bias_sigma_deg_s'])
        known = math.isfinite(rec.gyro_bias_variance)
        bx, by = (float(v) if math.isfinite(v) else 0.0 for v in rec.gyro_bias_inplane_rad_s)
        s_xy = math.sqrt(rec.gyro_bias_variance) if known else offset
        axial = math.isfinite(rec.axial_gyro_bias_variance) and math.isfinite(rec.axial_gyro_bias_rad_s)
        bz = float(rec.axial_gyro_bias_rad_s) if axial else 0.0
        s_z = math.sqrt(rec.axial_gyro_bias_variance) if axial else offset
        return (bx, by, bz), (s_xy, s_xy, s_z)

    def _publish(self, out) -> None:
        frame = self.settings['body_frame_id']
        for rec in out.records:
            if not (np.all(np.isfinite(rec.rate_body_rad_s)) and np.all(np.isfinite(rec.specific_force_body_m_s2))):
                continue  # never NaN on the wire; counted by the core
            header = Header(stamp=conv.time_msg(rec.t_s, self.time_origin), frame_id=frame)
            # no orientation from the demodulator
            self.pubs['imu'].publish(conv.imu_msg(header, rec.rate_body_rad_s, rec.specific_force_body_m_s2,
                                                  gyro_var=self._rate_variances(rec)))
            bias = Vector3Stamped(header=Header(stamp=header.stamp, frame_id=topics.IMU_FRAME))
            sigma = Vector3Stamped(header=Header(stamp=header.stamp, frame_id=topics.IMU_FRAME))
            (bias.vector.x, bias.vector.y, bias.vector.z), (sigma.vector.x, sigma.vector.y, sigma.vector.z) = \
                self._bias_estimates(rec)
            self.pubs['gyro_bias'].publish(bias)
            self.pubs['gyro_bias_sigma'].publish(sigma)
            self.records_published += 1

    # ------------------------------------------------------------------ diagnostics
    def diagnostic_values(self) -> tuple[int, str, dict]:
        d = self.demodulator
        values = {'mode': d.mode, 'reason': d.reason or 'none', 'records_published': self.records_published,
                  'angle_reference': d.angle_reference, 'spin_coupling': d.spin_coupling}
        values.update({f'core.{k}': v for k, v in d.counts.items()})
        values.update(input_counters(self.merger, self.subscriptions_by_stream))
        values.update(output_counters(self.pubs))
        if d.mode == 'demodulated':
            return DiagnosticStatus.OK, 'demodulating whole revolutions', values
        return DiagnosticStatus.WARN, f'pass-through: {d.reason or "no rotation yet"}', values

    def publish_diagnostics(self) -> None:
        check_inputs_arrived(self.input_wait, self.merger, self.subscriptions_by_stream, self._lock)
        level, message, values = self.diagnostic_values()
        self.pubs['diagnostics'].publish(conv.diagnostic_array(self.get_clock().now().to_msg(),
                                                    f'{self.get_name()}: carousel', self.hardware_id,
                                                    level, message, values))

    def shutdown(self) -> None:
        with self._lock:
            self._process_buffered(flush=True)
            self._publish(self.demodulator.flush())
        self.get_logger().info(f'stopped: {self.records_published} outputs published')


def main(args=None) -> int:
    return run_node(CarouselDemodulatorNode, 'carousel_node', args)


if __name__ == '__main__':
    sys.exit(main())
