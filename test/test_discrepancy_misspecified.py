"""`discover` names a wandering bias only when the residual has its signature.

Bags: the simulator's `null` scenario (the static_ramp temperature profile, drift exactly
a*T + b*dT/dt + c, 2 h at a 2 Hz IMU so each discover call takes seconds) with a deterministic
disturbance no library candidate has the shape of, added here to the z gyro stream and written
with the package's bag writer: a sinusoid, a bias step, a heating/cooling loop of another shape
than the library's hysteresis. Never a stochastic name for them; the simulator's own random walk
keeps its name. Plain-array tests of the signature functions and of the matched-filter limit."""
import math
import re

import numpy as np
import pytest

from gyro_thermal_comp.bag_io import BagWriter
from gyro_thermal_comp.discrepancy import discover
from gyro_thermal_comp.discrepancy.detection import _perp_norm2
from gyro_thermal_comp.discrepancy.signature import ALPHA, _branch_sign, axis_tests, profile_loglik
from gyro_thermal_comp.samples import ImuSamples
from gyro_thermal_comp.sim import make_config, simulate
from gyro_thermal_comp.sim.thermal import TemperatureProfile, static_ramp_shape

RATES = dict(imu_rate_hz=2.0, mag_rate_hz=2.0, temp_rate_hz=1.0)
DURATION_S = 7200.0
STOCHASTIC = {'rate_random_walk', 'bias_instability'}
PROFILE = TemperatureProfile(static_ramp_shape(), 23.0, 58.0)   # the null scenario's case temperature


def _bag(tmp_path, name, disturbance_rad_s, seed, effects=None):
    """Simulated bag with `disturbance_rad_s(t)` added to the z gyro; sensor streams only."""
    path = tmp_path / name
    with BagWriter(path) as w:
        for c in simulate(make_config('null', seed=seed, effects=effects or {}, **RATES)):
            g = c.imu.gyro.copy()
            g[:, 2] += disturbance_rad_s(c.imu.t)
            w.write_chunk(c.with_streams(imu=ImuSamples(c.imu.t, g, c.imu.accel), gyro_bias=None,
                                         mag_disturbance=None, odom=None))
    return path


def _lens_loop(t):
    """A heating/cooling loop of another shape than the library's (a lagged tanh of dT/dt): the
    last branch sign times sin(pi (T - 23) / 35) - open in the middle of the range, closed at both
    ends, no relaxation in holds (unit amplitude)."""
    tt = np.arange(0.0, DURATION_S + 1.0)
    temp, rate = PROFILE(tt)
    return np.interp(t, tt, _branch_sign(rate) * np.sin(np.pi * np.clip((temp - 23.0) / 35.0, 0.0, 1.0)))


def _signature_checks(r):
    return [c for it in r.to_dict()['iterations'] for c in it['encompassing_checks'] if 'signature' in c]


def test_slow_sinusoid_is_unexplained_with_a_reason(tmp_path):
    """18 min period, 0.01 deg/s: a matched filter of the known sinusoid has SNR ~ 15 on this record
    (about 3x its 5-sigma limit); no candidate has that shape."""
    amp = math.radians(0.01)
    r = discover(_bag(tmp_path, 'sine', lambda t: amp * np.sin(2 * np.pi * t / 1100.0), seed=1), reference='static')
    noise = math.radians(r.to_dict()['data']['gyro_noise_dps_rthz'][2])          # rad/s in a 1 s bin
    snr = amp * math.sqrt(DURATION_S / 2.0) / noise
    assert 8.0 < snr < 30.0, snr                                                  # a few x the limit of 5
    assert r.verdict == 'unexplained_residual' and r.effects == [], r.candidates
    assert r.unexplained_reason                                                   # one line saying what


def test_slow_large_sinusoid_refuses_the_random_walk(tmp_path):
    """40 min period, 0.02 deg/s: a random walk fits it (before this check it was named); the
    residual's spectral line refuses it the name."""
    amp = math.radians(0.02)
    r = discover(_bag(tmp_path, 'sine40', lambda t: amp * np.sin(2 * np.pi * t / 2400.0), seed=3),
                 reference='static')
    assert not STOCHASTIC & set(r.effects), r.effects
    assert r.verdict == 'unexplained_residual' or 'periodic' in (r.unexplained_reason or ''), r.effects
    refused = [c for c in _signature_checks(r) if not c['signature']['holds']]
    assert refused and refused[0]['signature']['kind'] == 'periodic'
    assert 'period 2400 s' in r.unexplained_reason


def test_bias_step_is_unexplained_and_located(tmp_path):
    """0.03 deg/s at 5040 s (cooling): a random walk fits it, and so does the hysteresis branch
    state (a cooling-branch offset): named thermal_hysteresis in 7 of 10 sweep bags without the
    check of named regressors against shapes outside the library (outside.py). A step gives
    unexplained_residual, here with its time."""
    amp = math.radians(0.03)
    r = discover(_bag(tmp_path, 'step', lambda t: amp * (t > 5040.0), seed=2), reference='static')
    assert r.verdict == 'unexplained_residual' and r.effects == [], r.effects
    assert re.search(r'steps? at t = (\d+ s and )?50\d\d s', r.unexplained_reason), r.unexplained_reason


def test_other_shape_hysteresis_is_hysteresis_or_unexplained(tmp_path):
    amp = math.radians(0.03)
    r = discover(_bag(tmp_path, 'lens', lambda t: amp * _lens_loop(t), seed=4), reference='static')
    assert not STOCHASTIC & set(r.effects), r.effects
    assert r.effect == 'thermal_hysteresis' or r.verdict == 'unexplained_residual', r.effects


def test_simulated_random_walk_keeps_its_name_and_detection_is_reported(tmp_path):
    """The simulator's own rate random walk (4e-4 deg/s/sqrt(s), named in 5 of 5 seeds before this
    check) is still named: its residual passes the signature test."""
    r = discover(_bag(tmp_path, 'rrw', lambda t: 0.0 * t, seed=1, effects={'rate_random_walk': 4e-4}),
                 reference='static')
    assert r.effect == 'rate_random_walk', r.candidates
    assert any(c['signature']['holds'] for c in _signature_checks(r))
    det = r.to_dict()['detection']
    for name in ('thermal_curvature', 'thermal_hysteresis', 'thermal_lag'):
        d = det[name]
        assert d['detection_snr'] >= 0.0 and d['detection_limit'] > 0.0 and d['snr_threshold'] == 5.0
    assert det['thermal_lag']['detection_unit'] == 's'


# ------------------------------------------------------------------ plain arrays, fast
STEP_S = 30.0
T_C = (np.arange(int(DURATION_S / STEP_S)) + 0.5) * STEP_S
TEMP, RATE = PROFILE(T_C)
X = np.column_stack([np.ones_like(T_C), TEMP, RATE])
X = X / np.sqrt(np.mean(X * X, axis=0))
V = np.full(T_C.size, math.radians(0.04) ** 2 / STEP_S)     # 0.04 deg/s/sqrt(Hz) in 30 s means


def _p_family_wise(m, markov=False):
    tests = axis_tests(m, V, X, T_C, TEMP, RATE, markov, STEP_S, 2)
    worst = min(tests, key=lambda x: x.p)
    return min(1.0, worst.p * len(tests)), worst


def test_branch_sign_is_held_through_holds():
    rate = np.concatenate([np.zeros(5), np.full(10, 0.01), np.zeros(10), np.full(10, -0.01), np.zeros(5)])
    b = _branch_sign(rate)
    assert np.all(b[:5] == 0) and np.all(b[5:25] == 1) and np.all(b[25:] == -1)


def test_signature_finds_a_line_and_a_step_on_plain_arrays():
    rng = np.random.default_rng(7)
    noise = rng.standard_normal(T_C.size) * np.sqrt(V)
    sine = math.radians(0.02) * np.sin(2 * np.pi * T_C / 1500.0)
    p, worst = _p_family_wise(noise + sine)
    assert p < ALPHA and worst.family == 'periodic' and abs(worst.detail['period_s'] - 1500.0) < 100.0
    step = math.radians(0.03) * (T_C > 4000.0)
    p, worst = _p_family_wise(noise + step)
    assert p < ALPHA and worst.family == 'step' and abs(worst.detail['step_t_s'] - 4000.0) <= STEP_S


def _refused(m, markov=False):
    """The signature's decision on one axis (wander_signature): the LR test or a shape alone."""
    tests = axis_tests(m, V, X, T_C, TEMP, RATE, markov, STEP_S, 2)
    return min(1.0, len(tests) * min(x.p for x in tests)) < ALPHA or any(x.beats_wander for x in tests)


def _wander_significant(m, markov=False):
    ll, ll_none = profile_loglik(m, V, X, markov, STEP_S)
    return 2.0 * (ll - ll_none) >= (2 if markov else 1) * math.log(T_C.size) + 10.0


def test_small_steps_that_a_random_walk_would_fit_are_refused_the_name():
    """One or two bias steps of 0.005..0.05 deg/s, as in the calibration (where a random walk is
    significant for them: before the step margins (signature.MUST_BEAT) and the two-step family,
    12 % of single and 36 % of double steps kept the random walk's name there, 11 of these 29):
    at most 2 of ~30 keep it (calibrated: 0-2 %; the misses are the smallest steps, ~0.008 deg/s,
    where D falls just short of its margin)."""
    rng = np.random.default_rng(23)
    tried = kept = 0
    for i in range(40):
        amp = math.radians(10 ** rng.uniform(-2.3, -1.3))
        m = rng.standard_normal(T_C.size) * np.sqrt(V) + amp * (T_C > rng.uniform(0.1, 0.5) * T_C[-1])
        if i % 2:
            m += amp * rng.uniform(-1.5, 1.5) * (T_C > rng.uniform(0.5, 0.9) * T_C[-1])
        if not _wander_significant(m):
            continue
        tried += 1
        kept += not _refused(m)
    assert tried >= 25 and kept <= 2, (tried, kept)


def test_signature_false_alarms_on_simulated_wanders_are_rare():
    """Random walks and Gauss-Markov biases strong enough to be named: refused (by the LR test or
    the shape-alone rule) at most once in 12 draws (calibrated false alarms a few %; signature.py)."""
    rng = np.random.default_rng(11)
    refused = 0
    for i in range(12):
        e = rng.standard_normal(T_C.size) * np.sqrt(V)
        if i % 3:
            k = math.radians(10 ** rng.uniform(-3.5, -2.7))                     # rad/s/sqrt(s)
            u, markov = np.cumsum(k * math.sqrt(STEP_S) * rng.standard_normal(T_C.size)), False
        else:
            phi, sig = math.exp(-STEP_S / 300.0), math.radians(0.02)
            u = np.zeros(T_C.size)
            for j in range(1, T_C.size):
                u[j] = phi * u[j - 1] + sig * math.sqrt(1 - phi * phi) * rng.standard_normal()
            markov = True
        refused += _refused(u + e, markov)
    assert refused <= 1, refused


def test_matched_filter_snr_of_a_sinusoid():
    """sum w (P s)^2 of a unit sinusoid over whole periods with the constant projected out is
    w N / 2; a trend takes its share (the sine's own linear part); a column in the span gives 0."""
    n = 7200
    t = np.arange(n) + 0.5
    s = np.sin(2 * np.pi * t / 1200.0)
    w = np.full(n, 4.0)
    every = np.ones(n, bool)
    assert _perp_norm2(s, np.ones((n, 1)), w, every) == pytest.approx(4.0 * n / 2.0, rel=1e-9)
    trend = np.column_stack([np.ones(n), t])
    slope = np.polyfit(t, s, 1)[0]
    left = 4.0 * float(np.sum((s - np.polyval(np.polyfit(t, s, 1), t)) ** 2))
    assert slope != 0.0 and _perp_norm2(s, trend, w, every) == pytest.approx(left, rel=1e-9)
    assert _perp_norm2(3.0 * t - 2.0, trend, w, every) == pytest.approx(0.0, abs=1e-6)


# ------------------------------------------------------------------ second truth family, named shapes
def _family_b(shape: str, seed: int):
    from gyro_thermal_comp.sim.truth_family import family_configs
    case = next(c for c in family_configs('B', 'discover_effects', [seed], imu_rate_hz=5.0, mag_rate_hz=2.0,
                                          temp_rate_hz=2.0) if c.shape == shape)
    return discover(simulate(case.config), reference='static')


def test_a_step_a_named_regressor_took_in_whole_is_found_without_it():
    """Family B seed 1 (an oscillating profile, bias steps at 478 s and 5176 s): the hysteresis branch
    state took the steps so well that M's own residual showed none (step scan p = 0.03), and the
    bag was named thermal_hysteresis. Scanned on the model without it, the step is found, and the
    hysteresis adds nothing given it."""
    r = _family_b('bias_step', 1)
    assert r.verdict == 'unexplained_residual' and r.effects == [], r.effects
    audit = r.to_dict()['remaining_structure']['outside_shape']
    assert audit['withdrawn'] == ['thermal_hysteresis'], audit
    assert 'thermal_hysteresis only stood in for it' in r.unexplained_reason


def test_a_true_effect_partly_mimicked_by_an_outside_shape_keeps_its_name():
    """Family B seed 0's curvature (SNR 8.9): a sinusoid fits part of it, and the curvature adds
    nothing significant given the sinusoid (p = 0.02); the curvature fits the residual without it
    better (61 against 57) and keeps its name (withdrawn without that rule)."""
    r = _family_b('curvature', 0)
    assert r.effects == ['thermal_curvature'], r.effects
    tests = r.to_dict()['remaining_structure']['outside_shape']['given_shape']
    assert any(not t['significant'] and t['effect_gain'] > t['shape_gain'] for t in tests.values()), tests
