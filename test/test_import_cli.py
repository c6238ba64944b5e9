"""The command line on recordings that are not the package's own bags: a PX4 ULog, an ArduPilot
DataFlash log and a ROS 1 bag (written by the tests) through `import`, `replay` and `calibrate`;
`evaluate` says in one line that a flight log has nothing to score it against; a robot's ROS 2 bag
with its own topic names through `--topic` on every command; a bad file is one line, exit 2."""
import json

import pytest
import yaml

from gyro_thermal_comp.bag_io import BagReader, BagWriter
from gyro_thermal_comp.cli import main
from gyro_thermal_comp.nodes.state_store import StateStore
from gyro_thermal_comp.thermal.model_file import DriftModelFile
from logfiles import simulated, write_dataflash, write_rosbag1, write_ulog

from conftest import BAGS

WRITERS = {'ulg': write_ulog, 'bin': write_dataflash, 'bag': write_rosbag1}


@pytest.fixture(scope='module')
def logs(tmp_path_factory):
    d = tmp_path_factory.mktemp('cli_logs')
    rec = simulated(600.0, 10.0)
    for ext, write in WRITERS.items():
        write(d / f'bench.{ext}', rec)
    return d


def _run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize('ext', list(WRITERS))
def test_flight_log_through_import_replay_calibrate(logs, tmp_path, capsys, ext):
    src = logs / f'bench.{ext}'
    code, out, err = _run(capsys, 'import', src, '--out', tmp_path / 'imported')
    assert code == 0, err
    with BagReader(tmp_path / 'imported') as r:
        assert set(r.streams_present()) == {'imu', 'mag', 'temperature'}
        assert json.loads(r.text('/import/source')[0])['source'] == str(src)

    code, out, err = _run(capsys, 'replay', src, '--out', tmp_path / 'replayed')
    assert code == 0, err
    with BagReader(tmp_path / 'replayed') as r:
        counts = {t.topic: t.count for t in r.topics}
    assert counts['/imu/data'] == counts['/imu/data_raw'] == 6000 and counts['/diagnostics'] > 0

    code, out, err = _run(capsys, 'calibrate', src, '--out', tmp_path / 'cal')
    assert code == 0, err
    model = DriftModelFile.load(tmp_path / 'cal' / 'drift_model.yaml')
    with StateStore(tmp_path / 'cal' / 'stkf_state.json') as store:
        loaded = store.load()
    assert loaded.warm and loaded.state['terms'] == list(model.names)
    assert (tmp_path / 'cal' / 'report.png').stat().st_size > 10_000
    assert 'static' in (tmp_path / 'cal' / 'report.md').read_text()

    code, out, err = _run(capsys, 'evaluate', src)
    assert code == 0 and err == ''
    assert out.strip().endswith('without independent heading truth (no odom stream): nothing to score')
    assert len(out.strip().splitlines()) == 1


@pytest.mark.parametrize('ext, content', [('ulg', b'ULog\x01\x12\x35\x01' + b'\xff' * 40),
                                          ('bin', b'\xa3\x95\x80' + b'\x00' * 20),
                                          ('bag', b'#ROSBAG V2.0\n' + b'\x00' * 30)])
@pytest.mark.parametrize('command', ['import', 'replay', 'calibrate'])
def test_bad_flight_log_is_one_line(tmp_path, capsys, ext, content, command):
    bad = tmp_path / f'broken.{ext}'
    bad.write_bytes(content)
    code, out, err = _run(capsys, command, bad, '--out', tmp_path / 'out')
    assert code == 2
    assert len(err.strip().splitlines()) == 1 and err.startswith('gyro-thermal-comp: error:') and 'broken' in err
    assert 'Traceback' not in err and not (tmp_path / 'out').exists()


@pytest.fixture(scope='module')
def robot_bag(tmp_path_factory):
    """The first 10 min of bags/static_ramp as a robot records it: /my_imu/* topics."""
    out = tmp_path_factory.mktemp('robot') / 'robot_bag'
    rename = {'/imu/data_raw': '/my_imu/data_raw', '/imu/mag': '/my_imu/mag',
              '/imu/temperature': '/my_imu/temperature'}
    with BagReader(BAGS / 'static_ramp') as reader, BagWriter(out, time_origin_ns=reader.time_origin_ns) as writer:
        for chunk, raw in reader.chunks(60.0, keep_raw=True):
            raw = raw.select(raw.stamp_s < 600.0).renamed(rename)
            writer.write_raw_records(raw)
    return out


ROBOT_TOPICS = ['--topic', 'imu=/my_imu/data_raw', '--topic', 'imu/mag=/my_imu/mag',
                '--topic', 'imu/temperature:=/my_imu/temperature']


def test_a_robots_own_bag_needs_its_topic_map(robot_bag, tmp_path, capsys):
    code, out, err = _run(capsys, 'discover', robot_bag)
    assert code == 2 and len(err.splitlines()) == 1
    assert 'has no message on /imu/data_raw' in err and 'map its topics with --topic' in err
    assert '/my_imu/data_raw (Imu)' in err

    code, out, err = _run(capsys, 'discover', robot_bag, *ROBOT_TOPICS, '--json')
    assert code == 0, err
    assert json.loads(out)['verdict'] in ('effect_found', 'no_missing_effect', 'unexplained_residual')

    code, out, err = _run(capsys, 'evaluate', robot_bag, *ROBOT_TOPICS, '--no-peers')
    assert code == 0, err
    assert 'stkf' in out

    code, out, err = _run(capsys, 'replay', robot_bag, *ROBOT_TOPICS, '--out', tmp_path / 'replayed')
    assert code == 0, err
    with BagReader(tmp_path / 'replayed') as r:   # the inputs under the package's names, beside the outputs
        counts = {t.topic: t.count for t in r.topics}
    assert counts['/imu/data_raw'] == counts['/imu/data'] == 6000 and '/my_imu/data_raw' not in counts

    code, out, err = _run(capsys, 'info', robot_bag, *ROBOT_TOPICS)
    assert code == 0 and 'imu <- /my_imu/data_raw' in out

    code, out, err = _run(capsys, 'evaluate', robot_bag, '--topic', 'gyro=/my_imu/data_raw')
    assert code == 2 and "unknown stream 'gyro'" in err


def test_a_table_with_a_bad_map_or_wrong_units_is_one_line(tmp_path, capsys):
    from logfiles import CATS_MAP, cats_arrays, write_cats_netcdf4
    write_cats_netcdf4(tmp_path / 'tag.nc', cats_arrays(simulated(600.0, 10.0)))
    cases = {'unknown_unit': {**CATS_MAP, 'streams': {**CATS_MAP['streams'],
                                                      'mag': {'column': 'magnetic_density', 'unit': 'Tesla'}}},
             'wrong_unit': {**CATS_MAP, 'streams': {**CATS_MAP['streams'],
                                                    'accel': {'column': 'acceleration', 'unit': 'g'}}},
             'not_a_map': ['gyro', 'accel']}
    for name, spec in cases.items():
        (tmp_path / f'{name}.yaml').write_text(yaml.safe_dump(spec))
        code, out, err = _run(capsys, 'import', tmp_path / 'tag.nc', '--map', tmp_path / f'{name}.yaml', '--level',
                              '--out', tmp_path / name)
        assert code == 2 and len(err.strip().splitlines()) == 1 and err.startswith('gyro-thermal-comp: error:'), err
        assert not (tmp_path / name).exists()
    code, out, err = _run(capsys, 'import', tmp_path / 'tag.nc', '--out', tmp_path / 'no_map')
    assert code == 2 and 'a table needs a column map' in err
