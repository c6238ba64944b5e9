"""The STKF node reads its inputs and writes imu/data and imu/heading as serialized CDR (raw
subscriptions and publishers): the same numbers and bytes as rclpy's message objects give,
and bytes that are no message are dropped, counted and reported, never published."""
import math

import numpy as np
from rclpy.serialization import deserialize_message, serialize_message
from geometry_msgs.msg import PoseWithCovarianceStamped
from sensor_msgs.msg import Imu, MagneticField, Temperature

from conftest import BAGS, Capture
from gyro_thermal_comp import cdr
from gyro_thermal_comp.bag_io import read_chunks
from gyro_thermal_comp.nodes.compose import make_stkf_node
from gyro_thermal_comp.nodes.replay import _messages
from test_cdr import FRAMES, bits, mixed_messages, rosbags_view

TYPES = {'imu': Imu, 'mag': MagneticField, 'temperature': Temperature}
CALLBACKS = {'imu': '_on_imu', 'mag': '_on_mag', 'temperature': '_on_temperature'}
# fed faster than real time: the stamp merger must not release a topic for silence (wall time)
PATIENT = {'max_latency_s': 60.0, 'first_sample_wait_s': 60.0}


def serialized_inputs(seconds: float) -> list[tuple[str, bytes]]:
    """vehicle_loop's first `seconds` as (stream, CDR bytes) in stamp order, as DDS delivers them."""
    chunk = next(read_chunks(BAGS / 'vehicle_loop', seconds, streams=list(TYPES)))
    return [(stream, serialize_message(msg)) for _, stream, msg in _messages(chunk, tuple(TYPES))]


def feed(node, inputs, typed: bool = False, garbage=lambda k, stream, raw: ()) -> None:
    """The node's subscription callbacks with each input (bytes, or as rclpy message objects) and
    after the k-th the bytes `garbage(k, stream, raw)`, a slow-path batch every 100 inputs, then its
    shutdown flush."""
    for k, (stream, raw) in enumerate(inputs):
        callback = getattr(node, CALLBACKS[stream])
        callback(deserialize_message(raw, TYPES[stream]) if typed else raw)
        for bad in garbage(k, stream, raw):
            callback(bad)
        if k % 100 == 0:
            node.process_buffered()
    node.process_buffered(flush=True)


class RawCapture:
    """Wraps a real rclpy publisher (so the node publishes bytes to it) and keeps what is published."""

    def __init__(self, publisher, subscribers: int = 1):
        self.msgs = []
        publisher.publish = self.msgs.append
        publisher.get_subscription_count = lambda: subscribers


def test_one_message_reads_what_rosbags_reads_and_writes_it_back():
    """cdr.OneMessage (a live node, one message at a time) against rosbags on good messages of every
    frame_id length and on what the fast path must not take (big endian, padded, cut short, bad
    terminator or UTF-8, a lying length, another encapsulation)."""
    for msgtype in (cdr.IMU, cdr.MAG):
        one = cdr.OneMessage(msgtype)
        raws = mixed_messages(np.random.default_rng(3), msgtype)
        unreadable = same_bytes = 0
        for raw in raws:
            expected = rosbags_view(raw, msgtype)
            try:
                stamp_ns, frame_id, header, values = one.decode(raw)
            except cdr.MalformedMessage:
                assert isinstance(expected, type), 'rosbags reads it'
                unreadable += 1
                continue
            leaves = tuple(tuple(bits(np.array(values[one.offset(leaf.name):one.offset(leaf.name) + leaf.width]))
                                 .tolist()) for leaf in cdr.layout(msgtype))
            assert (stamp_ns, frame_id, leaves) == expected
            again = one.encode(header, values)
            assert one.decode(again)[:3] == (stamp_ns, frame_id, header)
            if raw[:4] == cdr.ENCAPSULATION and len(raw) == len(again):   # written by cdr.encode
                assert again == raw
                same_bytes += 1
        assert unreadable > 20 and same_bytes >= 3 * len(FRAMES)


def test_raw_outputs_are_the_typed_outputs_field_for_field(ros):
    """A node publishing CDR bytes to real publishers gives, message for message, what rclpy
    serialises from the message objects the same node gives stand-in publishers; fed message
    objects instead of bytes, it computes the same messages."""
    inputs = serialized_inputs(40.0)
    typed, raw, from_objects = (make_stkf_node(PATIENT) for _ in range(3))
    for node in (typed, from_objects):
        node.pubs = {**node.pubs, 'imu': Capture(), 'heading': Capture()}
    raw_imu, raw_heading = RawCapture(raw.pubs['imu']), RawCapture(raw.pubs['heading'])
    feed(typed, inputs)
    feed(raw, inputs)
    feed(from_objects, inputs, typed=True)
    imu, heading = typed.pubs['imu'].msgs, typed.pubs['heading'].msgs
    assert len(imu) == len(heading) == len(raw_imu.msgs) == len(raw_heading.msgs) > 1500
    assert all(isinstance(m, bytes) for m in raw_imu.msgs + raw_heading.msgs)
    # field for field, floats exactly (rclpy's own bytes carry whatever its buffer held in the padding)
    assert [deserialize_message(m, Imu) for m in raw_imu.msgs] == imu == from_objects.pubs['imu'].msgs
    assert [deserialize_message(m, PoseWithCovarianceStamped) for m in raw_heading.msgs] == heading == \
        from_objects.pubs['heading'].msgs
    assert all(m[:4] == cdr.ENCAPSULATION for m in raw_imu.msgs + raw_heading.msgs)
    assert all(sub.raw for sub in raw.subscriptions_by_stream.values())   # DDS hands the node bytes
    for node in (typed, raw, from_objects):
        node.destroy_node()


class Log:
    def __init__(self):
        self.warnings = []   # (text, throttle_duration_sec)

    def warning(self, text, throttle_duration_sec=None, **_):
        self.warnings.append((text, throttle_duration_sec))

    def info(self, *_, **__):
        pass


def test_unreadable_messages_are_dropped_counted_and_reported_never_published(ros):
    """Cut-short, empty and garbage bytes on each input (and a MagneticField's on the IMU's): the
    node keeps running, drops and counts each one (input.<stream>_dropped_malformed, summed into
    input_samples_dropped), warns (throttled), publishes nothing for them and never a NaN; the good
    messages around them are published as if the bad ones had not been there."""
    inputs = serialized_inputs(30.0)
    mag_bytes = next(raw for stream, raw in inputs if stream == 'mag')
    n_bad = dict.fromkeys(TYPES, 0)

    def garbage(k, stream, raw):
        if k % 97:
            return []
        out = [raw[:-1], raw[:10], b'', bytes(range(256)) * 2] + ([mag_bytes] if stream == 'imu' else [])
        n_bad[stream] += len(out)
        return out
    clean, dirty = make_stkf_node(PATIENT), make_stkf_node(PATIENT)
    for node in (clean, dirty):
        node.pubs = {**node.pubs, 'imu': Capture(), 'heading': Capture()}
    dirty.get_logger = lambda log=Log(): log
    feed(clean, inputs)
    feed(dirty, inputs, garbage=garbage)
    _, message, values = dirty.diagnostic_values()
    for stream in TYPES:
        assert values[f'input.{stream}_dropped_malformed'] == n_bad[stream] > 0
    _, _, clean_values = clean.diagnostic_values()   # the bag's own (a driver's jitter: late samples)
    assert values['input_samples_dropped'] - clean_values['input_samples_dropped'] == sum(n_bad.values())
    assert f"{values['input_samples_dropped']} input samples dropped" in message
    warnings = [(text, every) for text, every in dirty.get_logger().warnings if 'unreadable' in text]
    assert len(warnings) == sum(n_bad.values()) and all(every and every >= 1.0 for _, every in warnings)
    assert all('_dropped_malformed' in text for text, _ in warnings)
    got, expected = dirty.pubs['imu'].msgs, clean.pubs['imu'].msgs
    assert len(got) == len(expected) > 1000
    assert got == expected
    for m in got:
        assert all(math.isfinite(v) for v in (m.angular_velocity.z, m.orientation.w, m.orientation_covariance[8]))
    for node in (clean, dirty):
        node.destroy_node()


def test_endpoints_that_can_never_match_are_named_once(ros):
    """The node has no rclpy QoS-event handlers (they cost every executor turn); its EndpointCheck
    says what they would: a publisher of another type or an incompatible QoS on an input, a
    subscription requesting an incompatible QoS on an output. Once each; compatible ones never."""
    import time

    import rclpy
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    node = make_stkf_node({'reliable_inputs': True})
    assert all(not sub.event_handlers for sub in node.subscriptions_by_stream.values())
    assert all(not pub.event_handlers for pub in node.pubs.values())
    node.endpoint_check.logger = log = Log()
    context = rclpy.Context()     # a participant of its own: DDS takes another type on a topic there only
    rclpy.init(context=context)
    probe = rclpy.create_node('gtc_endpoint_probe', context=context)
    probe.create_publisher(Imu, 'imu/data_raw', QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT))
    probe.create_publisher(Imu, 'imu/data_raw', QoSProfile(depth=5))                    # reliable: matches
    probe.create_publisher(Temperature, 'imu/mag', QoSProfile(depth=5))
    probe.create_subscription(Imu, 'imu/data', print, QoSProfile(depth=5, durability=DurabilityPolicy.TRANSIENT_LOCAL))
    probe.create_subscription(Imu, 'imu/data', print, QoSProfile(depth=5))              # matches
    end = time.monotonic() + 30.0      # discovery: a limit on a hang, not a condition of the result
    while node.endpoint_check.check() < 3 and time.monotonic() < end:
        time.sleep(0.1)
    node.endpoint_check.check()
    texts = [text for text, _ in log.warnings]
    assert len(texts) == 3, texts
    assert any("'/imu/data_raw'" in t and 'best effort' in t.lower() for t in texts)
    assert any("'/imu/mag'" in t and 'sensor_msgs/msg/Temperature' in t for t in texts)
    assert any("'/imu/data'" in t and 'transient local' in t.lower() for t in texts)
    assert node.diagnostic_values()[2]['incompatible_endpoints'] == 3
    probe.destroy_node()
    rclpy.try_shutdown(context=context)
    node.destroy_node()


def test_any_bytes_are_a_message_or_malformed_never_an_error():
    """Random bytes, and real messages with random bytes changed, cut or extended: decoding gives
    a message (what rosbags reads) or cdr.MalformedMessage, nothing else."""
    rng = np.random.default_rng(7)
    one = cdr.OneMessage(cdr.IMU)
    good = cdr.encode_imu(np.array([1_700_000_000_123_456_789]), 'imu_link', angular_velocity=[[0.1, 0.2, 0.3]])[0]
    outcomes = {'read': 0, 'malformed': 0}
    for k in range(3000):
        if k % 3 == 0:
            raw = rng.integers(0, 256, rng.integers(0, 400)).astype(np.uint8).tobytes()
        else:
            raw = bytearray(good)
            for i in rng.integers(0, len(raw), rng.integers(1, 4)):
                raw[i] = int(rng.integers(0, 256))
            raw = bytes(raw[:rng.integers(0, len(raw) + 1)] if k % 3 == 2 else raw + bytes(rng.integers(0, 3)))
        try:
            stamp_ns, frame_id, header, values = one.decode(raw)
        except cdr.MalformedMessage:
            outcomes['malformed'] += 1
            continue
        outcomes['read'] += 1
        expected = rosbags_view(raw, cdr.IMU)
        assert not isinstance(expected, type) and (stamp_ns, frame_id) == expected[:2]
        assert len(values) == one.body.size // 8
    assert min(outcomes.values()) > 300, outcomes
