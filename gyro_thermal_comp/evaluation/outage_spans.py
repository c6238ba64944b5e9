"""Outage spans: each run of magnetic outage in a record and what every heading did inside it.

A span is a run of scored samples inside a magnetic outage (the disturbance truth above the
scorer's threshold, scoring.py). Per span and per method (the oracle included): the heading error
and its excess over the oracle at the span's first and last sample and their largest magnitude.
Per method only: the excess growth it would have had with its drift estimate frozen at the span's
start, and how often its published heading sigma covers the excess grown since the start. A span
that goes on at a batch's end is continued by the next batch.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from .scored_rows import ScoredRows


@dataclass
class SpanScore:
    """One method inside one outage span. Errors rad; growth = end minus start."""
    e_start: float = np.nan
    e_end: float = np.nan
    excess_start: float = np.nan
    excess_end: float = np.nan
    max_abs_error: float = np.nan
    max_abs_excess: float = np.nan
    # the excess growth had the method's drift estimate frozen at the span start (what the paper's
    # KF does): integral of (D_true - D_hat(start)) dt, heading-axis tilt factor taken as 1
    frozen_excess_growth: float = np.nan
    drift_start: float = np.nan
    t_last: float = np.nan
    sigma_samples: int = 0          # samples with a published heading sigma
    sigma_covered: int = 0          # ... where |excess - excess at the start| <= 2 sigma

    @property
    def sigma_coverage(self) -> float:
        """Fraction of the span's samples whose excess growth the published 2-sigma covers (NaN: no sigma)."""
        return self.sigma_covered / self.sigma_samples if self.sigma_samples else np.nan

    @property
    def growth(self) -> float:
        return self.e_end - self.e_start

    @property
    def excess_growth(self) -> float:
        return self.excess_end - self.excess_start


@dataclass
class OutageSpan:
    t_start_s: float
    t_end_s: float                       # time of the last sample inside the span
    methods: dict[str, SpanScore] = field(default_factory=dict)  # includes the oracle
    closed: bool = False                 # False if the record ended inside the span

    @property
    def duration_s(self) -> float:
        return self.t_end_s - self.t_start_s


class OutageSpans:
    """The outage spans of one record in time order, scored batch by batch. `oracle`: the name scored
    for its error and excess only (it has no drift estimate and no sigma); `method_names`: the
    methods."""

    def __init__(self, oracle: str, method_names: Sequence[str]):
        self.oracle = oracle
        self.method_names = list(method_names)
        self.spans: list[OutageSpan] = []
        self._open: OutageSpan | None = None   # the span the last batch ended inside

    def add(self, rows: ScoredRows, errors: dict[str, np.ndarray], excesses: dict[str, np.ndarray]) -> None:
        """One batch: `errors` and `excesses` per method and the oracle (e0 removed), rad."""
        t, outage = rows.t, rows.outage
        if not outage.any():
            if self._open is not None:
                self._open.closed = True
                self._open = None
            return
        edges = np.flatnonzero(np.diff(outage.astype(np.int8))) + 1
        starts = np.concatenate([[0], edges])
        stops = np.concatenate([edges, [t.size]])
        for i0, i1 in zip(starts, stops):
            if not outage[i0]:
                if self._open is not None:
                    self._open.closed = True
                    self._open = None
                continue
            span = self._open
            if span is None:
                span = OutageSpan(float(t[i0]), float(t[i0]),
                                  {n: SpanScore() for n in [self.oracle] + self.method_names})
                self.spans.append(span)
                self._open = span
            span.t_end_s = float(t[i1 - 1])
            for name, sc in span.methods.items():
                e, x = errors[name][i0:i1], excesses[name][i0:i1]
                if np.isnan(sc.e_start):
                    sc.e_start, sc.excess_start = float(e[0]), float(x[0])
                sc.e_end, sc.excess_end = float(e[-1]), float(x[-1])
                if np.isfinite(e).any():
                    sc.max_abs_error = np.nanmax([sc.max_abs_error, np.nanmax(np.abs(e))])
                if np.isfinite(x).any():
                    sc.max_abs_excess = np.nanmax([sc.max_abs_excess, np.nanmax(np.abs(x))])
                if name != self.oracle:
                    self._frozen(sc, t[i0:i1], rows.drift[name][i0:i1], rows.true_drift[i0:i1])
                    sigma = rows.sigma[name][i0:i1]
                    if np.isfinite(sigma).any():   # does the published sigma cover the excess grown since the start?
                        sc.sigma_samples += int(np.count_nonzero(np.isfinite(sigma)))
                        sc.sigma_covered += int(np.count_nonzero(np.abs(x - sc.excess_start) <= 2.0 * sigma))
            if i1 < t.size:
                span.closed = True
                self._open = None

    @staticmethod
    def _frozen(sc: SpanScore, t, drift, d_true) -> None:
        """Integrate D_true - D_hat(start) over these samples of the span into `frozen_excess_growth`."""
        if np.isnan(sc.t_last):
            sc.drift_start, sc.t_last, sc.frozen_excess_growth = float(drift[0]), float(t[0]), 0.0
        dt = np.diff(np.concatenate(([sc.t_last], t)))
        sc.frozen_excess_growth += float(np.nansum((d_true - sc.drift_start) * dt))
        sc.t_last = float(t[-1])
