"""`discover` memory does not grow with the record beyond its binned data.

The cause fixed: every candidate variant's fit (hundreds per analysis: one per time constant, rate
scale, time offset, per axis) kept its (bins x k) design, target and per-batch Grams, so memory grew
as bins x variants, and the variant grids widen with the record (341 MB for 2 h, 2.16 GB for 8 h).
A fit now keeps only fold sums and one number per 60 s batch; designs are rebuilt when needed.
Both tests measure allocation sizes (tracemalloc, nbytes), never time. Fast: a few seconds."""
import tracemalloc

import numpy as np

from gyro_thermal_comp.discrepancy import bin_chunks, discover
from gyro_thermal_comp.discrepancy.candidates import ThermalCurvature, ThermalLag
from gyro_thermal_comp.discrepancy.model import Analysis, base_spec
from gyro_thermal_comp.discrepancy.selection import Criteria, score_all
from gyro_thermal_comp.samples import ImuSamples, SensorChunk, TemperatureSamples

LIBRARY = (ThermalCurvature(), ThermalLag())   # thermal_lag: its tau grid widens with the record


def _chunks(duration_s: float, rate_hz: float = 2.0, seed: int = 0):
    """A static unit heated and cooled once (degC), drift with curvature (rad/s), white noise."""
    rng = np.random.default_rng(seed)
    temp_of = lambda t: 25.0 + 20.0 * np.sin(np.pi * t / duration_s)
    for t0 in np.arange(0.0, duration_s, 600.0):
        t = np.arange(t0, min(t0 + 600.0, duration_s), 1.0 / rate_hz)
        dT = temp_of(t) - 25.0
        gyro = (1e-3 * dT + 2e-5 * dT ** 2)[:, None] + 2e-3 * rng.standard_normal((t.size, 3))
        tt = t[::int(rate_hz)]
        yield SensorChunk(imu=ImuSamples(t, gyro, np.tile([0.0, 0.0, 9.81], (t.size, 1))),
                          temperature=TemperatureSamples(tt, temp_of(tt)))


def _owned_bytes(comp, shared) -> int:
    """Bytes of the numpy arrays a fitted component keeps for itself (not the analysis' shared ones)."""
    arrays = [v for v in vars(comp.stats).values() if isinstance(v, np.ndarray)]
    arrays += [a for a in comp.stats.cv() if isinstance(a, np.ndarray)]
    arrays += [v for v in vars(comp).values()
               if isinstance(v, np.ndarray) and not any(np.shares_memory(v, s) for s in shared)]
    return sum(a.nbytes for a in arrays)


def test_a_cached_fit_keeps_less_than_one_number_per_bin():
    data = bin_chunks(_chunks(7200.0), 'static')
    n_bins = len(data.t)
    an = Analysis(data)
    score_all(an, base_spec(data), Criteria(), LIBRARY)
    assert len(an._fits) > 30   # every thermal_lag variant is cached
    shared = (an.gyro_w, an.mask)
    worst = max(_owned_bytes(c, shared) for fit in an._fits.values() for c in fit.comps)
    # a (bins x k) design alone would be >= 8 * k * n_bins bytes (k >= 3 here)
    assert worst < 8 * n_bins, (worst, 8 * n_bins)


def test_discover_peak_grows_less_than_linearly_with_bins():
    peaks = {}
    for n in (1800, 7200):
        data = bin_chunks(_chunks(float(n)), 'static')
        tracemalloc.start()
        try:
            base = tracemalloc.get_traced_memory()[0]
            result = discover(None, data=data, library=LIBRARY, max_effects=1)
            peaks[n] = tracemalloc.get_traced_memory()[1] - base
        finally:
            tracemalloc.stop()
        assert result.effects == ['thermal_curvature']   # the analysis did its job on both
    # keeping every variant's design gave 4.1x for 4x the bins (and 9 kB per bin); the transient
    # per-bin arrays of one fit at a time now give ~2.4x and ~0.5 kB per bin
    assert peaks[7200] <= 3.0 * peaks[1800], peaks
    assert peaks[7200] / 7200 < 2000.0, peaks
