"""The gyro drift model D = H x (docs/design.md eq. 2), as a list of named regressor terms.

The filter never looks inside the model: it sees a state of `len(model)` parameters and rows H
built here, so a new term (T^2, lagged T, specific force...) is one `Term` added to the list and
no filter code changes.

Inputs are named arrays (all shape (N,), SI units, temperature in degC):
  'temperature'       T, degC (smoothed)
  'temperature_rate'  dT/dt, degC/s
  'rate'              measured heading-axis rate w, rad/s (for scale-factor terms)
  'thermal_branch'    heating/cooling branch state in [-1, 1] (model_inputs.py computes it causally)
With a die-temperature lag (model_inputs.py) 'temperature' and 'temperature_rate' are the die's.
A term may require any other named input; `rows` raises a clear KeyError if one is missing.

Temperature enters as (T - temperature_ref_c): with T near 25-60 degC an uncentred T makes `a` and
`c` almost collinear and makes a random walk on `c` mean "drift at 0 degC". `paper_coefficients`
converts back to the paper's c (drift at T = 0).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Mapping, Sequence

import numpy as np

Inputs = Mapping[str, np.ndarray]


@dataclass(frozen=True)
class Term:
    """One regressor: D += x_i * fn(inputs, t_ref). `unit` is the parameter's unit (docs/diagnostics).

    `prior_sigma` is the default 1-sigma of the parameter before any data (SI units), used by the
    filter to build P0; `q_sigma` is its default random-walk sigma per sqrt(s) (process noise Q).
    """
    name: str
    unit: str
    fn: Callable[[Inputs, float], np.ndarray]
    requires: tuple[str, ...]
    prior_sigma: float
    q_sigma: float = 0.0


def temperature_offset(inputs: Inputs, t_ref: float) -> np.ndarray:
    return inputs['temperature'] - t_ref


# Default magnitudes are for a MEMS rate gyro (ADXRS623 class): slopes up to ~0.02 deg/s/degC
# (3.5e-4 rad/s/degC), gradient terms (including the lag of the die behind the temperature sensor)
# up to ~1 deg/s per degC/s (1.75e-2 rad/s per degC/s). The priors matter where the data cannot
# separate the terms: during an exponential warm-up T and dT/dt are exactly collinear, and a loose
# prior lets noisy windows push a and b to absurd, opposite values.
BUILTIN_TERMS: dict[str, Term] = {t.name: t for t in (
    Term('temperature', 'rad/s/degC', temperature_offset, ('temperature',), prior_sigma=3.5e-4, q_sigma=2e-8),
    Term('temperature_rate', 'rad/s/(degC/s)', lambda i, r: i['temperature_rate'],
         ('temperature_rate',), prior_sigma=1.75e-2, q_sigma=2e-6),
    Term('constant', 'rad/s', lambda i, r: np.ones_like(i['temperature']), ('temperature',),
         prior_sigma=1e-2, q_sigma=1e-7),
    # curvature in T (the simple model's known weakness; off by default)
    # (prior: +-0.1 deg/s of curvature 35 degC from t_ref; looser lets early, short-range fits explode)
    Term('temperature_squared', 'rad/s/degC^2', lambda i, r: temperature_offset(i, r) ** 2, ('temperature',),
         prior_sigma=2e-6, q_sigma=1e-10),
    # scale factor k(T) = k1 (T - t_ref) + k0 (docs/design.md section 2, paper 4.3): w_meas = (1 + k) w + D, and
    # w_meas stands in for the true rate (second order in k).
    Term('rate_temperature', '1/degC', lambda i, r: i['rate'] * temperature_offset(i, r), ('rate', 'temperature'),
         prior_sigma=1e-3, q_sigma=1e-8),
    Term('rate', '1', lambda i, r: i['rate'], ('rate',), prior_sigma=3e-2, q_sigma=1e-6),
    # terms `discover` can name (discrepancy/candidates.py) and a model file can add
    Term('temperature_cubed', 'rad/s/degC^3', lambda i, r: temperature_offset(i, r) ** 3, ('temperature',),
         prior_sigma=1e-6, q_sigma=1e-11),
    Term('thermal_branch', 'rad/s', lambda i, r: i['thermal_branch'], ('thermal_branch',),
         prior_sigma=1e-3, q_sigma=1e-8),
)}

PAPER_TERMS = ('temperature', 'temperature_rate', 'constant')   # docs/design.md eq. 2
DEFAULT_TERMS = PAPER_TERMS
# eq. 2 plus curvature in T: real drift is not linear in T (docs/design.md section 2, "why MLR loses");
# with a physical prior it is what keeps coasting right after the temperature turns
CURVATURE_TERMS = PAPER_TERMS + ('temperature_squared',)
SCALE_FACTOR_TERMS = ('rate_temperature', 'rate')


class DriftModel:
    """Linear-in-parameters drift model D = sum_i x_i * term_i(inputs)."""

    def __init__(self, terms: Sequence[str | Term] = DEFAULT_TERMS, temperature_ref_c: float = 25.0):
        self.terms: tuple[Term, ...] = tuple(BUILTIN_TERMS[t] if isinstance(t, str) else t for t in terms)
        names = [t.name for t in self.terms]
        if len(set(names)) != len(names):
            raise ValueError(f'duplicate drift-model terms: {names}')
        self.temperature_ref_c = float(temperature_ref_c)
        self.requires = tuple(sorted({r for t in self.terms for r in t.requires}))

    def __len__(self) -> int:
        return len(self.terms)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(t.name for t in self.terms)

    def index(self, name: str) -> int | None:
        return self.names.index(name) if name in self.names else None

    def rows(self, inputs: Inputs) -> np.ndarray:
        """Regressor rows H, shape (N, len(self)), from named (N,) input arrays."""
        missing = [r for r in self.requires if r not in inputs]
        if missing:
            raise KeyError(f'drift model needs inputs {missing}')
        shape = np.shape(inputs[self.requires[0]])
        out = np.empty(shape + (len(self.terms),))
        for i, t in enumerate(self.terms):
            out[..., i] = t.fn(inputs, self.temperature_ref_c)
        return out

    def neutral_inputs(self, temperature_c, temperature_rate_c_s=0.0, rate_rad_s=0.0) -> dict[str, np.ndarray]:
        """Inputs at the given temperature, its rate and turn rate, every other input 0 (no branch,
        no lag transient): for a drift at a point, not along a record."""
        temp = np.atleast_1d(np.asarray(temperature_c, dtype=float))
        out = {r: np.zeros_like(temp) for r in self.requires}
        out['temperature'] = temp
        out['temperature_rate'] = np.broadcast_to(np.asarray(temperature_rate_c_s, float), temp.shape).copy()
        out['rate'] = np.broadcast_to(np.asarray(rate_rad_s, float), temp.shape).copy()
        return out

    def response(self, x: np.ndarray, inputs: Inputs) -> tuple[np.ndarray, np.ndarray]:
        """(k, D_dot) per row: dD/dw (1; the scale-factor terms' weight on the measured rate) and the
        drift's trend as the temperature goes on along its rate for 1 s (rad/s^2, secant), every
        other input held."""
        zero = {**inputs, 'rate': np.zeros_like(inputs['temperature'])}
        d0 = self.evaluate(x, zero)
        k = self.evaluate(x, {**zero, 'rate': zero['rate'] + 1.0}) - d0 if 'rate' in self.requires else 0.0 * d0
        ahead = {**zero, 'temperature': inputs['temperature'] + inputs['temperature_rate']}
        return k, self.evaluate(x, ahead) - d0

    def evaluate(self, x: np.ndarray, inputs: Inputs) -> np.ndarray:
        """Drift D = H x in rad/s, shape (N,)."""
        return self.rows(inputs) @ np.asarray(x, dtype=float)

    def prior_sigmas(self) -> np.ndarray:
        return np.array([t.prior_sigma for t in self.terms])

    def q_sigmas(self) -> np.ndarray:
        return np.array([t.q_sigma for t in self.terms])

    def initial_state(self, bias_rad_s: float, temperature_c: float,
                      known: Mapping[str, float] | None = None) -> np.ndarray:
        """x0 from a still period: all terms zero (or `known`) except `constant`, set so that
        D(T0, Tdot=0, w=0) equals the measured still bias: c0 = mean(w_meas) - a0 (T0 - t_ref)."""
        known = dict(known or {})
        x = np.array([known.get(n, 0.0) for n in self.names])
        i_c = self.index('constant')
        if i_c is not None and 'constant' not in known:
            x[i_c] = bias_rad_s - float(self.evaluate(x, self.neutral_inputs(temperature_c))[0])
        return x

    def paper_coefficients(self, x: np.ndarray) -> dict[str, float]:
        """Named parameters; `constant` also as the paper's c (drift at T = 0 degC, linear terms)."""
        out = {n: float(v) for n, v in zip(self.names, x)}
        if 'constant' in out and 'temperature' in out:
            t_ref = self.temperature_ref_c
            out['constant_at_0c'] = out['constant'] - out['temperature'] * t_ref + \
                out.get('temperature_squared', 0.0) * t_ref ** 2
        return out
