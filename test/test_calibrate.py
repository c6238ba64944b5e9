"""`calibrate`: a unit's drift model file, warm-start state and report from its logs; a node warm-started
from them holds heading better than a cold one; many units by file name or log field, in processes on
this machine or on a Dask cluster, with the same files either way."""
import json
import math
import shutil

import numpy as np
import pytest
import yaml

from gyro_thermal_comp.angles import wrap_angle, yaw_from_quat
from gyro_thermal_comp.bag_io import BagReader
from gyro_thermal_comp.calibration import FILES, CalibrationError, calibrate_fleet, group_logs
from gyro_thermal_comp.cli import main
from gyro_thermal_comp.nodes.replay import replay
from gyro_thermal_comp.nodes.stkf_node import NODE_NAME
from logfiles import simulated, write_dataflash, write_ulog

from conftest import BAGS

FIRST_MINUTES_S = 600.0
STILL_S = 30.0          # the node's default still period, s


def _heading_figures(out) -> tuple[float, float, float, str]:
    """(max |heading error - its first-minute mean| deg, the same after the still period, max
    |heading of the compensated gyro| deg after the still period, the node's state_file status)
    over a replay's output bag."""
    yaw, truth_yaw, rate, truth_rate, status = [], [], [], [], ''
    with BagReader(out) as r:
        for topic, _, _, m in r.messages(['/imu/data', '/ground_truth/odom', '/diagnostics']):
            if topic == '/diagnostics':
                status = status or next((kv.value for s in m.status for kv in s.values if kv.key == 'state_file'), '')
                continue
            t = r.stamp_s(m.header)
            if topic == '/imu/data':
                q = m.orientation
                yaw.append((t, yaw_from_quat(np.array([q.x, q.y, q.z, q.w]))))
                rate.append((t, m.angular_velocity.z))
            else:
                q = m.pose.pose.orientation
                truth_yaw.append((t, yaw_from_quat(np.array([q.x, q.y, q.z, q.w]))))
                truth_rate.append((t, m.twist.twist.angular.z))
    yaw, truth_yaw, rate, truth_rate = map(np.array, (yaw, truth_yaw, rate, truth_rate))
    err = np.unwrap(wrap_angle(yaw[:, 1] - np.interp(yaw[:, 0], truth_yaw[:, 0], np.unwrap(truth_yaw[:, 1]))))
    err = np.degrees(err - err[yaw[:, 0] < yaw[0, 0] + 60.0].mean())
    rate_err = rate[:, 1] - np.interp(rate[:, 0], truth_rate[:, 0], truth_rate[:, 1])
    after_still = rate[:, 0] >= STILL_S
    drift = np.degrees(np.cumsum(rate_err[after_still] * np.gradient(rate[after_still, 0])))
    return (float(np.abs(err).max()), float(np.abs(err[yaw[:, 0] >= STILL_S]).max()),
            float(np.abs(drift - drift[0]).max()), status)


def _replay_first_minutes(tmp_path, name, params):
    params_file = tmp_path / f'{name}.yaml'
    params_file.write_text(yaml.safe_dump({NODE_NAME: {'ros__parameters': params or {'window_s': 10.0}}}))
    out = tmp_path / name
    replay(BAGS / 'static_ramp_outages', out, params_file=params_file, duration_s=FIRST_MINUTES_S)
    return _heading_figures(out)


def test_warm_start_from_a_bench_calibration_holds_heading_better(tmp_path, capsys):
    """Calibrated on the 2 h lab run of the same unit (its constant handed on as a turn-on bias to
    be measured again, its temperature terms as learned, no compass map: that is the mounting's);
    over the first 10 min of the outage bag the node started from the calibration is compared with
    a cold node."""
    assert main(['calibrate', str(BAGS / 'static_ramp_unit2'), '--out', str(tmp_path / 'cal')]) == 0
    cal = tmp_path / 'cal'
    state = tmp_path / 'state.json'
    shutil.copy(cal / FILES['state'], state)   # the node learns on into its state file
    assert 'heading' not in json.loads(state.read_text())
    warm_max, warm_after, warm_drift, status = _replay_first_minutes(
        tmp_path, 'warm', {'state_file': str(state), 'drift_model_file': str(cal / FILES['model'])})
    assert status.startswith('warm start from')
    cold_max, cold_after, cold_drift, status = _replay_first_minutes(tmp_path, 'cold', None)
    assert status.startswith('cold start')
    with capsys.disabled():
        print(f'\nfirst 10 min of static_ramp_outages, max |heading error - first-minute mean|: warm {warm_max:.5f} '
              f'deg, cold {cold_max:.5f} deg; after the still period: warm {warm_after:.5f} deg, cold '
              f'{cold_after:.5f} deg; compensated gyro heading drift: warm {warm_drift:.3f} deg, '
              f'cold {cold_drift:.3f} deg')
    assert warm_max < cold_max
    assert warm_after < cold_after
    assert warm_drift < cold_drift


@pytest.fixture(scope='module')
def fleet(tmp_path_factory):
    """Two units' bench logs, named by unit; unit B's a DataFlash log of another unit draw."""
    d = tmp_path_factory.mktemp('fleet')
    write_ulog(d / 'unitA_bench.ulg', simulated(300.0, 10.0, seed=21))
    write_dataflash(d / 'unitB_bench.bin', simulated(300.0, 10.0, seed=22))
    return d


def _files(folder) -> dict:
    out = {}
    for name in (FILES['model'], FILES['summary'], FILES['report'], FILES['state'], FILES['figure']):
        data = (folder / name).read_bytes()
        if name == FILES['state']:
            record = json.loads(data)
            record.pop('saved_unix_s')   # when it was written
            data = record
        out[name] = data
    return out


def test_dask_cluster_gives_the_single_machine_files(fleet, tmp_path):
    from dask.distributed import LocalCluster
    logs = sorted(fleet.iterdir())
    local = calibrate_fleet(logs, tmp_path / 'local', unit=r'^(unit[A-Z])_', jobs=1)   # this process
    assert [o.error for o in local] == [None, None]
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host='127.0.0.1',
                      dashboard_address=None) as cluster:
        remote = calibrate_fleet(logs, tmp_path / 'dask', unit=r'^(unit[A-Z])_', scheduler=cluster.scheduler_address)
    assert sorted(o.unit for o in remote) == ['unitA', 'unitB']
    for unit in ('unitA', 'unitB'):
        a, b = _files(tmp_path / 'local' / unit), _files(tmp_path / 'dask' / unit)
        assert a == b, unit
    assert _files(tmp_path / 'local' / 'unitA') != _files(tmp_path / 'local' / 'unitB')


def test_unit_from_a_log_field(fleet):
    groups = group_logs([fleet / 'unitA_bench.ulg'], 'field:sys_uuid')
    assert groups == {'UNIT0042': [str(fleet / 'unitA_bench.ulg')]}
    assert list(group_logs([fleet / 'unitB_bench.bin'], 'field:param.INS_GYR_ID')) == ['2752522.0']
    with pytest.raises(CalibrationError, match="no field 'serial'"):
        group_logs([fleet / 'unitA_bench.ulg'], 'field:serial')
    with pytest.raises(CalibrationError, match='does not match --unit'):
        group_logs([fleet / 'unitA_bench.ulg'], r'^(robot\d+)')


def test_a_unit_without_temperature_fails_alone(fleet, tmp_path, capsys):
    """Two units in two processes (the default on one machine): the one that cannot be calibrated
    says why in one line, the other is written."""
    rec = simulated(300.0, 10.0, seed=21)
    write_ulog(tmp_path / 'unitC_bench.ulg', rec, temp_offsets=(math.nan, math.nan))
    code = main(['calibrate', str(fleet / 'unitA_bench.ulg'), str(tmp_path / 'unitC_bench.ulg'), '--unit',
                 r'^(unit[A-Z])_', '--out', str(tmp_path / 'out')])
    out, err = capsys.readouterr()
    assert code == 2
    assert err.strip() == ('gyro-thermal-comp: error: unit unitC: ' + str(tmp_path / 'unitC_bench.ulg')
                           + ': no gyro temperature: a thermal calibration needs one')
    assert (tmp_path / 'out' / 'unitA' / FILES['state']).is_file() and not (tmp_path / 'out' / 'unitC').exists()
