"""`calibrate_unit`: the bench calibration of one gyro from its warm-up or drive logs (any format
`sources.open_source` reads). Pure: no ROS, no files written (fleet.py writes), so a Dask worker
can run it.

1. Each log's reference for the true rate: `odom` (a record with ground truth), `static` (the unit
   at rest: true rate = Earth rate, a constant the model's `constant` absorbs; `discover`'s own
   motion test decides) or `compass` (neither: only the STKF, which learns from compass against
   gyro heading, can use it).
2. The model's structure: `discover` on the static or odom log with the widest temperature span
   names what the paper's model misses; its drift model file (discrepancy/model_export.py) starts
   each term at that log's all-data fit. Without such a log: the paper's terms.
3. The state: the node's own estimator (thermal/estimator.py, the node's default parameters with
   that model file) runs over every log in time order, each log a restart warm-started from the
   state the previous one left, as `stkf_node` with a `state_file` would. What it holds at the end
   is the state file `stkf_node` warm-starts from. Each log is another power-up, and so is the
   node's next start: the constant is handed on with its prior's variance added (the turn-on bias
   does not repeat; model_state.after_power_cycle), the temperature terms as learned. The heading
   filter's compass deviation map and gyro scale factor are not handed on: the map is the hard and
   soft iron of wherever the unit was mounted for these logs, not of the vehicle it goes into
   (and a bench log, at one heading, cannot observe it); the node learns them on the vehicle and
   keeps them in its own state file across restarts there.
4. The figures: measured drift (heading-axis rate minus the reference, per 1 s bin) against
   temperature with the all-data fit of the named terms, and the residual; for a compass-only log
   the drift the STKF learned instead (it has no independent measurement).
"""
from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..sources import Source, open_source

REFERENCES = ('auto', 'static', 'odom', 'compass')
_DECIMATE_S = 10.0   # the learned-drift series is kept every this many seconds


class CalibrationError(ValueError):
    """Logs that cannot calibrate a unit (no temperature, no usable reference): one line."""


@dataclass
class LogSummary:
    path: str
    kind: str
    reference: str
    start_ns: int
    duration_s: float
    temperature_c: tuple
    notes: list = field(default_factory=list)


@dataclass
class UnitCalibration:
    """Everything a unit's calibration produced, as plain data (fleet.py writes the files)."""
    unit: str
    logs: list                    # LogSummary, in time order
    model: dict                   # DriftModelFile.to_dict()
    state: dict                   # ThermalDriftEstimator.get_state(): terms, temperature_ref_c, x, P, coverage
    drift: dict                   # series for the report: see _measured_drift / _learned_drift
    notes: list = field(default_factory=list)

    def coefficients(self) -> dict:
        """Term -> (value, 1-sigma) of the state, SI units."""
        x = np.asarray(self.state.get('x', []), float)
        P = np.asarray(self.state.get('P') or np.full((len(x), len(x)), np.nan), float)
        return {name: (float(v), float(math.sqrt(max(P[i, i], 0.0))) if np.isfinite(P[i, i]) else float('nan'))
                for i, (name, v) in enumerate(zip(self.state.get('terms', []), x))}


def node_config(model_file=None):
    """The estimator configuration `stkf_node` runs with its default parameters (and `model_file`)."""
    from ..nodes.parameters import all_specs, config_from_params
    cfg = config_from_params({s.name: s.default for s in all_specs()})
    return cfg if model_file is None else replace(cfg, drift_model_file=model_file)


def _temperature_range(src: Source) -> tuple[float, float]:
    lo, hi = math.inf, -math.inf
    for chunk in src.chunks(600.0, ['temperature']):
        finite = chunk.temperature.temp_c[np.isfinite(chunk.temperature.temp_c)]
        if finite.size:
            lo, hi = min(lo, float(finite.min())), max(hi, float(finite.max()))
    return lo, hi


def _classify(src: Source, reference: str):
    """(LogSummary, BinnedData or None): the log's reference and, for static/odom, its bins."""
    from ..discrepancy.data import DiscoveryInputError, load_bins
    path = src.path
    present = src.streams_present()
    if 'imu' not in present:
        raise CalibrationError(f'{path}: no IMU stream')
    if 'temperature' not in present:
        raise CalibrationError(f'{path}: no gyro temperature: a thermal calibration needs one')
    summary = LogSummary(str(path), src.kind, '', src.time_origin_ns + int(src.span_s()[0] * 1e9),
                         src.duration_s, _temperature_range(src), list(src.notes))
    has_odom = 'odom' in present
    candidates = {'auto': (['odom'] if has_odom else []) + ['static'], 'odom': ['odom'], 'static': ['static'],
                  'compass': []}[reference]
    reason = None
    for ref in candidates:
        if ref == 'odom' and not has_odom:
            reason = 'no odom stream'
            continue
        streams = ['imu', 'temperature', 'mag'] + (['odom'] if ref == 'odom' else [])
        try:
            data = load_bins(src.chunks(60.0, streams), ref)
        except DiscoveryInputError as exc:
            reason = str(exc)
            continue
        summary.reference = ref
        return summary, data
    if reference in ('static', 'odom'):
        raise CalibrationError(f'{path}: reference {reference} cannot be used: {reason}')
    summary.reference = 'compass'
    if reason:
        summary.notes.append(f'compass reference ({reason.split(";")[0]})')
    return summary, None


def _measured_drift(result, data) -> dict:
    """Per 1 s bin: heading-axis drift measured against the reference, the all-data fit of the named
    terms, the residual (rad/s), the temperature (degC) and the time (s)."""
    from ..discrepancy.model_export import HEADING_AXIS
    from ..discrepancy.model import Analysis
    an = Analysis(data)
    spec = result.spec_after
    y = an.gyro_target(spec, HEADING_AXIS)
    r = an.residuals(spec, 'gyro', held_out=False)[:, HEADING_AXIS]
    ok = an.mask & np.isfinite(r) & np.isfinite(y)
    return {'kind': 'measured', 't_s': data.t[ok].tolist(), 'temperature_c': an.temp[ok].tolist(),
            'drift_rad_s': y[ok].tolist(), 'fit_rad_s': (y[ok] - r[ok]).tolist(), 'residual_rad_s': r[ok].tolist()}


def _run_estimator(sources: list[Source], model_file, keep_series: bool):
    """The node's estimator over the logs in order, each a warm restart from the previous state.
    Returns (state, learned-drift series of the last log or None)."""
    from ..thermal.estimator import ThermalDriftEstimator
    from ..thermal.model_state import after_power_cycle
    cfg = node_config(model_file)
    turn_on = _turn_on_sigma(cfg)
    state, series = None, None
    for src in sources:
        est = ThermalDriftEstimator(cfg)
        if state is not None and 'x' in state:
            est.set_state(after_power_cycle(state, turn_on))
        t, temp, d_hat, open_ = [], [], [], []
        last_key = -math.inf
        for chunk in src.chunks(60.0, ['imu', 'mag', 'temperature']):
            out = est.process(chunk)
            if keep_series and chunk.imu is not None and len(chunk.imu.t):
                ts = chunk.imu.t
                keys = np.floor(ts / _DECIMATE_S)   # the first sample of every _DECIMATE_S
                pick = np.flatnonzero(np.r_[keys[0] > last_key, np.diff(keys) > 0])
                last_key = keys[-1]
                if pick.size:
                    t.append(ts[pick])
                    temp.append(out.temperature_c[pick])
                    d_hat.append(chunk.imu.gyro[pick, 2] - out.gyro_compensated[pick, 2])
                    open_.append(out.gate_open[pick])
        state = est.get_state()
        if keep_series and t:
            series = {'t_s': np.concatenate(t), 'temperature_c': np.concatenate(temp),
                      'drift_rad_s': np.concatenate(d_hat), 'gate_open': np.concatenate(open_)}
    state = {k: v for k, v in state.items() if k != 'heading'}   # the mounting's, not the unit's
    return (state if 'x' not in state else after_power_cycle(state, turn_on)), series


def _turn_on_sigma(cfg) -> float:
    """The bias's turn-on repeatability, rad/s: no log measures it (each log is one power-up), so
    the constant's prior sigma (the model file's, else the term's): the unit's next start measures
    its constant again, from the calibrated slopes. 0 for a model without a constant term."""
    model = cfg.model()
    i = model.index('constant')
    return 0.0 if i is None else float(cfg.prior_sigma_values(model)[i])


def _learned_drift(state: dict, series: dict, model) -> dict:
    """The STKF's drift estimate against temperature, the final model at (T, dT/dt) and the residual."""
    ok = np.isfinite(series['temperature_c']) & np.isfinite(series['drift_rad_s'])
    t, temp, d = series['t_s'][ok], series['temperature_c'][ok], series['drift_rad_s'][ok]
    rate = np.gradient(temp, t) if len(t) > 2 else np.zeros_like(temp)
    inputs = model.neutral_inputs(temp, rate, np.zeros_like(temp))
    fit = model.rows(inputs) @ np.asarray(state['x'], float)
    return {'kind': 'learned', 't_s': t.tolist(), 'temperature_c': temp.tolist(), 'drift_rad_s': d.tolist(),
            'fit_rad_s': fit.tolist(), 'residual_rad_s': (d - fit).tolist()}


def calibrate_unit(logs, *, unit: str = 'unit', source_options: dict | None = None,
                   reference: str = 'auto') -> UnitCalibration:
    """Calibrate one unit from `logs` (paths of any format; `source_options` as open_source takes
    them). `reference`: 'auto' (odom if the log has it, else static if the unit rests, else
    compass), or force one. CalibrationError / SourceError (one line) if the logs cannot do it."""
    from ..discrepancy import discover
    from ..discrepancy.model_export import model_file_from_discovery
    from ..thermal.drift_model import DEFAULT_TERMS
    from ..thermal.model_file import DriftModelFile, TermSetting
    if reference not in REFERENCES:
        raise CalibrationError(f'reference {reference!r}: use one of {", ".join(REFERENCES)}')
    logs = [str(p) for p in logs]
    if not logs:
        raise CalibrationError(f'unit {unit}: no log')
    with contextlib.ExitStack() as stack:   # each log opened once: flight logs are parsed whole
        sources = [stack.enter_context(open_source(p, **(source_options or {}))) for p in logs]
        classified = sorted(((_classify(src, reference), src) for src in sources), key=lambda c: c[0][0].start_ns)
        summaries = [c[0][0] for c in classified]
        notes = []
        with_reference = [c[0] for c in classified if c[0][1] is not None]
        drift = None
        if with_reference:
            s, data = max(with_reference, key=lambda item: item[0].temperature_c[1] - item[0].temperature_c[0])
            result = discover(None, data=data)
            model = model_file_from_discovery(result, s.path)
            model = replace(model, source={**model.source, 'written_by': 'gyro-thermal-comp calibrate', 'unit': unit})
            notes.append(f'model from {Path(s.path).name} ({s.reference} reference): {result.verdict}'
                         + (f', named {", ".join(result.effects)}' if result.effects else ''))
            drift = _measured_drift(result, data)
            drift['log'] = s.path
        else:
            model = DriftModelFile(terms=tuple(TermSetting(n) for n in DEFAULT_TERMS),
                                   source={'written_by': 'gyro-thermal-comp calibrate', 'unit': unit, 'logs': logs})
            notes.append("no log at rest or with ground truth: the paper's terms, learned from the compass")
        state, series = _run_estimator([c[1] for c in classified], model, drift is None)
    if 'x' not in state:
        raise CalibrationError(f'unit {unit}: the estimator learned nothing (every log shorter than its still period?)')
    if drift is None:
        drift = _learned_drift(state, series, model.model())
        drift['log'] = summaries[-1].path
    return UnitCalibration(unit, [s.__dict__ for s in summaries], model.to_dict(), state, drift, notes)


__all__ = ['CalibrationError', 'REFERENCES', 'UnitCalibration', 'calibrate_unit', 'node_config']
