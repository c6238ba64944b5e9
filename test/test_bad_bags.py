"""Unusable bags are errors, truncated ones warn once, outputs appear only
when complete, and a baseline that cannot run on a record does not stop the others.

Every bad bag is built in a temporary folder from a bundled bag (never modified) or from scratch,
and every command runs as the user runs it: `python -m gyro_thermal_comp.cli` in a subprocess."""
import json
import math
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from conftest import BAGS
from gyro_thermal_comp.bag_io import BagError, BagReader, BagWriter
from gyro_thermal_comp.evaluation import ORACLE, NotApplicable, evaluate
from gyro_thermal_comp.evaluation.report import chunks_from_list
from gyro_thermal_comp.evaluation.synthetic import DriftIntegrator, level_unit_chunks
from gyro_thermal_comp.samples import ImuSamples, SensorChunk

PROG = 'gyro-thermal-comp'
SOURCE = BAGS / 'null'   # a bundled bag: read, copied, never written


def run_cli(*args, timeout=300):
    return subprocess.run([sys.executable, '-m', 'gyro_thermal_comp.cli', *map(str, args)],
                          capture_output=True, text=True, timeout=timeout)


def stderr_lines(proc) -> list[str]:
    return [ln for ln in proc.stderr.splitlines() if ln.strip()]


def cut_copy(dst: Path, fraction: float, metadata: bool) -> Path:
    """SOURCE with its mcap cut to `fraction` of its size, with or without its metadata.yaml."""
    dst.mkdir()
    (mcap_file,) = SOURCE.glob('*.mcap')
    data = mcap_file.read_bytes()
    (dst / mcap_file.name).write_bytes(data[: int(len(data) * fraction)])
    if metadata:
        shutil.copy(SOURCE / 'metadata.yaml', dst / 'metadata.yaml')
    return dst


def string_imu_bag(dst: Path) -> Path:
    """A valid rosbag2 (written with rosbags itself) whose /imu/data_raw is std_msgs/msg/String."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore
    store = get_typestore(Stores.ROS2_JAZZY)
    string = store.types['std_msgs/msg/String']
    with Writer(dst, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection('/imu/data_raw', 'std_msgs/msg/String', typestore=store)
        for k in range(20):
            writer.write(conn, k * 10_000_000, store.serialize_cdr(string(data=f'sample {k}'), 'std_msgs/msg/String'))
    return dst


def zero_byte_bag(dst: Path) -> Path:
    dst.mkdir()
    (dst / 'zero.mcap').write_bytes(b'')
    return dst


def random_bytes_mcap(dst: Path) -> Path:
    """A bare .mcap file (no folder) of random bytes."""
    dst.write_bytes(np.random.default_rng(12).bytes(64_000))
    return dst


BAD_BAGS = {  # name -> (builder, the words the error line must contain)
    'zero_bytes': (zero_byte_bag, ['empty']),
    'random_bytes': (lambda p: random_bytes_mcap(p.with_suffix('.mcap')), ['not a readable MCAP']),
    'cut_0.1%_with_metadata': (lambda p: cut_copy(p, 0.001, metadata=True), ['no readable message']),
    'cut_0.1%_bare_mcap': (lambda p: cut_copy(p, 0.001, metadata=False), ['no readable message']),
    'imu_as_string': (string_imu_bag, ['/imu/data_raw', 'std_msgs/msg/String', 'sensor_msgs/msg/Imu']),
}


@pytest.fixture(scope='module')
def bad_bags(tmp_path_factory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp('bad_bags')
    return {name: build(folder / name.replace('%', 'pc')) for name, (build, _) in BAD_BAGS.items()}


def assert_one_line_error(proc, needles):
    lines = stderr_lines(proc)
    assert proc.returncode == 2, proc.stderr
    assert len(lines) == 1, proc.stderr
    assert 'Traceback' not in proc.stderr and 'Warning:' not in proc.stderr
    assert lines[0].startswith(f'{PROG}: error: '), lines[0]
    for needle in needles:
        assert needle in lines[0], lines[0]


@pytest.mark.parametrize('command', ['replay', 'evaluate', 'info', 'discover'])
@pytest.mark.parametrize('bag', list(BAD_BAGS))
def test_unusable_bag_is_one_line_and_exit_2(bad_bags, tmp_path, bag, command):
    args = [command, bad_bags[bag]]
    if command == 'replay':
        args += ['--out', tmp_path / 'out']
    proc = run_cli(*args)
    assert_one_line_error(proc, BAD_BAGS[bag][1])
    assert list(tmp_path.iterdir()) == []   # no output bag, no temporary folder
    assert proc.stdout == ''


def test_failing_replay_over_an_existing_output_keeps_it(bad_bags, tmp_path):
    """--force replaces the output only when the replay succeeds; a bad bag leaves the old one."""
    out = tmp_path / 'out'
    out.mkdir()
    (out / 'keep.txt').write_text('previous run')
    assert_one_line_error(run_cli('replay', bad_bags['zero_bytes'], '--out', out), ['exists'])
    assert_one_line_error(run_cli('replay', bad_bags['zero_bytes'], '--out', out, '--force'), ['empty'])
    assert sorted(p.name for p in tmp_path.iterdir()) == ['out']
    assert (out / 'keep.txt').read_text() == 'previous run'


@pytest.fixture(scope='module')
def half_bag(tmp_path_factory) -> Path:
    return cut_copy(tmp_path_factory.mktemp('half') / 'null_half', 0.5, metadata=True)


def warning_lines(proc) -> list[str]:
    return [ln for ln in stderr_lines(proc) if 'warning' in ln.lower()]


def test_truncated_bag_replays_what_is_there_with_one_warning(half_bag, tmp_path):
    out = tmp_path / 'out'
    proc = run_cli('replay', half_bag, '--out', out, '--duration', '300')
    assert proc.returncode == 0, proc.stderr
    assert 'Traceback' not in proc.stderr and 'UserWarning' not in proc.stderr
    (line,) = warning_lines(proc)
    assert line.startswith(f'{PROG}: warning: bag {half_bag} is truncated'), line
    # what else is on stderr is the node's own ROS log line, not a warning
    assert all(ln == line or '[INFO]' in ln for ln in stderr_lines(proc)), proc.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ['out']   # renamed; no temporary folder left
    assert sorted(p.name for p in out.iterdir()) == ['metadata.yaml', 'out.mcap']
    with BagReader(out) as reader:
        counts = {t.topic: t.count for t in reader.topics}
        assert not reader.truncated
    assert counts['/imu/data_raw'] == counts['/imu/data'] > 0


def test_truncation_warning_is_one_line_once_per_bag(half_bag):
    proc = run_cli('info', half_bag, half_bag)   # the bag is opened twice
    assert proc.returncode == 0, proc.stderr
    assert stderr_lines(proc) == warning_lines(proc)
    (line,) = warning_lines(proc)
    assert line.startswith(f'{PROG}: warning: bag {half_bag} is truncated'), line
    assert proc.stdout.count('[TRUNCATED]') == 2


# ---------------------------------------------------------------- BagWriter: temporary name, rename
def test_writer_renames_on_success_and_leaves_nothing_on_failure(tmp_path):
    chunk = SensorChunk(imu=ImuSamples(np.arange(10) * 0.01, np.zeros((10, 3)), np.ones((10, 3))))
    with pytest.raises(RuntimeError, match='boom'):
        with BagWriter(tmp_path / 'bag') as writer:
            writer.write_chunk(chunk)
            assert not (tmp_path / 'bag').exists()   # written under a temporary name meanwhile
            raise RuntimeError('boom')
    assert list(tmp_path.iterdir()) == []
    with BagWriter(tmp_path / 'bag') as writer:
        writer.write_chunk(chunk)
    assert [p.name for p in tmp_path.iterdir()] == ['bag']
    assert sorted(p.name for p in (tmp_path / 'bag').iterdir()) == ['bag.mcap', 'metadata.yaml']
    with pytest.raises(BagError, match='exists'):
        BagWriter(tmp_path / 'bag')
    with pytest.raises(ValueError, match='boom'):   # --force: a failed run keeps the old bag
        with BagWriter(tmp_path / 'bag', overwrite=True) as writer:
            writer.write_chunk(SensorChunk(imu=ImuSamples(np.arange(3) * 0.01, np.zeros((3, 3)), np.ones((3, 3)))))
            raise ValueError('boom')
    with BagReader(tmp_path / 'bag') as reader:
        assert {t.topic: t.count for t in reader.topics} == {'/imu/data_raw': 10}
    with BagWriter(tmp_path / 'bag', overwrite=True) as writer:   # --force: a good run replaces it
        writer.write_chunk(SensorChunk(imu=ImuSamples(np.arange(3) * 0.01, np.zeros((3, 3)), np.ones((3, 3)))))
    with BagReader(tmp_path / 'bag') as reader:
        assert {t.topic: t.count for t in reader.topics} == {'/imu/data_raw': 3}
    assert [p.name for p in tmp_path.iterdir()] == ['bag']


def test_replay_failing_midway_leaves_no_output(tmp_path, monkeypatch):
    """The node fails after inputs were written: nothing under --out, no temporary folder."""
    from gyro_thermal_comp.nodes import replay as replay_module

    def fail_after_one_chunk(kind, node_obj, reader, writer, t_end, total):
        writer.write_chunk(next(reader.chunks(10.0)))
        raise RuntimeError('node failed')

    monkeypatch.setattr(replay_module, '_replay_in_process', fail_after_one_chunk)
    with pytest.raises(RuntimeError, match='node failed'):
        replay_module.replay(SOURCE, tmp_path / 'out')
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------- evaluate: a baseline that cannot run
class CannotFit(DriftIntegrator):
    def fit(self, chunks):
        next(iter(chunks))
        raise NotApplicable('needs what this record does not have')


def test_not_applicable_method_is_reported_and_the_others_scored():
    chunks = level_unit_chunks(100.0, 50.0, yaw0_rad=0.4, drift_rad_s=2e-3, noise_rad_s=2e-3,
                               chunk_s=10.0, seed=5)
    rep = evaluate(chunks_from_list(chunks), [DriftIntegrator('first', 1e-4, 0.4), CannotFit('cannot', 0.0, 0.4),
                                              DriftIntegrator('last', 2e-4, 0.4)])
    assert rep.method_names == ['first', 'last']
    assert rep.not_applicable == {'cannot': 'needs what this record does not have'}
    lines = rep.to_text().splitlines()
    names = [ln.split()[0] for ln in lines if ln.split()[:1] in (['first'], ['cannot'], ['last'], [ORACLE])]
    assert names == ['first', 'cannot', 'last', ORACLE]   # in its place
    assert next(ln for ln in lines if ln.startswith('cannot')).split(None, 1)[1] == \
        'not applicable: needs what this record does not have'
    d = json.loads(rep.to_json())
    assert list(d['methods']) == ['first', 'cannot', 'last', ORACLE]
    assert d['methods']['cannot'] == {'status': 'not_applicable', 'reason': 'needs what this record does not have'}
    assert 'status' not in d['methods']['first'] and math.isfinite(d['methods']['last']['rms_deg'])
    assert 'cannot' not in d['update_time_s'] and 'cannot' not in d['allan_rate_error']


def test_evaluate_cli_reports_mlr_not_applicable_and_scores_stkf(tmp_path):
    """50 s of static_ramp: the still period and one clean window, fewer than the whole-record MLR
    fit's 3 parameters."""
    bag = tmp_path / 'short'
    proc = run_cli('simulate', 'static_ramp', '--duration', '50', '--out', bag)
    assert proc.returncode == 0, proc.stderr
    proc = run_cli('evaluate', bag, '--no-peers', '--json')
    assert proc.returncode == 0, proc.stderr
    methods = json.loads(proc.stdout)['methods']
    assert methods['mlr_whole_record']['status'] == 'not_applicable'
    assert 'MLR needs at least 3 clean windows' in methods['mlr_whole_record']['reason']
    for name in ('stkf', 'kf', 'lsm', 'uncompensated_gyro'):
        assert 'status' not in methods[name] and math.isfinite(methods[name]['rms_deg']), name
    text = run_cli('evaluate', bag, '--no-peers')
    assert text.returncode == 0, text.stderr
    mlr = next(ln for ln in text.stdout.splitlines() if ln.startswith('mlr_whole_record '))
    assert 'not applicable: MLR needs at least 3 clean windows' in mlr
    stkf = next(ln for ln in text.stdout.splitlines() if ln.startswith('stkf ')).split()
    assert math.isfinite(float(stkf[4]))   # RMS deg
