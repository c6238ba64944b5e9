"""Streams as they come, made usable without inventing anything: rows with a non-finite value and
stamps that do not increase are dropped (and counted), gaps are counted and kept, temperature
streams far faster than temperature changes are averaged down. Values are never corrected here:
uncalibrated sensors are the estimator's business (its input guard drops what is out of range)."""
from __future__ import annotations

import numpy as np

from ..samples import TemperatureSamples, slice_samples
from .base import DropReport, sample_fields

GAP_FACTOR = 2.5          # an interval this many median periods long is a gap
TEMPERATURE_MAX_HZ = 10.0  # a gyro temperature changes over seconds: faster readings are averaged


def clean(name: str, samples, report: DropReport):
    """`samples` with non-finite rows and non-increasing stamps dropped; what was dropped and the
    gaps go into `report`. Returns None if nothing is left."""
    if samples is None or not len(samples.t):
        return None
    finite = np.isfinite(samples.t)
    for f in sample_fields(samples):
        v = getattr(samples, f)
        finite &= np.isfinite(v).reshape(len(v), -1).all(axis=1)
    report.add(name, 'not finite', int((~finite).sum()))
    samples = slice_samples(samples, finite)
    if not len(samples.t):
        return None
    order = np.argsort(samples.t, kind='stable')
    late = int(np.sum(np.diff(samples.t) < 0))
    if late:
        samples = slice_samples(samples, order)
        report.add(name, 'out of order (re-sorted, kept)', late)
    keep = np.r_[True, np.diff(samples.t) > 0]
    report.add(name, 'repeated stamp', int((~keep).sum()))
    samples = slice_samples(samples, keep)
    if len(samples.t) > 2:
        dt = np.diff(samples.t)
        gaps = dt > GAP_FACTOR * float(np.median(dt))
        if gaps.any():
            old = report.gaps.get(name, (0, 0.0))
            report.gaps[name] = (old[0] + int(gaps.sum()), max(old[1], float(dt[gaps].max())))
    return samples


def decimate_temperature(samples: TemperatureSamples, max_hz: float = TEMPERATURE_MAX_HZ):
    """Block means of a temperature stream faster than `max_hz` (the readings' quantisation
    averages out; nothing a gyro's temperature does is lost). Returns (samples, note or None)."""
    if samples is None or len(samples.t) < 3:
        return samples, None
    rate = 1.0 / float(np.median(np.diff(samples.t)))
    factor = int(rate // max_hz)
    if factor < 2:
        return samples, None
    n = len(samples.t) // factor * factor
    t = samples.t[:n].reshape(-1, factor).mean(axis=1)
    temp = samples.temp_c[:n].reshape(-1, factor).mean(axis=1)
    return TemperatureSamples(t, temp), f'temperature {rate:.4g} Hz averaged over {factor} readings'
