"""DriftBacktest: what past drift predictions missed beyond their own variance, by their age."""
import numpy as np
import pytest

from gyro_thermal_comp.thermal.backtest import DriftBacktest

WINDOW_S, CONFIRM_S = 10.0, 5.0


def feed(slope_rad_s2: float, sigma_r_rad_s: float, windows: int, seed: int) -> DriftBacktest:
    """A 'constant'-only model whose parameter is updated to the true drift at each window's
    confirmation; the truth moves at `slope`, so a prediction `age` s old is off by slope * age."""
    rng = np.random.default_rng(seed)
    bt = DriftBacktest()
    bt.add_update(0.0, np.array([0.0]), np.zeros((1, 1)))
    h = np.array([1.0])
    for k in range(windows):
        t0, t1 = k * WINDOW_S, (k + 1) * WINDOW_S
        t_mid = 0.5 * (t0 + t1)
        y = slope_rad_s2 * t_mid + sigma_r_rad_s * rng.standard_normal()
        bt.add_window(t0, t1, y, h, sigma_r_rad_s ** 2)
        bt.add_update(t1 + CONFIRM_S, np.array([slope_rad_s2 * (t1 + CONFIRM_S)]), np.zeros((1, 1)))
    return bt


def test_a_drift_the_model_misses_shows_as_error_growing_with_the_age():
    slope, sigma_r = 1e-6, 1e-4            # rad/s per s; window noise rad/s (the estimate scatters ~6 % at 160 s)
    bt = feed(slope, sigma_r, 400, seed=1)
    for age in (160.0, 320.0, 640.0):
        # the parameters in force at t_mid - age were set up to one window earlier: age + ~5 s on average
        expected = slope * np.sqrt(np.mean((age + np.linspace(0.0, WINDOW_S, 101)) ** 2))
        assert np.sqrt(bt.variance_at(age)) == pytest.approx(expected, rel=0.2), age
    assert bt.variance_at(0.0) == 0.0
    assert bt.variance_at(80.0) < bt.variance_at(160.0) < bt.variance_at(320.0)
    # beyond the longest horizon it carries on in proportion to the age
    assert np.sqrt(bt.variance_at(2560.0)) == pytest.approx(2 * np.sqrt(bt.variance_at(1280.0)), rel=1e-12)


def test_predictions_as_good_as_their_noise_add_nothing():
    """No missing effect: e^2 scatters around R and the significance test keeps the backtest at 0
    (expected in about 1 % of such runs; these 20 seeds are fixed)."""
    fired = sum(np.any(feed(0.0, 2e-4, 400, seed=s).variances() > 0) for s in range(20))
    assert fired <= 1


def test_nothing_is_known_before_the_history_reaches_a_horizon():
    bt = feed(1e-6, 2e-4, 60, seed=2)      # 600 s of windows
    assert np.all(bt.variances()[bt.horizons_s > 600.0] == 0.0)
    bt.add_window(200.0, 210.0, float('nan'), np.array([1.0]), 1e-8)   # a bad window changes nothing
    assert np.all(np.isfinite(bt.variances()))


def test_errors_the_parameters_own_covariance_foresaw_are_not_counted():
    """Parameters off by as much as their P says (a filter still learning): no missing effect. The
    same errors with a P that claims certainty are a miss."""
    def run(p_claimed: float, seed: int) -> np.ndarray:
        rng = np.random.default_rng(seed)
        bt = DriftBacktest()
        sigma_x, sigma_r = 3e-4, 1e-4
        bt.add_update(0.0, np.array([sigma_x * rng.standard_normal()]), np.full((1, 1), p_claimed))
        for k in range(400):
            t1 = (k + 1) * WINDOW_S
            bt.add_window(t1 - WINDOW_S, t1, sigma_r * rng.standard_normal(), np.array([1.0]), sigma_r ** 2)
            bt.add_update(t1 + CONFIRM_S, np.array([sigma_x * rng.standard_normal()]), np.full((1, 1), p_claimed))
        return bt.variances()
    assert all(np.all(run(3e-4 ** 2, s) == 0.0) for s in range(5))
    assert all(np.all(np.sqrt(run(0.0, s)) > 2e-4) for s in range(5))

