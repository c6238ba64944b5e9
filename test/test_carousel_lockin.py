"""Synchronous (lock-in) in-plane bias estimation and the bias-measurement source."""
import numpy as np
import pytest

from gyro_thermal_comp.carousel import CarouselConfig, CarouselDemodulator, RevolutionStats
from gyro_thermal_comp.carousel.lockin import LockInEstimator, solve
from gyro_thermal_comp.carousel.synthetic import simulate, spin_rate_profile

G = 9.80665


def test_least_squares_exact_on_partial_wobbly_turns_where_a_mean_fails():
    t = np.linspace(0, 2.6, 400)
    theta = 0.4 + 2 * np.pi * 0.5 * t + 0.3 * np.sin(2.1 * t)          # 1.3 uneven turns
    beta = 0.021 - 0.034j
    body = (0.3 + 0.05 * t) - (0.2 - 0.02 * t) * 1j                      # drifting body in-plane signal
    z = beta + np.exp(-1j * theta) * body
    stats = RevolutionStats.from_samples(t, theta, z, order=1)
    sol = solve([stats], order=1)[0]
    assert abs(sol.bias - beta) < 1e-12
    assert abs(sol.body_inplane - (0.3 + 0.05 * stats.t_ref_s - (0.2 - 0.02 * stats.t_ref_s) * 1j)) < 1e-12
    assert abs(np.mean(z) - beta) > 0.01                                  # naive mean is far off
    # re-basing the normal equations to another reference time changes nothing
    sol2 = solve([stats.rebased(7.0)], order=1, t_ref_s=7.0)[0]
    assert abs(sol2.bias - beta) < 1e-12


def test_sliding_window_combines_revolutions_and_restarts_on_tag_change():
    rng = np.random.default_rng(0)
    est = LockInEstimator(revolutions=3, order=1, max_span_s=100.0)
    for k in range(5):
        t = k + np.linspace(0, 1, 100, endpoint=False)
        th = 2 * np.pi * t
        z = (0.01 + 0.02j) + np.exp(-1j * th) * (1.0 + 0.1 * t) + 1e-3 * rng.standard_normal(100)
        est.add(RevolutionStats.from_samples(t, th, z, 1, k + 0.5), tag='A')
    sol = est.estimate()[0]
    assert sol.n_revolutions == 3 and sol.n_samples == 300
    assert abs(sol.bias - (0.01 + 0.02j)) < 5 * np.sqrt(sol.bias_variance)
    est.add(RevolutionStats.from_samples(t, th, z, 1, 5.0), tag='B')
    assert est.estimate()[0].n_revolutions == 1


@pytest.mark.parametrize('encoder', [True, False])
def test_lockin_recovers_known_inplane_biases(encoder):
    bias_g = np.array([0.023, -0.017, 0.004])
    bias_a = np.array([0.12, -0.07, 0.03])
    tilt = 0.05                                          # rad: gravity has an in-plane body component
    chunk, _ = simulate(40.0, 100.0, spin_rate_profile(1.0, 0.05, 0.2),
                        body_rate=lambda t: np.column_stack((0.01 * np.sin(0.2 * t), 0.005 + 0 * t, 0 * t)),
                        body_force=(G * np.sin(tilt), 0.0, G * np.cos(tilt)), gyro_bias=bias_g,
                        accel_bias=bias_a, gyro_noise=0.003, accel_noise=0.02,
                        encoder_hz=100.0 if encoder else None, seed=11)
    demod = CarouselDemodulator(CarouselConfig(lockin_revolutions=8, lockin_poly_order=1))
    recs = [r for r in demod.update(chunk).records if r.mode == 'demodulated']
    last = recs[-1]
    sigma = np.sqrt(last.gyro_bias_variance)
    assert 1e-5 < sigma < 3e-4
    assert np.all(np.abs(last.gyro_bias_inplane_rad_s - bias_g[:2]) < 4 * sigma + 1e-5)
    assert np.all(np.abs(last.accel_bias_inplane_m_s2 - bias_a[:2]) < 3e-3)
    np.testing.assert_allclose(demod.book.gyro[:2], bias_g[:2], atol=4 * sigma + 1e-5)
    assert not demod.book.known[2]                       # the axial bias is not observable without a flip


def test_bias_measurements_are_independent_calibrated_and_track_thermal_drift():
    """Per-revolution measurements for the thermal estimator: one per in-plane axis per revolution,
    honest variances, and they follow a temperature-driven drift."""
    temp = lambda t: 25.0 + 0.2 * t                       # deg C
    drift = lambda t: np.column_stack((0.01 + 4e-4 * (temp(t) - 25), -0.02 - 2e-4 * (temp(t) - 25), 0 * t))
    chunk, truth = simulate(60.0, 100.0, spin_rate_profile(2.0, 0.05, 0.3), gyro_bias=drift, gyro_noise=0.004,
                            body_rate=(0.0, 0.0, 0.01), encoder_hz=100.0, temperature=temp, seed=12)
    out = CarouselDemodulator().update(chunk)
    meas = out.bias_measurements
    n_rev = sum(r.mode == 'demodulated' for r in out.records)
    assert len(meas) == 2 * n_rev
    for axis, col in (('x', 0), ('y', 1)):
        m = [x for x in meas if x.axis == axis]
        t_mid = np.array([x.t_s - 0.5 * x.duration_s for x in m])
        val = np.array([x.bias_rad_s for x in m])
        var = np.array([x.variance_rad2_s2 for x in m])
        err = val - drift(t_mid)[:, col]
        ratio = np.std(err) / np.sqrt(np.mean(var))
        assert 0.75 < ratio < 1.33                     # reported variance matches the scatter
        assert abs(np.mean(err)) < 3 * np.std(err) / np.sqrt(len(err))
        temps = np.array([x.temperature_c for x in m])
        np.testing.assert_allclose(temps, temp(t_mid), atol=0.02)
        (slope, _), cov = np.polyfit(temps, val, 1, cov=True)
        assert abs(slope - (4e-4, -2e-4)[col]) < 4 * np.sqrt(cov[0, 0])
        assert np.sqrt(cov[0, 0]) < 3e-5                 # the drift slope is resolved (4e-4, 2e-4)
        assert all(x.temperature_rate_c_s == pytest.approx(0.2, rel=1e-6) for x in m if x.t_s > 2.0)


def test_measurements_ignore_a_linear_manoeuvre_within_the_revolution():
    """A body rate ramping during a revolution would leak ~ramp*T/(2pi) into a constant-body fit;
    the default first-order body model keeps it out of the bias measurement."""
    bias = np.array([0.01, -0.02, 0.0])
    chunk, _ = simulate(12.0, 100.0, spin_rate_profile(0.5, 0.05, 0.2),
                        body_rate=lambda t: np.column_stack((0.005 * t, -0.003 * t, 0 * t)),
                        gyro_bias=bias, encoder_hz=100.0)
    errs = {}
    for order in (0, 1):
        meas = CarouselDemodulator(CarouselConfig(measurement_poly_order=order)).update(chunk).bias_measurements
        errs[order] = max(abs(m.bias_rad_s - bias['xyz'.index(m.axis)]) for m in meas)
    assert errs[1] < 1e-10
    assert errs[0] > 5e-4
