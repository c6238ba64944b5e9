"""The outage information floor: the Gauss-Markov bound it states matches a Monte Carlo of the
least-squares predictor it describes; the wander floor matches a Monte Carlo of the bias it describes."""
import numpy as np
import pytest
from scipy.signal import lfilter

from gyro_thermal_comp.evaluation.information_floor import outage_floor_rad, wander_floor_rad
from gyro_thermal_comp.thermal.drift_model import DriftModel, PAPER_TERMS


def _profile():
    """Heating at a varying rate, then a hold: T degC and dT/dt degC/s at 1 s."""
    t = np.arange(0.0, 3000.0)
    rate = np.where(t < 2000, 0.006 + 0.004 * np.sin(t / 300.0), 0.0)
    return t, 23.0 + np.cumsum(rate), rate


def test_floor_matches_a_monte_carlo_of_the_least_squares_prediction():
    t, temp, rate = _profile()
    arw, window = np.radians(0.04), 10.0
    spans = [(1200.0, 1500.0), (2100.0, 2700.0)]
    floor = outage_floor_rad(t, temp, rate, spans, arw, window_s=window)
    # the same windows, noisy measurements of a true paper-model drift, LS fit, predict the outage
    edges = np.arange(t[0], t[-1] + window, window)
    mid = 0.5 * (edges[:-1] + edges[1:])
    H = DriftModel(PAPER_TERMS).rows({'temperature': np.interp(mid, t, temp),
                                      'temperature_rate': np.interp(mid, t, rate), 'rate': 0 * mid})
    rng = np.random.default_rng(0)
    x_true = np.array([1e-4, 2e-3, -3e-3])
    for (t0, t1), f in zip(spans, floor):
        before = (edges[1:] <= t0) & (edges[:-1] >= 30.0) & ~((edges[1:] > 1200) & (edges[:-1] < 1500))
        inside = (mid >= t0) & (mid < t1)
        errs = []
        for _ in range(400):
            y = H[before] @ x_true + rng.normal(0.0, arw / np.sqrt(window), np.count_nonzero(before))
            x = np.linalg.lstsq(H[before], y, rcond=None)[0]
            errs.append(np.sum(H[inside] @ (x - x_true)) * window)
        assert np.std(errs) == pytest.approx(f, rel=0.12)
    assert np.all(np.isfinite(floor))


def test_no_windows_before_the_outage_gives_nan():
    t, temp, rate = _profile()
    assert np.isnan(outage_floor_rad(t, temp, rate, [(20.0, 300.0)], np.radians(0.04))[0])


@pytest.mark.parametrize('duration_s', [300.0, 600.0])
def test_wander_floor_matches_a_monte_carlo_of_the_wandering_bias(duration_s):
    """A Gauss-Markov bias (sigma 0.002 deg/s, tau 300 s, stationary start) plus a rate random walk
    (5e-5 deg/s/sqrt(s)), integrated over the outage against the best prediction from the exact bias
    at its start; holding the start value instead is worse (the decay is part of the best prediction)."""
    sigma, tau, q, dt, n = np.radians(0.002), 300.0, np.radians(5e-5), 0.5, 3000
    rng = np.random.default_rng(1)
    steps = int(duration_s / dt)
    phi = np.exp(-dt / tau)
    b0 = sigma * rng.standard_normal(n)
    gm, _ = lfilter([1.0], [1.0, -phi], sigma * np.sqrt(1 - phi ** 2) * rng.standard_normal((n, steps)),
                    axis=1, zi=(phi * b0)[:, None])
    gm = np.concatenate((b0[:, None], gm), axis=1)
    rw = np.concatenate((np.zeros((n, 1)), np.cumsum(q * np.sqrt(dt) * rng.standard_normal((n, steps)), axis=1)), axis=1)
    t = np.arange(steps + 1) * dt
    integral = np.trapezoid(gm + rw, t, axis=1)
    best = integral - b0 * tau * (1.0 - np.exp(-duration_s / tau))
    held = integral - b0 * duration_s
    floor = wander_floor_rad(duration_s, sigma, tau, q)
    assert np.std(best) == pytest.approx(floor, rel=0.06)
    assert np.std(held) > 1.1 * floor
    assert wander_floor_rad(duration_s, sigma, tau, 0.0) < floor          # both parts count
    assert wander_floor_rad(duration_s, 0.0, tau, q) == pytest.approx(q * duration_s ** 1.5 / np.sqrt(3.0))
