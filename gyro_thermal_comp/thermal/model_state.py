"""`checked_state`: learned drift-model parameters from outside (a state file, a calibration),
accepted only if they belong to this model and describe a gyro that could exist.

Checked before anything changes: the same terms (matched by name, in any order: a model file
written again may list them differently) and reference temperature, one finite value per term, a
finite covariance of the right shape, and a drift that stays inside the gyro's range over the
declared temperature range, its plausible rates and the measurable turn rates (x = 1e300 in a
file once crash-looped a node; a model that predicts what the sensor cannot measure is no
calibration).

`after_power_cycle`: a learned state carried to another power-up of the unit. A MEMS gyro's bias
does not repeat from one turn-on to the next (its datasheet's turn-on repeatability), while its
temperature response does: the constant is handed over with that repeatability added to its
variance, so the next still period measures it and the learned slopes are kept, as the thermal
calibrations of ArduPilot and PX4 keep their fit and measure the offset at each boot.
"""
from __future__ import annotations

import math

import numpy as np

from .drift_model import DriftModel
from .estimator_config import EstimatorConfig


def checked_state(state: dict, model: DriftModel, cfg: EstimatorConfig) -> tuple[np.ndarray, np.ndarray | None]:
    """(x, P or None) of `state` in the model's term order; ValueError naming what does not fit."""
    terms = [str(n) for n in state.get('terms', model.names)]
    if sorted(terms) != sorted(model.names):
        raise ValueError(f"state terms {state.get('terms')} do not match the model {list(model.names)}")
    if float(state.get('temperature_ref_c', model.temperature_ref_c)) != model.temperature_ref_c:
        raise ValueError('state temperature_ref_c differs from the model')
    x = np.asarray(state['x'], dtype=float).reshape(-1)
    P = None if state.get('P') is None else np.asarray(state['P'], dtype=float)
    if x.size != len(model) or not np.all(np.isfinite(x)):
        raise ValueError('state x must hold one finite value per model term')
    if P is not None and (P.shape != (x.size, x.size) or not np.all(np.isfinite(P)) or np.any(np.diag(P) < 0)):
        raise ValueError('state P must be a finite covariance of the model terms')
    order = [terms.index(name) for name in model.names]   # the state's index of each model term
    x = x[order]
    P = None if P is None else P[np.ix_(order, order)]
    worst = largest_drift(x, model, cfg)
    if not worst <= cfg.gyro_range_rad_s:
        raise ValueError(f'state x predicts a drift of {worst:.3g} rad/s inside the declared temperature range, '
                         f'beyond the gyro range {cfg.gyro_range_rad_s:.3g} rad/s')
    return x, P


def largest_drift(x: np.ndarray, model: DriftModel, cfg: EstimatorConfig) -> float:
    """Largest |D| (rad/s) the parameters predict at the corners of temperature (min, reference,
    max), its rate (+- the plausible limit) and the turn rate (+- the gyro range, 0)."""
    corners = np.array(np.meshgrid([cfg.temperature_min_c, cfg.temperature_ref_c, cfg.temperature_max_c],
                                   [-cfg.temperature_max_rate_c_s, cfg.temperature_max_rate_c_s],
                                   [-cfg.gyro_range_rad_s, 0.0, cfg.gyro_range_rad_s])).reshape(3, -1)
    with np.errstate(all='ignore'):
        d = model.rows(model.neutral_inputs(*corners)) @ x
    return float(np.max(np.abs(d))) if np.all(np.isfinite(d)) else math.inf


def after_power_cycle(state: dict, turn_on_sigma_rad_s: float) -> dict:
    """`state` (get_state's plain data) with `turn_on_sigma_rad_s`^2 added to the variance of its
    `constant` (a rank-one addition: P stays symmetric positive definite). Unchanged without P or
    without a constant term."""
    terms = [str(n) for n in state.get('terms', [])]
    if state.get('P') is None or 'constant' not in terms:
        return state
    P = np.array(state['P'], dtype=float)
    i = terms.index('constant')
    P[i, i] += float(turn_on_sigma_rad_s) ** 2
    return {**state, 'P': P.tolist()}
