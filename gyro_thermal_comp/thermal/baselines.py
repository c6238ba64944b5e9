"""The paper's baselines (docs/design.md section 2), on the same inputs, gate, windows and heading filter.

Each is a `ThermalDriftEstimator` with another parameter learner or model, so only the drift
estimation differs from the STKF and the comparison is about that alone:
- `KfDriftBaseline`: the drift itself is the state (model `constant` only), a random walk, same
  compass window measurement; in an outage its estimate freezes.
- `FrozenBiasBaseline`: the same filter under the name the scorer's outage reference uses: the
  bias in force at the outage start is held through the outage.
(MLR and LSM use the paper's model a T + b dT/dt + c, whatever the STKF's terms.)
- `MlrBaseline`: a, b, c from ONE weighted least-squares fit over every clean window of the whole
  record (two passes: `fit(chunks)`, then `update`), fixed thereafter.
- `LsmBaseline`: modified LSM, a, b, c refitted by least squares at every window on the windows of
  the last `recent_s` seconds; holds its last fit in outages.
- `UncompensatedBaseline`: gyro integrated with only the still-period bias removed, no compass.
"""
from __future__ import annotations

import math

from collections import deque
from dataclasses import replace
from typing import Iterable

import numpy as np

from ..samples import SensorChunk
from .drift_model import PAPER_TERMS
from .estimator import EstimatorConfig, ThermalDriftEstimator
from .learner import FixedParameters
from .stkf import StepResult


def kf_config(base: EstimatorConfig = EstimatorConfig(), name: str = 'kf',
              drift_q_rad_s_sqrt_s: float = 2e-6) -> EstimatorConfig:
    """Random-walk drift state: model `constant` only, plain KF (s = 1, as the paper's, without the
    divergence reset). The default random walk (2e-6 rad/s per sqrt(s)) follows a 0.2 deg/s
    thermal swing over half an hour."""
    return replace(base, name=name, terms=('constant',), scale_factor=False, fading_s=1.0,
                   adaptive_fading=False, q_sigmas=(drift_q_rad_s_sqrt_s,), prior_sigmas=None,
                   diverged_nis=math.inf)


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
        cfg = replace(config or EstimatorConfig(), name='lsm', terms=PAPER_TERMS, scale_factor=False)
        n_win = max(3, int(round(recent_s / cfg.window_s)))
        super().__init__(cfg, learner=lambda x0, P0, Q: SlidingLeastSquares(x0, P0, n_win))


class NotApplicable(ValueError):
    """A method that cannot run on this record (its `fit` found too little usable data); the
    message is the reason. `evaluation.evaluate` reports such a method as not applicable and scores
    the others. A ValueError, so callers that caught the old error still do."""


class MlrBaseline:
    """Two passes: `fit(chunks)` collects every clean window's (y, h, R) (running the STKF for a
    realistic gate), solves one weighted least squares; `update` then runs with those parameters.
    Fewer clean windows than parameters: `fit` raises `NotApplicable`."""

    def __init__(self, config: EstimatorConfig | None = None):
        self.cfg = replace(config or EstimatorConfig(), name='mlr', terms=PAPER_TERMS, scale_factor=False)
        self.name = self.cfg.name
        self.x: np.ndarray | None = None
        self._run: ThermalDriftEstimator | None = None

    def fit(self, chunks: Iterable[SensorChunk]) -> np.ndarray:
        probe = ThermalDriftEstimator(replace(self.cfg, name='mlr_fit'))
        for chunk in chunks:
            probe.update(chunk)
        rows = [w for w in probe.learning.window_log if w.clean]
        if len(rows) < len(probe.model):
            raise NotApplicable(f'MLR needs at least {len(probe.model)} clean windows (no closed gate or '
                                f'time gap), got {len(rows)}')
        H = np.array([w.h for w in rows])
        y = np.array([w.y for w in rows])
        sw = 1.0 / np.sqrt(np.array([w.R for w in rows]))
        self.x = np.linalg.lstsq(H * sw[:, None], y * sw, rcond=None)[0]
        self._run = ThermalDriftEstimator(replace(self.cfg, learn=False), learner=FixedParameters.factory(self.x))
        return self.x

    def update(self, chunk: SensorChunk):
        if self._run is None:
            raise RuntimeError('MlrBaseline.fit(chunks) must run before update()')
        return self._run.update(chunk)

    def process(self, chunk: SensorChunk):
        if self._run is None:
            raise RuntimeError('MlrBaseline.fit(chunks) must run before process()')
        return self._run.process(chunk)


class UncompensatedBaseline(ThermalDriftEstimator):
    def __init__(self, config: EstimatorConfig | None = None):
        super().__init__(replace(config or EstimatorConfig(), name='uncompensated_gyro', terms=('constant',),
                                 scale_factor=False, learn=False, heading_correction=False))
