"""ROS parameters of the nodes, derived from their config dataclasses so the two cannot drift apart.

Every config field is a parameter (nested configs as `gate.*`, `heading.*`, `flip.*`); `None` is
spelled NaN for numbers and an unset (empty) array for lists. Only the gate thresholds and the
node's periods may change at run time; everything that shapes the filter's state is read-only.

Each number has an allowed range, kept in one table per config (`_RANGES`, `_CAROUSEL_RANGES`; a
test keeps them complete). ROS ranges are inclusive, so a strict bound (`above(0, ...)`: 0 would
divide by zero or stick a test shut) is declared inclusive and enforced by `check_value`, which runs
on every value at start (`declare_parameters`) and on every runtime change (`first_problem`).
What can only be judged on the whole config (confirm_s < window_s, known drift-model terms, one
prior sigma per term, ...) is `config_problems`, run by `config_from_params` and, for a runtime
change, by `first_problem` on the config the change would give.
"""
from __future__ import annotations

import array
import inspect
import math
import re
from dataclasses import dataclass, fields, is_dataclass, replace
from functools import lru_cache
from typing import Any, NamedTuple

from ..carousel.config import CarouselConfig
from ..thermal.drift_model import BUILTIN_TERMS
from ..thermal.estimator import EstimatorConfig


class ParameterFileError(ValueError):
    """A parameter file with unknown keys, wrong types, out-of-range or inconsistent values: one line
    at start-up (exit 2), never a traceback."""


@dataclass(frozen=True)
class ParamSpec:
    name: str
    default: Any
    description: str
    read_only: bool = True
    min_value: float | None = None
    max_value: float | None = None
    min_exclusive: bool = False   # the range is (min, max]: enforced by check_value (ROS ranges are inclusive)
    unset_array: bool = False     # a list of numbers that may stay unset (None in the config)
    example: Any = None           # shown, commented out, in the generated parameter file
    choices: tuple = ()           # a string parameter: the values allowed


class Range(NamedTuple):
    lo: float
    hi: float
    lo_open: bool = False

    def __str__(self) -> str:
        return f"{'(' if self.lo_open else '['}{_num(self.lo)}, {_num(self.hi)}]"


def _num(v: float) -> str:
    return str(int(v)) if float(v).is_integer() and abs(v) < 1e12 else f'{v:g}'


def closed(lo: float, hi: float) -> Range:
    """lo <= value <= hi."""
    return Range(float(lo), float(hi))


def above(lo: float, hi: float) -> Range:
    """lo < value <= hi (typically lo = 0: zero would divide by zero or stick a test shut)."""
    return Range(float(lo), float(hi), True)


def count(lo: int, hi: int) -> Range:
    """An integer lo <= value <= hi."""
    return Range(int(lo), int(hi))


_DAY_S = 86400.0
_PI = math.pi

# How a node takes its inputs and names its hardware (both nodes).
INPUT_PARAMS = (
    ParamSpec('input_queue_depth', 1000, 'subscription queue depth, messages', True, 5, 100000),
    ParamSpec('reliable_inputs', False, 'subscribe with reliable QoS (lossless when the publisher is reliable; a '
              'best-effort driver is then not matched). Default: best effort, which matches every driver', True),
    ParamSpec('max_latency_s', 2.0, 'a silent topic holds the others back at most this long (> the slowest '
              'topic period, e.g. 1 Hz temperature), s', True, 0.01, 60.0),
    ParamSpec('first_sample_wait_s', 0.25, 'a topic whose period is not known yet (no or one sample) is waited for '
              'this long behind the others (cross-topic delivery delay), not until its next sample, s', True,
              0.0, 60.0),
    ParamSpec('hardware_id', '', 'diagnostics hardware_id; empty = the frame_id of the first IMU message '
              "('imu' before one)"),
)

# Queue of the STKF node's per-sample outputs and how long a stopping node waits for them to be delivered.
OUTPUT_QUEUE_DEPTH = 200        # imu/data, imu/heading: 4 s of a 50 Hz IMU a reliable subscriber may lag
DELIVERY_WAIT_S = 5.0           # a stopping node waits this long for its reliable subscribers' acknowledgements

# Frames and covariances of the STKF node's outputs.
OUTPUT_PARAMS = (
    ParamSpec('output_queue_depth', OUTPUT_QUEUE_DEPTH, 'publisher queue depth of imu/data and imu/heading (reliable, '
              'keep last): outputs a reliable subscriber may lag behind before the oldest is overwritten, '
              'messages', True, 10, 100000),
    ParamSpec('stop_delivery_wait_s', DELIVERY_WAIT_S, 'on a stop, how long the node waits for its reliable '
              'subscribers to acknowledge its last outputs (what is unacknowledged when the process exits is '
              'lost), s', True, 0.0, 600.0),
    ParamSpec('world_frame', 'enu', "world frame of the published orientation (REP 103): 'enu' (yaw CCW from "
              "east) or 'ned' (as imu_filter_madgwick: yaw clockwise from north, a level imu_link has roll pi)",
              choices=('enu', 'ned')),
    ParamSpec('fixed_frame', 'odom', 'frame_id of imu/heading and parent frame of the TF (use a *_ned name with '
              'world_frame ned, REP 103)'),
    ParamSpec('publish_tf', False, 'broadcast fixed_frame -> IMU frame (rotation only) on /tf, one per output '
              '(needs tf2_msgs: a ROS install)'),
    ParamSpec('tilt_floor_rad', math.radians(0.5), 'roll/pitch 1-sigma no averaging removes: accelerometer '
              'zero-g offset (1 mg = 0.001 rad) and axis misalignment; MEMS AHRS datasheets: 0.5 deg RMS static, rad',
              True, 0.0, math.pi / 4),
    ParamSpec('compass_deviation_sigma_rad', math.radians(3.0), 'yaw 1-sigma of the compass deviation left at the '
              'start heading (hard/soft iron after calibration; the heading filter learns only how it changes with '
              'heading). AHRS datasheets: 2 deg RMS in a clean field; 3 deg for a vehicle. Uncalibrated: raise it, rad',
              True, 0.0, math.pi),
    ParamSpec('declination_sigma_rad', math.nan, 'yaw 1-sigma of declination_rad; unset: 0.5 deg (a field-model '
              'value) if declination_rad is set, 10 deg if it is left at 0 (the local declination unknown), rad',
              True, 0.0, math.pi),
)

# Node-level settings of the STKF node (not the estimator's).
NODE_PARAMS = (
    ParamSpec('state_file', '', 'learned a/b/c + covariance file; empty = no persistence'),
    ParamSpec('drift_model_file', '', 'drift model YAML (`gyro-thermal-comp discover BAG --write-model FILE`): '
              'its terms, derived inputs (die-temperature lag, heating/cooling branch) and priors replace terms, '
              'prior_sigmas, q_sigmas and temperature_ref_c; empty = the built-in model'),
    ParamSpec('temperature_sensor', True, 'the IMU publishes its gyro temperature on imu/temperature. false: '
              'declared absent, the node learns the constant drift only and its diagnostics say so as designed '
              '(OK), not as a missing input (WARN)'),
    ParamSpec('state_save_period_s', 60.0, 'how often the state file is rewritten, s', False, 1.0, 86400.0),
    ParamSpec('diagnostics_period_s', 1.0, 'diagnostics publication period, s', False, 0.1, 60.0),
    ParamSpec('process_period_s', 0.1, 'the estimator runs on the buffered inputs this often, s (imu/data does '
              'not wait for it: it needs output_delay_s > this + the slowest input period)', True, 0.0005, 0.5),
    ParamSpec('output_delay_s', 1.0, 'a model update or compass correction stamped t compensates the IMU samples '
              'from t + this on (thermal/fast_path.py); each IMU output is published on arrival as long as the '
              'estimator lags less than this: more than the slowest input period plus transport, s',
              True, 0.05, 30.0),
    *INPUT_PARAMS,
    ParamSpec('buffer_max_samples', 200000, 'bound of the stamp-ordering buffer, samples', True, 1000, 10_000_000),
    ParamSpec('accel_noise_density_m_s2_rthz', 110e-6 * 9.80665, 'accelerometer noise density for covariances, m/s^2/sqrt(Hz)',
              True, 0.0, 0.1),
    *OUTPUT_PARAMS,
)

# Estimator fields with a human description. Fields not listed here are described by their comment
# in the dataclass; a test keeps every description meaningful.
_DOCS = {
    'name': 'method name in reports',
    'terms': 'drift-model terms, at least one, of the built-in ' + ', '.join(BUILTIN_TERMS)
             + ' (thermal_branch needs a drift model file: its branch inputs)',
    'scale_factor': 'also learn a temperature-dependent scale factor k(T) on rotating segments',
    'temperature_ref_c': 'reference temperature of the model, degC',
    'learn': 'false: keep the parameters fixed (replay of a calibration)',
    'window_s': 'STKF update interval = drift-measurement window, s',
    'fading_s': 'fading-memory factor s >= 1 per update (1 = plain Kalman filter)',
    'adaptive_fading': "Zhou's adaptive strong-tracking factor on top of s",
    'prior_sigmas': 'prior 1-sigma per drift-model term, SI, one per term in the order of terms (then '
                    "rate_temperature, rate with scale_factor); unset = the terms' defaults",
    'q_sigmas': 'random walk per sqrt(s) per drift-model term, SI, one per term as prior_sigmas; unset = the '
                "terms' defaults",
    'diverged_nis': 'mean innovation^2/variance over the last 30 windows beyond this: diverged, back to the '
                    'last good parameters (inf = off)',
    'arw_rad_sqrt_s': 'gyro angle random walk (noise density), rad/sqrt(s) (datasheets: deg/sqrt(h); '
                      '1 deg/sqrt(h) = 2.909e-4 rad/sqrt(s))',
    'latitude_deg': 'latitude for Earth-rate removal, deg; NaN = unknown (absorbed in c)',
    'declination_rad': 'magnetic declination (east positive), rad',
    'still_period_s': 'the unit is assumed motionless this long after start, s',
    'max_gap_s': 'IMU stamps further apart than this are a time gap, s',
    'compass_sigma_default_rad': 'compass noise 1-sigma used until the still period has measured it, rad',
    'tilt_window_s': 'roll/pitch = direction of the mean specific force over this long (turning samples left out), '
                     'so a car\'s acceleration and braking average out; not a real-time attitude, s',
    'gate.mismatch_noise_sigma': "the bend threshold is at least this many sigma of the bend's own noise "
                                 '(smoothed compass noise, angle random walk)',
    'heading.reject_max_s': 'a compass disagreeing this long and steadily (within heading.reject_steady_rad of a '
                            'line in time) is accepted and the filter re-converges, s',
    'heading.reject_steady_rad': 'how straight a disagreement must be to count as steady (heading.reject_max_s), rad',
    # carousel fields without a comment of their own
    'min_samples_per_revolution': 'a revolution with fewer IMU samples is not averaged (pass-through)',
    'flip.enabled': 'a flip mechanism with an auxiliary IMU is fitted',
}

# Angles are in radians (SI, REP 103) in every parameter; latitude_deg alone keeps degrees, the unit
# of geographic coordinates in ROS (sensor_msgs/NavSatFix). Parameters renamed for this: old name ->
# (new name, factor new/old). A robot's file that sets an old name keeps its value, converted, and
# the node says so once (`renamed_values`).
RENAMED = {old: (old.replace('_deg', '_rad'), math.pi / 180.0) for old in (
    'arw_deg_sqrt_s', 'compass_sigma_deg', 'compass_sigma_floor_deg', 'compass_sigma_default_deg',
    'still_motion_deg', 'gate.dip_tc_prior_deg', 'gate.dip_tol_deg', 'gate.mismatch_deg', 'gate.mismatch_drift_deg_s',
    'gate.mismatch_line_rms_deg', 'gate.turn_rate_deg_s', 'tilt_floor_deg', 'compass_deviation_sigma_deg',
    'declination_sigma_deg', 'gyro_bias_sigma_deg_s', 'gyro_noise_density_deg_s_rthz')}


def renamed_values(values: dict) -> tuple[dict, list[str]]:
    """`values` (name -> value) with every old name of RENAMED under its new name, converted; and
    one line per conversion for the log. Both names set: ParameterFileError (which one is meant?)."""
    out, notes = dict(values), []
    for old, (new, factor) in RENAMED.items():
        if old not in out:
            continue
        if new in out:
            raise ParameterFileError(f'parameter {old} is the old name of {new}: set only {new}')
        value = out.pop(old)
        out[new] = value * factor if _is_number(value) else value
        notes.append(f'parameter {old} is deprecated: read as {new} = {out[new]:.6g} (set {new} instead)')
    return out, notes


# Parameters that no longer exist, with why: a robot's file that still sets one keeps working (the
# node says so once and ignores it) instead of stopping on an unknown key.
RETIRED = {
    'coast_shrink': 'the drift change while coasting is weighed by one rule that is always on '
                    '(thermal/coasting.py)',
}

# Allowed range of every numeric field of EstimatorConfig (with gate.* and heading.*), from what the
# code does with it. Strict lower bounds (`above`) where 0 divides by zero, silently disables what
# the field is for, or sticks a test (gate, innovation test, stream guard) shut or open for ever.
_RANGES: dict[str, Range] = {
    # drift model
    'temperature_ref_c': closed(-60, 150),
    # parameter learning
    'window_s': closed(1, 600),
    'edge_s': closed(0, 300),                       # <= window_s / 2 (config_problems)
    'confirm_s': closed(0, 600),                    # < window_s (config_problems)
    'fading_s': closed(1, 2),                       # StrongTrackingKF refuses s < 1
    'r_floor_rad_s': closed(0, 0.1),
    'reject_sigma': above(0, 100),                  # 0 would refuse every window
    'innovation_windows': count(1, 10000),          # 10000 windows of 10 s: a day
    'diverged_nis': above(2, math.inf),             # consistent: mean NIS 1, 'good' <= 2; inf = off
    # sensors
    'arw_rad_sqrt_s': above(0, math.radians(10)),   # every gyro has noise; 0 makes every allowance zero
    'latitude_deg': closed(-90, 90),
    'temp_window_s': above(0, 3600),                # regression window: 0 raises
    'temp_stuck_s': above(0, 30 * _DAY_S),          # 0 flags every unchanged reading as stuck
    'temp_hold_max_s': closed(0, 3600),
    'declination_rad': closed(-_PI, _PI),
    'compass_block_s': above(0, 60),                # 0 divides by zero; <= window_s (config_problems)
    'reopen_probation_s': closed(0, 3600),          # 0: only confirm_s is undone
    'compass_sigma_rad': above(0, _PI / 2),         # NaN = learned; 0 would silently mean the default
    'compass_sigma_floor_rad': above(0, _PI / 2),   # a zero compass variance is an infinite weight
    'compass_sigma_default_rad': above(0, _PI / 2),
    'mag_timeout_s': above(0, 3600),                # 0: no compass between samples, gate shut
    'tilt_window_s': above(0, 3600),                # 0: no mean (one bin)
    # input plausibility
    'gyro_range_rad_s': above(0, 100),              # 0 drops every sample; MEMS full scales end at 70
    'accel_range_m_s2': above(0, 4000),             # 400 g: high-g MEMS parts
    'field_range_t': above(0, 0.01),                # 100 gauss: beyond any MEMS magnetometer
    'field_norm_min_t': closed(0, 1e-4),            # < field_range_t (config_problems)
    'temperature_min_c': closed(-100, 300),         # < temperature_max_c (config_problems)
    'temperature_max_c': closed(-100, 300),
    'temperature_max_rate_c_s': closed(0, 100),
    'temperature_timeout_s': above(0, 3600),        # 0: every reading stale at once, no learning
    'temperature_drift_c_s': closed(0, 10),
    'max_time_jump_s': above(0, _DAY_S),            # 0: every stamp step is a jump
    'time_jump_confirm_samples': count(1, 1000),
    # start, gaps
    'still_period_s': closed(0, 3600),
    'still_motion_rad': above(0, 2 * _PI),          # 0: gyro noise ends the still period at once
    'max_gap_s': closed(0.001, 60),
    'gap_rate_sigma_rad_s': closed(0, 10),
    # magnetic gate (runtime): a zero threshold divides by zero or keeps its test active for ever
    'gate.reference_memory_s': above(0, 30 * _DAY_S),
    'gate.reference_relearn_s': closed(0, 3600),
    'gate.norm_tc_prior': closed(0, 0.1),
    'gate.dip_tc_prior_rad': closed(0, math.radians(10)),
    'gate.field_norm_tol': above(0, 1),
    'gate.dip_tol_rad': above(0, _PI / 2),
    'gate.mismatch_rad': above(0, _PI),
    'gate.mismatch_window_s': above(0, 3600),       # 0: no second difference, test silently off
    'gate.mismatch_smooth_s': closed(0, 3600),      # < mismatch_window_s (config_problems)
    'gate.mismatch_sigma': closed(0, 20),           # sigmas
    'gate.mismatch_noise_sigma': closed(0, 20),
    'gate.mismatch_drift_rad_s': closed(0, math.radians(10)),
    'gate.mismatch_settle_s': closed(0, 3600),
    'gate.mismatch_max_s': closed(0, _DAY_S),
    'gate.mismatch_line_s': closed(0, 3600),        # 0: no drift-line test
    'gate.mismatch_line_rms_rad': above(0, _PI),
    'gate.turn_rate_rad_s': above(0, math.radians(2000)),   # a gyro's full scale
    'gate.turn_window_s': above(0, 600),            # 0: the turn rate is never measured
    'gate.accel_norm_tol_m_s2': above(0, 50),
    'gate.hysteresis': above(0, 1),                 # a fraction of the threshold; 0: never reopens
    'gate.holdoff_s': closed(0, 3600),
    # output heading filter
    'heading.harmonics': count(0, 8),
    'heading.deviation_sigma_rad': closed(0, _PI),
    'heading.deviation_q_rad2_s': closed(0, 0.01),
    'heading.scale_factor_prior': closed(0, 0.5),
    'heading.scale_factor_sigma': closed(0, 0.5),
    'heading.min_turn_rad': above(0, _PI),          # 0: every step is a turn
    'heading.max_slew_rad_s': closed(0, 10),        # 0 = no limit
    'heading.settle_s': closed(0, 3600),            # 0: max_slew_rad_s alone
    'heading.align_s': closed(0, 3600),             # 0: the slew limit from the first sample
    'heading.norm_offset_sigma': closed(0, 10),
    'heading.norm_offset_q_s': closed(0, 0.01),
    'heading.reject_sigma': closed(0, 100),         # 0 = no innovation test
    'heading.reject_max_s': closed(0, 3600),
    'heading.reject_steady_rad': above(0, _PI),     # 0: a steady disagreement is never accepted
}
# Elements of the per-term lists (units differ per term; only the sign and finiteness are physics).
_ARRAY_RANGES: dict[str, Range] = {
    'prior_sigmas': above(0, 1e3),                  # a zero prior pins a term for ever
    'q_sigmas': closed(0, 1e3),
}

# Allowed range of every numeric field of CarouselConfig (with flip.*).
_CAROUSEL_RANGES: dict[str, Range] = {
    'boundary_phase_rad': closed(-2 * _PI, 2 * _PI),
    'initial_angle_rad': closed(-2 * _PI, 2 * _PI),
    'encoder_timeout_s': closed(0, 60),
    'encoder_max_gap_s': above(0, 10),              # 0: the encoder is never interpolated
    'max_revolution_period_s': above(0, 3600),      # 2 pi / it is the slowest spin
    'min_samples_per_revolution': count(3, 10_000_000),  # fewer cannot average a sinusoid out
    'max_rate_deviation': above(0, 1),              # 0: no real revolution is valid
    'pass_through_period_s': above(0, 3600),
    'max_gap_s': above(0, 60),                      # 0: every sample is a gap
    'nominal_spin_rate_rad_s': above(0, 1000),      # NaN = unknown
    'gyro_spin_window_s': above(0, 600),            # 0: no spin rate is ever measured
    'still_rate_rad_s': above(0, 10),               # 0: nothing is ever still
    'still_accel_tol_m_s2': above(0, 100),          # 0: no still start is ever accepted
    'angle_ref_min_inplane_m_s2': above(0, 100),    # 0: noise alone would steer the angle
    'angle_ref_gyro_noise_rad_s_rthz': above(0, 1),  # 0: the filter would stop listening
    'angle_ref_bias_sigma_rad_s': above(0, 10),     # a zero prior pins the bias at 0
    'angle_ref_scale_sigma': closed(0, 0.5),
    'angle_ref_bias_walk_rad_s_rts': closed(0, 1),
    'angle_ref_floor_rad': above(0, 1),             # 0: a noise-free revolution gets infinite weight
    'angle_ref_gate_sigma': above(0, 100),          # 0 would reject every measurement
    'mag_ref_inplane_tol': above(0, 1),             # 0: every revolution is refused
    'mag_ref_axial_tol': above(0, 1),
    'wheel_radius_m': above(0, 5),                  # NaN = not a wheel
    'wheel_radius_sigma': closed(0, 0.5),           # 0: the radius as given
    'spin_coupling_sigma': above(0, 1),             # a zero prior pins k at 0
    'spin_coupling_rest_sigma_rad_s': above(0, 1),  # 0: never used
    'spin_coupling_bias_walk_rad_s_rts': closed(0, 1),
    'lockin_revolutions': count(1, 1000),
    'lockin_poly_order': count(0, 2),
    'lockin_max_span_s': above(0, _DAY_S),
    'measurement_poly_order': count(0, 1),
    'bias_variance_floor': closed(0, 1),
    'temperature_rate_window_s': above(0, _DAY_S),  # regression window: 0 raises
    'max_block_samples': count(1, 100_000_000),
    'min_batch_s': closed(0, 60),
    'flip.initial_position': count(0, 3),           # quarter turns
    'flip.rate_threshold_rad_s': above(0, 100),     # 0: noise reads as flipping
    'flip.guard_s': closed(0, 60),
    'flip.max_angle_error_rad': above(0, _PI / 4),
    'flip.aux_timeout_s': closed(0, 60),
    'flip.aux_max_gap_s': above(0, 10),
    'flip.aux_calibration_tau_s': above(0, 30 * _DAY_S),   # divides
}

_RANGE_TABLES = {EstimatorConfig: _RANGES, CarouselConfig: _CAROUSEL_RANGES}
_RUNTIME_PREFIXES = ('gate.',)  # safe to change live: ThermalDriftEstimator.set_gate_config rebuilds what follows


def range_table(config_cls) -> dict[str, Range]:
    """The range table of a config class (empty for one without)."""
    return _RANGE_TABLES.get(config_cls, {})


@lru_cache(maxsize=None)
def _field_comments(cls) -> dict[str, str]:
    """`name: type = default  # comment` lines of a config dataclass -> {name: comment}."""
    comments = {}
    for line in inspect.getsource(cls).splitlines():
        m = re.match(r'\s+(\w+):[^#]*#\s*(.+)$', line)
        if m:
            comments[m.group(1)] = m.group(2).strip()
    return comments


def _describe(cfg_cls, name: str, key: str) -> str:
    return _DOCS.get(key) or _field_comments(cfg_cls).get(name) or f'{cfg_cls.__name__}.{name}'


def _parameter_fields(cfg) -> list:
    """The config's fields that are node parameters (not those a node sets from a file it loads,
    metadata parameter=False: the drift model file)."""
    return [f for f in fields(cfg) if f.metadata.get('parameter', True)]


def _flatten(cfg, prefix: str = '') -> dict[str, tuple[Any, str]]:
    """Nested config -> {'gate.field': (value, description)}."""
    out = {}
    for f in _parameter_fields(cfg):
        value, key = getattr(cfg, f.name), prefix + f.name
        if is_dataclass(value):
            out.update(_flatten(value, key + '.'))
        else:
            out[key] = (value, _describe(type(cfg), f.name, key))
    return out


def _to_ros(value):
    """Config value -> a value ROS parameters can hold (tuples -> lists, 3x3 -> 9 numbers)."""
    if isinstance(value, tuple):
        return [float(v) for row in value for v in row] if value and isinstance(value[0], tuple) else list(value)
    return value


def _optional_fields(cfg, prefix: str = '') -> dict[str, str]:
    """Fields that may be None: {'name': 'number' (`float | None`, spelled NaN) or 'array' (a tuple)}."""
    out = {}
    for f in _parameter_fields(cfg):
        value = getattr(cfg, f.name)
        if is_dataclass(value):
            out.update(_optional_fields(value, f'{prefix}{f.name}.'))
        elif 'float | None' in str(f.type):
            out[prefix + f.name] = 'number'
        elif 'None' in str(f.type):
            out[prefix + f.name] = 'array'
    return out


def _optional_numbers(cfg) -> set[str]:
    return {k for k, v in _optional_fields(cfg).items() if v == 'number'}


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def config_specs(base, *, ranges=None, runtime_prefixes=()) -> tuple[ParamSpec, ...]:
    """One ParamSpec per (flattened) field of a config dataclass instance; numbers get their range
    from `ranges` (default: the table of the config's class)."""
    ranges = range_table(type(base)) if ranges is None else ranges
    optional = _optional_fields(base)
    specs = []
    for name, (value, description) in _flatten(base).items():
        rng = ranges.get(name) if (_is_number(value) or optional.get(name) == 'number') else None
        if rng is None and optional.get(name) == 'array':
            rng = _ARRAY_RANGES.get(name)
        lo, hi, lo_open = (None, None, False) if rng is None else Range(*rng)
        unset_array = optional.get(name) == 'array'
        if value is None:
            value = math.nan if optional.get(name) == 'number' else []
        specs.append(ParamSpec(name, _to_ros(value), description, not name.startswith(runtime_prefixes),
                               lo, hi, lo_open, unset_array))
    return tuple(specs)


def estimator_specs(base: EstimatorConfig = EstimatorConfig()) -> tuple[ParamSpec, ...]:
    specs = config_specs(base, ranges=_RANGES, runtime_prefixes=_RUNTIME_PREFIXES)
    model = base.model()
    examples = {'prior_sigmas': model.prior_sigmas(), 'q_sigmas': model.q_sigmas()}
    return tuple(replace(s, example=[float(v) for v in examples[s.name]]) if s.name in examples else s
                 for s in specs)


def all_specs() -> tuple[ParamSpec, ...]:
    return NODE_PARAMS + estimator_specs()


def allowed_range(spec: ParamSpec) -> str | None:
    """'(0, 600]' etc., or None for a parameter without a range."""
    if spec.min_value is None:
        return None
    return str(Range(spec.min_value, spec.max_value, spec.min_exclusive))


def _outside(spec: ParamSpec, value) -> bool:
    lo, hi = spec.min_value, spec.max_value
    return not (lo < value <= hi if spec.min_exclusive else lo <= value <= hi)


def check_value(spec: ParamSpec, value) -> str | None:
    """Why `value` is not acceptable for `spec` (one sentence naming the parameter and what is
    allowed), or None."""
    name = spec.name
    unset_ok = spec.unset_array or (isinstance(spec.default, float) and math.isnan(spec.default))
    if value is None:   # an empty list in a params file reads as "not set"
        if unset_ok:
            return None
        return f'{name} must not be empty' if isinstance(spec.default, list) else f'{name} must be set'
    if isinstance(spec.default, bool) or isinstance(value, bool):
        return None if isinstance(value, bool) == isinstance(spec.default, bool) else f'{name} must be a bool'
    if spec.choices and value not in spec.choices:
        return f"{name} must be one of {', '.join(map(repr, spec.choices))}, not {value!r}"
    if spec.unset_array:
        if not isinstance(value, (list, tuple, array.array)) or not all(_is_number(v) for v in value):
            return f'{name} must be a list of numbers'
        for v in value:
            if math.isnan(v) or (spec.min_value is not None and _outside(spec, v)):
                return f'{name}: every value must be in {allowed_range(spec) or "the finite numbers"}, not {v!r}'
        return None
    if _is_number(value):
        if math.isnan(value):
            return None if unset_ok else f'{name} must be a number, not NaN'
        if spec.min_value is not None and _outside(spec, value):
            return f'{name} = {value!r} is outside the allowed range {allowed_range(spec)}'
        if spec.min_value is None and math.isinf(value):   # (a range ending at inf allows it: "inf = off")
            return f'{name} must be finite, not {value!r}'
    return None


def config_problems(cfg) -> list[str]:
    """What makes a whole config unusable (one sentence per problem, naming the parameters): the
    config's own `problems()` (cross-field consistency: confirm_s < window_s, known and distinct
    drift-model terms, one prior sigma per term, a rotation matrix, ...) and anything its drift model
    refuses."""
    try:
        out = list(cfg.problems()) if hasattr(cfg, 'problems') else []
    except (TypeError, ValueError, KeyError, AttributeError) as exc:
        return [f'inconsistent parameters: {exc}']
    if not out and hasattr(cfg, 'model'):
        try:
            cfg.model()
        except (TypeError, ValueError, KeyError) as exc:
            out.append(f'terms: {exc}')
    return out


def config_from_params(values: dict[str, Any], base=None, *, check: bool = True):
    """Flat parameter values -> a config like `base` (default EstimatorConfig()): NaN/unset -> None,
    lists -> tuples, 9 numbers -> 3x3 where the field is a matrix. With `check` (the default) a
    config the code cannot run with raises ParameterFileError (one line naming the parameter) instead
    of failing later, inside the estimator or at run time."""
    base = base if base is not None else EstimatorConfig()
    optional = _optional_numbers(base)
    values = renamed_values(values)[0]

    def build(cfg, prefix=''):
        changes = {}
        for f in _parameter_fields(cfg):
            current = getattr(cfg, f.name)
            if is_dataclass(current):
                changes[f.name] = build(current, f'{prefix}{f.name}.')
                continue
            key = prefix + f.name
            if key not in values:
                continue
            v = values[key]
            if isinstance(v, float) and math.isnan(v) and key in optional:
                v = None
            elif isinstance(v, (list, tuple, array.array)) and current and isinstance(current, tuple) \
                    and isinstance(current[0], tuple):
                v = tuple(tuple(float(x) for x in v[i:i + 3]) for i in range(0, len(v), 3))
            elif isinstance(v, (list, tuple, array.array)):
                v = tuple(float(x) if _is_number(x) else x for x in v) if len(v) else (None if current is None else ())
            elif isinstance(current, float) and _is_number(v):
                v = float(v)
            changes[f.name] = v
        return replace(cfg, **changes)
    try:
        cfg = build(base)
    except (TypeError, ValueError) as exc:    # the config's own __post_init__ checks
        if not check:
            raise
        raise ParameterFileError(f'inconsistent parameters: {exc}') from None
    if check:
        problems = config_problems(cfg)
        if problems:
            raise ParameterFileError(problems[0])
    return cfg


# stkf_node's parameter file, in the order a robot team reads it: what they set, then each group of
# the rest with what it tunes. Every parameter sits in exactly one group (a test holds it).
STKF_FILE_SECTIONS = (
    ('Set these for your robot', ('state_file', 'drift_model_file', 'temperature_sensor', 'declination_rad',
                                  'latitude_deg', 'still_period_s', 'arw_rad_sqrt_s', 'gyro_range_rad_s',
                                  'compass_deviation_sigma_rad', 'world_frame', 'fixed_frame', 'publish_tf',
                                  'reliable_inputs')),
    ('Advanced, the node: how inputs are ordered and outputs sent, queues, state and diagnostics periods',
     ('state_save_period_s', 'diagnostics_period_s', 'process_period_s', 'output_delay_s', 'input_queue_depth',
      'max_latency_s', 'first_sample_wait_s', 'hardware_id', 'buffer_max_samples', 'output_queue_depth',
      'stop_delivery_wait_s', 'name')),
    ('Advanced, covariances: the floors and noise behind the published roll, pitch and yaw sigmas',
     ('tilt_floor_rad', 'declination_sigma_rad', 'accel_noise_density_m_s2_rthz', 'tilt_window_s')),
    ('Advanced, the drift model and its learning (STKF)',
     ('terms', 'scale_factor', 'temperature_ref_c', 'learn', 'window_s', 'edge_s', 'confirm_s', 'fading_s',
      'adaptive_fading', 'prior_sigmas', 'q_sigmas', 'coast_backtest', 'r_floor_rad_s', 'reject_sigma',
      'innovation_windows', 'adaptive_r', 'diverged_nis')),
    ('Advanced, the inputs: what is a sensor fault (dropped and counted) and how the temperature is read',
     ('accel_range_m_s2', 'field_range_t', 'field_norm_min_t', 'temperature_min_c', 'temperature_max_c',
      'temperature_max_rate_c_s', 'temperature_timeout_s', 'temperature_drift_c_s', 'max_time_jump_s',
      'time_jump_confirm_samples', 'temp_window_s', 'temp_stuck_s', 'temp_hold_max_s')),
    ('Advanced, the start, gaps and the compass', ('still_motion_rad', 'max_gap_s', 'gap_rate_sigma_rad_s',
                                                   'heading_correction', 'compass_block_s', 'reopen_probation_s',
                                                   'compass_sigma_rad', 'compass_sigma_floor_rad',
                                                   'compass_sigma_default_rad', 'mag_timeout_s')),
    ('Advanced, the magnetic gate: when the field is trusted', 'gate.'),
    ('Advanced, the output heading filter: compass deviation, scale factor, slew', 'heading.'),
)


def file_sections(specs, sections) -> list[tuple[str, list]]:
    """`specs` grouped as `sections` ((title, names or a name prefix), ...) lays them out; KeyError
    naming a spec no section holds, or one two sections hold."""
    out, placed = [], set()
    for title, members in sections:
        chosen = [sp for sp in specs if (sp.name.startswith(members) if isinstance(members, str)
                                          else sp.name in members)]
        if isinstance(members, tuple):
            chosen.sort(key=lambda sp: members.index(sp.name))
        twice = placed.intersection(sp.name for sp in chosen)
        if twice:
            raise KeyError(f'parameters in two file sections: {sorted(twice)}')
        placed.update(sp.name for sp in chosen)
        out.append((title, chosen))
    missing = [sp.name for sp in specs if sp.name not in placed]
    if missing:
        raise KeyError(f'parameters in no file section: {missing}')
    return out


def params_yaml(node_name: str, specs, executable: str, file_name: str, sections=None) -> str:
    """A default parameter file (config/*.yaml), generated from the specs; grouped as `sections`
    lays them out (file_sections), else in the specs' order."""
    lines = [f'# Parameters of {executable} (node {node_name}): the defaults, generated from the code',
             '# (regenerate: gyro-thermal-comp params --write config/).',
             f'# Use: ros2 run gyro_thermal_comp {executable} --ros-args --params-file config/{file_name}',
             '# Ranges: [lo, hi] includes lo, (lo, hi] excludes it; [runtime]: may be changed while running.',
             f'# /**/{node_name}: this node in any namespace (a bare `{node_name}:` is the root namespace only).',
             f'/**/{node_name}:', '  ros__parameters:']
    groups = file_sections(specs, sections) if sections else [(None, list(specs))]
    for title, group in groups:
        if title:
            lines.append(f'    # ---- {title}')
        lines += [_param_line(spec) for spec in group]
    return '\n'.join(lines) + '\n'


def _param_line(spec) -> str:
    """One parameter's line: its default, description, range and whether it changes at run time."""
    value = spec.default
    rng = allowed_range(spec)
    tags = ('' if rng is None else f', range {rng}') + ('' if spec.read_only else ' [runtime]')
    if isinstance(value, float) and math.isnan(value):
        return f'    # {spec.name}: .nan   # {spec.description} (unset = unknown){tags}'
    if isinstance(value, list) and not value:
        shown = _yaml_value(spec.example) if spec.example else '[]'
        return f'    # {spec.name}: {shown}   # {spec.description}{tags}'
    return f'    {spec.name}: {_yaml_value(value)}   # {spec.description}{_in_degrees(spec.name, value)}{tags}'


# an angle parameter's unit after `_rad` -> the same unit in degrees, for the parameter file's reader
_DEGREE_UNITS = {'': 'deg', '_s': 'deg/s', '_sqrt_s': 'deg/sqrt(s)', '_s_rthz': 'deg/s/sqrt(Hz)',
                 '_s_rts': 'deg/s/sqrt(s)'}


def _in_degrees(name: str, value) -> str:
    """' (= 0.5 deg)' after an angle's description: the default as most datasheets state it."""
    unit = _DEGREE_UNITS.get(name.rpartition('_rad')[2]) if '_rad' in name else None
    if unit is None or not isinstance(value, float) or not math.isfinite(value) or value == 0.0:
        return ''
    return f' (= {math.degrees(value):.4g} {unit})'


def _yaml_value(value) -> str:
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, float):
        mantissa, e, exponent = repr(value).partition('e')
        if '.' not in mantissa and mantissa.lstrip('-').isdigit():
            mantissa += '.0'  # YAML 1.1 (and the ROS parser) read 2e-05 as a string
        return mantissa + e + exponent
    if isinstance(value, str):
        return f"'{value}'"
    if isinstance(value, list):
        return '[' + ', '.join(_yaml_value(v) for v in value) + ']'
    return str(value)


def with_model_file(cfg, path: str):
    """`cfg` running the drift model file at `path` ('' = unchanged); ParameterFileError (one line
    naming the parameter and what is wrong with the file) if it cannot be used."""
    if not path:
        return cfg
    from ..thermal.model_file import DriftModelFile
    try:
        return replace(cfg, drift_model_file=DriftModelFile.load(path))
    except ValueError as exc:
        raise ParameterFileError(f'drift_model_file: {exc}') from None

