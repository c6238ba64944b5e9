"""The heading filter's run of refused compass measurements.

A compass measurement whose innovation exceeds `reject_sigma` standard deviations is refused (a
disturbance that the field tests could not see, e.g. one that began during a turn, when there is no
reference). If the compass keeps disagreeing for `reject_max_s` and steadily (innovations within
`reject_steady_rad` of a straight line in time: an offset or a drift error, not a breathing
disturbance), the filter must be what is wrong: the measurement is taken, with the offset variance
inflated by the disagreement so that the filter re-converges on the compass.
"""
from __future__ import annotations

import numpy as np


class CompassRefusals:
    """The current run of refused compass measurements, and how many were refused in all.
    `reject_max_s` (s) and `reject_steady_rad` (rad) as in `HeadingFilterConfig`; the innovation test
    itself is the filter's."""

    def __init__(self, reject_max_s: float, reject_steady_rad: float):
        self.reject_max_s = reject_max_s
        self.reject_steady_rad = reject_steady_rad
        self.t_start: float | None = None   # start of the current run of refused measurements, s
        self.sums = np.zeros(6)             # sums over the run's innovations: n, t, t^2, nu, t nu, nu^2
        self.n_rejected = 0

    def refuse(self, t: float, nu: float) -> bool:
        """For a measurement at time t (s) whose innovation nu (rad) failed the filter's test: True to
        refuse it; False once the disagreement has lasted `reject_max_s` and is steady, when the filter
        is what is wrong and takes the measurement with its offset variance inflated by nu^2. A
        measurement that passes the test ends the run (`t_start = None`)."""
        if self.t_start is None:
            self.t_start = t
            self.sums[:] = 0.0
        u = t - self.t_start
        self.sums += (1.0, u, u * u, nu, u * nu, nu * nu)
        if u < self.reject_max_s:
            self.n_rejected += 1
            return True
        # residual variance of the refused innovations about a straight line in time
        n, st, stt, sn, stn, snn = self.sums
        vt = stt - st * st / n
        vn = snn - sn * sn / n
        cov = stn - st * sn / n
        resid = max(vn - (cov * cov / vt if vt > 0 else 0.0), 0.0) / n
        if resid > self.reject_steady_rad ** 2:
            self.n_rejected += 1
            self.t_start = t  # judge steadiness afresh over the next period
            self.sums[:] = 0.0
            return True
        self.t_start = None
        return False
