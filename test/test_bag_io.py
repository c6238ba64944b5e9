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
        from gyro_thermal_comp.bag_io import _imu_msgs
        for t_ns, msg in _imu_msgs(chunk.imu, 'vn_link', Covariances()):
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
