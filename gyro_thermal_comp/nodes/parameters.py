"""ROS parameters of the STKF node, derived from `EstimatorConfig` so the two cannot drift apart.

Every estimator field is a parameter (nested configs as `gate.*`, `heading.*`); `None` is spelled
NaN for numbers and an empty array for lists. Only the gate thresholds and the node's periods may
change at run time; everything that shapes the filter's state is read-only.
"""
from __future__ import annotations

import inspect
import math
import re
from dataclasses import dataclass, fields, is_dataclass, replace
from functools import lru_cache
from typing import Any

from ..thermal.estimator import EstimatorConfig


@dataclass(frozen=True)
class ParamSpec:
    name: str
    default: Any
    description: str
    read_only: bool = True
    min_value: float | None = None
    max_value: float | None = None


# Node-level settings (not the estimator's).
NODE_PARAMS = (
    ParamSpec('state_file', '', 'learned a/b/c + covariance file; empty = no persistence'),
    ParamSpec('state_save_period_s', 60.0, 'how often the state file is rewritten, s', False, 1.0, 86400.0),
    ParamSpec('diagnostics_period_s', 1.0, 'diagnostics publication period, s', False, 0.1, 60.0),
    ParamSpec('process_period_s', 0.02, 'inputs are buffered and processed in batches this often, s', True, 0.0005, 0.5),
    ParamSpec('input_queue_depth', 1000, 'subscription queue depth , messages', True, 5, 100000),
    ParamSpec('reliable_inputs', False, 'subscribe with reliable QoS (lossless when the publisher is reliable; a '
              'best-effort driver is then not matched). Default: best effort, which matches every driver', True),
    ParamSpec('max_latency_s', 2.0, 'a silent topic holds the others back at most this long (> the slowest '
              'topic period, e.g. 1 Hz temperature), s', True, 0.01, 60.0),
    ParamSpec('buffer_max_samples', 200000, 'bound of the stamp-ordering buffer, samples', True, 1000, 10_000_000),
    ParamSpec('accel_noise_density_m_s2_rthz', 110e-6 * 9.80665, 'accelerometer noise density for covariances, m/s^2/sqrt(Hz)',
              True, 0.0, 1.0),
)

# Estimator fields with a human description and, for numbers, a range. Fields not listed here get
# a generic description and no range; a test keeps this table in step with EstimatorConfig.
_DOCS = {
    'name': 'method name in reports',
    'terms': 'drift-model terms (temperature, temperature_rate, constant, ...)',
    'scale_factor': 'also learn a temperature-dependent scale factor k(T) on rotating segments',
    'temperature_ref_c': 'reference temperature of the model, degC',
    'learn': 'false: keep the parameters fixed (replay of a calibration)',
    'window_s': 'STKF update interval = drift-measurement window, s',
    'fading_s': 'fading-memory factor s >= 1 per update (1 = plain Kalman filter)',
    'adaptive_fading': "Zhou's adaptive strong-tracking factor on top of s",
    'arw_deg_sqrt_s': 'gyro angle random walk (noise density), deg/sqrt(s)',
    'latitude_deg': 'latitude for Earth-rate removal, deg; NaN = unknown (absorbed in c)',
    'declination_rad': 'magnetic declination (east positive), rad',
    'still_period_s': 'the unit is assumed motionless this long after start, s',
    'max_gap_s': 'IMU stamps further apart than this are a time gap, s',
}
_RANGES = {
    'window_s': (1.0, 600.0), 'fading_s': (1.0, 2.0), 'arw_deg_sqrt_s': (0.0, 10.0),
    'latitude_deg': (-90.0, 90.0), 'declination_rad': (-math.pi, math.pi), 'still_period_s': (0.0, 3600.0),
    'max_gap_s': (0.001, 60.0), 'temperature_ref_c': (-60.0, 150.0),
}
_RUNTIME_PREFIXES = ('gate.',)  # safe to change live: ThermalDriftEstimator.set_gate_config rebuilds what follows


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


def _flatten(cfg, prefix: str = '') -> dict[str, tuple[Any, str]]:
    """Nested config -> {'gate.field': (value, description)}."""
    out = {}
    for f in fields(cfg):
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


_NO_UPPER_BOUND = 1e12


def _optional_numbers(cfg, prefix: str = '') -> set[str]:
    """Fields typed `float | None`, spelled NaN when unset (the other optional fields are lists)."""
    out = set()
    for f in fields(cfg):
        value = getattr(cfg, f.name)
        if is_dataclass(value):
            out |= _optional_numbers(value, f'{prefix}{f.name}.')
        elif 'float | None' in str(f.type):
            out.add(prefix + f.name)
    return out


def config_specs(base, *, ranges=None, runtime_prefixes=()) -> tuple[ParamSpec, ...]:
    """One ParamSpec per (flattened) field of a config dataclass instance."""
    ranges, optional = ranges or {}, _optional_numbers(base)
    specs = []
    for name, (value, description) in _flatten(base).items():
        lo, hi = ranges.get(name, (None, None))
        if lo is None and isinstance(value, (int, float)) and not isinstance(value, bool) and value >= 0:
            lo, hi = 0, _NO_UPPER_BOUND  # tolerances, times, sigmas: a negative value is meaningless
        if value is None:
            value = math.nan if name in optional else []
        specs.append(ParamSpec(name, _to_ros(value), description, not name.startswith(runtime_prefixes), lo, hi))
    return tuple(specs)


def estimator_specs(base: EstimatorConfig = EstimatorConfig()) -> tuple[ParamSpec, ...]:
    return config_specs(base, ranges=_RANGES, runtime_prefixes=_RUNTIME_PREFIXES)


def all_specs() -> tuple[ParamSpec, ...]:
    return NODE_PARAMS + estimator_specs()


def check_value(spec: ParamSpec, value) -> str | None:
    """Why `value` is not acceptable for `spec`, or None."""
    if isinstance(spec.default, bool) or isinstance(value, bool):
        return None if isinstance(value, bool) == isinstance(spec.default, bool) else f'{spec.name} must be a bool'
    if isinstance(value, (int, float)) and spec.min_value is not None:
        if math.isnan(value):
            unset_ok = isinstance(spec.default, float) and math.isnan(spec.default)
            return None if unset_ok else f'{spec.name} must be a number, not NaN'
        if not spec.min_value <= value <= spec.max_value:
            return f'{spec.name}={value} is outside [{spec.min_value}, {spec.max_value}]'
    return None


def config_from_params(values: dict[str, Any], base=None):
    """Flat parameter values -> a config like `base` (default EstimatorConfig()): NaN/empty -> None,
    lists -> tuples, 9 numbers -> 3x3 where the field is a matrix."""
    optional = _optional_numbers(base if base is not None else EstimatorConfig())

    def build(cfg, prefix=''):
        changes = {}
        for f in fields(cfg):
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
            elif isinstance(v, (list, tuple)) and current and isinstance(current, tuple) and isinstance(current[0], tuple):
                v = tuple(tuple(float(x) for x in v[i:i + 3]) for i in range(0, len(v), 3))
            elif isinstance(v, (list, tuple)):
                v = tuple(v) if len(v) else (None if current is None else ())
            elif isinstance(current, float) and isinstance(v, int) and not isinstance(v, bool):
                v = float(v)
            changes[f.name] = v
        return replace(cfg, **changes)
    return build(base if base is not None else EstimatorConfig())


def params_yaml(node_name: str, specs, executable: str, file_name: str) -> str:
    """A default parameter file (config/*.yaml), generated from the specs."""
    lines = [f'# Parameters of {executable} (node {node_name}): the defaults, generated from the code',
             '# (regenerate: gyro-thermal-comp params --write config/).',
             f'# Use: ros2 run gyro_thermal_comp {executable} --ros-args --params-file config/{file_name}',
             f'{node_name}:', '  ros__parameters:']
    for spec in specs:
        value = spec.default
        if isinstance(value, float) and math.isnan(value):
            lines.append(f'    # {spec.name}: .nan   # {spec.description} (unset = unknown)')
            continue
        if isinstance(value, list) and not value:
            lines.append(f'    # {spec.name}: []   # {spec.description} (unset = default)')
            continue
        lines.append(f'    {spec.name}: {_yaml_value(value)}   # {spec.description}'
                     + ('' if spec.read_only else ' [runtime]'))
    return '\n'.join(lines) + '\n'


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
