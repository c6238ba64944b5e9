"""The source interface: flight logs and ROS 1 bags written by the tests read back as the simulated
unit that was written into them (axes, units, stamps, IMU choice); axis conventions, rotations and
the gyro-handedness check; a file that is not what it claims is one clear error."""
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gyro_thermal_comp.samples import ImuSamples, MagSamples, SensorChunk, concat_chunks
from gyro_thermal_comp.sources import SourceError, detect_kind, open_source, parse_topic_map
from gyro_thermal_comp.sources import frames
from gyro_thermal_comp.sources.base import ArraySource
from gyro_thermal_comp.sources.checks import check_streams
from logfiles import EPOCH_UTC_NS, simulated, write_dataflash, write_rosbag1, write_ulog

F32 = 2e-7   # float32 relative rounding of the logged values


@pytest.fixture(scope='module')
def rec():
    return simulated(600.0, 10.0)


@pytest.fixture(scope='module')
def logs(rec, tmp_path_factory):
    d = tmp_path_factory.mktemp('logs')
    write_ulog(d / 'bench.ulg', rec)
    write_dataflash(d / 'bench.bin', rec)
    write_rosbag1(d / 'bench.bag', rec)
    return d


def _read(path, **opts):
    with open_source(path, **opts) as src:
        return src, concat_chunks(src.chunks(60.0))


@pytest.mark.parametrize('name', ['bench.ulg', 'bench.bin', 'bench.bag'])
def test_flight_logs_read_back_as_the_simulated_unit(logs, rec, name):
    """FRD -> FLU, gauss / milligauss -> tesla, boot time dated by GPS to the simulator's UTC epoch."""
    src, c = _read(logs / name)
    assert src.time_origin_ns == EPOCH_UTC_NS
    assert np.allclose(c.imu.t, rec.t, rtol=0, atol=1e-6)
    np.testing.assert_allclose(c.imu.gyro, rec.gyro, rtol=F32, atol=1e-9)
    np.testing.assert_allclose(c.imu.accel, rec.accel, rtol=F32, atol=1e-6)
    mag_lsb = 1e-7 if name.endswith('.bin') else 1e-12   # DataFlash logs the field in whole milligauss
    np.testing.assert_allclose(c.mag.field, rec.mag, rtol=F32, atol=mag_lsb / 2 + 1e-12)
    assert c.temperature.temp_c.min() == pytest.approx(rec.temp_c.min(), abs=0.05)
    assert c.temperature.temp_c.max() == pytest.approx(rec.temp_c.max(), abs=0.05)
    assert src.dropped.to_text() == 'nothing dropped'


@pytest.mark.parametrize('name, offset', [('bench.ulg', 4.0), ('bench.bin', 6.0)])
def test_imu_instance_is_chosen_and_named(logs, rec, name, offset):
    src, first = _read(logs / name)
    assert any('IMU 0 of 2' in n and 'choose with --imu N' in n for n in src.notes)
    src, second = _read(logs / name, imu=1)
    assert any(n.startswith('IMU 1 of 2') for n in src.notes)
    assert np.median(second.temperature.temp_c - first.temperature.temp_c) == pytest.approx(offset, abs=1e-3)
    with pytest.raises(SourceError, match='has no IMU 5'):
        open_source(logs / name, imu=5)


def test_ros1_bag_with_other_topic_names_needs_a_topic_map(rec, tmp_path):
    path = tmp_path / 'robot.bag'
    write_rosbag1(path, rec, {'imu': '/my_imu/data_raw', 'mag': '/my_imu/mag', 'temperature': '/my_imu/temp'})
    with pytest.raises(SourceError, match=r'no message on /imu/data_raw; map its topics with --topic imu=/name.*'
                                          r'/my_imu/data_raw \(Imu\)'):
        open_source(path)
    src, c = _read(path, topic_map=['imu=/my_imu/data_raw', 'imu/mag:=/my_imu/mag', 'temperature=/my_imu/temp'])
    assert set(src.streams_present()) == {'imu', 'mag', 'temperature'}
    np.testing.assert_array_equal(c.imu.gyro, rec.gyro)


def test_time_window_selects_seconds_or_utc(logs):
    src, c = _read(logs / 'bench.ulg', start=100, end=200)
    assert c.imu.t[0] >= 100 and c.imu.t[-1] < 200 and len(c.imu.t) == pytest.approx(1000, abs=1)
    _, d = _read(logs / 'bench.ulg', start='2024-01-01T00:01:40Z', end='2024-01-01T00:03:20Z')
    np.testing.assert_array_equal(c.imu.t, d.imu.t)


def test_topic_map_accepts_stream_and_node_topic_names():
    assert parse_topic_map(['imu=/a/raw', 'imu/mag=/a/mag', 'imu/temperature:=/a/t']) == \
        {'imu': '/a/raw', 'mag': '/a/mag', 'temperature': '/a/t'}
    for bad in (['imu'], ['gyro=/x'], ['imu=/a', 'imu/data_raw=/b']):
        with pytest.raises(SourceError):
            parse_topic_map(bad)


# ---------------------------------------------------------------- frames
def test_axis_conventions():
    assert np.linalg.det(frames.axes_matrix('FLU')) == pytest.approx(1.0)
    assert np.array_equal(frames.axes_matrix('NED'), frames.axes_matrix('FRD'))
    assert np.array_equal(frames.axes_matrix('ENU'), frames.axes_matrix('RFU'))
    fru = frames.axes_matrix('FRU')
    assert frames.is_left_handed(fru)
    # an axial vector follows a mirror with the sign: the right-hand rule survives the conversion
    assert np.array_equal(frames.gyro_matrix(fru, 'pseudovector'), -fru)
    assert np.array_equal(frames.gyro_matrix(fru, 'vector'), fru)
    for bad in ('FFU', 'XYZ', 'FL'):
        with pytest.raises(SourceError):
            frames.axes_matrix(bad)


def test_rotations_must_be_proper():
    with pytest.raises(SourceError, match='reflection'):
        frames.check_rotation(np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(SourceError, match='orthonormal'):
        frames.check_rotation(np.eye(3) * 1.01)
    rng = np.random.default_rng(0)
    for up in [*rng.normal(size=(20, 3)), (0, 0, -1.0), (0, 0, 1.0)]:
        up = np.asarray(up) / np.linalg.norm(up)
        R = frames.levelling_rotation(up)
        assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-12)
        np.testing.assert_allclose(R @ up, [0, 0, 1], atol=1e-12)


def _turning_unit(n=400, dt=0.05):
    """Specific force and field of a unit tumbling about a tilted axis at 40 deg/s (body frame)."""
    t = np.arange(n) * dt
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    w = np.tile(axis * math.radians(40.0), (n, 1))
    body_to_world = Rotation.from_rotvec(np.outer(t, axis * math.radians(40.0)))
    f = body_to_world.inv().apply([0.0, 0.0, 9.81])
    b = body_to_world.inv().apply([0.0, 20e-6, -40e-6])
    return t, w, f, b


def test_kinematic_check_tells_a_mirrored_gyro():
    t, w, f, b = _turning_unit()
    good, mirrored = frames.KinematicCheck(), frames.KinematicCheck()
    good.add(t, w, f)
    good.add(t, w, b)
    mirrored.add(t, -w, f)
    assert good.verdict()[0] == 'ok' and good.correlation > 0.99
    assert mirrored.verdict()[0] == 'mirrored'
    assert frames.KinematicCheck().verdict()[0] == 'untested'
    assert good.slope == pytest.approx(1.0, abs=0.01)
    in_degrees = frames.KinematicCheck()    # deg/s read as rad/s: the gyro turns the fields 57 x too far
    in_degrees.add(t, np.degrees(w), f)
    assert in_degrees.verdict()[0] == 'scale'


# ---------------------------------------------------------------- bad input: one line
@pytest.mark.parametrize('name, content, match', [
    ('x.ulg', b'not a ulog at all' * 10, 'is not a PX4 ULog'),
    ('x.bin', b'TimeUS,GyrX\n1,2\n', 'is not a ArduPilot DataFlash log'),
    ('x.bag', b'#ROSBAG V1.2\n', 'is not a ROS 1 bag'),
    ('x.dat', b'\x00\x01\x02garbage', 'not a recording this package reads'),
    ('x.ulg', b'', 'is not a PX4 ULog'),
])
def test_a_file_that_is_not_what_it_claims(tmp_path, name, content, match):
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(SourceError, match=match) as err:
        open_source(path)
    assert '\n' not in str(err.value)


@pytest.mark.parametrize('name', ['bench.ulg', 'bench.bin', 'bench.bag'])
def test_a_cut_log_is_read_to_the_cut_or_refused_in_one_line(logs, tmp_path, name):
    data = (logs / name).read_bytes()
    path = tmp_path / name
    path.write_bytes(data[:len(data) // 3])
    try:
        src, c = _read(path)
    except SourceError as exc:
        assert '\n' not in str(exc)
    else:
        assert 0 < c.imu.t[-1] < 600.0


def test_options_a_format_does_not_use_are_errors(logs):
    with pytest.raises(SourceError, match='--topic maps the topics of ROS bags'):
        open_source(logs / 'bench.ulg', topic_map=['imu=/x'])
    with pytest.raises(SourceError, match='--imu picks an IMU of a flight log'):
        open_source(logs / 'bench.bag', imu=1)
    with pytest.raises(SourceError, match='a column map is for tables'):
        open_source(logs / 'bench.bin', column_map={'streams': {}})
    assert detect_kind(logs / 'bench.bin') == 'dataflash'


@pytest.mark.parametrize('field, scale, match', [
    ('gyro', 1e3, 'gyro declared in rad/s reads a median'),      # mrad/s logged, rad/s declared
    ('accel', 9.80665, 'accel declared in m/s\\^2'),            # m/s^2 logged, g declared
    ('mag', 1e4, 'mag declared in T'),                           # gauss logged, tesla declared
])
def test_units_that_cannot_be_right(rec, field, scale, match):
    imu = ImuSamples(rec.t, rec.gyro * (scale if field == 'gyro' else 1), rec.accel * (scale if field == 'accel' else 1))
    mag = MagSamples(rec.mag_t, rec.mag * (scale if field == 'mag' else 1))
    with pytest.raises(SourceError, match=match):
        check_streams(imu, mag, where='test')
    check_streams(ImuSamples(rec.t, rec.gyro, rec.accel), MagSamples(rec.mag_t, rec.mag), where='test')


def test_array_source_chunks_and_windows(rec):
    src = ArraySource('mem', {'imu': ImuSamples(rec.t, rec.gyro, rec.accel)})
    chunks = list(src.chunks(100.0))
    assert len(chunks) == 6 and sum(len(c.imu.t) for c in chunks) == len(rec.t)
    src.select(50.0, 150.0)
    inside = concat_chunks(src.chunks(30.0))
    assert inside.imu.t[0] == pytest.approx(50.0) and inside.imu.t[-1] < 150.0
    assert isinstance(chunks[0], SensorChunk)
