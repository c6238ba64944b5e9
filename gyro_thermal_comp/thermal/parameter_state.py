"""`ParameterState`: the drift-model parameters in force, and their state as plain data.

Once the still period has ended the parameters are the learner's (x, P). Before, they are those of a
warm start (`set_state`: the parameters and their covariance of an earlier run; the still period's
drift measurement is combined with them there, still_period.initial_state), or zeros. `get` and
`set` carry, with x and P, the model they belong to (terms, reference temperature), the input
ranges the learned parameters have seen (coasting.InputCoverage) and the heading filter's learned
map; what comes from outside is checked before anything changes (model_state.py).
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from .coasting import DriftPrediction, InputCoverage
from .drift_learning import DriftLearning
from .drift_model import DriftModel
from .estimator_config import EstimatorConfig
from .heading_filter import HeadingFilter
from .learner import ParameterLearner
from .model_file import DriftModelFile
from .model_state import checked_state


class ParameterState:
    """Parameters in force, their 1-sigmas, and their state for a file (`get`/`set`)."""

    def __init__(self, model: DriftModel, prediction: DriftPrediction, learning: DriftLearning,
                 heading: HeadingFilter):
        self.model, self.prediction, self.learning, self.heading = model, prediction, learning, heading
        self.warm: dict | None = None   # a warm start's x and P (None: no covariance), plain data

    @property
    def learner(self) -> ParameterLearner | None:
        return self.learning.learner

    def params(self) -> np.ndarray:
        """Drift-model parameters in force (SI units, order of `model.names`); before the still period
        ends, those of a warm start (its `constant` is re-measured there) or zeros."""
        if self.learner is not None:
            return self.learner.x
        return np.asarray(self.warm['x'], dtype=float) if self.warm is not None else np.zeros(len(self.model))

    def sigmas(self) -> np.ndarray:
        """1-sigma of each parameter (NaN before the learner exists)."""
        if self.learner is None:
            return np.full(len(self.model), np.nan)
        return np.sqrt(np.maximum(self.learner.P.diagonal(), 0.0))

    def starting_values(self, model_file: DriftModelFile | None) -> dict | None:
        """What the still period's end starts from: the warm start, else the model file's starting
        values (without a covariance), else nothing."""
        if self.warm is None and model_file is not None:
            priors = model_file.priors()
            return {'x': [priors.get(n, 0.0) for n in self.model.names], 'P': None}
        return self.warm

    def get(self) -> dict:
        """Parameters and covariance (plain data) with the model they belong to."""
        st = {'terms': list(self.model.names), 'temperature_ref_c': self.model.temperature_ref_c}
        if self.prediction.coverage.temp is not None:   # what the learned parameters have seen
            st['coverage'] = self.prediction.coverage.to_dict()
        if self.learner is not None:
            st.update({'x': self.learner.x.tolist(), 'P': self.learner.P.tolist()})
        elif self.warm is not None:
            st.update(self.warm)
        heading = self.heading.learned() or self.heading.carried   # the vehicle's compass deviation, scale factor
        if heading is not None:
            st['heading'] = heading
        return st

    def set(self, state: dict, cfg: EstimatorConfig, live_row: Callable[[], np.ndarray]) -> None:
        """Before the still period ends: the warm start (and a `heading` map of the heading filter
        carries over). After: replaces the running parameters, and sigma_d follows at the live
        inputs (`live_row()`: their regressor row). A state that does not fit the model, or is
        implausible under `cfg`, raises ValueError before anything changes."""
        x, P = checked_state(state, self.model, cfg)
        coverage = InputCoverage(state['coverage']) if state.get('coverage') else None   # ValueError before any change
        if state.get('heading') is not None and not self.heading.initialized:
            self.heading.carry_over(state['heading'])
        if coverage is not None:
            coverage.memory_s = self.prediction.coverage.memory_s
            self.prediction.coverage = coverage
        if self.learner is not None:
            self.learner.set_state(x, P)
            self.learning.update_sigma_d(live_row())
        else:
            self.warm = {'x': x.tolist(), 'P': None if P is None else P.tolist()}
