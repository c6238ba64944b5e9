"""The samples of one output interval [ta, tb], with values at ta and tb interpolated.

A revolution's ends lie on exact boundary angles; there the in-plane values use the same two-point
model as the angle integral (integrals.interpolate_at_angle), so cutting a sample interval at a
boundary changes nothing. Pass-through intervals use plain time interpolation.
"""
from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from .bias_book import SensorBiasBook
from .blocks import CoreBlock
from .integrals import inplane, interpolate_at_angle, time_integral


@dataclass(frozen=True)
class IntervalSignals:
    """Platform-frame signals with the bias estimates removed: arrays, or scalars at one time."""
    t: np.ndarray               # s
    theta: np.ndarray           # carousel angle, rad
    gyro_inplane: np.ndarray    # complex x + i y, rad/s
    accel_inplane: np.ndarray   # complex, m/s^2
    gyro_axial: np.ndarray      # rad/s
    accel_axial: np.ndarray     # m/s^2
    spin: np.ndarray            # rad/s
    mag_inplane: np.ndarray | None = None   # complex, raw magnetometer (hard iron in), T
    mag_axial: np.ndarray | None = None     # T


@dataclass(frozen=True)
class IntervalWindow:
    signals: IntervalSignals    # at ta, at every sample strictly inside, at tb
    inside: CoreBlock           # the buffered samples strictly inside (ta, tb), as stored
    mag_ok: bool = False        # every sample used (the inside and one either side) has a magnetometer value

    @property
    def duration_s(self) -> float:
        return self.signals.t[-1] - self.signals.t[0]

    def time_mean(self, values: np.ndarray):
        """Time mean over the interval of values on the window's grid (trapezoid)."""
        return time_integral(self.signals.t, values) / self.duration_s


def cut_window(samples: CoreBlock, book: SensorBiasBook, ta: float, tb: float,
               theta_a: float | None = None, theta_b: float | None = None) -> IntervalWindow:
    """[ta, tb] from the buffered samples; theta_a/theta_b: exact boundary angles of a revolution."""
    i0 = int(np.searchsorted(samples.t, ta, side='right'))
    i1 = int(np.searchsorted(samples.t, tb, side='left'))
    lo, hi = max(i0 - 1, 0), min(i1 + 1, len(samples.t))
    near = samples.rows(slice(lo, hi))      # the inside plus one sample either side
    bias = book.per_sample(near.source, near.position)
    gyro, accel = near.gyro - bias.gyro, near.accel - bias.accel
    local = IntervalSignals(t=near.t, theta=near.theta, gyro_inplane=inplane(gyro), accel_inplane=inplane(accel),
                            gyro_axial=gyro[:, 2], accel_axial=accel[:, 2], spin=near.spin,
                            mag_inplane=inplane(near.mag), mag_axial=near.mag[:, 2])
    start = _end_point(local, i0 - 1 - lo, ta, theta_a)
    end = _end_point(local, i1 - 1 - lo, tb, theta_b)
    inner = slice(i0 - lo, i1 - lo)
    signals = IntervalSignals(**{f.name: np.concatenate(([getattr(start, f.name)], getattr(local, f.name)[inner],
                                                         [getattr(end, f.name)]))
                                 for f in fields(IntervalSignals)})
    return IntervalWindow(signals, samples.rows(slice(i0, i1)), bool(len(near.t)) and bool(np.all(near.mag_ok)))


def _end_point(local: IntervalSignals, j: int, t_c: float, theta_c: float | None) -> IntervalSignals:
    """Values at time t_c between local samples j and j + 1 (at angle theta_c if given)."""
    t = local.t
    if j + 1 >= len(t) or t[j + 1] == t[j]:
        return IntervalSignals(t_c, local.theta[j] if theta_c is None else theta_c, local.gyro_inplane[j],
                               local.accel_inplane[j], local.gyro_axial[j], local.accel_axial[j], local.spin[j],
                               local.mag_inplane[j], local.mag_axial[j])
    f = (t_c - t[j]) / (t[j + 1] - t[j])

    def lerp(v):
        return v[j] + f * (v[j + 1] - v[j])

    if theta_c is None:
        theta, gyro_inplane, accel_inplane = lerp(local.theta), lerp(local.gyro_inplane), lerp(local.accel_inplane)
        mag_inplane = lerp(local.mag_inplane)
    else:
        th = local.theta
        theta = theta_c

        def at_angle(v):
            return interpolate_at_angle(th[j], th[j + 1], v[j], v[j + 1], theta_c, f)

        gyro_inplane, accel_inplane, mag_inplane = (at_angle(local.gyro_inplane), at_angle(local.accel_inplane),
                                                    at_angle(local.mag_inplane))
    return IntervalSignals(t_c, theta, gyro_inplane, accel_inplane, lerp(local.gyro_axial), lerp(local.accel_axial),
                           lerp(local.spin), mag_inplane, lerp(local.mag_axial))
