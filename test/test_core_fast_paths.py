"""The estimator core's cheap paths for the usual input decide exactly as its general ones.

Each cheap path (a few samples as Python floats, every sample in range, no time gap, one gravity
bin, no flag to set...) is taken or not depending on the batch, so feeding the same samples in
batches of different sizes must give the same numbers; where a rule is simple enough, it is
checked against its definition directly.
"""
import math

import numpy as np
import pytest

from gyro_thermal_comp.thermal.heading_filter import HeadingFilter, HeadingFilterConfig
from gyro_thermal_comp.thermal.imu_stretch import GravityAverage
from gyro_thermal_comp.thermal.output_rows import OutputRows
from gyro_thermal_comp.thermal.reasons import REASON_BIT
from gyro_thermal_comp.thermal.temperature_rate import TemperatureRateEstimator
from gyro_thermal_comp.thermal.time_base import TimeBase, _no_step_back


def _pieces(n: int, sizes, seed: int) -> list[slice]:
    """Consecutive slices of 0..n with lengths drawn from `sizes`."""
    rng = np.random.default_rng(seed)
    cuts, i = [], 0
    while i < n:
        k = int(rng.choice(sizes))
        cuts.append(slice(i, min(i + k, n)))
        i += k
    return cuts


@pytest.mark.parametrize('seed', range(6))
def test_a_few_stamps_are_judged_as_the_definition_says(seed):
    """`_no_step_back` on up to 8 stamps (Python floats) against its definition: all finite, the
    first not more than max_jump_s before `last`, no step back by more than max_jump_s."""
    rng = np.random.default_rng(seed)
    for _ in range(300):
        n = int(rng.integers(1, 9))
        # whole seconds: steps and limits exactly at +-60 s happen
        t = 100.0 + np.concatenate(([0.0], np.cumsum(rng.choice([1.0, 1.0, -1.0, -60.0, -61.0], n - 1))))
        if rng.random() < 0.2:
            t[rng.integers(n)] = rng.choice([np.nan, np.inf, -np.inf])
        last = float(rng.choice([-math.inf, 99.0, 160.0, 161.0]))
        expected = bool(np.all(np.isfinite(t)) and t[0] >= last - 60.0 and np.all(np.diff(t) >= -60.0))
        assert _no_step_back(t, last, 60.0) == expected


def test_time_base_maps_stamps_the_same_in_any_batching():
    """A clock that jumps back and a compass that follows it, cut into batches at the same arrival
    times: a few stamps per batch (the cheap paths) and many give the same internal times."""
    rng = np.random.default_rng(1)
    t_imu = np.concatenate((np.arange(0.0, 300.0, 0.01), np.arange(10.0, 200.0, 0.01)))
    t_mag = np.concatenate((np.arange(0.0, 300.0, 0.1), np.arange(10.0, 200.0, 0.1)))
    t_mag[rng.integers(0, t_mag.size, 5)] = np.nan
    arrival_imu, arrival_mag = 0.01 * np.arange(t_imu.size), 0.1 * np.arange(t_mag.size)
    out = []
    for step_s in ((0.01, 0.08), (5.0, 40.0)):
        edges = np.cumsum(np.random.default_rng(2).uniform(*step_s, 50000))
        edges = np.concatenate(([0.0], edges[edges < arrival_imu[-1]], [np.inf]))
        cut_i, cut_m = arrival_imu.searchsorted(edges), arrival_mag.searchsorted(edges)
        tb = TimeBase(gap_s=1.0, max_jump_s=60.0)
        imu, mag = [], []
        for k in range(edges.size - 1):
            imu.append(tb.imu(t_imu[cut_i[k]:cut_i[k + 1]]))
            mag.append(tb.other('mag', t_mag[cut_m[k]:cut_m[k + 1]]))
        out.append((np.concatenate(imu), np.concatenate(mag), tb.changes))
    (imu_a, mag_a, n_a), (imu_b, mag_b, n_b) = out
    assert n_a == n_b == 1                                    # the jump back: one new time base
    assert np.all(np.diff(imu_a) > 0)                         # internal time keeps increasing
    np.testing.assert_array_equal(imu_a, imu_b)
    np.testing.assert_array_equal(mag_a, mag_b)
    assert np.nanmin(np.diff(mag_a)) > 0                      # the compass follows the new base


def test_a_temperature_spike_inside_a_batch_is_refused_as_one_at_a_time():
    """Readings within the rate limit of the one before pass in one go; a spike inside a batch
    must still be refused, and a real step still taken after `confirm_samples` readings."""
    t = np.arange(0.0, 400.0, 0.5)
    temp = 25.0 + 0.01 * t
    temp[100] += 40.0                    # one spike
    temp[500:] += 8.0                    # a real step, confirmed by the readings after it
    runs = {}
    for name, sizes in (('one', (1,)), ('batches', (7, 60, 250))):
        est = TemperatureRateEstimator(60.0, max_rate_c_s=0.5, confirm_samples=10)
        parts = [est.update(t[sl], temp[sl]) for sl in _pieces(t.size, sizes, 4)]
        runs[name] = (np.concatenate([p.t for p in parts]), np.concatenate([p.temp_c for p in parts]),
                      np.concatenate([p.rate_c_s for p in parts]), est.dropped_rate)
    one, batches = runs['one'], runs['batches']
    assert one[3] == batches[3] == 1 + 9                     # the spike, and the step's first 9
    assert 50.0 not in one[0] and 50.0 not in batches[0]     # (the spike, at 50 s, is not used)
    for a, b in zip(one[:3], batches[:3]):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-9)


def test_gravity_average_is_the_same_in_any_chunking():
    """One 1 s bin per call (a live node's chunks) or many bins per call: the same means (to
    rounding: a bin cut between calls sums its rows in two runs)."""
    rng = np.random.default_rng(5)
    t = np.arange(0.0, 200.0, 0.01) + 0.003
    acc = np.array([0.3, -0.2, 9.8]) + 0.5 * rng.standard_normal((t.size, 3))
    use = rng.random(t.size) > 0.1
    use[:50] = False                                          # nothing usable at first: own values
    means = {}
    for sizes in ((1, 3, 20), (1500, 4000)):
        avg = GravityAverage(30.0)
        means[sizes] = np.concatenate([avg.update(t[sl], acc[sl], use[sl]) for sl in _pieces(t.size, sizes, 6)])
    a, b = means.values()
    np.testing.assert_allclose(a, b, rtol=1e-13, atol=0)
    np.testing.assert_array_equal(a[:50], acc[:50])


def _laps(blocks: int, seed: int):
    """Compass-minus-gyro measurements of a vehicle on square laps at 10 Hz: turns (the scale
    factor applies), compass deviation, noise, and two outliers the innovation test refuses."""
    rng = np.random.default_rng(seed)
    t = 0.1 * np.arange(1, blocks + 1)
    rate = np.where((t % 30.0) > 25.0, np.radians(18.0), 0.0)        # a 90 deg turn every 30 s
    psi_g = np.cumsum(rate * 0.1)
    psi_c = 1.01 * psi_g + np.radians(3.0) * np.sin(psi_g) + np.radians(0.3) * rng.standard_normal(blocks)
    z = psi_c - psi_g
    z[[200, 900]] += np.radians(40.0)
    use = rate == 0.0
    return t, z, psi_g, use


def test_heading_filter_in_one_batch_equals_block_by_block():
    """The filter precomputes what its state does not change (steps, measurement rows) for a whole
    batch: one batch and one block per call give the same output (to rounding: P is symmetrised at
    the end of every call)."""
    t, z, psi_g, use = _laps(1500, 7)
    outs, filters = [], []
    for per_block in (False, True):
        hf = HeadingFilter(HeadingFilterConfig(), math.radians(0.04))
        hf.initialize(0.0, float(z[0]), float(psi_g[0] + z[0]), math.radians(0.5) ** 2, float(psi_g[0]))
        var = np.full(t.size, math.radians(0.3) ** 2)
        if per_block:
            out = np.vstack([hf.run(t[i:i + 1], z[i:i + 1], var[i:i + 1], psi_g[i:i + 1], use[i:i + 1], 1e-4,
                                    jump=i == 700) for i in range(t.size)])
        else:
            out = np.vstack([hf.run(t[:700], z[:700], var[:700], psi_g[:700], use[:700], 1e-4),
                             hf.run(t[700:], z[700:], var[700:], psi_g[700:], use[700:], 1e-4, jump=True)])
        outs.append(out)
        filters.append(hf)
    assert hf.n_rejected >= 2                                 # the outliers were refused
    assert np.array_equal(outs[0][:, 3], outs[1][:, 3])       # the same blocks used
    np.testing.assert_allclose(outs[0], outs[1], rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(filters[0].x, filters[1].x, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(filters[0].P, filters[1].P, rtol=1e-9, atol=1e-15)


def test_output_reasons_are_set_exactly_where_they_are_due():
    """`flagged` skips the flags no row can carry: the reasons must still be exactly their
    definitions, row by row (no compass for mag_timeout_s, a time gap, the still period, a stale
    temperature after the first reading, a stuck one everywhere)."""
    rng = np.random.default_rng(8)
    n = 400
    t = np.sort(rng.uniform(0.0, 100.0, n))
    temp = np.where(rng.random(n) < 0.1, np.nan, 30.0)
    gap = rng.random(n) < 0.05
    rows = OutputRows.initial(np.zeros(3))
    rows = OutputRows(*(np.repeat(getattr(rows, f), n, axis=0) for f in rows.__dataclass_fields__))
    rows = OutputRows(**{**{f: getattr(rows, f) for f in rows.__dataclass_fields__},
                         'temp': temp, 'gap': gap, 'open': np.ones(n, bool)})
    last_mag_t = t - rng.choice([0.0, 0.2, 3.0], n)
    for still_end, first_temp, stuck in ((-1.0, np.inf, False), (30.0, 50.0, False), (200.0, -1.0, True)):
        got = rows.flagged(t, last_mag_t, 1.0, still_end, stuck, first_temp)
        no_mag = t - last_mag_t > 1.0
        want = (np.where(no_mag, REASON_BIT['no_compass'], 0) | np.where(gap, REASON_BIT['time_gap'], 0)
                | np.where(t < still_end, REASON_BIT['still_period'], 0)
                | np.where(np.isnan(temp) & (t >= first_temp), REASON_BIT['temperature_stale'], 0)
                | (REASON_BIT['temperature_stuck'] if stuck else 0))
        np.testing.assert_array_equal(got.reasons, want)
        np.testing.assert_array_equal(got.open, ~no_mag)


def test_core_speed_times_the_loops_over_every_closed_compass_block():
    """benchmarks/core_speed.py times the heading filter and the gate apart: over every block the
    estimator closed in the timed part of the record, and as a part of the estimator's CPU."""
    import importlib.util
    from pathlib import Path
    path = Path(__file__).resolve().parent.parent / 'benchmarks' / 'core_speed.py'
    spec = importlib.util.spec_from_file_location('core_speed', path)
    core_speed = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(core_speed)
    loops = core_speed.block_loops(core_speed.simulated(100.0, 40.0), 10.0, 1)
    # the second 20 s of the record are timed, in 0.1 s blocks (the newest still open at the end)
    assert 195 <= loops['blocks'] <= 200
    assert 0.0 < loops['share_of_estimator'] < 1.0
    assert all(v > 0.0 for v in loops['us_per_block'].values())
