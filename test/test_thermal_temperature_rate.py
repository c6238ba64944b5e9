"""dT/dt from a slow, quantized, noisy temperature stream."""
import numpy as np
import pytest

from gyro_thermal_comp.thermal.temperature_rate import TemperatureRateEstimator


def _quantized_ramp(rate_c_s=0.01, hz=1.0, duration_s=600.0, lsb=0.0625, noise=0.01, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration_s, 1.0 / hz)
    true = 25.0 + rate_c_s * t
    return t, np.round((true + noise * rng.standard_normal(t.size)) / lsb) * lsb, true


def test_rate_is_robust_to_quantization():
    t, temp, true = _quantized_ramp()
    est = TemperatureRateEstimator(window_s=60.0)
    out = est.update(t, temp)
    late = t > 60.0
    assert np.all(np.abs(out.rate_c_s[late] - 0.01) < 0.0025)      # within 25 % everywhere
    assert np.mean(out.rate_c_s[late]) == pytest.approx(0.01, rel=0.05)
    assert np.all(np.abs(out.temp_c[late] - true[late]) < 0.06)     # below one quantum
    naive = np.diff(temp) / np.diff(t)                               # what differencing gives
    assert np.max(np.abs(naive[60:] - 0.01)) > 0.05


def test_streaming_equals_batch_and_holds_no_more_than_a_window():
    t, temp, _ = _quantized_ramp(hz=10.0, duration_s=300.0)
    batch = TemperatureRateEstimator(60.0).update(t, temp)
    stream = TemperatureRateEstimator(60.0)
    parts = [stream.update(t[i:i + 7], temp[i:i + 7]) for i in range(0, t.size, 7)]
    assert np.concatenate([p.rate_c_s for p in parts]) == pytest.approx(batch.rate_c_s, abs=1e-12)
    assert np.concatenate([p.temp_c for p in parts]) == pytest.approx(batch.temp_c, abs=1e-9)
    assert stream._buf_t.size <= 601


def test_nan_repeated_and_out_of_order_samples_are_dropped_and_counted():
    t, temp, _ = _quantized_ramp(duration_s=200.0)
    temp = temp.copy()
    temp[50] = np.nan
    t_bad = np.concatenate([t[:100], t[99:100], t[90:91], t[100:]])   # a repeat and a step back
    temp_bad = np.concatenate([temp[:100], temp[99:100], temp[90:91], temp[100:]])
    est = TemperatureRateEstimator(60.0)
    out = est.update(t_bad, temp_bad)
    assert est.guard.dropped_nonfinite == 1 and est.guard.dropped_order == 2
    assert np.all(np.isfinite(out.rate_c_s)) and np.all(np.isfinite(out.temp_c))
    assert np.all(np.diff(out.t) > 0)


def test_stuck_sensor_is_flagged_and_lookup_is_causal():
    est = TemperatureRateEstimator(60.0, stuck_after_s=100.0)
    t = np.arange(0.0, 300.0)
    est.update(t[:50], 25.0 + 0.01 * t[:50])
    assert not est.stuck
    est.update(t[50:], np.full(250, 25.5))
    assert est.stuck and est.stuck_for_s() > 100.0
    # lookup: extrapolate from the last line for at most hold_max_s, never look ahead
    e2 = TemperatureRateEstimator(30.0, hold_max_s=2.0)
    tt = np.arange(0.0, 100.0)
    res = e2.update(tt, 20.0 + 0.1 * tt)
    temp, rate, ok = e2.at(res, np.array([-1.0, 50.5, 99.0, 150.0]), None)
    assert not ok[0] and np.isnan(temp[0])
    assert temp[1] == pytest.approx(20.0 + 0.1 * 50.5, abs=1e-6)
    assert temp[3] == pytest.approx(20.0 + 0.1 * 101.0, abs=1e-6)  # held 2 s after the last one
    assert rate[2] == pytest.approx(0.1)
