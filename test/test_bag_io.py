"""bag_io: exact round trip, streaming in time order, damaged bags read as far as they go."""
import shutil
import warnings

import numpy as np
import pytest

from gyro_thermal_comp.bag_io import BagError, BagReader, BagWriter, Covariances, read_chunks
from gyro_thermal_comp.samples import (ImuSamples, JointSamples, MagSamples, PoseSamples, SensorChunk,
                                       TemperatureSamples, VectorSamples, concat_chunks)


def make_chunk(t0=0.0, n=3000, rate=100.0, seed=0):
    rng = np.random.default_rng(seed)
    t = t0 + np.arange(n) / rate
    m = n // 10
    quat = rng.normal(size=(m, 4))
    return SensorChunk(
        imu=ImuSamples(t, rng.normal(size=(n, 3)), rng.normal(size=(n, 3))),
        mag=MagSamples(t[::2], rng.normal(size=(n // 2, 3)) * 5e-5),
        temperature=TemperatureSamples(t[::10], 20 + rng.normal(size=m)),
        odom=PoseSamples(t[::10], quat / np.linalg.norm(quat, axis=1, keepdims=True), rng.normal(size=(m, 3)),
                         rng.normal(size=(m, 3)), rng.normal(size=(m, 3))),
        gyro_bias=VectorSamples(t[::10], rng.normal(size=(m, 3)) * 1e-3),
        mag_disturbance=VectorSamples(t[::10], np.zeros((m, 3))),
        joint=JointSamples(t, 2 * np.pi * 0.5 * t, np.full(n, np.pi)),
    )


def write(path, chunks, **kw):
    with BagWriter(path, **kw) as writer:
        for c in chunks:
            writer.write_chunk(c)
    return writer


def assert_same(a: SensorChunk, b: SensorChunk):
    assert a.streams().keys() == b.streams().keys()
    for name, samples in a.streams().items():
        other = getattr(b, name)
        for field in samples.__dataclass_fields__:
            x, y = getattr(samples, field), getattr(other, field)
            if field == 't':  # stamps are stored as integer ns
                x, y = np.rint(x * 1e9), np.rint(y * 1e9)
            assert np.array_equal(x, y), (name, field)


def test_round_trip_is_exact(tmp_path):
    chunks = [make_chunk(0.0, seed=1), make_chunk(30.0, seed=2)]
    writer = write(tmp_path / 'bag', chunks, covariances=Covariances(gyro_rad2_s2=2e-5))
    assert writer.counts['/imu/data_raw'] == 6000
    back = concat_chunks(read_chunks(tmp_path / 'bag', chunk_s=7.0))
    assert_same(concat_chunks(chunks), back)


def test_chunks_stream_in_time_order(tmp_path):
    write(tmp_path / 'bag', [make_chunk(0.0, n=6000)])
    with BagReader(tmp_path / 'bag') as reader:
        chunks = list(reader.chunks(chunk_s=10.0))
        assert not reader.truncated
    assert len(chunks) == 6
    last = -np.inf
    for c in chunks:
        assert np.all(np.diff(c.imu.t) > 0) and c.imu.t[0] > last
        assert c.imu.t[-1] - c.imu.t[0] < 10.0
        last = c.imu.t[-1]


def test_truncated_bag_reads_what_is_there(tmp_path):
    write(tmp_path / 'bag', [make_chunk(0.0, n=20000)])
    (mcap_file,) = (tmp_path / 'bag').glob('*.mcap')
    data = mcap_file.read_bytes()
    mcap_file.write_bytes(data[: len(data) // 2])
    with pytest.warns(UserWarning, match='truncated'):
        with BagReader(tmp_path / 'bag') as reader:
            imu = concat_chunks(reader.chunks(60.0)).imu
            assert reader.truncated
    assert 0 < len(imu.t) < 20000
    assert np.all(np.diff(imu.t) > 0) and np.all(np.isfinite(imu.gyro))


def test_bare_mcap_without_metadata(tmp_path):
    write(tmp_path / 'bag', [make_chunk(0.0, n=500)])
    (tmp_path / 'bag' / 'metadata.yaml').unlink()
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')
        back = concat_chunks(read_chunks(tmp_path / 'bag'))
    assert len(back.imu.t) == 500


def test_topic_map_reads_foreign_topic_names(tmp_path):
    chunk = make_chunk(0.0, n=200)
    with BagWriter(tmp_path / 'bag') as writer:
        writer.write_chunk(SensorChunk(mag=chunk.mag))
        from gyro_thermal_comp.bag_messages import imu_msgs
        for t_ns, msg in imu_msgs(chunk.imu, 'vn_link', Covariances()):
            writer.write('/vectornav/imu', 'sensor_msgs/msg/Imu', t_ns, msg)
    back = concat_chunks(read_chunks(tmp_path / 'bag', topic_map={'imu': '/vectornav/imu'}))
    assert np.array_equal(back.imu.gyro, chunk.imu.gyro)
    with pytest.raises(BagError, match='unknown stream'):
        BagReader(tmp_path / 'bag', topic_map={'gps': '/fix'})


def test_clear_errors(tmp_path):
    with pytest.raises(BagError, match='does not exist'):
        BagReader(tmp_path / 'nope')
    (tmp_path / 'empty').mkdir()
    with pytest.raises(BagError, match='cannot open'):
        with BagReader(tmp_path / 'empty'):
            pass
    write(tmp_path / 'bag', [make_chunk(0.0, n=10)])
    with pytest.raises(BagError, match='exists'):
        BagWriter(tmp_path / 'bag')
    with pytest.raises(BagError, match='does not exist'):
        BagWriter(tmp_path / 'missing' / 'bag')
    shutil.rmtree(tmp_path / 'bag')


# ---------------------------------------------------------------- bulk CDR paths
def records(path):
    """(topic, log time, publish time, bytes) of every message, in file order."""
    from mcap.reader import make_reader
    (mcap_file,) = path.glob('*.mcap')
    with open(mcap_file, 'rb') as f:
        return [(c.topic, m.log_time, m.publish_time, m.data)
                for _, c, m in make_reader(f).iter_messages(log_time_order=False)]


def test_write_chunk_writes_what_the_message_builders_serialise(tmp_path):
    """The fixed-layout streams are encoded in bulk (cdr.py): same bytes as building each message."""
    from gyro_thermal_comp.bag_io import TYPESTORE
    from gyro_thermal_comp.bag_messages import imu_msgs, mag_msgs, temperature_msgs
    chunk, origin = make_chunk(0.0, n=400, seed=5), 1_704_067_200 * 10**9
    cov = Covariances(gyro_rad2_s2=[1e-5, 2e-5, 3e-5], accel_m2_s4=4e-3, mag_t2=1e-14, temperature_c2=0.25)
    write(tmp_path / 'bag', [chunk], covariances=cov, time_origin_ns=origin)
    got = records(tmp_path / 'bag')
    for topic, build, samples, msgtype in [('/imu/data_raw', imu_msgs, chunk.imu, 'sensor_msgs/msg/Imu'),
                                           ('/imu/mag', mag_msgs, chunk.mag, 'sensor_msgs/msg/MagneticField'),
                                           ('/imu/temperature', temperature_msgs, chunk.temperature,
                                            'sensor_msgs/msg/Temperature')]:
        expected = [(t, t, bytes(TYPESTORE.serialize_cdr(m, msgtype))) for t, m in build(samples, 'imu_link', cov, origin)]
        assert [r[1:] for r in got if r[0] == topic] == expected, topic
    assert [r[1] for r in got] == sorted(r[1] for r in got)   # interleaved in stamp order


def corrupt_imu_bag(path):
    """20 good Imu messages, 3 big endian ones (valid CDR), 4 that cannot be decoded."""
    from gyro_thermal_comp import cdr
    rng = np.random.default_rng(8)
    t = np.arange(27) * 10_000_000 + 1_704_067_200 * 10**9
    good = cdr.encode_imu(t, 'imu_link', angular_velocity=rng.normal(size=(27, 3)),
                          linear_acceleration=rng.normal(size=(27, 3)))
    raws = list(good)
    for k in (3, 9, 15):
        msg = cdr.TYPESTORE.deserialize_cdr(good[k], cdr.IMU)
        raws[k] = bytes(cdr.TYPESTORE.serialize_cdr(msg, cdr.IMU, little_endian=False))
    bad = {5: good[5][:-9], 11: b'\x00\x01\x00\x00garbage', 17: b'', 23: good[23][:16] + b'\xff' * 300}
    raws = [bad.get(k, r) for k, r in enumerate(raws)]
    with BagWriter(path) as writer:
        for k, raw in enumerate(raws):
            writer.write_raw('/imu/data_raw', 'sensor_msgs/msg/Imu', int(t[k]), raw)
    keep = [k for k in range(27) if k not in bad]
    return cdr.decode([good[k] for k in keep], cdr.IMU), t[keep]


def test_undecodable_messages_are_dropped_counted_and_warned_once(tmp_path):
    expected, stamps = corrupt_imu_bag(tmp_path / 'bag')
    with pytest.warns(UserWarning) as caught:
        with BagReader(tmp_path / 'bag') as reader:
            imu = concat_chunks(reader.chunks(0.05)).imu
            assert reader.undecodable == 4 and not reader.truncated
    messages = [str(w.message) for w in caught]
    assert len(messages) == 1 and 'cannot decode a sensor_msgs/msg/Imu message on /imu/data_raw' in messages[0]
    assert np.array_equal(imu.gyro, expected.fields['angular_velocity'])     # big endian ones read too
    assert np.array_equal(imu.accel, expected.fields['linear_acceleration'])
    assert np.array_equal(np.rint(imu.t * 1e9).astype(np.int64), stamps - stamps[0])
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')
        with BagReader(tmp_path / 'bag') as reader:
            assert len(list(reader.messages())) == 23 and reader.undecodable == 4


def test_keep_raw_copies_records_unchanged(tmp_path):
    write(tmp_path / 'bag', [make_chunk(0.0, n=3000, seed=3)], covariances=Covariances(gyro_rad2_s2=2e-5))
    with BagReader(tmp_path / 'bag') as reader:
        plain = list(reader.chunks(7.0))
        with_raw = list(reader.chunks(7.0, keep_raw=True))
        with BagWriter(tmp_path / 'copy', time_origin_ns=reader.time_origin_ns) as writer:
            for chunk, raw in with_raw:
                writer.write_raw_records(raw)
    assert len(plain) == len(with_raw) == 5
    for chunk, (same, raw) in zip(plain, with_raw):
        assert_same(chunk, same)
        for name, topic in [('imu', '/imu/data_raw'), ('odom', '/ground_truth/odom'), ('joint', '/carousel/joint_states')]:
            assert np.array_equal(raw.stamp_s[raw.topic == topic], getattr(chunk, name).t), name
    assert records(tmp_path / 'copy') == records(tmp_path / 'bag')
    assert writer.counts == topic_counts(tmp_path / 'bag') == topic_counts(tmp_path / 'copy')
    first = with_raw[0][1]
    early = first.select(first.stamp_s < 1.0)
    assert len(early) == sum(int(np.sum(getattr(with_raw[0][0], n).t < 1.0)) for n in with_raw[0][0].streams())


def topic_counts(path):
    with BagReader(path) as reader:
        return {i.topic: i.count for i in reader.topics}


def test_write_raw_many(tmp_path):
    from gyro_thermal_comp import cdr
    t = np.arange(5) * 1_000_000 + 7 * 10**9
    data = cdr.encode_pose_with_covariance_stamped(t, 'odom', [0.0, 0.0, 0.6, 0.8], covariance=np.eye(6).ravel())
    with BagWriter(tmp_path / 'bag') as writer:
        writer.write_raw_many('/imu/heading', 'geometry_msgs/msg/PoseWithCovarianceStamped', t, data)
        with pytest.raises(ValueError, match='log times'):
            writer.write_raw_many('/imu/heading', 'geometry_msgs/msg/PoseWithCovarianceStamped', t[:4], data)
    assert writer.counts == {'/imu/heading': 5}
    assert records(tmp_path / 'bag') == [('/imu/heading', int(a), int(a), d) for a, d in zip(t, data)]
    with BagReader(tmp_path / 'bag') as reader:
        msgs = list(reader.messages())
    assert [m.pose.pose.orientation.w for *_, m in msgs] == [0.8] * 5


def test_array_stamps_are_the_scalar_conversion_float_for_float():
    from gyro_thermal_comp.bag_messages import seconds_since_many
    from gyro_thermal_comp.stamps import seconds_since
    rng = np.random.default_rng(2)
    ns = np.concatenate([rng.integers(-2**62, 2**62, 2000), rng.integers(0, 4 * 10**18, 2000), [0, 1, -1]])
    origin = 1_704_067_200_123_456_789
    ns = np.clip(ns, -2**62, 2**62)
    assert seconds_since_many(ns, origin).tolist() == [seconds_since(int(v), origin) for v in ns]


@pytest.mark.parametrize('batched', [False, True])
def test_mcap_file_writes_the_mcap_writers_bytes(batched):
    """bag_storage.McapFile (messages in batches) writes byte for byte what mcap's own Writer
    writes for the same calls: chunks closed at the same message, indexes, statistics, CRCs."""
    import io
    from mcap.writer import CompressionType, Writer
    from gyro_thermal_comp.bag_storage import McapFile

    def drive(writer, batches):
        rng = np.random.default_rng(1)
        writer.start(profile='ros2', library='test')
        schema = writer.register_schema('a/msg/A', 'ros2msg', b'float64 x')
        channels = [writer.register_channel('/a', 'cdr', schema, {'k': 'v'}),
                    writer.register_channel('/b', 'cdr', schema, {})]
        t = 1_704_067_200 * 10**9
        for step in range(30):
            n = int(rng.integers(1, 300))
            chans = rng.choice(channels, n)
            times = t + np.cumsum(rng.integers(0, 10**6, n)) - rng.integers(0, 10**5, n)   # not sorted
            data = [rng.bytes(int(k)) for k in rng.integers(0, 200, n)]
            t = int(times.max())
            if step == 15:   # a late schema and channel land inside a chunk
                channels.append(writer.register_channel('/c', 'cdr', writer.register_schema('b/msg/B', 'ros2msg',
                                                                                            b'int8 y' * 500), {}))
            if batches and step % 3:
                writer.add_messages(chans, times, data)
            else:
                for c, tt, d in zip(chans.tolist(), times.tolist(), data):
                    writer.add_message(c, tt, d, tt)
        writer.flush()
        writer.add_metadata('rosbag2', {'serialized_metadata': 'x: 1'})
        writer.finish()

    theirs, ours = io.BytesIO(), io.BytesIO()
    drive(Writer(theirs, chunk_size=4096, compression=CompressionType.ZSTD, enable_crcs=True,
                 enable_data_crcs=True), False)
    drive(McapFile(ours, chunk_size=4096), batched)
    assert theirs.getvalue().count(b'zstd') > 20      # many chunks
    assert ours.getvalue() == theirs.getvalue()
