"""Every bundled bag reads the same through three independent readers.

rosbags (its own rosbag2 reader), `mcap` with `mcap-ros2-support`'s decoder, and the package's
own `bag_io.BagReader` must agree on message counts and on every value, stamps to the nanosecond.
"""
from collections import defaultdict

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from conftest import bundled_bags
from gyro_thermal_comp import topics
from gyro_thermal_comp.bag_io import BagReader


def _stamp_ns(msg) -> int:
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


def _values(msgtype: str, msg) -> tuple:
    """Stamp (ns), frame_id and every number the package reads, in the order BagReader stores them."""
    if msgtype.endswith('Imu'):
        g, a = msg.angular_velocity, msg.linear_acceleration
        nums = (g.x, g.y, g.z, a.x, a.y, a.z, *msg.angular_velocity_covariance, *msg.orientation_covariance)
    elif msgtype.endswith('MagneticField'):
        m = msg.magnetic_field
        nums = (m.x, m.y, m.z, *msg.magnetic_field_covariance)
    elif msgtype.endswith('Temperature'):
        nums = (msg.temperature, msg.variance)
    elif msgtype.endswith('Odometry'):
        p, q, v, w = msg.pose.pose.position, msg.pose.pose.orientation, msg.twist.twist.linear, msg.twist.twist.angular
        nums = (q.x, q.y, q.z, q.w, p.x, p.y, p.z, v.x, v.y, v.z, w.x, w.y, w.z)
    elif msgtype.endswith('Vector3Stamped'):
        nums = (msg.vector.x, msg.vector.y, msg.vector.z)
    elif msgtype.endswith('JointState'):
        nums = (*msg.position, *msg.velocity)
    elif msgtype.endswith('String'):
        return (msg.data,)
    else:
        raise AssertionError(f'unexpected type {msgtype}')
    return (_stamp_ns(msg), msg.header.frame_id, *map(float, nums))


def read_with_rosbags(path):
    out = defaultdict(list)
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        for conn, _, raw in reader.messages():
            out[conn.topic].append(_values(conn.msgtype, reader.deserialize(raw, conn.msgtype)))
    return out


def read_with_mcap(path):
    out = defaultdict(list)
    (mcap_file,) = path.glob('*.mcap')
    with open(mcap_file, 'rb') as f:
        for schema, channel, _, msg in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
            out[channel.topic].append(_values(schema.name, msg))
    return out


def read_with_package(path):
    """Per stream: (stamps ns since 1970, value matrix) in the layout of _values (numbers only)."""
    out = {}
    with BagReader(path) as reader:
        present, origin_ns = reader.streams_present(), reader.time_origin_ns
        parts = defaultdict(list)
        for chunk in reader.chunks(30.0):
            for name, samples in chunk.streams().items():
                parts[name].append(samples)
    for name, chunks in parts.items():
        arrays = [np.column_stack([getattr(c, f).reshape(len(c.t), -1) for f in c.__dataclass_fields__])
                  for c in chunks]
        data = np.vstack(arrays)
        out[present[name]] = (np.rint(data[:, 0] * 1e9).astype(np.int64) + origin_ns, data[:, 1:])
    return out


BAGS = bundled_bags()


def test_bags_are_bundled():
    names = {p.name for p in BAGS}
    assert {'static_ramp', 'static_ramp_outages', 'vehicle_loop', 'carousel_vertical',
            'carousel_horizontal', 'carousel_wheel', 'null'} <= names


def test_bundle_is_small():
    total = sum(f.stat().st_size for p in BAGS for f in p.iterdir())
    assert total < 40e6, f'bundled bags take {total / 1e6:.1f} MB'


@pytest.mark.parametrize('bag', BAGS, ids=[p.name for p in BAGS])
def test_three_readers_agree(bag):
    by_rosbags, by_mcap, by_package = read_with_rosbags(bag), read_with_mcap(bag), read_with_package(bag)
    assert by_rosbags.keys() == by_mcap.keys()
    for topic in by_rosbags:
        assert len(by_rosbags[topic]) == len(by_mcap[topic]) > 0, topic
        assert by_rosbags[topic] == by_mcap[topic], f'rosbags and mcap disagree on {topic}'
    stream_topics = {topic for topic, _ in topics.BAG_STREAMS.values()} & by_rosbags.keys()
    assert stream_topics == by_package.keys()
    for topic in stream_topics:
        stamps, values = by_package[topic]
        rows = by_rosbags[topic]
        assert len(rows) == len(stamps), topic
        assert np.array_equal(stamps, [r[0] for r in rows]), topic
        width = values.shape[1]
        assert np.array_equal(values, np.array([r[2:2 + width] for r in rows])), topic


def test_package_reads_every_layout_as_rosbags_does(tmp_path):
    """Imu/MagneticField/Temperature are decoded in bulk (cdr.py); frame_ids of every length (every
    alignment), mixed within a topic, and big-endian messages (rosbags' path) read as rosbags reads them."""
    from gyro_thermal_comp import cdr
    from gyro_thermal_comp.bag_io import BagWriter
    rng = np.random.default_rng(11)
    n = 200
    t = np.sort(rng.choice(10**10, n, replace=False)) + 1_704_067_200 * 10**9
    frames = [f'f{"x" * (k % 10)}'[: k % 10] for k in range(n)]
    gyro, accel, field, temp = rng.normal(size=(n, 3)), rng.normal(size=(n, 3)), rng.normal(size=(n, 3)), rng.normal(size=n)
    with BagWriter(tmp_path / 'bag') as writer:
        for k in range(n):
            for topic, msgtype, raw in [
                    ('/imu/data_raw', cdr.IMU, cdr.encode_imu(t[k:k + 1], frames[k], angular_velocity=gyro[k],
                                                              linear_acceleration=accel[k])[0]),
                    ('/imu/mag', cdr.MAG, cdr.encode_mag(t[k:k + 1], frames[k], field[k])[0]),
                    ('/imu/temperature', cdr.TEMPERATURE, cdr.encode_temperature(t[k:k + 1], frames[k], temp[k])[0])]:
                if k % 7 == 3:
                    msg = cdr.TYPESTORE.deserialize_cdr(raw, msgtype)
                    raw = bytes(cdr.TYPESTORE.serialize_cdr(msg, msgtype, little_endian=False))
                writer.write_raw(topic, msgtype, int(t[k]), raw)
    by_rosbags, by_package = read_with_rosbags(tmp_path / 'bag'), read_with_package(tmp_path / 'bag')
    assert [r[1] for r in by_rosbags['/imu/data_raw']] == frames
    for topic in ('/imu/data_raw', '/imu/mag', '/imu/temperature'):
        stamps, values = by_package[topic]
        rows = by_rosbags[topic]
        assert np.array_equal(stamps, t) and np.array_equal(stamps, [r[0] for r in rows]), topic
        assert np.array_equal(values, np.array([r[2:2 + values.shape[1]] for r in rows])), topic
