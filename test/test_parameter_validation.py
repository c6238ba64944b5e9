"""Parameters: every bad value is one clear line and exit 2 at start, or a
refused SetParameters with a reason at run time; never a traceback, never accepted-then-crash."""
import math
import subprocess
import sys
from dataclasses import fields, is_dataclass

import numpy as np
import pytest
import rclpy
from rclpy.parameter import Parameter

from conftest import BAGS, Capture
from gyro_thermal_comp.bag_io import read_chunks
from gyro_thermal_comp.carousel import CarouselConfig
from gyro_thermal_comp.nodes.carousel_node import carousel_specs
from gyro_thermal_comp.nodes.compose import make_stkf_node
from gyro_thermal_comp.nodes.parameters import (ParameterFileError, all_specs, allowed_range, check_value,
                                                config_from_params, config_problems, range_table)
from gyro_thermal_comp.nodes.ros_params import first_problem
from gyro_thermal_comp.thermal.estimator import EstimatorConfig


def _numeric_fields(cfg, prefix=''):
    """Flattened names of the numeric fields (int, float, `float | None`) of a nested config."""
    out = []
    for f in fields(cfg):
        value = getattr(cfg, f.name)
        if is_dataclass(value):
            out += _numeric_fields(value, f'{prefix}{f.name}.')
        elif (isinstance(value, (int, float)) and not isinstance(value, bool)) or 'float | None' in str(f.type):
            out.append(prefix + f.name)
    return out


# ---------------------------------------------------------------- the range table
@pytest.mark.parametrize('base', [EstimatorConfig(), CarouselConfig.turntable()], ids=['estimator', 'carousel'])
def test_every_numeric_field_has_an_explicit_range(base):
    """A new numeric field of EstimatorConfig/GateConfig/HeadingFilterConfig/CarouselConfig/FlipConfig
    needs its physical range in nodes/parameters.py; a renamed one must not leave a stale entry."""
    table = range_table(type(base))
    numeric = _numeric_fields(base)
    assert len(numeric) > 20
    missing = [name for name in numeric if name not in table]
    assert not missing, f'no range in nodes/parameters.py for {missing}'
    stale = sorted(set(table) - set(numeric))
    assert not stale, f'range table entries without a field: {stale}'
    specs = {s.name: s for s in (all_specs() if isinstance(base, EstimatorConfig) else carousel_specs())}
    for name in numeric:
        spec = specs[name]
        assert spec.min_value is not None and spec.max_value is not None, name
        assert spec.max_value < 1e9 or spec.max_value == math.inf, name   # (inf: 'inf = off' fields)
        assert math.isfinite(spec.min_value) and spec.min_value < spec.max_value, name


def test_every_declared_number_has_a_range():
    for spec in all_specs() + carousel_specs():
        if isinstance(spec.default, (int, float)) and not isinstance(spec.default, bool):
            assert allowed_range(spec) is not None, spec.name


@pytest.mark.parametrize('specs, base', [(all_specs(), None), (carousel_specs(), CarouselConfig.turntable()),
                                         (carousel_specs(CarouselConfig.wheel()), CarouselConfig.turntable())],
                         ids=['stkf', 'carousel', 'carousel_wheel'])
def test_defaults_are_valid(specs, base):
    for spec in specs:
        assert check_value(spec, spec.default) is None, spec.name
    cfg = config_from_params({s.name: s.default for s in specs}, base)
    assert config_problems(cfg) == []


def test_strict_bounds_are_enforced_with_a_reason_naming_the_parameter():
    strict = [s for s in all_specs() + carousel_specs() if s.min_exclusive]
    assert {'gate.reference_memory_s', 'gate.hysteresis', 'gate.field_norm_tol', 'compass_block_s',
            'temp_window_s', 'flip.aux_calibration_tau_s'} <= {s.name for s in strict}
    for spec in strict:
        as_value = (lambda v: [v]) if spec.unset_array else (lambda v: v)   # noqa: E731 (lists: each element)
        reason = check_value(spec, as_value(spec.min_value))
        assert reason and spec.name in reason and allowed_range(spec) in reason and allowed_range(spec)[0] == '('
        assert check_value(spec, as_value(spec.max_value)) is None, spec.name
        if math.isfinite(spec.max_value):
            assert check_value(spec, as_value(spec.max_value * 1.01 + 1)) is not None, spec.name
            assert check_value(spec, as_value(math.inf)) is not None, spec.name


def test_new_output_parameters_have_physical_ranges():
    """Frames are checked against their choices; sigmas are non-negative and bounded;
    the start-up wait is a delivery delay, not a period."""
    specs = {s.name: s for s in all_specs()}
    assert check_value(specs['world_frame'], 'ned') is None
    assert 'world_frame' in check_value(specs['world_frame'], 'NWU')
    for name, good, bad in [('tilt_floor_rad', 0.01, -0.1), ('tilt_floor_rad', math.pi / 4, 0.8),
                            ('compass_deviation_sigma_rad', 0.0, 3.2), ('declination_sigma_rad', 0.01, -1.0),
                            ('first_sample_wait_s', 0.0, 61.0), ('accel_noise_density_m_s2_rthz', 1e-3, 0.2),
                            ('tilt_window_s', 1.0, 0.0), ('gate.turn_rate_rad_s', math.radians(2000.0), 35.0)]:
        assert check_value(specs[name], good) is None, name
        assert name in check_value(specs[name], bad), name
    assert check_value(specs['declination_sigma_rad'], math.nan) is None      # unset: derived
    carousel = {s.name: s for s in carousel_specs()}
    assert 'gyro_scale_factor_sigma' in check_value(carousel['gyro_scale_factor_sigma'], 0.6)
    assert check_value(carousel['gyro_bias_sigma_rad_s'], 0.01) is None


def test_hysteresis_is_a_fraction():
    spec = {s.name: s for s in all_specs()}['gate.hysteresis']
    assert check_value(spec, 1.0) is None and check_value(spec, 0.05) is None
    for bad in (0.0, 1.5, 5.0, -0.3, math.nan):
        assert 'gate.hysteresis' in check_value(spec, bad)


# ---------------------------------------------------------------- bad parameter files: one line, exit 2
def _params(body: str, node: str = 'stkf_drift_estimator') -> str:
    return f'{node}:\n  ros__parameters:\n' + ''.join(f'    {line}\n' for line in body.splitlines())


STKF_BAD_FILES = [
    ('unknown_term', _params("terms: ['temperature', 'bogus_term']"), 'bogus_term'),
    ('empty_terms', _params('terms: []'), 'terms'),
    ('scale_factor_term_twice', _params("terms: ['constant', 'rate']\nscale_factor: true"), 'terms'),
    ('compass_block_zero', _params('compass_block_s: 0.0'), 'compass_block_s'),
    ('temp_window_zero', _params('temp_window_s: 0.0'), 'temp_window_s'),
    ('prior_sigmas_length', _params('prior_sigmas: [1.0e-4, 1.0e-2]'), 'prior_sigmas'),
    ('q_sigmas_negative', _params('q_sigmas: [2.0e-8, -2.0e-6, 1.0e-7, 1.0e-10]'), 'q_sigmas'),
    ('prior_sigmas_not_a_list', _params("prior_sigmas: 'large'"), 'prior_sigmas'),
    ('confirm_not_below_window', _params('confirm_s: 10.0'), 'confirm_s'),
    ('edge_over_half_window', _params('edge_s: 6.0'), 'edge_s'),
    ('temperature_range_inverted', _params('temperature_min_c: 90.0\ntemperature_max_c: 40.0'), 'temperature_min_c'),
    ('latitude_out_of_range', _params('latitude_deg: 91.0'), 'latitude_deg'),
    ('window_infinite', _params('window_s: .inf'), 'window_s'),
    ('confirm_samples_zero', _params('time_jump_confirm_samples: 0'), 'time_jump_confirm_samples'),
    ('gate_reference_memory_zero', _params('gate.reference_memory_s: 0.0'), 'gate.reference_memory_s'),
    ('gate_hysteresis_over_one', _params('gate.hysteresis: 5.0'), 'gate.hysteresis'),
    ('world_frame_unknown', _params("world_frame: 'nwu'"), 'world_frame'),
    ('gate_field_norm_tol_zero', _params('gate.field_norm_tol: 0.0'), 'gate.field_norm_tol'),
    ('gate_smoothing_over_window', _params('gate.mismatch_smooth_s: 20.0'), 'gate.mismatch_smooth_s'),
    ('broken_yaml', _params('window_s: [10.0'), 'cannot read parameter file'),
    ('not_yaml_at_all', ': : :\n\t- [', 'cannot read parameter file'),
    ('mixed_type_list', _params('prior_sigmas: [1.0, 2, 3.0, 4.0]'), 'cannot read parameter file'),
]


def _run(module: str, params_file) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, '-m', module, '--ros-args', '--params-file', str(params_file)],
                          capture_output=True, text=True, timeout=60)


def _assert_one_error_line(proc, needle: str) -> str:
    assert proc.returncode == 2, proc.stderr
    assert 'Traceback' not in proc.stderr, proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, proc.stderr
    assert 'error' in lines[0].lower() and needle in lines[0], proc.stderr
    return lines[0]


@pytest.mark.parametrize('content, needle', [c[1:] for c in STKF_BAD_FILES], ids=[c[0] for c in STKF_BAD_FILES])
def test_bad_stkf_parameter_file_gives_one_clear_line_and_exit_2(tmp_path, content, needle):
    path = tmp_path / 'bad.yaml'
    path.write_text(content)
    line = _assert_one_error_line(_run('gyro_thermal_comp.nodes.stkf_node', path), needle)
    assert line.startswith('stkf_node: error: ')
    if needle == 'cannot read parameter file':
        assert str(path) in line


def test_missing_parameter_file_gives_one_clear_line(tmp_path):
    path = tmp_path / 'nowhere.yaml'
    line = _assert_one_error_line(_run('gyro_thermal_comp.nodes.stkf_node', path), 'cannot read parameter file')
    assert str(path) in line


CAROUSEL_BAD_FILES = [
    ('aux_tau_zero', 'flip.aux_calibration_tau_s: 0.0', 'flip.aux_calibration_tau_s'),
    ('not_a_rotation', 'carousel_to_body: [2.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]', 'carousel_to_body'),
    ('angle_source', "angle_source: 'encoder'", 'angle_source'),
]


@pytest.mark.parametrize('body, needle', [c[1:] for c in CAROUSEL_BAD_FILES], ids=[c[0] for c in CAROUSEL_BAD_FILES])
def test_bad_carousel_parameter_file_gives_one_clear_line_and_exit_2(tmp_path, body, needle):
    path = tmp_path / 'bad.yaml'
    path.write_text(_params(body, 'carousel_demodulator'))
    line = _assert_one_error_line(_run('gyro_thermal_comp.nodes.carousel_node', path), needle)
    assert line.startswith('carousel_node: error: ')


STARTUP_REFUSED = [   # the same start-up path in-process (cheaper than a process per case)
    ({'terms': ['constant', 'constant']}, 'terms'),
    ({'compass_block_s': 20.0}, 'compass_block_s'),
    ({'q_sigmas': [1e-8, 1e-6, 1e-7]}, 'q_sigmas'),
    ({'prior_sigmas': [3.5e-4, 0.0, 1e-2, 2e-6]}, 'prior_sigmas'),
    ({'scale_factor': True, 'prior_sigmas': [3.5e-4, 1.75e-2, 1e-2, 2e-6]}, 'prior_sigmas'),
    ({'field_norm_min_t': 8e-5, 'field_range_t': 5e-5}, 'field_norm_min_t'),
    ({'arw_rad_sqrt_s': 0.0}, 'arw_rad_sqrt_s'),
    ({'mag_timeout_s': 0.0}, 'mag_timeout_s'),
    ({'max_time_jump_s': 0.0}, 'max_time_jump_s'),
    ({'gyro_range_rad_s': 0.0}, 'gyro_range_rad_s'),
    ({'gate.hysteresis': 0.0}, 'gate.hysteresis'),
    ({'gate.mismatch_window_s': 0.0}, 'gate.mismatch_window_s'),
    ({'gate.dip_tol_rad': 0.0}, 'gate.dip_tol_rad'),
    ({'heading.harmonics': 20}, 'heading.harmonics'),
    ({'heading.reject_steady_rad': 0.0}, 'heading.reject_steady_rad'),
    ({'innovation_windows': 0}, 'innovation_windows'),
    ({'world_frame': 'nwu'}, 'world_frame'),
    ({'tilt_floor_rad': -1.0}, 'tilt_floor_rad'),
    ({'tilt_window_s': 0.0}, 'tilt_window_s'),
]


@pytest.mark.parametrize('params, needle', STARTUP_REFUSED, ids=[n for _, n in STARTUP_REFUSED])
def test_bad_start_values_are_a_parameter_file_error(ros, params, needle):
    with pytest.raises(ParameterFileError) as info:
        make_stkf_node(params)
    assert needle in str(info.value) and '\n' not in str(info.value)

def test_fields_whose_range_ends_at_infinity_accept_inf_as_off(ros):
    unbounded = [s.name for s in all_specs() if s.max_value == math.inf]
    for name in unbounded:
        node = make_stkf_node({name: math.inf})
        value = node.estimator.cfg
        for part in name.split('.'):
            value = getattr(value, part)
        assert value == math.inf
        node.destroy_node()

# ---------------------------------------------------------------- prior_sigmas / q_sigmas
@pytest.fixture
def ros_with_params(tmp_path):
    def start(body: str):
        path = tmp_path / 'params.yaml'
        path.write_text(_params(body))
        rclpy.init(args=['--ros-args', '--params-file', str(path)])
        return make_stkf_node()
    yield start
    rclpy.try_shutdown()


def test_prior_and_q_sigmas_from_a_params_file_reach_the_estimator(ros_with_params):
    node = ros_with_params('prior_sigmas: [1.0e-4, 2.0e-2, 5.0e-3, 1.0e-6]\nq_sigmas: [1, 0, 0, 0]')
    assert node.estimator.cfg.prior_sigmas == (1e-4, 2e-2, 5e-3, 1e-6)
    assert node.estimator.cfg.q_sigmas == (1.0, 0.0, 0.0, 0.0)
    assert all(isinstance(v, float) for v in node.estimator.cfg.q_sigmas)
    np.testing.assert_array_equal(node.estimator.cfg.prior_sigma_values(node.estimator.model), [1e-4, 2e-2, 5e-3, 1e-6])
    node.destroy_node()


def test_unset_sigmas_are_the_terms_defaults_and_readable(ros):
    node = make_stkf_node()
    assert node.estimator.cfg.prior_sigmas is None and node.estimator.cfg.q_sigmas is None
    # every parameter can be read (ros2 param dump asks for all of them at once)
    names = list(node._parameters)  # noqa: SLF001
    assert len(node.get_parameters(names)) == len(names)
    assert node.get_parameter('prior_sigmas').value is None
    result = node.set_parameters([Parameter('prior_sigmas', value=[1e-3, 1e-3, 1e-3, 1e-3])])[0]
    assert not result.successful and 'prior_sigmas' in result.reason   # read-only: shapes the filter
    node.destroy_node()


def test_empty_sigma_list_in_a_params_file_means_unset(ros_with_params):
    node = ros_with_params('prior_sigmas: []')
    assert node.estimator.cfg.prior_sigmas is None
    node.destroy_node()


# ---------------------------------------------------------------- runtime changes
RUNTIME_REFUSED = [
    ('gate.reference_memory_s', 0.0, 'gate.reference_memory_s'),
    ('gate.hysteresis', 5.0, 'gate.hysteresis'),
    ('gate.hysteresis', 0.0, 'gate.hysteresis'),
    ('gate.mismatch_window_s', 0.0, 'gate.mismatch_window_s'),
    ('gate.field_norm_tol', 0.0, 'gate.field_norm_tol'),
    ('gate.dip_tol_rad', 0.0, 'gate.dip_tol_rad'),
    ('gate.mismatch_rad', 0.0, 'gate.mismatch_rad'),
    ('gate.turn_rate_rad_s', 0.0, 'gate.turn_rate_rad_s'),
    ('gate.turn_window_s', 0.0, 'gate.turn_window_s'),
    ('gate.accel_norm_tol_m_s2', 0.0, 'gate.accel_norm_tol_m_s2'),
    ('gate.field_norm_tol', math.nan, 'gate.field_norm_tol'),
    ('gate.mismatch_settle_s', math.inf, 'gate.mismatch_settle_s'),
    ('gate.holdoff_s', -1.0, 'gate.holdoff_s'),
    ('gate.hysteresis', 1, ''),                              # wrong type (rclpy's reason)
    ('window_s', 20.0, 'window_s'),                          # read-only: cannot take effect
    ('prior_sigmas', [1e-3, 1e-3, 1e-3, 1e-3], 'prior_sigmas'),
    ('diagnostics_period_s', 0.0, 'diagnostics_period_s'),
]


@pytest.mark.parametrize('name, value, needle', RUNTIME_REFUSED,
                         ids=[f'{n}={v}' for n, v, _ in RUNTIME_REFUSED])
def test_runtime_change_is_refused_with_a_reason_and_the_node_keeps_running(ros, name, value, needle):
    node = make_stkf_node()
    gate_before = node.estimator.gate.cfg
    value_before = node.get_parameter(name).value
    result = node.set_parameters([Parameter(name, value=value)])[0]
    assert not result.successful and result.reason
    assert needle in result.reason
    assert node.estimator.gate.cfg == gate_before and node.get_parameter(name).value == value_before
    # the node keeps running on the old values
    node.pubs = {**node.pubs, 'imu': Capture(), 'heading': Capture()}
    for chunk in read_chunks(BAGS / 'vehicle_loop', 2.0, streams=['imu', 'mag', 'temperature']):
        node.process_chunk(chunk)
        if chunk.imu is not None and chunk.imu.t[0] > 3.0:
            break
    msgs = node.pubs['imu'].msgs
    assert len(msgs) > 100
    values = [[m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z,
               m.orientation.x, m.orientation.y, m.orientation.z, m.orientation.w] for m in msgs]
    assert np.all(np.isfinite(values))
    headings = [[getattr(m.pose.pose.orientation, c) for c in 'xyzw'] + [m.pose.covariance[35]]
                for m in node.pubs['heading'].msgs]
    assert len(headings) == len(msgs) and np.all(np.isfinite(headings))
    node.destroy_node()


def test_valid_runtime_gate_change_is_accepted_and_applied(ros):
    node = make_stkf_node()
    result = node.set_parameters_atomically([Parameter('gate.hysteresis', value=1.0),
                                             Parameter('gate.field_norm_tol', value=0.05)])
    assert result.successful
    assert node.estimator.gate.cfg.hysteresis == 1.0 and node.estimator.gate.cfg.field_norm_tol == 0.05
    node.destroy_node()


def test_cross_field_runtime_problem_is_found_on_the_whole_config(ros):
    """first_problem with the node's values in force judges the config the change would give."""
    node = make_stkf_node()
    change = [Parameter('gate.mismatch_smooth_s', value=20.0)]   # longer than gate.mismatch_window_s = 10
    reason = first_problem(node._specs, change, node.settings)  # noqa: SLF001
    assert reason and 'gate.mismatch_smooth_s' in reason and 'gate.mismatch_window_s' in reason
    assert first_problem(node._specs, change) is None   # (each value alone is in range)  # noqa: SLF001
    ok = [Parameter('gate.mismatch_smooth_s', value=20.0), Parameter('gate.mismatch_window_s', value=60.0)]
    assert first_problem(node._specs, ok, node.settings) is None  # noqa: SLF001
    node.destroy_node()


def test_cross_field_runtime_change_is_refused_by_the_node(ros):
    node = make_stkf_node()
    result = node.set_parameters([Parameter('gate.mismatch_smooth_s', value=20.0)])[0]
    gate_smooth = node.estimator.gate.cfg.mismatch_smooth_s
    node.destroy_node()
    assert not result.successful and 'gate.mismatch_smooth_s' in result.reason
    assert gate_smooth == 1.0


# ---------------------------------------------------------------- the config checks themselves
@pytest.mark.parametrize('values, needle', [
    ({'terms': ['temperature', 'nope']}, 'nope'),
    ({'terms': []}, 'terms'),
    ({'prior_sigmas': [1e-3]}, 'prior_sigmas'),
    ({'confirm_s': 12.0}, 'confirm_s'),
    ({'gate.hysteresis': 1.5}, 'gate.hysteresis'),
])
def test_config_from_params_refuses_what_the_estimator_cannot_run(values, needle):
    with pytest.raises(ParameterFileError, match=needle.replace('.', r'\.')):
        config_from_params(values)


def test_carousel_config_problems():
    assert CarouselConfig.turntable().problems() == [] and CarouselConfig.wheel().problems() == []
    with pytest.raises(ParameterFileError, match='carousel_to_body'):
        config_from_params({'carousel_to_body': [0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 2.0]},
                           CarouselConfig.turntable())
    with pytest.raises(ParameterFileError, match='flip.axis'):
        config_from_params({'flip.axis': 'z'}, CarouselConfig.turntable())
    cfg = config_from_params({'carousel_to_body': [0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0]},
                             CarouselConfig.turntable())
    assert cfg.carousel_to_body == ((0.0, 1.0, 0.0), (0.0, 0.0, 1.0), (1.0, 0.0, 0.0))


@pytest.mark.parametrize('args, needle', [
    (['--executor', 'fast'], "--executor must be one of single, events, not 'fast'"),
    (['--executor'], '--executor must be one of'),
    (['--verbose'], "unknown argument '--verbose'"),
], ids=['unknown_executor', 'executor_without_value', 'unknown_argument'])
def test_bad_node_arguments_give_one_clear_line_and_exit_2(args, needle):
    """The executable's own arguments (before --ros-args) are checked before rclpy starts."""
    for module, name in (('gyro_thermal_comp.nodes.stkf_node', 'stkf_node'),
                         ('gyro_thermal_comp.nodes.carousel_node', 'carousel_node')):
        proc = subprocess.run([sys.executable, '-m', module, *args, '--ros-args', '-p', 'diagnostics_period_s:=1.0'],
                              capture_output=True, text=True, timeout=60)
        assert _assert_one_error_line(proc, needle).startswith(f'{name}: error: ')


# ---------------------------------------------------------------- renamed parameters
def test_a_params_file_with_renamed_degree_parameters_keeps_its_settings(ros_with_params):
    """A robot's file from before the move to radians: each old name is read as its new one,
    converted, and said in the log."""
    node = ros_with_params('gate.turn_rate_deg_s: 5.0\narw_deg_sqrt_s: 0.1\ntilt_floor_deg: 1')
    cfg = node.estimator.cfg
    assert cfg.gate.turn_rate_rad_s == pytest.approx(math.radians(5.0), rel=1e-15)
    assert cfg.arw_rad_sqrt_s == pytest.approx(math.radians(0.1), rel=1e-15)
    assert node.get_parameter('tilt_floor_rad').value == pytest.approx(math.radians(1.0), rel=1e-15)
    assert node.pipeline.orientation_variance.floors.tilt_rad == pytest.approx(math.radians(1.0), rel=1e-15)
    node.destroy_node()


def test_renamed_parameters_convert_in_scripts_and_refuse_both_names(ros):
    from gyro_thermal_comp.nodes.parameters import RENAMED, config_from_params, renamed_values
    assert all(new.replace('_rad', '_deg') == old and factor == math.pi / 180 for old, (new, factor) in RENAMED.items())
    assert config_from_params({'gate.dip_tol_deg': 2.0}).gate.dip_tol_rad == pytest.approx(math.radians(2.0))
    values, notes = renamed_values({'still_motion_deg': 3.0})
    assert values == {'still_motion_rad': pytest.approx(math.radians(3.0))} and 'still_motion_rad' in notes[0]
    with pytest.raises(ParameterFileError, match='still_motion_rad'):
        renamed_values({'still_motion_deg': 3.0, 'still_motion_rad': 0.05})
    node = make_stkf_node({'compass_deviation_sigma_deg': 6.0})
    assert node.settings['compass_deviation_sigma_rad'] == pytest.approx(math.radians(6.0))
    node.destroy_node()
    from gyro_thermal_comp.nodes.compose import make_carousel_node
    node = make_carousel_node({'gyro_bias_sigma_deg_s': 1.0})
    assert node.settings['gyro_bias_sigma_rad_s'] == pytest.approx(math.radians(1.0))
    node.destroy_node()
