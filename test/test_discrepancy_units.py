"""Discrepancy workflow building blocks: binning, terms, filters, fitting, errors (fast)."""
import math

import numpy as np
import pytest

from gyro_thermal_comp.discrepancy import DiscoveryInputError, bin_chunks, discover
from gyro_thermal_comp.discrepancy import terms as T
from gyro_thermal_comp.discrepancy.model import BlockStats
from gyro_thermal_comp.discrepancy.selection import Criteria, _t_noise
from gyro_thermal_comp.discrepancy.stochastic import whiteness
from gyro_thermal_comp.discrepancy.wander import fit_wander, local_level
from gyro_thermal_comp.samples import ImuSamples, SensorChunk, TemperatureSamples, VectorSamples
from gyro_thermal_comp.thermal.drift_model import DriftModel


def _static_chunks(duration_s=600.0, rate=10.0, bias=0.01, sigma=0.002, seed=0, chunk_s=60.0):
    rng = np.random.default_rng(seed)
    t_all = np.arange(0.0, duration_s, 1.0 / rate)
    for t0 in np.arange(0.0, duration_s, chunk_s):
        t = t_all[(t_all >= t0) & (t_all < t0 + chunk_s)]
        gyro = np.column_stack([np.full(t.size, bias)] * 3) + sigma * rng.standard_normal((t.size, 3))
        accel = np.tile([0.0, 0.0, 9.81], (t.size, 1))
        tt = t[::10]
        yield SensorChunk(imu=ImuSamples(t, gyro, accel),
                          temperature=TemperatureSamples(tt, 25.0 + 0.001 * tt),
                          gyro_bias=VectorSamples(t, np.full((t.size, 3), np.nan)))   # truth: must be ignored


def test_binning_means_and_own_noise_estimate():
    d = bin_chunks(_static_chunks(chunk_s=37.0), 'static', bin_s=1.0)   # chunk edges inside bins
    assert len(d.t) == 600 and np.all(d.n_imu == 10)
    assert np.allclose(d.gyro.mean(axis=0), 0.01, atol=1e-4)
    # within-bin variance of one sample, pooled: the white noise the workflow scores against
    assert np.allclose(np.sqrt(d.gyro_noise_var), 0.002, rtol=0.05)
    assert np.allclose(d.temp_c[~np.isnan(d.temp_c)][:3], 25.0 + 0.001 * np.array([0.0, 1.0, 2.0]))


def test_truth_drift_stream_is_never_read():
    d = bin_chunks(_static_chunks(), 'static')
    assert np.all(np.isfinite(d.gyro))   # the NaN truth stream did not leak in


def test_odom_reference_needs_odom():
    with pytest.raises(DiscoveryInputError, match='odom'):
        bin_chunks(_static_chunks(), 'odom')
    with pytest.raises(DiscoveryInputError):
        bin_chunks(_static_chunks(), 'nonsense')


def _turning(chunks, every_s=20.0, turn_s=4.0, rate_rad_s=0.35):
    """The same record with a 20 deg/s yaw turn of turn_s every every_s (a vehicle, not a bench)."""
    for c in chunks:
        g = c.imu.gyro.copy()
        g[:, 2] += rate_rad_s * ((c.imu.t % every_s) < turn_s)
        yield SensorChunk(imu=ImuSamples(c.imu.t, g, c.imu.accel), temperature=c.temperature)


def test_static_reference_refuses_a_unit_that_turns():
    """A moving record under reference 'static' would put the turns into the drift fit (a vehicle
    calibration run gave b = 2.3 deg/s per degC/s, and the STKF running that model had a median max
    heading error of 3259 deg on the vehicle records).
    A few bumps (under 1 % of the bins) are a bench, not a vehicle."""
    with pytest.raises(DiscoveryInputError, match=r"reference 'static', but the unit turned: 20 % .*odom"):
        bin_chunks(_turning(_static_chunks()), 'static')
    d = bin_chunks(_turning(_static_chunks(), every_s=300.0, turn_s=2.0), 'static')   # two 2 s bumps
    assert len(d.t) == 600


def test_first_order_lag_is_exact_for_a_ramp():
    step, tau = 1.0, 50.0
    t = np.arange(0, 2000.0, step)
    u = 0.01 * t
    y = T.first_order_lag(u, step, tau)
    exact = 0.01 * (t - tau * (1 - np.exp(-t / tau)))   # lag of a ramp from equilibrium at 0
    assert np.max(np.abs(y - exact)) < 1e-9
    t_die, rate = T.die_temperature(u, step, tau)
    assert abs(rate[-1] - 0.01) < 1e-6


def test_thermal_branch_signs():
    rate = np.concatenate([np.full(1000, 0.01), np.zeros(200), np.full(1000, -0.01)])
    m = T.thermal_branch(rate, 1.0, 100.0, 0.001)
    assert m[999] > 0.99 and m[-1] < -0.99 and 0 < m[1199] < m[999]


def test_library_terms_extend_drift_model():
    from gyro_thermal_comp.thermal import drift_model as dm
    builtin = dict(dm.BUILTIN_TERMS)
    model = T.drift_model(('constant', 'temperature', 'temperature_rate', 'temperature_squared',
                           'temperature_cubed', 'specific_force_x', 'thermal_branch'))
    inputs = {'temperature': np.array([25.0, 35.0]), 'temperature_rate': np.zeros(2),
              'specific_force_x': np.array([0.0, 1.0]), 'thermal_branch': np.array([1.0, -1.0])}
    H = model.rows(inputs)
    assert H.shape == (2, 7) and H[1, 4] == pytest.approx(1000.0)
    assert dm.BUILTIN_TERMS == builtin                       # thermal's own term table is untouched
    assert len(DriftModel(T.drift_model(('constant', 'temperature_cubed')).terms)) == 2   # terms as objects


def test_block_cv_matches_direct_refits():
    rng = np.random.default_rng(1)
    n, K = 600, 5
    X = np.column_stack([np.ones(n), rng.standard_normal(n)])
    y = 0.3 + 2.0 * X[:, 1] + rng.standard_normal(n)
    batch = np.arange(n) // 20
    batch_fold = np.arange(batch.max() + 1) * K // (batch.max() + 1)
    st = BlockStats(X, y, np.ones(n), batch, batch_fold, K)
    held, train, betas, held_b = st.cv()
    fold = batch_fold[batch]
    for k in range(K):
        tr = fold != k
        beta = np.linalg.lstsq(X[tr], y[tr], rcond=None)[0]
        assert held[k] == pytest.approx(np.sum((y[~tr] - X[~tr] @ beta) ** 2), rel=1e-9)
    assert held_b.sum() == pytest.approx(held.sum())


def test_local_level_smoother_interpolates_a_gap():
    m = np.concatenate([np.zeros(20), np.full(10, np.nan), np.ones(20)])
    xs, ll = local_level(m, np.full(m.size, 1e-4), 1e-3)
    assert xs[5] == pytest.approx(0.0, abs=0.02) and xs[-5] == pytest.approx(1.0, abs=0.02)
    assert 0.2 < xs[25] < 0.8                       # the gap is bridged, not held
    assert math.isfinite(ll)


def test_whiteness_flags_structure_only():
    rng = np.random.default_rng(3)
    n = 7200
    var = np.full((n, 1), 1.0)
    white = rng.standard_normal((n, 1))
    assert whiteness(white, var, np.ones(n, bool), 1.0).p_min > 1e-3
    wavy = white + 0.5 * np.sin(2 * np.pi * np.arange(n) / 600.0)[:, None]
    assert whiteness(wavy, var, np.ones(n, bool), 1.0).p_min < 1e-6


def test_too_short_record_is_a_clear_error():
    with pytest.raises(ValueError, match='too little data'):
        discover(_static_chunks(duration_s=60.0), 'static')


def test_heldout_gain_t_counts_noise_not_the_unevenness_of_the_structure():
    """The gain of a batch is |delta|^2 + 2 e.delta: only the cross term is noise. Under the null the
    test keeps its level; a real structure present in one batch of six only is not penalised for
    its unevenness, as a t over the spread of the batch gains is."""
    rng = np.random.default_rng(1)
    nb, n = 120, 60
    crit = Criteria()
    false = 0
    for _ in range(400):
        delta = 0.05 * rng.standard_normal((nb, n))            # a spurious held-out change
        e = rng.standard_normal((nb, n)) - delta                # the candidate's held-out residual
        t, dof = _t_noise(((e + delta) ** 2 - e ** 2).sum(1), (e * delta).sum(1))
        false += t >= crit.t_crit(dof)
    assert false <= 8                                          # 1 % level (+ slack): <= 2 %
    delta = np.zeros((nb, n))
    delta[::6] = 0.35                                          # structure in one batch of six
    e = rng.standard_normal((nb, n))
    gains = ((e + delta) ** 2 - e ** 2).sum(1)
    t, dof = _t_noise(gains, (e * delta).sum(1))
    t_spread = gains.mean() / (gains.std(ddof=1) / math.sqrt(nb))
    assert t >= crit.t_crit(dof) and t > 1.3 * t_spread


def _wander_data(seed, markov, J=960, step=30.0):
    rng = np.random.default_rng(seed)
    t = np.arange(J) * step
    X = np.column_stack([np.ones(J), np.sin(np.pi * t / t[-1]), (t / t[-1]) ** 2])   # slow regressors
    if markov:                                                  # Gauss-Markov, tau 300 s, sigma 3
        phi, x = math.exp(-step / 300.0), np.zeros(J)
        for j in range(1, J):
            x[j] = phi * x[j - 1] + 3.0 * math.sqrt(1.0 - phi * phi) * rng.standard_normal()
    else:
        x = np.cumsum(0.5 * rng.standard_normal(J))
    return x + X @ [3.0, 2.0, -1.0] + rng.standard_normal(J), np.ones(J), X


@pytest.mark.parametrize('markov', [False, True])
def test_gauss_markov_bias_told_from_random_walk(markov):
    """Restricted likelihood with the model's slow regressors estimated jointly: a random walk is
    not mistaken for a mean-reverting bias (detrending alone makes it look so), and a Gauss-Markov
    bias of tau 300 s is, over 8 h, with its tau recovered."""
    m, v, X = _wander_data(0, markov)
    fit = fit_wander(m, v, X, 30.0)
    ll_rw, tau, ll_gm, ll0 = fit.random_walk.loglik, fit.gauss_markov.tau_s, fit.gauss_markov.loglik, fit.loglik_none
    assert ll_rw > ll0 + 50                                     # a strong wander either way
    gain = 2.0 * (ll_gm - ll_rw)                                # the mean reversion's evidence
    if markov:
        assert gain > 2.0 * math.log(m.size) and 150.0 < tau < 600.0
    else:
        assert gain < math.log(m.size)


def test_one_sample_per_bin_noise_estimate_is_unbiased_despite_quantisation():
    """At one IMU sample per bin the noise comes from bin-to-bin differences; quantised samples
    (ADXRS623: the noise is ~7 LSB at 1 Hz) must not bias it (a median of them moves in LSB steps)."""
    lsb, sigma = 0.0061, 0.04
    rng = np.random.default_rng(5)

    def chunks():
        for t0 in np.arange(0.0, 7200.0, 60.0):
            t = t0 + np.arange(60.0)
            g = np.radians(lsb * np.round(sigma * rng.standard_normal((60, 3)) / lsb))
            yield SensorChunk(imu=ImuSamples(t, g, np.tile([0.0, 0.0, 9.81], (60, 1))),
                              temperature=TemperatureSamples(t, np.full(60, 25.0)))
    d = bin_chunks(chunks(), 'static')
    assert np.all(d.n_imu == 1) and d.notes
    assert np.allclose(np.degrees(np.sqrt(d.gyro_noise_var)), math.sqrt(sigma ** 2 + lsb ** 2 / 12), rtol=0.02)
