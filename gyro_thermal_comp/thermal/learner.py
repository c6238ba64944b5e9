"""`ParameterLearner`: how the drift-model parameters are learned from window measurements.

The estimator only needs this protocol, so the STKF, the paper's baselines (a sliding least-squares
refit, fixed parameters from one global fit) and a user's own learner all run the same pipeline.
A `LearnerFactory(x0, P0, Q)` builds one when the still period ends (x0, P0: the initial state and
covariance it measured; Q: the per-window random walk of the parameters).
"""
from __future__ import annotations

from typing import Callable, Protocol

import numpy as np

from .stkf import StepResult


class ParameterLearner(Protocol):
    n_updates: int            # measurements taken
    n_rejected: int           # measurements refused
    n_resets: int             # returns to the last good parameters after a divergence

    @property
    def x(self) -> np.ndarray: ...          # parameters in force (SI, order of the model's terms)

    @property
    def P(self) -> np.ndarray: ...          # their covariance

    def step(self, y: float | None = None, h=None, R: float | None = None) -> StepResult:
        """One update window: predict, then take y = h . x + v (v ~ N(0, R)) if y is given."""

    def set_state(self, x, P=None) -> None: ...


LearnerFactory = Callable[[np.ndarray, np.ndarray, np.ndarray], ParameterLearner]


class FixedParameters:
    """Parameters that never change (a calibration, or MLR's one global fit): a learner that
    learns nothing. Its covariance is zero: the estimator treats the parameters as exact."""

    def __init__(self, x):
        self._x = np.asarray(x, dtype=float).reshape(-1).copy()
        self.n_updates = 0
        self.n_rejected = 0
        self.n_resets = 0

    @property
    def x(self) -> np.ndarray:
        return self._x.copy()

    @property
    def P(self) -> np.ndarray:
        return np.zeros((self._x.size, self._x.size))

    def step(self, y=None, h=None, R=None) -> StepResult:
        return StepResult(np.nan, np.nan, 1.0, False)

    def set_state(self, x, P=None) -> None:
        self._x = np.asarray(x, dtype=float).reshape(-1).copy()

    @classmethod
    def factory(cls, x) -> LearnerFactory:
        return lambda x0, P0, Q: cls(x)
