"""A robot-wide params file: wildcard sections with other nodes' keys start both nodes (said, ignored);
an unknown key under this node's own name stops it with one line."""
import queue
import signal
import subprocess
import sys
import threading
import time

import pytest

from gyro_thermal_comp.nodes.param_files import files_not_applying, keys_addressed_to, ros_arguments

from conftest import REPO

ROBOT_WIDE = """\
/**:
  ros__parameters:
    use_mag: true          # imu_filter_madgwick's, not ours
    gain: 0.1
    stateless: false
    window_s: 12.0
/**/imu_filter_madgwick:
  ros__parameters:
    zeta: 0.0
stkf_drift_estimator:
  ros__parameters:
    compass_block_s: 1.0
carousel_demodulator:
  ros__parameters:
    max_revolution_period_s: 4.0
"""


def _start(module: str, params_file, until: str, limit_s: float = 180.0, preexec_fn=None) -> subprocess.CompletedProcess:
    """Run a node executable on a params file; Ctrl-C once stderr shows `until` (the node is past its
    parameters: started). A node that refuses to start ends by itself. `limit_s` only turns a hang
    into a failure (no expectation on speed)."""
    cmd = [sys.executable, '-m', module, '--ros-args', '--params-file', str(params_file)]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, preexec_fn=preexec_fn)
    lines: queue.Queue = queue.Queue()
    threading.Thread(target=lambda: [lines.put(ln) for ln in proc.stderr] + [lines.put(None)], daemon=True).start()
    err, end = [], time.monotonic() + limit_s
    while True:
        try:
            line = lines.get(timeout=max(0.0, end - time.monotonic()))
        except queue.Empty:
            proc.kill()
            pytest.fail(f'no exit and no {until!r} within {limit_s} s:\n' + ''.join(err))
        if line is None:
            break
        err.append(line)
        if until in line and '[was running]\n' not in err:   # one Ctrl-C
            proc.send_signal(signal.SIGINT)
            err.append('[was running]\n')
    return subprocess.CompletedProcess(cmd, proc.wait(timeout=limit_s), '', ''.join(err))


@pytest.mark.parametrize('module', ['gyro_thermal_comp.nodes.stkf_node', 'gyro_thermal_comp.nodes.carousel_node'])
def test_a_robot_wide_params_file_with_foreign_keys_starts_the_node(tmp_path, module):
    path = tmp_path / 'robot.yaml'
    path.write_text(ROBOT_WIDE)
    proc = _start(module, path, until='ignoring parameter(s)')
    assert '[was running]' in proc.stderr and proc.returncode == 0, proc.stderr
    assert 'ignoring parameter(s)' in proc.stderr and 'use_mag' in proc.stderr, proc.stderr
    assert 'Traceback' not in proc.stderr


def test_a_node_started_from_a_background_job_still_stops_on_ctrl_c(tmp_path):
    """`cmd &` in a script starts it with SIGINT ignored; ros2 launch stops nodes with SIGINT."""
    path = tmp_path / 'robot.yaml'
    path.write_text(ROBOT_WIDE)
    proc = _start('gyro_thermal_comp.nodes.stkf_node', path, until='ignoring parameter(s)',
                  preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
    assert proc.returncode == 0 and 'stopped:' in proc.stderr, proc.stderr


def test_an_unknown_key_under_the_nodes_own_name_stops_it_with_one_line(tmp_path):
    path = tmp_path / 'robot.yaml'
    path.write_text(ROBOT_WIDE + 'stkf_drift_estimator:\n  ros__parameters:\n    windw_s: 12.0\n')
    proc = _start('gyro_thermal_comp.nodes.stkf_node', path, until='ignoring parameter(s)')
    assert proc.returncode == 2, proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and 'windw_s' in lines[0] and str(path) in lines[0], proc.stderr


def test_addressing_follows_rcl_names():
    args = ['prog', '--ros-args', '-r', '__ns:=/robot1', '-p', 'stkf_drift_estimator:a:=1', '-p', 'b:=2',
            '--params-file', 'f.yaml', '--', '-p', 'not_ros:=1']
    assert ros_arguments(args) == [('-p', 'stkf_drift_estimator:a:=1'), ('-p', 'b:=2'), ('--params-file', 'f.yaml')]
    assert keys_addressed_to('/stkf_drift_estimator', args[:7]) == {'a': '-p stkf_drift_estimator:a:=1'}


def test_nested_namespaces_and_wildcards_in_a_file(tmp_path):
    path = tmp_path / 'p.yaml'
    path.write_text('robot1:\n  stkf_drift_estimator:\n    ros__parameters:\n      gate:\n        hysteresis: 0.5\n'
                    '/robot1/*:\n  ros__parameters:\n    other: 1\n'
                    'stkf_drift_estimator:\n  ros__parameters:\n    root_only: 1\n')
    addressed = keys_addressed_to('/robot1/stkf_drift_estimator', ['--ros-args', '--params-file', str(path)])
    assert set(addressed) == {'gate.hysteresis'}   # the root-namespace section is another node's
    assert keys_addressed_to('/stkf_drift_estimator', ['--ros-args', '--params-file', str(path)]) == {
        'root_only': f'{path} under stkf_drift_estimator'}


def test_a_script_naming_an_unknown_parameter_of_a_composed_node_is_refused():
    from gyro_thermal_comp.nodes.compose import make_carousel_node, make_stkf_node
    from gyro_thermal_comp.nodes.parameters import ParameterFileError
    for make, typo in ((make_stkf_node, 'windw_s'), (make_carousel_node, 'max_revolution_perid_s')):
        with pytest.raises(ParameterFileError, match=typo):
            make({typo: 1.0})   # refused before rclpy is touched: no init needed


def test_a_namespaced_nodes_diagnostics_reach_the_absolute_topic():
    """diagnostic_updater's `/diagnostics`, not `/robot1/diagnostics` that no aggregator reads."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.executors import SingleThreadedExecutor
    from gyro_thermal_comp.nodes.compose import make_carousel_node, make_stkf_node
    rclpy.init()
    try:
        nodes = [make_stkf_node(namespace='robot1'), make_carousel_node(namespace='robot1')]
        probe = rclpy.create_node('diagnostics_probe')
        got = []
        sub = probe.create_subscription(DiagnosticArray, '/diagnostics', got.append, 1000)
        executor = SingleThreadedExecutor()
        for n in (*nodes, probe):
            executor.add_node(n)
        assert all(n.pubs['diagnostics'].topic_name == '/diagnostics' for n in nodes)
        names = set()
        for _ in range(120):   # condition-fenced: each round publishes once and runs 10 callbacks
            for n in nodes:
                n.publish_diagnostics()
            for _ in range(10):   # the nodes' own timers compete with the probe for the executor
                executor.spin_once(timeout_sec=0.05)
            names = {s.name.split(':')[0] for m in got for s in m.status}
            if len(names) == 2:
                break
        assert names == {'stkf_drift_estimator', 'carousel_demodulator'}, f'{sub.get_publisher_count()} publishers matched'
    finally:
        rclpy.try_shutdown()


def test_a_section_naming_the_node_under_a_namespace_wildcard_addresses_it(tmp_path):
    """`/**/stkf_drift_estimator` (the package's own files) applies in any namespace and names the
    node: a typo under it stops the node, as under its full name."""
    path = tmp_path / 'p.yaml'
    path.write_text('/**/stkf_drift_estimator:\n  ros__parameters:\n    windw_s: 12.0\n'
                    '/**:\n  ros__parameters:\n    use_mag: true\n'
                    '/**/imu_filter_madgwick:\n  ros__parameters:\n    zeta: 0.0\n')
    args = ['--ros-args', '--params-file', str(path)]
    for fqn in ('/stkf_drift_estimator', '/rover1/stkf_drift_estimator', '/fleet/rover1/stkf_drift_estimator'):
        assert keys_addressed_to(fqn, args) == {'windw_s': f'{path} under **/stkf_drift_estimator'}
        assert files_not_applying(fqn, args) == []


def test_a_parameter_file_none_of_whose_sections_applies_is_named(tmp_path):
    path = tmp_path / 'p.yaml'
    path.write_text('stkf_drift_estimator:\n  ros__parameters:\n    declination_rad: 0.1\n'
                    '/rover2/stkf_drift_estimator:\n  ros__parameters:\n    declination_rad: 0.2\n')
    args = ['--ros-args', '--params-file', str(path)]
    assert files_not_applying('/stkf_drift_estimator', args) == []
    assert files_not_applying('/rover2/stkf_drift_estimator', args) == []
    [problem] = files_not_applying('/rover1/stkf_drift_estimator', args)
    assert str(path) in problem and 'no section applies to /rover1/stkf_drift_estimator' in problem
    assert 'stkf_drift_estimator, rover2/stkf_drift_estimator' in problem and '/**/stkf_drift_estimator' in problem


def test_the_shipped_parameter_file_applies_in_a_namespace(ros, tmp_path, monkeypatch):
    """An edited copy of config/stkf.yaml (declination and state file set) for a node started with
    `-r __ns:=/rover1`: its values are the ones in force."""
    from gyro_thermal_comp.nodes import ros_params
    from gyro_thermal_comp.nodes.stkf_node import StkfDriftEstimatorNode
    text = (REPO / 'config' / 'stkf.yaml').read_text()
    state = tmp_path / 'stkf_state.json'
    for old, new in (("    declination_rad: 0.0", "    declination_rad: 0.12"),
                     ("    state_file: ''", f"    state_file: '{state}'")):
        assert old in text
        text = text.replace(old, new)
    path = tmp_path / 'stkf.yaml'
    path.write_text(text)
    import rclpy
    args = ['--ros-args', '--params-file', str(path), '-r', '__ns:=/rover1']
    context = rclpy.Context()
    rclpy.init(args=args, context=context)
    monkeypatch.setattr(ros_params, '_GLOBAL_ARGS', ['stkf_node', *args])
    try:
        node = StkfDriftEstimatorNode(context=context)
        try:
            assert node.get_fully_qualified_name() == '/rover1/stkf_drift_estimator'
            assert node.settings['declination_rad'] == 0.12 and node.settings['state_file'] == str(state)
            assert node.state_status.startswith('cold start: no state file at')
        finally:
            node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
