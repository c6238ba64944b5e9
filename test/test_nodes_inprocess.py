"""The ROS nodes in one process: parameters, REP 145 output, persistence, composition."""
import json
import math
import os
import re
import subprocess
import sys

import numpy as np
import pytest
import yaml
from rclpy.parameter import Parameter

from conftest import BAGS, Capture, REPO
from gyro_thermal_comp.angles import rotation_matrix_from_quat, wrap_angle, yaw_from_quat
from gyro_thermal_comp.bag_io import read_chunks
from gyro_thermal_comp.cli import default_param_files
from gyro_thermal_comp.nodes.compose import make_carousel_node, make_stkf_node


def feed(node, bag, seconds, streams=('imu', 'mag', 'temperature')):
    for chunk in read_chunks(bag, 10.0, streams=list(streams)):
        if chunk.imu is not None and chunk.imu.t[0] >= seconds:
            break
        node.process_chunk(chunk)


# ---------------------------------------------------------------- parameters
def test_config_files_are_the_generated_defaults():
    for name, text in default_param_files().items():
        assert (REPO / 'config' / name).read_text() == text, f'config/{name} is stale: gyro-thermal-comp params --write config'


def test_the_stkf_params_file_starts_with_what_a_robot_team_sets():
    """Every parameter sits in one section; the first holds the essentials, about a dozen; a
    parameter left out of every section (a new one) is named, not dropped from the file."""
    from gyro_thermal_comp.nodes.parameters import STKF_FILE_SECTIONS, ParamSpec, all_specs, file_sections
    groups = file_sections(all_specs(), STKF_FILE_SECTIONS)
    assert sum(len(g) for _, g in groups) == len(all_specs())
    title, essentials = groups[0]
    assert title == 'Set these for your robot' and 8 <= len(essentials) <= 14
    assert {'state_file', 'declination_rad', 'still_period_s'} <= {sp.name for sp in essentials}
    text = (REPO / 'config' / 'stkf.yaml').read_text()
    assert text.index('# ---- Set these for your robot') < text.index('    state_file:') < text.index('# ---- Advanced')
    with pytest.raises(KeyError, match='new_setting'):
        file_sections((*all_specs(), ParamSpec('new_setting', 1.0, 'a new setting')), STKF_FILE_SECTIONS)


def test_every_parameter_in_the_yaml_is_declared_and_described(ros):
    node = make_stkf_node()
    declared = {p for p in node._parameters}  # noqa: SLF001 (rclpy keeps them there)
    params = yaml.safe_load((REPO / 'config' / 'stkf.yaml').read_text())['/**/stkf_drift_estimator']['ros__parameters']
    assert set(params) <= declared and len(params) > 20
    for name in params:
        desc = node.describe_parameter(name)
        assert desc.description and not re.match(r'^\w+Config\.\w+$', desc.description), name
        assert node.get_parameter(name).value == params[name] or isinstance(params[name], list)
    node.destroy_node()


def test_out_of_range_set_is_rejected_with_reason(ros):
    node = make_stkf_node()
    result = node.set_parameters([Parameter('gate.field_norm_tol', value=-1.0)])[0]
    assert not result.successful and 'field_norm_tol' in result.reason
    result = node.set_parameters([Parameter('window_s', value=20.0)])[0]   # read-only: shapes the filter
    assert not result.successful
    result = node.set_parameters([Parameter('gate.dip_tol_rad', value=math.radians(2.5))])[0]
    assert result.successful and node.estimator.gate.cfg.dip_tol_rad == math.radians(2.5)
    node.destroy_node()


def test_runtime_gate_windows_take_effect_as_if_started_with_them(ros):
    """Stale settings: a SetParameters of the gate's windows and turn rate must not replace the
    gate's config while its trailing windows (and the estimator's turn limit for the tilt) keep the old
    values. Changed before any data, the node must compute exactly what a node started with them does."""
    changed = {'gate.mismatch_window_s': 30.0, 'gate.turn_window_s': 3.0, 'gate.turn_rate_rad_s': math.radians(5.0)}
    started = make_stkf_node(changed)
    live = make_stkf_node()
    result = live.set_parameters([Parameter(k, value=v) for k, v in changed.items()])
    assert all(r.successful for r in result)
    outputs = []
    for node in (started, live):
        chunks = read_chunks(BAGS / 'vehicle_loop', 60.0, streams=['imu', 'mag', 'temperature'])
        outs = [node.estimator.process(next(chunks)) for _ in range(5)]
        outputs.append((np.concatenate([o.gate_open for o in outs]), np.concatenate([o.reasons for o in outs]),
                        np.concatenate([o.track.heading_rad for o in outs])))
        node.destroy_node()
    (open_a, reasons_a, heading_a), (open_b, reasons_b, heading_b) = outputs
    assert np.array_equal(open_a, open_b) and np.array_equal(reasons_a, reasons_b)
    np.testing.assert_allclose(heading_b, heading_a, rtol=0, atol=1e-12)
    default = make_stkf_node()
    chunks = read_chunks(BAGS / 'vehicle_loop', 60.0, streams=['imu', 'mag', 'temperature'])
    reasons_default = np.concatenate([default.estimator.process(next(chunks)).reasons for _ in range(5)])
    default.destroy_node()
    assert not np.array_equal(reasons_default, reasons_a), 'the changed windows must change what the gate decides'


@pytest.mark.parametrize('content, needle', [
    ('stkf_drift_estimator:\n  ros__parameters:\n    no_such_param: 1.0\n', 'no_such_param'),
    ('stkf_drift_estimator:\n  ros__parameters:\n    window_s: "ten"\n', 'window_s'),
    ('stkf_drift_estimator:\n  ros__parameters:\n    window_s: 9999.0\n', 'window_s'),
])
def test_bad_parameter_file_gives_one_clear_line(tmp_path, content, needle):
    path = tmp_path / 'bad.yaml'
    path.write_text(content)
    proc = subprocess.run([sys.executable, '-m', 'gyro_thermal_comp.nodes.stkf_node', '--ros-args', '--params-file',
                           str(path)], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    assert 'Traceback' not in proc.stderr
    errors = [ln for ln in proc.stderr.splitlines() if 'error' in ln.lower()]
    assert len(errors) == 1 and needle in errors[0], proc.stderr


# ---------------------------------------------------------------- outputs (REP 145 / REP 103)
def test_compensated_imu_follows_rep_145(ros):
    node = make_stkf_node()
    node.pubs = {**node.pubs, 'imu': Capture(), 'heading': Capture()}
    feed(node, BAGS / 'vehicle_loop', 120.0)
    imu, heading = node.pubs['imu'].msgs, node.pubs['heading'].msgs
    assert len(imu) == len(heading) == 120 * 50
    arw = node.estimator.cfg.arw_rad_sqrt_s
    for m, h in zip(imu[-100:], heading[-100:]):
        assert m.header.frame_id == 'imu_link' and h.header.stamp == m.header.stamp
        oc, gc = np.array(m.orientation_covariance), np.array(m.angular_velocity_covariance)
        assert oc[0] > 0 and oc[4] > 0 and oc[8] > 0          # estimated: filled, not -1
        assert gc[0] >= arw ** 2 * 50 * 0.99                  # at least the white noise of one sample
        q = np.array([m.orientation.x, m.orientation.y, m.orientation.z, m.orientation.w])
        assert abs(np.linalg.norm(q) - 1) < 1e-9
        # imu/heading: yaw only, ENU, in the fixed frame, with the yaw variance of imu/data
        assert h.header.frame_id == 'odom'
        o = h.pose.pose.orientation
        assert o.x == 0 and o.y == 0
        assert math.isclose(yaw_from_quat([o.x, o.y, o.z, o.w]), yaw_from_quat(q), abs_tol=1e-12)
        cov = np.array(h.pose.covariance).reshape(6, 6)
        assert cov[5, 5] == oc[8] and np.all(np.diag(cov)[:5] >= 1e6) and np.count_nonzero(cov) == 6
        assert all(math.isfinite(v) for v in (m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z))
    node.destroy_node()


def test_ned_world_frame_as_imu_filter_madgwick(ros):
    """world_frame ned: the same imu_link seen from north-east-down; yaw clockwise from north."""
    outputs = {}
    for frame in ('enu', 'ned'):
        node = make_stkf_node({'world_frame': frame, 'fixed_frame': f'odom_{frame}'})
        node.pubs = {**node.pubs, 'imu': Capture(), 'heading': Capture()}
        feed(node, BAGS / 'vehicle_loop', 60.0)
        outputs[frame] = (node.pubs['imu'].msgs[-500:], node.pubs['heading'].msgs[-500:])
        node.destroy_node()
    ned_from_enu = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
    for (m_enu, h_enu), (m_ned, h_ned) in zip(zip(*outputs['enu']), zip(*outputs['ned'])):
        q_enu, q_ned = ([m.orientation.x, m.orientation.y, m.orientation.z, m.orientation.w] for m in (m_enu, m_ned))
        np.testing.assert_allclose(rotation_matrix_from_quat(q_ned), ned_from_enu @ rotation_matrix_from_quat(q_enu),
                                   atol=1e-12)
        yaw_enu = yaw_from_quat([getattr(h_enu.pose.pose.orientation, c) for c in 'xyzw'])
        yaw_ned = yaw_from_quat([getattr(h_ned.pose.pose.orientation, c) for c in 'xyzw'])
        assert math.isclose(yaw_ned, wrap_angle(math.pi / 2 - yaw_enu), abs_tol=1e-12) and -math.pi < yaw_ned <= math.pi
        assert h_ned.header.frame_id == 'odom_ned' and h_ned.pose.covariance[35] == h_enu.pose.covariance[35]
        assert list(m_ned.orientation_covariance) == list(m_enu.orientation_covariance)


def test_publish_tf(ros):
    """fixed_frame -> imu frame on /tf where tf2_msgs exists; without it, one clear start-up error."""
    from gyro_thermal_comp.nodes.interface import TFMessage
    from gyro_thermal_comp.nodes.parameters import ParameterFileError
    if TFMessage is None:
        with pytest.raises(ParameterFileError, match='publish_tf'):
            make_stkf_node({'publish_tf': True})
        return
    node = make_stkf_node({'publish_tf': True, 'fixed_frame': 'map'})
    assert 'tf' in node.pubs
    node.pubs = {name: Capture() for name in node.pubs}
    feed(node, BAGS / 'vehicle_loop', 40.0)
    tf, imu = node.pubs['tf'].msgs, node.pubs['imu'].msgs
    node.destroy_node()
    assert len(tf) == len(imu)
    tr = tf[-1].transforms[0]
    assert tr.header.frame_id == 'map' and tr.child_frame_id == 'imu_link' and tr.header.stamp == imu[-1].header.stamp
    assert tr.transform.rotation == imu[-1].orientation


def test_world_frame_is_checked_and_hardware_id_follows_the_input(ros):
    from gyro_thermal_comp.nodes.parameters import ParameterFileError
    from sensor_msgs.msg import Imu
    from std_msgs.msg import Header
    with pytest.raises(ParameterFileError, match='world_frame'):
        make_stkf_node({'world_frame': 'nwu'})
    node = make_stkf_node()
    assert node.hardware_id == 'imu'                       # nothing received yet
    node._on_imu(Imu(header=Header(frame_id='xsens_imu')))  # noqa: SLF001 (the subscription callback)
    assert node.hardware_id == 'xsens_imu'
    node.destroy_node()
    node = make_stkf_node({'hardware_id': 'mti-1 s/n 0042'})
    assert node.hardware_id == 'mti-1 s/n 0042'
    node.destroy_node()


class Log:
    def __init__(self):
        self.lines = []

    def info(self, text, **_):
        self.lines.append(('info', text))

    def warning(self, text, **_):
        self.lines.append(('warning', text))


def test_still_period_is_announced_and_a_short_one_is_a_warning(ros):
    node = make_stkf_node({'still_period_s': 300.0})      # the car drives off after 30 s, turns later
    node.pubs = {name: Capture() for name in node.pubs}
    node.still_report.logger = log = Log()
    feed(node, BAGS / 'vehicle_loop', 320.0)
    node.destroy_node()
    assert log.lines[0][0] == 'info' and 'still period began' in log.lines[0][1] and '300 s' in log.lines[0][1]
    assert len(log.lines) == 2 and log.lines[1][0] == 'warning' and 'cut short by motion' in log.lines[1][1]


def test_inputs_that_do_not_arrive_are_named():
    from gyro_thermal_comp.nodes.startup_report import InputWaitReport
    now = [0.0]
    log = Log()
    report = InputWaitReport(log, {'imu': '/imu/data_raw', 'temperature': '/imu/temperature', 'joint': '/j'},
                             optional=('joint',), clock=lambda: now[0])
    assert report.check({'imu': 0}, {}) == [] and not log.lines          # a few seconds of grace
    now[0] = 6.0
    assert report.check({'imu': 100, 'temperature': 0}, {'temperature': 1}) == ['temperature']
    assert log.lines == [('warning', 'still waiting for data on /imu/temperature after 6 s (1 publisher(s) matched)')]
    now[0] = 7.0
    report.check({'imu': 150}, {'temperature': 1})
    assert len(log.lines) == 1                                            # throttled
    now[0] = 16.5
    report.check({'imu': 500}, {'joint': 1})
    assert len(log.lines) == 3 and 'no publisher' in log.lines[1][1] and '/j' in log.lines[2][1]
    report.check({'imu': 600, 'temperature': 1, 'joint': 3}, {})
    assert log.lines[-2:] == [('info', 'data arrived on /imu/temperature'), ('info', 'data arrived on /j')]


# ---------------------------------------------------------------- persistence
def test_state_persists_and_warm_starts(ros, tmp_path):
    state_file = tmp_path / 'stkf.json'
    node = make_stkf_node({'state_file': str(state_file)})
    feed(node, BAGS / 'static_ramp', 1800.0)
    node.shutdown()
    saved = json.loads(state_file.read_text())
    x_saved = np.array(saved['x'])
    node.destroy_node()

    warm = make_stkf_node({'state_file': str(state_file)})
    assert warm.state_status.startswith('warm start')
    assert np.array_equal(np.array(warm.estimator.get_state()['x']), x_saved)
    # the drift it will apply at a given temperature is the saved model's, before any new data
    inputs = {'temperature': np.array([30.0, 45.0]), 'temperature_rate': np.array([0.0, 0.01]),
              'rate': np.zeros(2)}
    model = warm.estimator.model
    assert np.array_equal(model.evaluate(np.array(warm.estimator.get_state()['x']), inputs),
                          model.evaluate(x_saved, inputs))
    warm.destroy_node()


@pytest.mark.parametrize('content', ['{not json', json.dumps({'format': 'other'}),
                                     json.dumps({'format': 'gyro_thermal_comp/stkf_state/1', 'x': [float('nan')]})])
def test_corrupt_state_file_means_cold_start(ros, tmp_path, content):
    state_file = tmp_path / 'stkf.json'
    state_file.write_text(content)
    node = make_stkf_node({'state_file': str(state_file)})
    assert node.state_status.startswith('cold start')
    assert 'x' not in node.estimator.get_state()
    node.destroy_node()


# ---------------------------------------------------------------- composition
def test_readme_composition_example_runs():
    assert '(examples/compose_nodes.py)' in (REPO / 'README.md').read_text(), 'README must link the example'
    proc = subprocess.run([sys.executable, str(REPO / 'examples' / 'compose_nodes.py'), '--seconds', '2'],
                          capture_output=True, text=True, timeout=120, env=dict(os.environ))
    assert proc.returncode == 0, proc.stderr
    assert '/stkf_drift_estimator' in proc.stdout and '/wheel/carousel_demodulator' in proc.stdout


def test_carousel_node_demodulates_bundled_bag(ros):
    node = make_carousel_node()
    node.pubs['imu'], node.pubs['gyro_bias'] = Capture(), Capture()
    feed(node, BAGS / 'carousel_vertical', 1e9, streams=('imu', 'joint', 'temperature'))
    node.shutdown()
    assert len(node.pubs['imu'].msgs) > 50
    offset_var = node.settings['gyro_bias_sigma_rad_s'] ** 2
    for m in node.pubs['imu'].msgs:
        assert m.header.frame_id == 'base_link'
        assert all(math.isfinite(v) for v in (m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z))
        cov = np.array(m.angular_velocity_covariance).reshape(3, 3)
        assert np.all(np.diag(cov) > 0) and cov[2, 2] >= offset_var   # the spin axis is not modulated
    node.destroy_node()


def test_a_dropped_sample_is_counted_once_by_its_streams_guard(ros):
    """Offline chunks and live samples meet the same guard: each drop counted once, under its cause."""
    from gyro_thermal_comp.samples import ImuSamples, SensorChunk
    node = make_stkf_node()
    chunk = next(read_chunks(BAGS / 'vehicle_loop', 10.0, streams=['imu', 'mag', 'temperature']))
    gyro = chunk.imu.gyro.copy()
    gyro[[5, 7]] = np.nan
    node.process_chunk(SensorChunk(imu=ImuSamples(chunk.imu.t, gyro, chunk.imu.accel), mag=chunk.mag,
                                   temperature=chunk.temperature))
    t_end = float(chunk.imu.t[-1])
    origin_ns = node.pipeline.time_origin.ns or 0      # the chunk's times are s since it
    ns = lambda t: origin_ns + int(round(t * 1e9))  # noqa: E731
    node.pipeline.push_imu(ns(t_end + 0.5), 'imu_link', b'', [np.nan] * 6)
    node.pipeline.push_imu(ns(t_end + 1.0), 'imu_link', b'', [0.0] * 6)
    node.pipeline.push_imu(ns(t_end + 0.7), 'imu_link', b'', [0.0] * 6)   # out of order
    _, message, values = node.diagnostic_values()
    assert values['core.imu_dropped_nonfinite'] == 3 and values['core.imu_dropped_order'] == 1
    assert values['input.imu_received'] == 3
    assert not any(k.startswith('input.') and '_dropped_nonfinite' in k for k in values)
    assert values['input.imu_publishers'] == 0
    assert '4 input samples dropped' in message
    node.destroy_node()


def _stream_guards(root) -> list[str]:
    """The stream names of every StreamGuard reachable from `root` through the package's objects."""
    from gyro_thermal_comp.input_guard import StreamGuard
    seen, names, todo = set(), [], [root]
    while todo:
        obj = todo.pop()
        if id(obj) in seen:
            continue
        seen.add(id(obj))
        if isinstance(obj, StreamGuard):
            names.append(obj.name)
        elif isinstance(obj, dict):
            todo += list(obj.values())
        elif isinstance(obj, (list, tuple)):
            todo += list(obj)
        elif type(obj).__module__.startswith('gyro_thermal_comp') and hasattr(obj, '__dict__'):
            todo += list(vars(obj).values())
    return sorted(names)


def test_each_pipeline_has_one_guard_per_stream(ros):
    """A sample is checked once: one StreamGuard per input stream in each node's pipeline."""
    node = make_stkf_node()
    assert _stream_guards(node.pipeline) == ['imu', 'mag', 'temperature']
    node.destroy_node()
    node = make_carousel_node()
    assert _stream_guards(node.pipeline) == ['imu', 'imu_aux', 'joint', 'mag', 'temperature']
    node.destroy_node()
