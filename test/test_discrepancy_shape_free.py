"""Structure no library candidate explains is not answered `no_missing_effect`.

The shape-free low-frequency test (lowfreq.py) on plain arrays: its level under white noise with the
model's regressors in the data, and its power on a small step; and through `discover` on 2 h, 2 Hz
bags of the simulator's `null` record with a disturbance on the z gyro: a small loop of another
shape, for which no candidate is significant, and a small step, which a random walk would fit, are
`unexplained_residual`; a null bag stays `no_missing_effect` with the test's record in
`remaining_structure`. (A named regressor that only stands in for a step: test_discrepancy_
misspecified.py, the bias step.)"""
import math

import numpy as np

from gyro_thermal_comp.discrepancy import discover
from gyro_thermal_comp.discrepancy.lowfreq import ALPHA, components, family_p
# 2 h, 2 Hz null bags with a z disturbance; the static ramp's 30 s coarse bins and design
from test_discrepancy_misspecified import STEP_S, T_C, X, _bag, _lens_loop

ONES = np.ones(T_C.size)
SPAN = T_C.size * STEP_S


def _p(Y):
    """The test's family-wise p for whitened coarse series Y (3, J) with the static ramp's design."""
    Z = np.array([components(T_C, y, X, ONES, 0.0, SPAN, T_C.size // 2) for y in Y])
    return family_p(Z)[0]


def test_level_under_white_noise_with_the_models_regressors_in_the_data():
    """400 draws of unit white noise plus a*T + b*dT/dt + c of any size (projected out exactly):
    p < ALPHA about ALPHA of the time, p roughly uniform."""
    rng = np.random.default_rng(3)
    ps = np.array([_p(rng.standard_normal((3, T_C.size)) + (X @ rng.normal(0.0, 50.0, (3, 3))).T)
                   for _ in range(400)])
    assert np.sum(ps < ALPHA) <= 10                        # binomial(400, 0.01): P(>= 11) < 1e-3
    assert 0.4 < np.mean(ps < 0.5) < 0.6


def test_power_on_a_step_at_matched_filter_snr_7():
    """A step on one axis at SNR 7 of the known shape (the part the regressors cannot absorb): the
    test that does not know the shape still finds it (measured power ~1 at SNR 7, docs)."""
    rng = np.random.default_rng(5)
    step = (T_C > 4000.0).astype(float)
    Q, _ = np.linalg.qr(X)
    perp = step - Q @ (Q.T @ step)
    found = 0
    for _ in range(20):
        Y = rng.standard_normal((3, T_C.size))
        Y[2] += 7.0 / np.linalg.norm(perp) * step
        found += _p(Y) < ALPHA
    assert found >= 18, found


def test_small_loop_that_no_candidate_names_is_unexplained(tmp_path):
    """A heating/cooling loop of another shape than the library's, 0.014 deg/s (matched-filter SNR
    ~6.6): no candidate is significant and the block-mean whiteness test does not reach its level;
    before the shape-free test this answered no_missing_effect."""
    amp = math.radians(0.014)
    r = discover(_bag(tmp_path, 'small_loop', lambda t: amp * _lens_loop(t), seed=1), reference='static')
    assert r.verdict == 'unexplained_residual' and r.effects == [], r.candidates
    assert r.unexplained_reason.startswith('slow residual structure'), r.unexplained_reason
    assert r.whiteness_after['gyro']['p_value'] >= 1e-3                  # the block-mean test alone: not seen


def test_small_step_is_unexplained_never_a_wander(tmp_path):
    """0.012 deg/s at 3000 s (heating), matched-filter SNR ~9: a random walk is significant for it
    and was named before the step margins (signature.MUST_BEAT); now the step model fits as well
    as the wander, and the answer is unexplained_residual with the step's time."""
    amp = math.radians(0.012)
    r = discover(_bag(tmp_path, 'small_step', lambda t: amp * (t > 3000.0), seed=3), reference='static')
    assert r.verdict == 'unexplained_residual' and r.effects == [], r.candidates
    assert '3000 s' in r.unexplained_reason, r.unexplained_reason


def test_null_record_keeps_no_missing_effect_and_reports_the_shape_free_test(tmp_path):
    r = discover(_bag(tmp_path, 'null', lambda t: 0.0 * t, seed=14), reference='static')
    assert r.verdict == 'no_missing_effect', r.unexplained_reason
    low = r.to_dict()['remaining_structure']['gyro']['low_frequency']
    assert low['p_value'] >= ALPHA and not low['structured'] and low['n_components'] == 120
