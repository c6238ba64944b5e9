"""Tables of the CATS tag's shape (1 Hz, FRU axes, mrad/s, uT, integer UTC seconds) written by the
tests as netCDF4, netCDF3 and CSV: imported through a column map into levelled package bags, with the
checks that make a wrong map or wrong units one clear line."""
import json

import numpy as np
import pytest
import yaml

from gyro_thermal_comp.bag_io import BagReader, read_chunks
from gyro_thermal_comp.samples import concat_chunks
from gyro_thermal_comp.sources import ColumnMap, SourceError, open_source
from gyro_thermal_comp.sources.importer import import_recording
from logfiles import (CATS_EPOCH_NS, CATS_MAP, CSV_MAP, UPSIDE_DOWN, cats_arrays, simulated, write_cats_csv,
                      write_cats_netcdf3, write_cats_netcdf4)

from conftest import REPO


@pytest.fixture(scope='module')
def rec():
    return simulated(1200.0, 20.0)


@pytest.fixture(scope='module')
def tables(rec, tmp_path_factory):
    d = tmp_path_factory.mktemp('tables')
    arrays = cats_arrays(rec)
    write_cats_netcdf4(d / 'cats.nc', arrays)
    write_cats_netcdf3(d / 'cats3.nc', arrays)
    write_cats_csv(d / 'cats.csv', arrays, nan_rows=(100, 101), repeat_rows=(300,))
    return d, arrays


def _bag(path):
    return concat_chunks(read_chunks(path, 600.0))


@pytest.mark.parametrize('name', ['cats.nc', 'cats3.nc'])
def test_netcdf_imports_levelled_as_the_unit_that_was_logged(tables, rec, tmp_path, name):
    """Upside down in FRU, mrad/s: after the mirror, the axial gyro's sign and the levelling rotation,
    the vertical axis reads what the simulated unit's z read (1 Hz point samples of it)."""
    d, arrays = tables
    out = tmp_path / 'bag'
    result = import_recording(d / name, out, column_map=CATS_MAP, level=True)
    assert any('axes FRU' in n and 'left-handed' in n for n in result.notes)
    [bag] = result.bags
    assert bag.up_angle_deg == pytest.approx(0.0, abs=1e-6)
    c = _bag(out)
    with BagReader(out) as r:
        assert r.time_origin_ns == CATS_EPOCH_NS + 480 * 10 ** 9      # the stamps keep their UTC
        info = json.loads(r.text('/import/source')[0])
    R = np.asarray(info['rotation'])
    assert np.linalg.det(R) == pytest.approx(1.0)
    # the unit lay upside down: levelling turns its z back up (to the tilt its accelerometer reads)
    assert (R @ UPSIDE_DOWN)[2, 2] > np.cos(np.radians(1.0))
    k = np.arange(0, len(rec.t), 20)
    np.testing.assert_allclose(c.imu.gyro, rec.gyro[k] @ (R @ UPSIDE_DOWN).T, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(c.imu.accel, rec.accel[k] @ (R @ UPSIDE_DOWN).T, rtol=1e-9, atol=1e-9)
    field = np.column_stack([np.interp(rec.t[k], rec.mag_t, rec.mag[:, j]) for j in range(3)])
    np.testing.assert_allclose(c.mag.field, field @ (R @ UPSIDE_DOWN).T, rtol=1e-9, atol=1e-15)


def test_z_pointing_down_is_refused_unless_levelled(tables, tmp_path):
    d, _ = tables
    with pytest.raises(SourceError, match=r'at rest the imported z axis points 1[78]\d deg from up.*--level') as err:
        import_recording(d / 'cats.nc', tmp_path / 'bag', column_map=CATS_MAP)
    assert '\n' not in str(err.value) and not (tmp_path / 'bag').exists()


def test_csv_drops_what_is_not_finite_or_repeated_and_says_so(tables, tmp_path):
    d, arrays = tables
    result = import_recording(d / 'cats.csv', tmp_path / 'bag', column_map=CSV_MAP, level=True)
    assert 'imu 2 not finite' in result.dropped and 'repeated stamp' in result.dropped
    c = _bag(tmp_path / 'bag')
    assert len(c.imu.t) == len(arrays['timestamp_utc']) - 2
    assert len(c.temperature.t) == len(arrays['timestamp_utc'])


def test_time_window_reads_only_its_rows(tables):
    d, arrays = tables
    with open_source(d / 'cats.nc', column_map=CATS_MAP, start='2021-09-20T09:05:00Z',
                     end='2021-09-20T09:10:00Z') as src:
        c = concat_chunks(src.chunks(60.0))
        assert len(c.imu.t) == 300 and src.time_origin_ns == CATS_EPOCH_NS + 780 * 10 ** 9
        assert any(n.startswith('rows 300..599 of 1200') for n in src.notes)


def test_period_from_the_map(tables):
    d, _ = tables
    spec = dict(CATS_MAP, periods={'first': ['2021-09-20T09:00:00Z', '2021-09-20T09:02:00Z']})
    with open_source(d / 'cats.nc', column_map=spec, period='first') as src:
        assert src.duration_s == pytest.approx(119.0)
    with pytest.raises(SourceError, match="no period 'second' in the column map \\(it has: first\\)"):
        open_source(d / 'cats.nc', column_map=spec, period='second')


def test_split_static_writes_one_levelled_bag_per_orientation(rec, tmp_path):
    """The unit upside down for 600 s, then turned onto its side: two periods, each with its own
    rotation putting its vertical on +z."""
    first = cats_arrays(rec)
    side = cats_arrays(rec, rotation=np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]))
    half = len(first['timestamp_utc']) // 2
    arrays = {k: np.concatenate([first[k][:half], side[k][half:]]) for k in first}
    write_cats_netcdf4(tmp_path / 'two.nc', arrays)
    result = import_recording(tmp_path / 'two.nc', tmp_path / 'periods', column_map=CATS_MAP, split_static=True,
                              min_static_s=300.0)
    assert [b.path.name for b in result.bags] == ['period_1', 'period_2']
    for bag in result.bags:
        c = _bag(bag.path)
        assert np.median(c.imu.accel[:, 2]) > 9.7 and np.abs(np.median(c.imu.accel[:, :2], axis=0)).max() < 0.05
        assert 500 < bag.duration_s < 600
    ups = json.loads((tmp_path / 'periods' / 'periods.json').read_text())
    assert np.dot(ups[0]['up_sensor_frame'], ups[1]['up_sensor_frame']) == pytest.approx(0.0, abs=0.05)


# ---------------------------------------------------------------- a bad map or wrong units: one line
@pytest.mark.parametrize('change, match', [
    ({'streams': {**CATS_MAP['streams'], 'gyro': {'column': 'angular_velocity', 'unit': 'rad/s'}}},
     "column map says gyro in rad/s, the file's angular_velocity says 'mrad/s'"),
    ({'streams': {**CATS_MAP['streams'], 'gyro': {'column': 'angular_velocity', 'unit': 'furlong/s'}}},
     "gyro: unknown unit 'furlong/s'"),
    ({'streams': {**CATS_MAP['streams'], 'mag': {'column': 'magnetic_field', 'unit': 'uT'}}},
     "no variable/column 'magnetic_field'"),
    ({'axes': 'FLU'}, 'column map says axes FLU, the file says FRU'),
    ({'rate_hz': 100.0}, 'declares rate_hz 100, the time column gives 1 Hz'),
    ({'streams': {'gyro': CATS_MAP['streams']['gyro']}}, 'streams needs accel'),
    ({'bogus': 1}, 'unknown key\\(s\\) bogus'),
    ({'axes': 'FFU'}, "axes 'FFU'"),
])
def test_bad_column_map_is_one_line(tables, tmp_path, change, match):
    d, _ = tables
    with pytest.raises(SourceError, match=match) as err:
        import_recording(d / 'cats.nc', tmp_path / 'bag', column_map={**CATS_MAP, **change}, level=True)
    assert '\n' not in str(err.value)


def test_wrong_units_in_a_csv_are_caught_by_what_they_read(tables, tmp_path):
    d, _ = tables
    spec = {**CSV_MAP, 'streams': {**CSV_MAP['streams'], 'gyro': {'column': ['gx', 'gy', 'gz'], 'unit': 'rad/s'}}}
    with pytest.raises(SourceError, match='gyro declared in rad/s reads a median .* is its unit right'):
        import_recording(d / 'cats.csv', tmp_path / 'bag', column_map=spec, level=True)
    spec = {**CSV_MAP, 'streams': {**CSV_MAP['streams'], 'temperature': {'column': 'temperature', 'unit': 'K'}}}
    with pytest.raises(SourceError, match='temperature declared in K reads a median -2\\d\\d'):
        import_recording(d / 'cats.csv', tmp_path / 'bag', column_map=spec, level=True)


def test_a_table_without_a_map_and_a_map_that_is_not_yaml(tables, tmp_path):
    d, _ = tables
    with pytest.raises(SourceError, match='a table needs a column map'):
        open_source(d / 'cats.csv')
    bad = tmp_path / 'map.yaml'
    bad.write_text('streams: [unclosed')
    with pytest.raises(SourceError, match=f'column map {bad}: not YAML'):
        open_source(d / 'cats.csv', column_map=bad)


def test_shipped_cats_map_reads_the_cats_layout(tables):
    """config/import/cats.yaml names what the real file has (and its three rest periods)."""
    d, _ = tables
    cmap = ColumnMap.load(REPO / 'config' / 'import' / 'cats.yaml')
    assert sorted(cmap.periods) == ['1', '2', '3'] and cmap.axes == 'FRU'
    with open_source(d / 'cats.nc', column_map=cmap) as src:
        assert set(src.streams_present()) == {'imu', 'mag', 'temperature'}
    assert yaml.safe_load((REPO / 'config' / 'import' / 'cats.yaml').read_text())['gyro_transform'] == 'pseudovector'
