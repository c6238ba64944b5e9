"""The command line: bad input gives one clear line and a non-zero exit, never a traceback."""
import os
import subprocess
import sys

import pytest

from conftest import BAGS


def run_cli(*args, cwd=None):
    return subprocess.run([sys.executable, '-m', 'gyro_thermal_comp.cli', *args],
                          capture_output=True, text=True, timeout=300, cwd=cwd)


def assert_one_line_error(proc, *needles):
    assert proc.returncode != 0
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, proc.stderr
    assert 'Traceback' not in proc.stderr
    for needle in needles:
        assert needle in lines[0], lines[0]


@pytest.mark.parametrize('args, needles', [
    (['simulate', 'no_such_scenario', '--out', '{tmp}/x'], ['no_such_scenario', 'static_ramp']),
    (['simulate', 'static_ramp', '--out', '{tmp}/missing/dir/x', '--duration', '10'], ['missing']),
    (['simulate', 'static_ramp', '--out', '{tmp}/x', '--duration', '-5'], ['-5']),
    (['simulate', 'static_ramp', '--out', '{tmp}/x', '--duration', 'nan'], ['nan']),
    (['simulate', 'static_ramp', '--out', '{tmp}/x', '--effect', 'bogus_effect=1'], ['bogus_effect']),
    (['simulate', 'static_ramp', '--out', '{tmp}/x', '--effect', 'thermal_lag'], ['NAME=VALUE']),
    (['simulate', 'static_ramp', '--out', '{tmp}/x', '--effect', 'thermal_lag=abc'], ['abc']),
    (['simulate', 'static_ramp', '--out', '{tmp}/x', '--effect', 'thermal_lag=-30'], ['thermal_lag']),
    (['simulate', 'static_ramp', '--out', '{tmp}/x', '--param', 'warp_speed=9'], ['warp_speed']),
    (['info', '{tmp}/not_a_bag'], ['not_a_bag']),
    (['evaluate', '{tmp}/nope'], ['nope']),
    (['evaluate', '{bags}/null', '--arw', '-0.04'], ['--arw', '-0.04']),
    (['discover', '{tmp}/nope'], ['nope']),
    (['discover', '{bags}/vehicle_loop', '--reference', 'static'], ["reference 'static'", 'turned', 'odom']),
    (['replay', '{tmp}/nope', '--out', '{tmp}/o'], ['nope']),
    (['replay', '{bags}/null', '--out', '{tmp}/o', '--params', '{tmp}/missing.yaml'], ['missing.yaml']),
    (['replay', '{bags}/null', '--out', '{tmp}/o', '--start', '99999'], ['99999', 'beyond the end']),
    (['replay', '{bags}/null', '--out', '{tmp}/o', '--start', '-1'], ['--start', '-1']),
    (['bogus-command'], ['bogus-command']),
    ([], ['COMMAND']),
])
def test_bad_input_one_line(tmp_path, args, needles):
    proc = run_cli(*[a.format(tmp=tmp_path, bags=BAGS) for a in args])
    assert_one_line_error(proc, *needles)
    assert not (tmp_path / 'x').exists()


def test_unwritable_output(tmp_path):
    if os.geteuid() == 0:
        target = '/proc/gtc_no_write/x'  # even root cannot create folders in /proc
    else:
        locked = tmp_path / 'locked'
        locked.mkdir(mode=0o500)
        target = str(locked / 'x')
    assert_one_line_error(run_cli('simulate', 'null', '--out', target, '--duration', '5'))


def test_existing_output_needs_force(tmp_path):
    out = tmp_path / 'bag'
    assert run_cli('simulate', 'null', '--out', str(out), '--duration', '5').returncode == 0
    assert_one_line_error(run_cli('simulate', 'null', '--out', str(out), '--duration', '5'), 'exists')
    assert run_cli('simulate', 'null', '--out', str(out), '--duration', '5', '--force').returncode == 0


def test_simulate_then_info_reads_back(tmp_path):
    out = tmp_path / 'ramp'
    proc = run_cli('simulate', 'static_ramp', '--out', str(out), '--duration', '30', '--seed', '3')
    assert proc.returncode == 0, proc.stderr
    info = run_cli('info', str(out))
    assert info.returncode == 0, info.stderr
    assert '/imu/data_raw' in info.stdout and 'static_ramp' in info.stdout
