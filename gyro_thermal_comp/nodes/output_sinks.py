"""Where the STKF node's outputs go: one `OutputSink` per way of publishing them (no decisions left
in the node). Each sink publishes, per sample, imu/data, imu/heading (only while `heading_built()`
says the pipeline builds it) and, with `publish_tf` and a `tf` publisher, the transform
`fixed_frame` -> IMU frame; `one` takes a sample published the moment it arrives (`OneOutput`),
`many` a batch (`OutputArrays`).

- `CdrSink`: real rclpy publishers, given serialized CDR (conversions.RawOutputs): building and
  converting message objects would cost more than the node's own work per sample.
- `MessageSink`: stand-ins for publishers (replay's recorders, tests), given message objects with
  the same numbers.
- `BulkSink`: replay; imu/data and imu/heading of a batch in one go (output_arrays.BulkRecorder),
  the transforms one by one; single samples go to the sink of its publishers.

`output_sink` picks one from the publishers; the node calls it whenever its publishers or its bulk
recorder change. The transform is a message object for every sink (tf2_msgs' TFMessage has no
fixed layout).
"""
from __future__ import annotations

from typing import Callable, Mapping, Protocol

from rclpy.publisher import Publisher

from .. import cdr, topics
from . import conversions as conv
from .stkf_outputs import OneOutput, OutputArrays


class OutputSink(Protocol):
    def heading_wanted(self) -> bool:
        """Whether imu/heading is worth building now (the node asks once per poll, not per sample)."""

    def one(self, o: OneOutput) -> None:
        """Publish one sample."""

    def many(self, o: OutputArrays) -> None:
        """Publish a batch of samples, in order."""


class _PerSample:
    """A sink that publishes sample by sample: the publishers, the fixed frame, and the batch as
    single samples (a header built from the stamp where a replayed chunk had none)."""

    def __init__(self, pubs: Mapping, fixed_frame: str, publish_tf: bool, heading_built: Callable[[], bool]):
        self.imu, self.heading = pubs['imu'], pubs['heading']
        self.tf = pubs['tf'] if publish_tf and 'tf' in pubs else None
        self.fixed_frame = fixed_frame
        self.heading_built = heading_built   # the pipeline's build_heading, read when publishing

    def one(self, o: OneOutput) -> None:
        self._send(*o)

    def many(self, o: OutputArrays) -> None:
        for k in range(o.ns.size):
            header = o.headers[k] or cdr.header_cdr(int(o.ns[k]), o.frame_id)
            self._send(header, o.gyro[k].tolist(), o.accel[k].tolist(), o.q_imu[k].tolist(),
                       o.orientation_var[k].tolist(), o.gyro_var, o.accel_var, o.q_heading[k].tolist())

    def _send(self, header: bytes, gyro, accel, q_imu, orientation_var, gyro_var, accel_var, q_heading) -> None:
        raise NotImplementedError

    def _transform(self, header, q_imu) -> None:
        """The transform fixed frame -> the sample's frame (`header`: a std_msgs/Header)."""
        self.tf.publish(conv.tf_message([conv.transform_msg(
            header.stamp, self.fixed_frame, header.frame_id or topics.IMU_FRAME, q_imu)]))


class CdrSink(_PerSample):
    """Real publishers: imu/data and imu/heading as CDR bytes (`header`: the input's, as CDR)."""

    def __init__(self, pubs: Mapping, fixed_frame: str, publish_tf: bool, heading_built: Callable[[], bool]):
        super().__init__(pubs, fixed_frame, publish_tf, heading_built)
        self._raw = conv.RawOutputs(fixed_frame)

    def heading_wanted(self) -> bool:
        """Only while somebody subscribes to imu/heading."""
        return self.heading.get_subscription_count() > 0

    def _send(self, header: bytes, gyro, accel, q_imu, orientation_var, gyro_var, accel_var, q_heading) -> None:
        self.imu.publish(self._raw.imu(header, gyro, accel, q_imu, gyro_var, accel_var, orientation_var))
        if self.heading_built():
            self.heading.publish(self._raw.heading(header, q_heading, orientation_var[2]))
        if self.tf is not None:
            self._transform(conv.header_msg(header), q_imu)


class MessageSink(_PerSample):
    """Stand-ins for publishers: imu/data and imu/heading as message objects."""

    def heading_wanted(self) -> bool:
        """Always: a stand-in cannot say whether anybody listens."""
        return True

    def _send(self, header: bytes, gyro, accel, q_imu, orientation_var, gyro_var, accel_var, q_heading) -> None:
        typed_header = conv.header_msg(header)
        self.imu.publish(conv.compensated_imu(typed_header, gyro, accel, q_imu, gyro_var=gyro_var,
                                              accel_var=accel_var, orientation_var=orientation_var))
        if self.heading_built():
            self.heading.publish(conv.heading_msg(typed_header.stamp, self.fixed_frame, q_heading, orientation_var[2]))
        if self.tf is not None:
            self._transform(typed_header, q_imu)


class BulkSink:
    """Replay: a batch's imu/data and imu/heading go to `recorder` (output_arrays.BulkRecorder, which
    writes both for every sample), its transforms one by one to the tf publisher of `per_sample`;
    single samples, and whether the heading is wanted, are `per_sample`'s."""

    def __init__(self, recorder, per_sample: _PerSample):
        self.recorder, self.per_sample = recorder, per_sample

    def heading_wanted(self) -> bool:
        return self.per_sample.heading_wanted()

    def one(self, o: OneOutput) -> None:
        self.per_sample.one(o)

    def many(self, o: OutputArrays) -> None:
        self.recorder.write(o)
        tf, fixed = self.per_sample.tf, self.per_sample.fixed_frame
        if tf is not None:
            for k, t_ns in enumerate(o.ns.tolist()):
                tf.publish(conv.tf_message([conv.transform_msg(conv.time_msg_ns(t_ns), fixed, o.frame_id,
                                                               o.q_imu[k])]))


def output_sink(pubs: Mapping, bulk=None, *, fixed_frame: str, publish_tf: bool,
                heading_built: Callable[[], bool]) -> OutputSink:
    """The sink for the publishers `pubs` (output name -> publisher or stand-in; imu and heading
    both real rclpy publishers or both stand-ins) and, in replay, the bulk recorder `bulk`."""
    real = [isinstance(pubs[name], Publisher) for name in ('imu', 'heading')]
    if real[0] != real[1]:
        raise TypeError('imu and heading must both be rclpy publishers or both stand-ins')
    sink = (CdrSink if real[0] else MessageSink)(pubs, fixed_frame, publish_tf, heading_built)
    return sink if bulk is None else BulkSink(bulk, sink)
