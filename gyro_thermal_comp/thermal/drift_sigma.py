"""`DriftSigma`: the 1-sigma of the drift estimate D_hat that the heading uncertainty integrates
(docs/design.md eq. 13), rad/s, in two accounts:
  gate      the model's own: sigma_d from the learner's P (drift_learning.py) and the variance the
            model's change since the last update adds (coasting.py: along P, beyond the covered
            inputs). The magnetic gate keeps this one: a wider allowance lets a slow disturbance
            back in (on a family-B outage it reopened inside a 27 deg rotation);
  heading   that plus what past predictions of this age missed beyond it (backtest.py, taken at
            each filter event) and the change the model foresaw but did not follow (coasting.py),
            for the heading filter and the published sigma.
Both are widened while the temperature is stale (inputs.py), and neither is ever smaller than since
the last compass correction: a learner step may shrink sigma_d, but not the error of a heading
nothing has measured since.
"""
from __future__ import annotations

import math
from typing import Callable

from .backtest import DriftBacktest
from .coasting import DriftPrediction
from .compass_blocks import HeadingRecords


class DriftSigma:
    """The two drift 1-sigmas now (`now`), and the largest of them since the last compass correction
    (`coast`), from the drift prediction's added variances."""

    def __init__(self, prediction: DriftPrediction):
        self.prediction = prediction
        self.coast = (0.0, 0.0)          # largest drift sigmas since the last compass correction, rad/s
        self.t_correction = -math.inf    # time of that correction, s
        self.backtest_var = 0.0          # what past predictions of the live age missed beyond P, (rad/s)^2

    def refresh(self, tick: float, backtest: DriftBacktest | None) -> None:
        """At a filter event `tick` (s): what past predictions of the live age missed (None: not counted)."""
        self.backtest_var = backtest.variance_at(tick - backtest.t_update) if backtest is not None else 0.0

    def now(self, sigma_d: float, latest: HeadingRecords,
            widen: Callable[[float], float] | None = None) -> tuple[float, float]:
        """(gate, heading) 1-sigmas from the learner's `sigma_d` (rad/s); `latest`: the newest compass
        block (open: a compass correction); `widen`: the stale-temperature widening of a sigma."""
        pred = self.prediction
        learned = sigma_d ** 2 + pred.var_change + pred.var_beyond
        sigmas = (math.sqrt(learned), math.sqrt(learned + self.backtest_var + pred.var_unfollowed))
        if widen is not None:
            sigmas = tuple(widen(s) for s in sigmas)
        if latest.open[0] and latest.t[0] != self.t_correction:   # a compass correction since
            self.t_correction = float(latest.t[0])
        else:
            sigmas = tuple(max(s, c) for s, c in zip(sigmas, self.coast))
        self.coast = sigmas
        return sigmas

    def published(self, sigma_d: float) -> float:
        """The heading account as last recorded, or `sigma_d` where larger (no side effect), rad/s."""
        return max(self.coast[1], sigma_d)
