"""The heading scorer against records whose every scored number is known in advance."""
import numpy as np
import pytest

from gyro_thermal_comp.angles import wrap_angle
from gyro_thermal_comp.evaluation import ORACLE, RAW, HeadingScorer, RunningStats, ScoringError
from gyro_thermal_comp.evaluation.report import chunks_from_list, evaluate
from gyro_thermal_comp.evaluation.synthetic import DriftIntegrator, level_unit_chunks
from gyro_thermal_comp.heading_track import HeadingTrack
from gyro_thermal_comp.samples import concat_chunks

RATE_HZ = 100.0
DT = 1.0 / RATE_HZ


class TruthPlus:
    """Fake method: true heading plus offset_fn(t_rel), wrapped; drift unknown (NaN)."""

    def __init__(self, name, offset_fn, yaw_fn, t0_s=1000.0):
        self.name, self.offset_fn, self.yaw_fn, self.t0 = name, offset_fn, yaw_fn, t0_s

    def update(self, chunk):
        t = chunk.imu.t
        rel = t - self.t0
        heading = wrap_angle(self.yaw_fn(rel) + self.offset_fn(rel))
        nan = np.full(t.size, np.nan)
        return HeadingTrack(t, heading, nan, nan, np.zeros(t.size, bool))


def ref_mean(t_rel, x, window=60.0):
    return x[t_rel < t_rel[0] + window].mean()


def test_running_stats_merge_equals_one_shot():
    rng = np.random.default_rng(1)
    x = rng.normal(3.0, 2.0, 10_001)
    x[::97] = np.nan
    s = RunningStats()
    for part in np.array_split(x, 13):
        s.add(part)
    ok = x[np.isfinite(x)]
    assert s.n == ok.size and s.n_skipped == x.size - ok.size
    assert s.mean == pytest.approx(ok.mean(), rel=1e-12)
    assert s.var == pytest.approx(ok.var(), rel=1e-10)
    assert s.rms == pytest.approx(np.sqrt(np.mean(ok ** 2)), rel=1e-10)
    assert s.max_abs == pytest.approx(np.abs(ok).max())
    assert np.isnan(RunningStats().mean) and np.isnan(RunningStats().max_abs)


@pytest.mark.parametrize('yaw0, yaw_rate', [(0.3, 0.0), (3.0, 0.2)])
def test_constant_bias_error_gives_linear_heading_error(yaw0, yaw_rate):
    """delta in the drift estimate: bias error mean delta, var 0; e(t) = -delta*(t - t_ref); the
    spinning case crosses +-pi about six times and must not jump."""
    delta = 2e-4
    duration = 200.0
    chunks = level_unit_chunks(duration, RATE_HZ, yaw0_rad=yaw0, yaw_rate_rad_s=yaw_rate,
                               drift_rad_s=lambda t: 1e-3 + 5e-6 * t, chunk_s=7.3)
    rep = evaluate(chunks_from_list(chunks), [DriftIntegrator('biased', delta, yaw0)])
    s = rep.result.scores['biased']
    assert s.bias_error.mean == pytest.approx(delta, rel=1e-9)
    assert s.bias_error.var == pytest.approx(0.0, abs=1e-18)
    t = np.arange(0, duration, DT)
    expected = -delta * t
    expected -= ref_mean(t, expected)
    assert s.error.max_abs == pytest.approx(np.abs(expected).max(), rel=1e-6)
    assert s.error.mean == pytest.approx(expected.mean(), abs=1e-9)
    assert s.error.var == pytest.approx(expected.var(), rel=1e-6)
    # no gyro noise: the oracle is exact, so the excess is the error
    assert rep.result.scores[ORACLE].error.max_abs < 1e-9
    assert s.excess.max_abs == pytest.approx(np.abs(expected).max(), rel=1e-6)
    # slope of the 1-s means
    series = rep.result.series
    tc = series.centers_s() - rep.result.t_start_s
    slope = np.polyfit(tc, series.error('biased'), 1)[0]
    assert slope == pytest.approx(-delta, rel=1e-6)
    assert np.max(np.abs(np.diff(series.error('biased')))) < 2 * delta  # no wrap jumps


def test_wrap_around_pi_makes_no_jumps():
    """Offset 3.1 rad plus a ramp: the raw difference crosses +-pi inside the reference window."""
    yaw_rate = -0.15
    yaw_fn = lambda t: 2.0 + yaw_rate * t  # noqa: E731
    chunks = level_unit_chunks(120.0, RATE_HZ, yaw_fn=yaw_fn, yaw_rate_rad_s=yaw_rate, chunk_s=9.0,
                               odom_rate_hz=40.0)
    m = TruthPlus('offset', lambda t: 3.1 + 1e-3 * t, yaw_fn)
    rep = evaluate(chunks_from_list(chunks), [m])
    s = rep.result.scores['offset']
    t = np.arange(0, 120.0, DT)
    t = t[t <= 119.975]  # odom at 40 Hz ends there; later IMU samples are not scored
    expected = 1e-3 * t - ref_mean(t, 1e-3 * t)
    assert s.error.max_abs == pytest.approx(np.abs(expected).max(), abs=1e-6)
    assert s.error.var == pytest.approx(expected.var(), rel=1e-4)
    assert s.reference_offset_rad == pytest.approx(3.1 + 1e-3 * ref_mean(t, t), abs=1e-6)
    assert np.isnan(s.bias_error.mean)  # drift not modelled


def test_series_keeps_the_per_sample_max_of_each_bin():
    """A wander inside each 1 s bin (period 0.37 s) that bin means average away: the series' bin max
    is the max |e| of that bin's samples (e0 removed), in any chunking, and its overall max is the
    record's max |e|."""
    yaw_fn = lambda t: 0.5 + 0.02 * t  # noqa: E731
    offset = lambda t: 0.01 * np.sin(2 * np.pi * t / 0.37) + 2e-4 * t  # noqa: E731
    t = np.arange(0, 120.0, DT)
    t = t[t <= 119.975]                     # odom at 40 Hz ends there
    e = offset(t) - ref_mean(t, offset(t))
    bins = np.floor(t + 1e-9).astype(int)
    expected = np.array([np.abs(e[bins == k]).max() for k in range(bins[-1] + 1)])
    for chunk_s in (1000.0, 2.3):
        chunks = level_unit_chunks(120.0, RATE_HZ, yaw_fn=yaw_fn, yaw_rate_rad_s=0.02, chunk_s=chunk_s,
                                   odom_rate_hz=40.0)
        rep = evaluate(chunks_from_list(chunks), [TruthPlus('m', offset, yaw_fn)])
        got = rep.result.series.error_max_abs('m')
        assert got == pytest.approx(expected, abs=1e-9)
        assert np.max(got) == pytest.approx(rep.result.scores['m'].error.max_abs, abs=1e-12)
        assert np.all(np.abs(rep.result.series.error('m')) <= got + 1e-12)


def test_outage_statistics_only_inside_spans():
    spans = [(100.0, 150.0), (200.0, 260.0)]

    def ramp(t):  # error grows 0.01 rad/s inside each span, zero outside
        out = np.zeros_like(t)
        for a, b in spans:
            inside = (t >= a) & (t < b)
            out[inside] = 0.01 * (t[inside] - a)
        return out

    yaw_fn = lambda t: 0.5 + 0 * t  # noqa: E731
    chunks = level_unit_chunks(300.0, RATE_HZ, yaw_fn=yaw_fn, outages=spans, mag_rate_hz=20.0,
                               chunk_s=11.0)
    rep = evaluate(chunks_from_list(chunks), [TruthPlus('wild', ramp, yaw_fn)])
    s = rep.result.scores['wild']
    t = np.arange(0, 300.0, DT)
    e = ramp(t)
    inside = np.zeros(t.size, bool)
    for a, b in spans:
        inside |= (t >= a) & (t < b)
    assert s.error_outage.n == np.count_nonzero(inside)
    assert s.error_outage.max_abs == pytest.approx(e[inside].max(), rel=1e-9)
    assert s.error_outage.mean == pytest.approx(e[inside].mean(), rel=1e-9)
    assert s.error.mean == pytest.approx(e.mean(), rel=1e-9)
    assert s.samples_outside == t.size - np.count_nonzero(inside)
    got = rep.result.spans
    assert len(got) == 2
    for span, (a, b) in zip(got, spans):
        assert span.t_start_s - rep.result.t_start_s == pytest.approx(a, abs=1e-9)
        assert span.duration_s == pytest.approx(b - a - DT, abs=1e-9)
        assert span.methods['wild'].growth == pytest.approx(0.01 * (b - a - DT), rel=1e-9)
        assert span.methods['wild'].excess_growth == pytest.approx(0.01 * (b - a - DT), rel=1e-9)
        assert span.methods[ORACLE].growth == pytest.approx(0.0, abs=1e-12)
        assert span.closed


def test_oracle_is_integrated_gyro_noise():
    sigma = 0.01
    chunks = level_unit_chunks(400.0, RATE_HZ, yaw0_rad=-2.0, drift_rad_s=lambda t: 2e-3 * np.sin(t / 30),
                               noise_rad_s=sigma, seed=7, chunk_s=6.1, odom_rate_hz=25.0,
                               odom_offset_s=0.0)
    whole = concat_chunks(chunks)
    noise = whole.imu.gyro[:, 2] - whole.gyro_bias.vec[:, 2]  # static: true rate is zero
    t = whole.imu.t - whole.imu.t[0]
    err = np.concatenate([[0.0], np.cumsum(0.5 * (noise[1:] + noise[:-1]) * np.diff(t))])
    scored = whole.imu.t <= whole.odom.t[-1]  # IMU samples after the last truth are not scored
    t, err = t[scored], err[scored]
    err -= ref_mean(t, err)
    perfect = DriftIntegrator('perfect', 0.0, -2.0)
    rep = evaluate(chunks_from_list(chunks), [perfect])
    o = rep.result.scores[ORACLE]
    assert o.error.max_abs == pytest.approx(np.abs(err).max(), rel=1e-9)
    assert o.error.mean == pytest.approx(err.mean(), abs=1e-12)
    assert o.error.var == pytest.approx(err.var(), rel=1e-9)
    assert rep.result.scores['perfect'].excess.max_abs < 1e-9
    # white rate noise: ADEV(tau) = sigma / sqrt(rate * tau) for the raw and oracle rate errors
    for name in (ORACLE, 'perfect'):
        tau, adev = rep.result.allan[name]
        k = np.searchsorted(tau, [1.0, 4.0])
        assert adev[k] == pytest.approx(sigma / np.sqrt(RATE_HZ * tau[k]), rel=0.2)


def test_chunking_does_not_change_scores():
    """One chunk vs 2.3-s chunks whose edges split truth (30 Hz) and IMU (100 Hz) differently."""
    kwargs = dict(yaw0_rad=1.0, yaw_rate_rad_s=0.05, drift_rad_s=1e-3, noise_rad_s=3e-3, seed=3,
                  outages=[(70.0, 90.0)], odom_rate_hz=30.0, mag_rate_hz=10.0)
    one = level_unit_chunks(120.0, RATE_HZ, chunk_s=1000.0, **kwargs)
    many = level_unit_chunks(120.0, RATE_HZ, chunk_s=2.3, **kwargs)
    results = [evaluate(chunks_from_list(c), [DriftIntegrator('m', 1e-4, 1.0)]).result for c in (one, many)]
    for name in ('m', ORACLE):
        a, b = (r.scores[name] for r in results)
        for attr in ('error', 'excess', 'error_outage'):
            sa, sb = getattr(a, attr), getattr(b, attr)
            assert sa.n == sb.n
            assert sb.max_abs == pytest.approx(sa.max_abs, rel=1e-7, abs=1e-12)
            assert sb.var == pytest.approx(sa.var, rel=1e-7, abs=1e-15)


def test_earth_rate_is_part_of_the_true_drift():
    omega_up = 5.6e-5  # Earth rate vertical at ~50 deg latitude
    chunks = level_unit_chunks(90.0, RATE_HZ, drift_rad_s=1e-3, chunk_s=10.0)
    chunks = [c.with_streams(imu=type(c.imu)(c.imu.t, c.imu.gyro + [0.0, 0.0, omega_up], c.imu.accel))
              for c in chunks]
    learner = DriftIntegrator('learner', omega_up, 0.0)  # subtracts D + Earth rate
    plain = evaluate(chunks_from_list(chunks), [DriftIntegrator('learner', omega_up, 0.0)]).result
    assert plain.scores['learner'].bias_error.mean == pytest.approx(omega_up)
    earth = evaluate(chunks_from_list(chunks), [learner],
                     earth_rate_enu_rad_s=[0.0, 3.6e-5, omega_up]).result
    assert abs(earth.scores['learner'].bias_error.mean) < 1e-12
    assert earth.scores[ORACLE].error.max_abs < 1e-9


def test_missing_bias_truth_leaves_oracle_and_bias_unscored():
    chunks = [c.with_streams(gyro_bias=None, mag_disturbance=None)
              for c in level_unit_chunks(70.0, RATE_HZ, drift_rad_s=1e-3)]
    yaw_fn = lambda t: 0 * t  # noqa: E731
    rep = evaluate(chunks_from_list(chunks), [TruthPlus('m', lambda t: 1e-3 * t, yaw_fn)])
    r = rep.result
    assert not r.has_bias_truth and not r.has_outage_truth and not r.spans
    assert np.isnan(r.scores[ORACLE].error.mean) and np.isnan(r.scores['m'].excess.mean)
    assert np.isfinite(r.scores['m'].error.max_abs)
    assert 'oracle, excess and bias error unavailable' in rep.to_text()


def test_bad_input_raises_scoring_error():
    chunks = level_unit_chunks(20.0, RATE_HZ)
    no_odom = [c.with_streams(odom=None) for c in chunks]
    with pytest.raises(ScoringError, match='odometry'):
        evaluate(chunks_from_list(no_odom), [DriftIntegrator('m', 0.0, 0.0)])

    class Short:
        name = 'short'

        def update(self, chunk):
            e = np.empty(0)
            return HeadingTrack(e, e, e, e, np.empty(0, bool))

    with pytest.raises(ScoringError, match='rows'):
        evaluate(chunks_from_list(chunks), [Short()])
    with pytest.raises(ScoringError, match='unique'):
        HeadingScorer(['a', 'a'])
    with pytest.raises(ScoringError, match='reserved'):
        HeadingScorer([ORACLE])
    assert RAW != ORACLE


def test_oracle_uses_yaw_kinematics_on_a_tilted_unit():
    """Constant roll 20 deg, pitch 10 deg, yaw rate 0.1 rad/s: the z gyro reads only
    cos(roll)cos(pitch) of the yaw rate; the oracle's ZYX kinematics must recover all of it."""
    from gyro_thermal_comp.angles import quat_from_euler
    from gyro_thermal_comp.samples import ImuSamples, PoseSamples

    roll, pitch, yaw_rate = np.radians(20.0), np.radians(10.0), 0.1
    chunks = level_unit_chunks(60.0, RATE_HZ, yaw0_rad=1.0, yaw_rate_rad_s=yaw_rate, drift_rad_s=1e-3,
                               chunk_s=10.0)
    body_rate = yaw_rate * np.array([-np.sin(pitch), np.sin(roll) * np.cos(pitch),
                                     np.cos(roll) * np.cos(pitch)])
    tilted = []
    for c in chunks:
        o = c.odom
        yaw = 1.0 + yaw_rate * (o.t - 1000.0)
        n = o.t.size
        odom = PoseSamples(o.t, quat_from_euler(np.full(n, roll), np.full(n, pitch), yaw),
                           o.position, o.velocity_body, np.tile(body_rate, (n, 1)))
        gyro = np.tile(body_rate, (c.imu.t.size, 1)) + c.gyro_bias.vec
        tilted.append(c.with_streams(odom=odom, imu=ImuSamples(c.imu.t, gyro, c.imu.accel)))
    naive = DriftIntegrator('z_only', 0.0, 1.0)  # integrates the z gyro as if level
    r = evaluate(chunks_from_list(tilted), [naive]).result
    assert r.scores[ORACLE].error.max_abs < 1e-9
    lost = yaw_rate * (1 - np.cos(roll) * np.cos(pitch))  # rad/s the level assumption misses
    t = np.arange(0, 60.0, DT)
    expected = -lost * t - ref_mean(t, -lost * t)
    assert r.scores['z_only'].error.max_abs == pytest.approx(np.abs(expected).max(), rel=1e-6)
