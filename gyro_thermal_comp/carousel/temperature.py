"""Gyro temperature over an output interval: its time mean, and its rate for bias measurements."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..samples import TemperatureSamples
from .blocks import TemperatureBlock
from .buffers import Columns
from .integrals import time_integral


@dataclass(frozen=True)
class IntervalTemperature:
    mean_c: float | None          # None: no temperature stream
    rate_c_s: float | None        # None: fewer than two samples in the rate window


class TemperatureTrack:
    """Guarded temperature samples, kept as long as an interval or the rate window may need them."""

    def __init__(self, rate_window_s: float):
        self.rate_window_s = rate_window_s
        self._samples = Columns(TemperatureBlock)

    def add(self, samples: TemperatureSamples | None) -> None:
        if samples is not None:
            self._samples.append(TemperatureBlock(t=samples.t, temp_c=samples.temp_c))

    def over(self, ta: float, tb: float) -> IntervalTemperature:
        """Mean over [ta, tb] and LS slope over the rate window ending at tb; older samples are dropped."""
        samples = self._samples.view()
        tt, temp = samples.t, samples.temp_c
        if len(tt) == 0:
            return IntervalTemperature(None, None)
        # Time mean of the piecewise-linear temperature over [ta, tb] (held beyond the samples), so a
        # 1 Hz sensor still gives the right mean over a 0.25 s revolution.
        inside = (tt > ta) & (tt < tb)
        pts = np.concatenate(([ta], tt[inside], [tb]))
        mean = float(time_integral(pts, np.interp(pts, tt, temp)) / (tb - ta))
        rate = None
        recent = (tt >= tb - self.rate_window_s) & (tt <= tb)
        if np.count_nonzero(recent) >= 2 and np.ptp(tt[recent]) > 0:
            rate = float(np.polyfit(tt[recent] - tb, temp[recent], 1)[0])
        self._samples.drop_front(int(np.searchsorted(tt, ta - self.rate_window_s)) - 1)
        return IntervalTemperature(mean, rate)
