"""STKF, drift measurement and drift model on plain synthetic arrays (no simulator)."""
import numpy as np
import pytest

from gyro_thermal_comp.thermal.drift_model import BUILTIN_TERMS, DriftModel, Term
from gyro_thermal_comp.thermal.stkf import DriftWindow, StrongTrackingKF



def _window_measurement(d_true, d_hat, edge_s=1.0, rate_hz=100.0, mag_hz=50.0, t0=0.0, t1=10.0):
    """One window on a motionless unit: gyro heading integrates d_true - d_hat, compass constant."""
    t_imu = np.arange(t0, t1, 1.0 / rate_hz)
    dt = 1.0 / rate_hz
    psi_g = np.cumsum(np.full(t_imu.size, (d_true - d_hat) * dt))
    i_d = np.cumsum(np.full(t_imu.size, d_hat * dt))
    model = DriftModel(('constant',))
    i_h = np.cumsum(np.full((t_imu.size, 1), dt), axis=0)
    tau = np.arange(t0, t1, 1.0 / mag_hz)
    k = np.searchsorted(t_imu, tau, side='right') - 1
    w = DriftWindow(t0, t1, edge_s, len(model))
    w.add(tau, psi_g[k] + i_d[k] - 0.0, i_h[k])
    return w.measurement(arw_rad_sqrt_s=np.radians(0.04), compass_var_rad2=np.radians(0.3) ** 2, r_floor=0.0)


@pytest.mark.parametrize('edge_s', [0.0, 1.0])
def test_positive_true_drift_gives_positive_measurement(edge_s):
    y, h, r, length = _window_measurement(d_true=np.radians(0.05), d_hat=0.0, edge_s=edge_s)
    assert y > 0
    assert y == pytest.approx(np.radians(0.05), rel=1e-6)
    assert h[0] == pytest.approx(1.0, rel=1e-6)  # window mean of the constant regressor
    assert r > 0 and length > 5.0


def test_measurement_is_exact_whatever_was_applied():
    """Exact form: y = mean applied D_hat + dpsi/dt does not depend on the D_hat in force."""
    y0 = _window_measurement(d_true=np.radians(0.02), d_hat=0.0)[0]
    y1 = _window_measurement(d_true=np.radians(0.02), d_hat=np.radians(0.07))[0]
    y2 = _window_measurement(d_true=np.radians(0.02), d_hat=np.radians(-0.03))[0]
    assert y0 == pytest.approx(np.radians(0.02), rel=1e-6)
    assert y1 == pytest.approx(y0, rel=1e-6) and y2 == pytest.approx(y0, rel=1e-6)
    # and the sign follows the residual: D_hat too large -> psi_g runs backwards, y still = D
    assert y1 > 0


def test_window_without_compass_at_both_ends_is_refused():
    w = DriftWindow(0.0, 10.0, 1.0, 1)
    tau = np.linspace(0.0, 0.5, 10)
    w.add(tau, np.zeros(10), np.zeros((10, 1)))
    assert w.measurement(1e-3, 1e-6, 0.0) is None


def _windows(x_true, n=600, window_s=10.0, sigma=np.radians(0.01), seed=0):
    """Window-mean regressors [T - 25, Tdot, 1] along heating and cooling at varying rates."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * window_s
    temp = 25.0 + 15.0 * np.sin(2 * np.pi * t / 3000.0) + 5.0 * np.sin(2 * np.pi * t / 1100.0)
    tdot = np.gradient(temp, t)
    h = np.column_stack([temp - 25.0, tdot, np.ones(n)])
    y = h @ x_true + sigma * rng.standard_normal(n)
    return h, y, sigma ** 2


def test_filter_recovers_a_b_c_from_a_linear_truth():
    x_true = np.array([np.radians(-0.006), np.radians(0.5), np.radians(0.2)])   # per degC, per degC/s, constant
    h, y, r = _windows(x_true)
    kf = StrongTrackingKF(np.zeros(3), np.diag([1e-3, 5e-2, 1e-2]) ** 2, np.zeros((3, 3)), fading_s=1.0)
    for hk, yk in zip(h, y):
        kf.step(yk, hk, r)
    sig = np.sqrt(np.diag(kf.P))
    assert np.all(np.abs(kf.x - x_true) < 4 * sig)
    assert kf.x[0] == pytest.approx(x_true[0], rel=0.05)
    assert kf.x[1] == pytest.approx(x_true[1], rel=0.1)
    assert kf.x[2] == pytest.approx(x_true[2], rel=0.02)


def test_fading_factor_tracks_a_step_faster():
    rng = np.random.default_rng(1)
    sigma = np.radians(0.01)
    c_before, c_after = np.radians(0.1), np.radians(0.15)
    errors = {}
    for s in (1.0, 1.1):
        # the fading alone (no divergence reset, which would rescue the plain filter too: see below)
        kf = StrongTrackingKF([0.0], [[np.radians(0.1) ** 2]], [[0.0]], fading_s=s, reject_sigma=1e9,
                              diverged_nis=np.inf)
        err = []
        for k in range(600):
            c = c_before if k < 300 else c_after
            kf.step(c + sigma * rng.standard_normal(), [1.0], sigma ** 2)
            if 300 <= k < 340:
                err.append(abs(kf.x[0] - c_after))
        errors[s] = np.mean(err)
    assert errors[1.1] < 0.5 * errors[1.0]


def test_a_diverged_filter_returns_to_its_last_good_parameters_and_relearns():
    """Filter health: a plain filter (s = 1) is sure of c after 300 windows; c then steps.
    Its innovations stay far beyond their predicted spread: within `health_windows` it is reset to
    the last good value with the prior's uncertainty, and re-learns the new c."""
    rng = np.random.default_rng(1)
    sigma = np.radians(0.01)
    c_before, c_after = np.radians(0.1), np.radians(0.15)
    kf = StrongTrackingKF([0.0], [[np.radians(0.1) ** 2]], [[0.0]], fading_s=1.0, reject_sigma=1e9,
                          health_windows=20)
    for k in range(300):
        kf.step(c_before + sigma * rng.standard_normal(), [1.0], sigma ** 2)
    assert kf.n_resets == 0                                   # consistent: never reset
    x_good = kf.x[0]
    for k in range(20):
        kf.step(c_after + sigma * rng.standard_normal(), [1.0], sigma ** 2)
        if kf.n_resets:
            break
    assert kf.n_resets == 1 and k >= 3                       # within the health window, not at once
    assert kf.x[0] == pytest.approx(x_good, abs=sigma)        # the last good value, not a half-way one
    assert kf.P[0, 0] == pytest.approx(np.radians(0.1) ** 2)
    for k in range(20):
        kf.step(c_after + sigma * rng.standard_normal(), [1.0], sigma ** 2)
    assert abs(kf.x[0] - c_after) < 3 * sigma and kf.n_resets == 1


def test_a_filter_never_consistent_keeps_its_state_on_divergence_not_its_first_guess():
    """A vehicle's windows can be noisier than their R says from the start, so the innovation
    history never looks good. A divergence then widens P but keeps the learned state: going back
    to the state of the first updates (the drift has moved 0.2 deg/s since) would throw away
    everything learned."""
    rng = np.random.default_rng(2)
    sigma = np.radians(0.01)
    kf = StrongTrackingKF([0.0], [[np.radians(0.5) ** 2]], [[0.0]], fading_s=1.05, reject_sigma=1e9,
                          health_windows=30)
    jumps = []
    for k in range(200):
        c = np.radians(0.4 - 0.001 * k)                                    # the drift moves
        x_before, resets = kf.x[0], kf.n_resets
        kf.step(c + 3 * sigma * rng.standard_normal(), [1.0], sigma ** 2)   # 3x noisier than R
        if kf.n_resets > resets:
            jumps.append(abs(kf.x[0] - x_before))
            assert kf.P[0, 0] == pytest.approx(np.radians(0.5) ** 2)       # widened to the prior
    assert len(jumps) >= 3                                                  # it did diverge, often
    assert max(jumps) < np.radians(0.03)                                    # and kept what it had


def test_zhou_adaptive_factor_reacts_to_a_step_and_stays_at_one_when_consistent():
    rng = np.random.default_rng(2)
    sigma = np.radians(0.01)
    kf = StrongTrackingKF([np.radians(0.1)], [[sigma ** 2]], [[0.0]], fading_s=1.0, adaptive=True, reject_sigma=1e9)
    quiet = [kf.step(np.radians(0.1) + sigma * rng.standard_normal(), [1.0], sigma ** 2).fading for _ in range(200)]
    jump = [kf.step(np.radians(0.2) + sigma * rng.standard_normal(), [1.0], sigma ** 2).fading for _ in range(5)]
    assert np.median(quiet) == pytest.approx(1.0)
    assert max(jump) > 5.0
    assert abs(kf.x[0] - np.radians(0.2)) < 3 * sigma


def test_outlier_refused_then_accepted_when_persistent_and_state_never_nan():
    sigma = np.radians(0.01)
    kf = StrongTrackingKF([0.0], [[sigma ** 2]], [[0.0]], reject_sigma=5.0, max_rejections=3)
    x0 = kf.x.copy()
    assert not kf.step(np.radians(1.0), [1.0], sigma ** 2).accepted       # a wild window is refused
    assert kf.x == pytest.approx(x0)
    assert not kf.step(np.nan, [1.0], sigma ** 2).accepted         # NaN is never taken
    assert not kf.step(0.0, [np.inf], sigma ** 2).accepted
    assert np.all(np.isfinite(kf.x)) and np.all(np.isfinite(kf.P))
    results = [kf.step(np.radians(1.0), [1.0], sigma ** 2).accepted for _ in range(6)]
    assert results[:2] == [False, False] and all(results[2:])  # after 3 refusals: it moved
    assert kf.x[0] == pytest.approx(np.radians(1.0), abs=5 * sigma)


def test_fading_keeps_variance_below_its_cap_while_nothing_is_measured():
    kf = StrongTrackingKF([0.0, 0.0], np.diag([1e-8, 1e-8]), np.zeros((2, 2)), fading_s=1.5,
                          p_max=[1e-6, 1e-6])
    for _ in range(200):
        kf.step(None)
    assert np.all(np.diag(kf.P) <= 1e-6 * (1 + 1e-9))
    assert np.all(np.linalg.eigvalsh(kf.P) >= 0)


def test_state_round_trips_through_plain_data():
    kf = StrongTrackingKF([1.0, 2.0], np.eye(2), np.zeros((2, 2)))
    kf2 = StrongTrackingKF([0.0, 0.0], np.eye(2) * 5, np.zeros((2, 2)))
    kf2.set_state(kf.x.tolist(), kf.P.tolist())
    assert kf2.x == pytest.approx([1.0, 2.0]) and kf2.P == pytest.approx(np.eye(2))
    with pytest.raises(ValueError):
        kf2.set_state([np.nan, 0.0])


def test_drift_model_rows_evaluate_and_initial_state():
    model = DriftModel()
    assert model.names == ('temperature', 'temperature_rate', 'constant')
    inputs = {'temperature': np.array([25.0, 35.0]), 'temperature_rate': np.array([0.0, 0.02]),
              'rate': np.zeros(2)}
    rows = model.rows(inputs)
    assert rows == pytest.approx(np.array([[0.0, 0.0, 1.0], [10.0, 0.02, 1.0]]))
    x = np.array([1e-4, 1e-2, 3e-3])
    assert model.evaluate(x, inputs) == pytest.approx(rows @ x)
    # c0 = mean(w) - a0 (T0 - t_ref): with a warm-start a, the still drift still comes out exactly
    x0 = model.initial_state(5e-3, 31.0, known={'temperature': 2e-4})
    d0 = model.evaluate(x0, {'temperature': np.array([31.0]), 'temperature_rate': np.zeros(1)})
    assert d0[0] == pytest.approx(5e-3)
    assert model.paper_coefficients(x)['constant_at_0c'] == pytest.approx(3e-3 - 1e-4 * 25.0)


def test_drift_model_takes_new_terms_without_filter_changes():
    lagged = Term('temperature_lagged', 'rad/s/degC', lambda i, r: i['temperature_lagged'] - r,
                  ('temperature_lagged',), prior_sigma=1e-3)
    model = DriftModel(('temperature', 'temperature_squared', lagged, 'constant'))
    assert len(model) == 4
    inputs = {'temperature': np.array([30.0]), 'temperature_lagged': np.array([28.0])}
    assert model.rows(inputs)[0] == pytest.approx([5.0, 25.0, 3.0, 1.0])
    kf = StrongTrackingKF(np.zeros(len(model)), np.diag(model.prior_sigmas() ** 2),
                          np.diag(model.q_sigmas() ** 2))
    kf.step(1e-3, model.rows(inputs)[0], 1e-8)
    assert kf.x.shape == (4,)
    with pytest.raises(KeyError):
        model.rows({'temperature': np.array([30.0])})
    with pytest.raises(ValueError):
        DriftModel(('constant', 'constant'))
    assert 'rate_temperature' in BUILTIN_TERMS  # scale-factor terms k(T) w are ordinary terms
