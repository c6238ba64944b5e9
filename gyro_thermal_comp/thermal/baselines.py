"""The paper's baselines (docs/design.md section 2), on the same inputs, gate, windows and heading filter.

Each is a `ThermalDriftEstimator` with another parameter learner or model, so only the drift
estimation differs from the STKF and the comparison is about that alone:
- `KfDriftBaseline`: the drift itself is the state (model `constant` only), a random walk, same
  compass window measurement; in an outage its estimate freezes.
- `FrozenBiasBaseline`: the same filter under the name the scorer's outage reference uses: the
  bias in force at the outage start is held through the outage.
(MLR and LSM use the paper's model a T + b dT/dt + c, whatever the STKF's terms.)
- `MlrCalibrated` (`mlr`): the paper's use of MLR. a, b, c are fitted beforehand on a calibration
  record (another run of the same unit: `MlrCalibration.fit`, saved with `save`/`load`) and then
  applied, fixed, to the record under test. Causal: it never sees the record it runs on.
- `MlrWholeRecord` (`mlr_whole_record`): a, b, c from ONE weighted least-squares fit over every
  clean window of the record under test itself (two passes: `fit(chunks)`, then `update`). It sees
  the future, so it is an offline reference (`causal = False`), not a method a vehicle can run.
- `LsmBaseline`: modified LSM, a, b, c refitted by least squares at every window on the windows of
  the last `recent_s` seconds; holds its last fit in outages.
- `UncompensatedBaseline`: gyro integrated with only the still-period bias removed, no compass.
"""
from __future__ import annotations

import math
import os
import tempfile
from collections import deque
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Iterable

import numpy as np
import yaml

from ..samples import SensorChunk
from .drift_model import BUILTIN_TERMS, PAPER_TERMS
from .estimator import EstimatorConfig, ThermalDriftEstimator
from .learner import FixedParameters
from .stkf import StepResult


def kf_config(base: EstimatorConfig = EstimatorConfig(), name: str = 'kf',
              drift_q_rad_s_sqrt_s: float = 2e-6) -> EstimatorConfig:
    """Random-walk drift state: model `constant` only, plain KF (s = 1, as the paper's, without the
    divergence reset, with the windows' R as computed, no backtest). The default random walk (2e-6 rad/s per
    sqrt(s)) follows a 0.2 deg/s thermal swing over half an hour."""
    return replace(base, name=name, terms=('constant',), scale_factor=False, fading_s=1.0,
                   adaptive_fading=False, q_sigmas=(drift_q_rad_s_sqrt_s,), prior_sigmas=None,
                   diverged_nis=math.inf, adaptive_r=False, coast_backtest=False)


class KfDriftBaseline(ThermalDriftEstimator):
    def __init__(self, config: EstimatorConfig | None = None, drift_q_rad_s_sqrt_s: float = 2e-6,
                 name: str = 'kf'):
        super().__init__(kf_config(config or EstimatorConfig(), name, drift_q_rad_s_sqrt_s))


class FrozenBiasBaseline(KfDriftBaseline):
    def __init__(self, config: EstimatorConfig | None = None, drift_q_rad_s_sqrt_s: float = 2e-6):
        super().__init__(config, drift_q_rad_s_sqrt_s, name='frozen_bias')


class SlidingLeastSquares:
    """`ParameterLearner` refitting by weighted least squares on the windows of the last `recent_s`
    seconds (`window_s` each). A weak ridge towards the initial state keeps the fit defined while
    the temperature has not moved (a and c are then not separable)."""

    def __init__(self, x0, P0, recent_windows: int, ridge_scale: float = 10.0):
        self.x0 = np.asarray(x0, dtype=float).copy()
        self._x = self.x0.copy()
        # ridge information: the prior, weakened by ridge_scale
        self._prior_info = np.linalg.pinv(np.asarray(P0, dtype=float)) / ridge_scale
        self._rows: deque = deque(maxlen=int(recent_windows))
        self._P = np.asarray(P0, dtype=float).copy()
        self.n_updates = 0
        self.n_rejected = 0
        self.n_resets = 0

    @property
    def x(self) -> np.ndarray:
        return self._x.copy()

    @property
    def P(self) -> np.ndarray:
        return self._P.copy()

    def set_state(self, x, P=None) -> None:
        self._x = np.asarray(x, dtype=float).reshape(-1).copy()
        if P is not None:
            self._P = np.asarray(P, dtype=float).copy()

    def step(self, y=None, h=None, R=None) -> StepResult:
        if y is None or h is None or R is None or not np.isfinite(y):
            return StepResult(np.nan, np.nan, 1.0, False)
        h = np.asarray(h, dtype=float).reshape(-1)
        self._rows.append((h, float(y), float(R)))
        H = np.array([r[0] for r in self._rows])
        w = 1.0 / np.array([r[2] for r in self._rows])
        yv = np.array([r[1] for r in self._rows])
        info = (H * w[:, None]).T @ H + self._prior_info
        rhs = (H * w[:, None]).T @ yv + self._prior_info @ self.x0
        try:
            x = np.linalg.solve(info, rhs)
            P = np.linalg.inv(info)
        except np.linalg.LinAlgError:
            self.n_rejected += 1
            return StepResult(np.nan, np.nan, 1.0, False)
        gamma = float(y - h @ self._x)
        self._x, self._P = x, 0.5 * (P + P.T)
        self.n_updates += 1
        return StepResult(gamma, float(h @ self._P @ h + R), 1.0, True)


class LsmBaseline(ThermalDriftEstimator):
    def __init__(self, config: EstimatorConfig | None = None, recent_s: float = 600.0):
        cfg = _paper_config(config, 'lsm')
        n_win = max(3, int(round(recent_s / cfg.window_s)))
        super().__init__(cfg, learner=lambda x0, P0, Q: SlidingLeastSquares(x0, P0, n_win))


class NotApplicable(ValueError):
    """A method that cannot run on this record (its `fit` found too little usable data, or it needs a
    calibration it was not given); the message is the reason. `evaluation.evaluate` reports such a
    method as not applicable and scores the others. A ValueError, so callers that caught the old
    error still do."""


class CalibrationError(ValueError):
    """A calibration file that cannot be used (unreadable, not YAML, wrong keys or values): one line."""


CALIBRATION_FORMAT = 'gyro_thermal_comp/mlr_calibration'
CALIBRATION_VERSION = 1
UNCALIBRATED_REASON = ('needs --calibration BAG (or --calibration-file FILE): MLR is calibrated beforehand '
                       'on another run of the same unit')


def _paper_config(config: EstimatorConfig | None, name: str) -> EstimatorConfig:
    """The paper's baselines (LSM, MLR): its model a*T + b*dT/dt + c, windows weighed by R as computed,
    the drift sigma from P alone (no backtest)."""
    return replace(config or EstimatorConfig(), name=name, terms=PAPER_TERMS, scale_factor=False, adaptive_r=False,
                   coast_backtest=False)


@dataclass(frozen=True, eq=False)
class MlrCalibration:
    """MLR parameters fitted on one record: drift = sum_i x_i * term_i (docs/design.md eq. 2), SI units
    (rad/s per the term's unit), temperature terms about `temperature_ref_c` (degC). `cov` is the
    fit covariance of x (the weighted least squares' (H^T R^-1 H)^-1, widened by the reduced
    chi-square when the windows scatter more than their R says); `windows` the clean windows used.
    `latitude_deg`: the estimator's Earth-rate setting during the fit (None: the Earth rate is in c),
    kept so that the parameters are applied with the same one."""
    terms: tuple[str, ...]
    temperature_ref_c: float
    x: np.ndarray
    cov: np.ndarray | None = None
    windows: int = 0
    latitude_deg: float | None = None
    source: str = ''

    @classmethod
    def fit(cls, chunks: Iterable[SensorChunk], config: EstimatorConfig | None = None, source: str = '',
            require_rank: bool = True) -> 'MlrCalibration':
        """One weighted least squares over every clean window (no closed gate, no time gap) of
        `chunks`, the windows found by running the STKF over them (a realistic gate). Raises
        `NotApplicable` with fewer clean windows than parameters, or (require_rank) when the
        windows do not separate the terms (a temperature that never moved)."""
        cfg = _paper_config(config, 'mlr_fit')
        probe = ThermalDriftEstimator(cfg)
        for chunk in chunks:
            probe.update(chunk)
        rows = [w for w in probe.learning.window_log if w.clean]
        p = len(probe.model)
        if len(rows) < p:
            raise NotApplicable(f'MLR needs at least {p} clean windows (no closed gate or time gap), got {len(rows)}')
        H = np.array([w.h for w in rows])
        y = np.array([w.y for w in rows])
        sw = 1.0 / np.sqrt(np.array([w.R for w in rows]))
        A = H * sw[:, None]
        x, _, rank, _ = np.linalg.lstsq(A, y * sw, rcond=None)
        if rank < p and require_rank:
            raise NotApplicable(f'MLR calibration: the clean windows do not separate the {p} terms (rank {rank}); '
                                'the calibration record needs a temperature that changes at varying rates')
        cov = None
        if rank == p:
            r = y * sw - A @ x
            chi2 = float(r @ r) / (len(rows) - p) if len(rows) > p else 1.0
            cov = np.linalg.inv(A.T @ A) * max(1.0, chi2)
        return cls(tuple(probe.model.names), float(cfg.temperature_ref_c), x, cov, len(rows), cfg.latitude_deg,
                   str(source))

    @property
    def sigmas(self) -> np.ndarray:
        """1-sigma of each parameter, SI (NaN without a covariance)."""
        return np.full(len(self.x), np.nan) if self.cov is None else np.sqrt(np.diag(self.cov))

    def estimator_config(self, base: EstimatorConfig | None = None, name: str = 'mlr') -> EstimatorConfig:
        """`base` running these parameters fixed: same terms, reference temperature, Earth-rate setting."""
        return replace(base or EstimatorConfig(), name=name, terms=self.terms, scale_factor=False, learn=False,
                       temperature_ref_c=self.temperature_ref_c, latitude_deg=self.latitude_deg)

    # -- file -------------------------------------------------------------------------------
    def to_dict(self) -> dict:
        return {'format': CALIBRATION_FORMAT, 'version': CALIBRATION_VERSION, 'method': 'mlr',
                'terms': list(self.terms),
                'units': [BUILTIN_TERMS[t].unit for t in self.terms],
                'temperature_ref_c': self.temperature_ref_c,
                'x': [float(v) for v in self.x],
                'cov': None if self.cov is None else [[float(v) for v in row] for row in self.cov],
                'windows': int(self.windows), 'latitude_deg': self.latitude_deg, 'source': self.source}

    @classmethod
    def from_dict(cls, d, where: str = 'calibration') -> 'MlrCalibration':
        def bad(why):
            raise CalibrationError(f'{where}: {why}')
        if not isinstance(d, dict):
            bad('not a mapping of calibration keys')
        if d.get('format', CALIBRATION_FORMAT) != CALIBRATION_FORMAT or d.get('version', 1) != CALIBRATION_VERSION:
            bad(f'not an MLR calibration (format {d.get("format")!r} version {d.get("version")!r}; '
                f'expected {CALIBRATION_FORMAT!r} version {CALIBRATION_VERSION})')
        missing = [k for k in ('terms', 'temperature_ref_c', 'x') if k not in d]
        if missing:
            bad(f'missing {", ".join(missing)}')
        terms = d['terms']
        if not isinstance(terms, list) or not all(isinstance(t, str) for t in terms) or not terms:
            bad('terms must be a list of term names')
        unknown = [t for t in terms if t not in BUILTIN_TERMS]
        if unknown or len(set(terms)) != len(terms):
            bad(f'unknown or repeated terms {unknown or terms}; known: {", ".join(BUILTIN_TERMS)}')
        x = _finite_array(d['x'], (len(terms),), 'x', bad)
        t_ref = _finite_array(d['temperature_ref_c'], (), 'temperature_ref_c', bad)
        cov = None if d.get('cov') is None else _finite_array(d['cov'], (len(terms),) * 2, 'cov', bad)
        lat = d.get('latitude_deg')
        if lat is not None and not -90.0 <= float(_finite_array(lat, (), 'latitude_deg', bad)) <= 90.0:
            bad(f'latitude_deg must be within [-90, 90], got {lat}')
        windows = d.get('windows', 0)
        if isinstance(windows, bool) or not isinstance(windows, int) or windows < 0:
            bad(f'windows must be a count, got {windows!r}')
        return cls(tuple(terms), float(t_ref), x, cov, windows, None if lat is None else float(lat),
                   str(d.get('source', '')))

    def save(self, path) -> Path:
        """Write YAML atomically (a temporary name in the same folder, then renamed)."""
        path = Path(path)
        text = ('# MLR calibration (gyro-thermal-comp): drift = sum x_i * term_i, SI units, temperature terms\n'
                '# about temperature_ref_c; fitted once, applied fixed (docs/evaluation.md)\n'
                + yaml.safe_dump(self.to_dict(), sort_keys=False))
        fd, tmp = tempfile.mkstemp(prefix=f'.{path.name}.', dir=path.parent or '.')
        try:
            with os.fdopen(fd, 'w') as f:
                f.write(text)
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
        return path

    @classmethod
    def load(cls, path) -> 'MlrCalibration':
        where = f'calibration file {path}'
        try:
            text = Path(path).read_text()
        except (OSError, UnicodeDecodeError) as exc:
            raise CalibrationError(f'{where}: cannot read it ({getattr(exc, "strerror", None) or exc})') from None
        try:
            d = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            raise CalibrationError(f'{where}: not YAML ({" ".join(str(exc).split())[:120]})') from None
        return cls.from_dict(d, where)


def _finite_array(value, shape, what, bad) -> np.ndarray:
    try:
        if isinstance(value, bool) or (isinstance(value, list) and any(isinstance(v, bool) for v in value)):
            raise TypeError
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        bad(f'{what} must be numbers, got {value!r}'[:200])
    if a.shape != shape:
        bad(f'{what} must have shape {shape}, got {a.shape}')
    if not np.all(np.isfinite(a)):
        bad(f'{what} must be finite')
    return a


class _FixedRun:
    """A `ThermalDriftEstimator` with parameters that never change (`run`), once it exists."""
    name: str
    _run: ThermalDriftEstimator | None = None

    def update(self, chunk: SensorChunk):
        return self._ready().update(chunk)

    def process(self, chunk: SensorChunk):
        return self._ready().process(chunk)

    @property
    def estimator(self) -> ThermalDriftEstimator | None:
        return self._run


class MlrCalibrated(_FixedRun):
    """`mlr`, the paper's use: parameters fitted beforehand on a calibration record of the same unit
    (`from_chunks`), given (`from_parameters`) or read from a file (`from_file`), then applied fixed:
    nothing is learned from the record it runs on. Without a calibration it is not applicable
    (`not_applicable` holds the reason; `evaluate` reports it) and `update` raises NotApplicable."""
    causal = True

    def __init__(self, calibration: MlrCalibration | None = None, config: EstimatorConfig | None = None,
                 name: str = 'mlr'):
        self.name = name
        self.calibration = calibration
        self.not_applicable = None if calibration is not None else UNCALIBRATED_REASON
        if calibration is not None:
            self._run = ThermalDriftEstimator(calibration.estimator_config(config, name),
                                              learner=FixedParameters.factory(calibration.x))

    @classmethod
    def from_chunks(cls, chunks: Iterable[SensorChunk], config: EstimatorConfig | None = None,
                    source: str = '') -> 'MlrCalibrated':
        return cls(MlrCalibration.fit(chunks, config, source), config)

    @classmethod
    def from_parameters(cls, x, terms=PAPER_TERMS, temperature_ref_c: float = 25.0,
                        config: EstimatorConfig | None = None) -> 'MlrCalibrated':
        cal = MlrCalibration.from_dict({'terms': list(terms), 'temperature_ref_c': temperature_ref_c,
                                        'x': [float(v) for v in np.asarray(x, dtype=float).reshape(-1)]},
                                       'MLR parameters')
        return cls(cal, config)

    @classmethod
    def from_file(cls, path, config: EstimatorConfig | None = None) -> 'MlrCalibrated':
        return cls(MlrCalibration.load(path), config)

    @property
    def x(self) -> np.ndarray | None:
        return None if self.calibration is None else self.calibration.x.copy()

    def _ready(self) -> ThermalDriftEstimator:
        if self._run is None:
            raise NotApplicable(self.not_applicable)
        return self._run


class MlrWholeRecord(_FixedRun):
    """`mlr_whole_record`, an offline reference: `fit(chunks)` solves the MLR least squares over every
    clean window of the very record it is then scored on (two passes), so it has seen the future
    of every sample: not causal, never a method a vehicle can run. Fewer clean windows than
    parameters: `fit` raises `NotApplicable`."""
    causal = False
    offline_reason = 'offline reference: fitted to the whole record it is scored on (sees the future)'

    def __init__(self, config: EstimatorConfig | None = None):
        self.cfg = _paper_config(config, 'mlr_whole_record')
        self.name = self.cfg.name
        self.x: np.ndarray | None = None

    def fit(self, chunks: Iterable[SensorChunk]) -> np.ndarray:
        self.x = MlrCalibration.fit(chunks, self.cfg, require_rank=False).x
        self._run = ThermalDriftEstimator(replace(self.cfg, learn=False), learner=FixedParameters.factory(self.x))
        return self.x

    def _ready(self) -> ThermalDriftEstimator:
        if self._run is None:
            raise RuntimeError('MlrWholeRecord.fit(chunks) must run before update()/process()')
        return self._run


MlrBaseline = MlrWholeRecord   # an older name of the whole-record fit, kept for callers (`mlr` is MlrCalibrated)


class UncompensatedBaseline(ThermalDriftEstimator):
    def __init__(self, config: EstimatorConfig | None = None):
        super().__init__(replace(config or EstimatorConfig(), name='uncompensated_gyro', terms=('constant',),
                                 scale_factor=False, learn=False, heading_correction=False))
