"""Carousel demodulator core: bias cancellation, streaming, bad input, stops, wheel mode,
high-rate output, temperature."""
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from gyro_thermal_comp.carousel import CarouselConfig, CarouselDemodulator, FlipConfig, records_as_arrays
from gyro_thermal_comp.carousel.integrals import time_integral
from gyro_thermal_comp.carousel.synthetic import simulate, spin_rate_profile, split_chunk
from gyro_thermal_comp.samples import ImuSamples, JointSamples, SensorChunk

G = 9.80665
BIAS_G = (0.02, -0.03, 0.005)        # rad/s, imu frame
BIAS_A = (0.15, -0.1, 0.05)          # m/s^2


def run(chunks, cfg=None, flush=True):
    demod = CarouselDemodulator(cfg or CarouselConfig())
    outs = [demod.update(c) for c in chunks]
    if flush:
        outs.append(demod.flush())
    return outs, demod


def all_records(outs):
    return [r for o in outs for r in o.records]


def assert_tiled(records, gaps_allowed=0):
    """Records follow each other without holes or overlaps (except across reported data gaps)."""
    starts = np.array([r.t_s - r.duration_s for r in records])
    ends = np.array([r.t_s for r in records])
    holes = np.abs(starts[1:] - ends[:-1]) > 1e-9
    assert np.count_nonzero(holes) <= gaps_allowed
    assert np.all(np.array([r.duration_s for r in records]) > 0)


def assert_finite(outs):
    for o in outs:
        for r in o.records:
            for v in (r.rate_body_rad_s, r.specific_force_body_m_s2, r.spin_rate_rad_s, r.axial_residual_rad_s,
                      r.gyro_bias_inplane_rad_s, r.accel_bias_inplane_m_s2):
                assert np.all(np.isfinite(v))
        if o.high_rate is not None:
            assert np.all(np.isfinite(o.high_rate.rate_body_rad_s))
            assert np.all(np.isfinite(o.high_rate.specific_force_body_m_s2))


@pytest.mark.parametrize('spin_hz', [0.5, 4.0])
@pytest.mark.parametrize('encoder', [True, False])
def test_constant_inplane_bias_vanishes_to_numerical_precision(spin_hz, encoder):
    """Sensor-fixed in-plane biases leave no trace in the per-revolution body output, even with a
    +-5 % wobbling spin rate, where a plain time average of the rotated samples leaks."""
    dur = 20.0 if spin_hz < 1 else 5.0
    chunk, truth = simulate(dur, 100.0, spin_rate_profile(spin_hz, 0.05, 0.37 * spin_hz),
                            body_force=(0.0, 0.0, G), gyro_bias=BIAS_G, accel_bias=BIAS_A,
                            encoder_hz=100.0 if encoder else None)
    outs, _ = run([chunk])
    recs = [r for r in all_records(outs) if r.mode == 'demodulated']
    assert len(recs) >= 8
    rate = np.array([r.rate_body_rad_s for r in recs])
    sf = np.array([r.specific_force_body_m_s2 for r in recs])
    assert np.max(np.abs(rate[:, :2])) < 1e-13
    assert np.max(np.abs(sf[:, :2])) < 1e-12
    np.testing.assert_allclose(sf[:, 2], G + BIAS_A[2], atol=1e-9)   # axial: not modulated
    # The same revolutions averaged naively in time: the wobble makes the bias leak.
    t, th = truth.t, truth.theta_rad
    g = chunk.imu.gyro
    z = np.exp(1j * th) * (g[:, 0] + 1j * g[:, 1])
    leak = []
    for r in recs:
        sel = (t >= r.t_s - r.duration_s) & (t <= r.t_s)
        leak.append(abs(time_integral(t[sel], z[sel]) / (t[sel][-1] - t[sel][0])))
    assert np.max(leak) > 1e-4


def test_constant_body_signal_passes_exactly_with_encoder():
    """A constant body rate and a tilted gravity come out exactly (in-plane via the angle integral,
    axial via the time mean minus the revolution-period spin rate)."""
    w_b = np.array([0.02, -0.01, 0.03])
    f_b = np.array([0.4, -0.3, np.sqrt(G ** 2 - 0.25)])
    chunk, _ = simulate(10.0, 100.0, spin_rate_profile(2.0, 0.05, 0.7), body_rate=w_b, body_force=f_b,
                        gyro_bias=BIAS_G, accel_bias=BIAS_A, encoder_hz=100.0)
    recs = [r for r in all_records(run([chunk])[0]) if r.mode == 'demodulated']
    rate = np.array([r.rate_body_rad_s for r in recs])
    sf = np.array([r.specific_force_body_m_s2 for r in recs])
    np.testing.assert_allclose(rate[:, :2], np.broadcast_to(w_b[:2], (len(recs), 2)), atol=1e-12)
    np.testing.assert_allclose(sf[:, :2], np.broadcast_to(f_b[:2], (len(recs), 2)), atol=1e-11)
    # spin removed, bias stays; left: boundary timing from linear angle interpolation, ~1e-5 Omega
    np.testing.assert_allclose(rate[:, 2], w_b[2] + BIAS_G[2], atol=1e-5 * 2 * np.pi * 2.0)


def test_chunk_size_does_not_change_output():
    chunk, _ = simulate(12.0, 100.0, spin_rate_profile(1.0, 0.05, 0.3), gyro_bias=BIAS_G, accel_bias=BIAS_A,
                        gyro_noise=0.003, accel_noise=0.02, encoder_hz=50.0, seed=4,
                        temperature=lambda t: 25 + 0.1 * t)
    ref_outs = run([chunk], CarouselConfig(high_rate=True))[0]
    ref = records_as_arrays(all_records(ref_outs))
    ref_hr = np.concatenate([o.high_rate.rate_body_rad_s for o in ref_outs if o.high_rate is not None])
    rng = np.random.default_rng(0)
    edges = np.cumsum(rng.choice([0.0005, 0.01, 0.013, 0.3, 1.7], size=2000))
    edges = edges[edges < 12.5]
    outs, _ = run(split_chunk(chunk, edges), CarouselConfig(high_rate=True))
    got = records_as_arrays(all_records(outs))
    assert len(got['t_s']) == len(ref['t_s'])
    np.testing.assert_array_equal(got['mode'], ref['mode'])
    np.testing.assert_allclose(got['t_s'], ref['t_s'], rtol=0, atol=1e-12)
    np.testing.assert_allclose(got['rate_body_rad_s'], ref['rate_body_rad_s'], rtol=0, atol=1e-12)
    hr = np.concatenate([o.high_rate.t for o in outs if o.high_rate is not None])
    np.testing.assert_array_equal(hr, chunk.imu.t)      # every sample out exactly once, in order
    hr_rate = np.concatenate([o.high_rate.rate_body_rad_s for o in outs if o.high_rate is not None])
    np.testing.assert_allclose(hr_rate, ref_hr, rtol=0, atol=1e-12)


def test_joint_stream_arriving_late_in_separate_chunks():
    """A live node gets IMU and joint messages separately; the IMU waits for the encoder."""
    chunk, _ = simulate(8.0, 100.0, spin_rate_profile(1.0, 0.05, 0.3), gyro_bias=BIAS_G, encoder_hz=100.0,
                        gyro_noise=0.003, seed=5)
    ref = records_as_arrays(all_records(run([chunk])[0]))
    pieces = split_chunk(chunk, np.arange(0.1, 8.1, 0.1))
    imu_only = [SensorChunk(imu=p.imu) for p in pieces]
    joint_only = [SensorChunk(joint=p.joint) for p in pieces]
    stream = []
    for i in range(len(pieces)):
        stream.append(imu_only[i])
        if i >= 1:
            stream.append(joint_only[i - 1])          # joint lags one IMU chunk (0.1 s < timeout)
    stream.append(joint_only[-1])
    outs, _ = run(stream)
    got = records_as_arrays(all_records(outs))
    assert set(got['reason']) == set(ref['reason'])
    np.testing.assert_allclose(got['rate_body_rad_s'], ref['rate_body_rad_s'], atol=1e-12)
    assert all(r.angle_source == 'encoder' for r in all_records(outs) if r.mode == 'demodulated')


def test_bad_input_dropped_counted_and_never_propagated():
    chunk, _ = simulate(20.0, 100.0, spin_rate_profile(1.0, 0.05, 0.3), gyro_bias=BIAS_G, accel_bias=BIAS_A,
                        encoder_hz=100.0, seed=6)
    imu = chunk.imu
    t, g, a = imu.t.copy(), imu.gyro.copy(), imu.accel.copy()
    g[100] = np.nan                      # NaN gyro row
    a[200, 1] = np.inf                   # infinite accel
    t[300] = np.nan                      # NaN stamp
    keep = ~((t >= 10.0) & (t <= 10.5))  # a 0.5 s gap (the NaN stamp stays)
    t, g, a = t[keep], g[keep], a[keep]
    dup = np.arange(400, 405)            # repeated stamps
    order = np.concatenate((np.arange(0, 600), dup, np.arange(600, len(t))))
    t, g, a = t[order], g[order], a[order]
    t[700], t[701] = t[701], t[700]      # one swapped pair: the later-arriving earlier stamp is dropped
    jt, jp = chunk.joint.t.copy(), chunk.joint.position.copy()
    jp[50] = np.nan
    joint = JointSamples(jt, jp, chunk.joint.velocity)
    # IMU in chunks of 37 samples by index (a NaN stamp cannot be split by time); encoder up front
    chunks = [SensorChunk(imu=ImuSamples(t[i:i + 37], g[i:i + 37], a[i:i + 37]), joint=joint if i == 0 else None)
              for i in range(0, len(t), 37)]
    outs, demod = run(chunks)
    assert_finite(outs)
    c = demod.counts
    assert c['imu_dropped_nonfinite'] == 3
    assert c['imu_dropped_order'] == 5 + 1
    assert c['joint_dropped_nonfinite'] == 1
    assert c['gaps'] == 1
    recs = all_records(outs)
    assert any('data gap' in r.reason for r in recs)
    assert_tiled(recs, gaps_allowed=1)
    after = [r for r in recs if r.t_s > 12.5]
    assert after and all(r.mode == 'demodulated' for r in after[:-1])   # recovers after the gap
    assert all(np.max(np.abs(r.rate_body_rad_s[:2])) < 1e-9 for r in recs if r.mode == 'demodulated')


@pytest.mark.parametrize('encoder', [True, False])
def test_spin_stop_goes_to_pass_through_and_output_continues(encoder):
    w_b = np.array([0.01, -0.02, 0.015])
    chunk, truth = simulate(50.0, 100.0, spin_rate_profile(1.0, 0.05, 0.2, stops=[(20.0, 32.0, 1.5)]),
                            body_rate=w_b, gyro_bias=BIAS_G, accel_bias=BIAS_A, gyro_noise=0.002,
                            accel_noise=0.01, encoder_hz=100.0 if encoder else None, seed=7)
    outs, demod = run(split_chunk(chunk, np.arange(0.25, 50, 0.25)))
    recs = all_records(outs)
    assert_finite(outs)
    assert_tiled(recs)
    modes = [(r.t_s, r.mode, r.reason) for r in recs]
    stopped = [m for m in modes if 24.0 < m[0] < 32.0]
    assert stopped and all(m[1] == 'pass_through' and 'too slow' in m[2] for m in stopped)
    assert max(np.diff([m[0] for m in stopped])) <= 0.5 + 1e-9           # output keeps coming
    assert all(m[1] == 'demodulated' for m in modes if 3.0 < m[0] < 19.0)
    assert all(m[1] == 'demodulated' for m in modes if 36.0 < m[0] < 49.0)
    # While stopped the last lock-in bias estimates are applied: body in-plane rates stay right.
    st = np.array([r.rate_body_rad_s for r in recs if 25.0 < r.t_s < 31.0])
    if encoder:
        assert np.max(np.abs(st[:, :2] - w_b[:2])) < 2e-3
        # stopped carousel: nothing to subtract, axial = body + axial bias
        assert np.max(np.abs(st[:, 2] - (w_b[2] + BIAS_G[2]))) < 2e-3
    else:
        # without encoder the in-plane frame turns with the integrated body yaw and axial bias
        # (docs/carousel.md); biases are still removed, so the in-plane magnitude is right
        assert np.max(np.abs(np.hypot(st[:, 0], st[:, 1]) - np.hypot(*w_b[:2]))) < 2e-3
    out_modes = [o.mode for o in outs]
    assert 'pass_through' in out_modes[100:140] and out_modes[-2] == 'demodulated'


def test_wheel_mode_varying_speed_reverse_and_irregular():
    """Wheel: speed ramps, an abrupt brake inside a revolution (irregular -> pass-through), then
    reversing; every demodulated revolution still cancels the biases."""
    def rate(t):
        t = np.asarray(t, dtype=float)
        w = np.interp(t, [0, 5, 10, 12.0, 12.15, 14, 16, 18, 25],
                      [2.0, 20.0, 20.0, 20.0, 4.0, 4.0, 0.0, -8.0, -8.0])
        return w
    chunk, _ = simulate(25.0, 200.0, rate, gyro_bias=BIAS_G, accel_bias=BIAS_A,
                        body_force=(0.5, 0.0, 9.79), encoder_hz=200.0)
    outs, _ = run([chunk], CarouselConfig.wheel())
    recs = all_records(outs)
    assert_tiled(recs)
    reasons = [r.reason for r in recs if r.mode == 'pass_through']
    assert any('irregular' in x for x in reasons)
    dem = [r for r in recs if r.mode == 'demodulated']
    spins = np.array([r.spin_rate_rad_s for r in dem])
    assert np.any(spins > 15) and np.any(spins < -5)         # forwards and reverse revolutions
    rate_in = np.array([r.rate_body_rad_s[:2] for r in dem])
    sf_in = np.array([r.specific_force_body_m_s2[:2] for r in dem])
    assert np.max(np.abs(rate_in)) < 1e-9
    assert np.max(np.abs(sf_in - [0.5, 0.0])) < 1e-9


def test_high_rate_output_tracks_truth_after_lockin():
    w_b = np.array([0.01, -0.02, 0.015])
    chunk, truth = simulate(20.0, 100.0, spin_rate_profile(2.0, 0.05, 0.3), body_rate=w_b, gyro_bias=BIAS_G,
                            accel_bias=BIAS_A, gyro_noise=0.002, accel_noise=0.01, encoder_hz=100.0, seed=8)
    outs, _ = run([chunk], CarouselConfig(high_rate=True))
    hr = outs[0].high_rate
    assert len(hr.t) == len(chunk.imu.t)
    late = hr.t > 5.0
    err = hr.rate_body_rad_s[late] - (w_b + [0, 0, BIAS_G[2]])
    assert np.max(np.abs(np.mean(err, axis=0))) < 3e-4
    assert np.std(err[:, 0]) < 0.004
    ferr = hr.specific_force_body_m_s2[late] - [0, 0, G + BIAS_A[2]]
    assert np.max(np.abs(np.mean(ferr, axis=0))) < 2e-3
    early = hr.rate_body_rad_s[hr.t < 0.5]          # before any estimate: biases still in
    assert np.abs(np.mean(np.hypot(early[:, 0] - w_b[0], early[:, 1] - w_b[1]))) > 0.02


def test_temperature_mean_and_rate_on_records_and_measurements():
    temp = lambda t: 30.0 + 0.05 * t
    chunk, _ = simulate(20.0, 100.0, spin_rate_profile(1.0), gyro_bias=BIAS_G, encoder_hz=100.0,
                        temperature=temp, temperature_hz=10.0)
    outs, _ = run(split_chunk(chunk, np.arange(0.3, 20, 0.3)))
    recs = [r for r in all_records(outs) if r.mode == 'demodulated']
    for r in recs:
        assert r.temperature_c == pytest.approx(temp(r.t_s - 0.5 * r.duration_s), abs=0.01)
    meas = [m for o in outs for m in o.bias_measurements]
    assert len(meas) == 2 * len(recs)
    assert all(m.temperature_rate_c_s == pytest.approx(0.05, rel=1e-6) for m in meas)


def test_encoder_dropout_switches_to_gyro_and_back():
    chunk, _ = simulate(30.0, 100.0, spin_rate_profile(1.0, 0.05, 0.3), gyro_bias=BIAS_G, encoder_hz=100.0)
    j = chunk.joint
    keep = (j.t < 10.0) | (j.t > 16.0)
    chunk = chunk.with_streams(joint=JointSamples(j.t[keep], j.position[keep], j.velocity[keep]))
    outs, demod = run(split_chunk(chunk, np.arange(0.1, 30, 0.1)))
    recs = all_records(outs)
    assert_tiled(recs)
    src = {(r.angle_source, r.mode) for r in recs if 12.5 < r.t_s < 15.5}
    assert ('gyro', 'demodulated') in src
    assert all(r.angle_source == 'encoder' for r in recs if r.t_s > 19.0 and r.mode == 'demodulated')
    assert demod.counts['angle_source_switches'] == 2
    assert any('angle source changed (encoder -> gyro)' in r.reason for r in recs)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 10_000), encoder=st.booleans(), flip=st.booleans(), high_rate=st.booleans(),
       bad_fraction=st.floats(0.0, 0.05), spin_hz=st.sampled_from([0.3, 1.0, 4.0]))
def test_fuzz_random_chunking_and_corruption_never_raises_or_emits_nan(seed, encoder, flip, high_rate,
                                                                       bad_fraction, spin_hz):
    rng = np.random.default_rng(seed)
    chunk, _ = simulate(8.0, 100.0, spin_rate_profile(spin_hz, 0.05, 0.3, stops=[(3.0, 4.5, 0.5)]),
                        gyro_bias=BIAS_G, accel_bias=BIAS_A, gyro_noise=0.003, encoder_hz=100.0 if encoder else None,
                        flips=[(5.0, 0.4, 1)] if flip else (), aux_hz=80.0 if flip else None, seed=seed)
    imu = chunk.imu
    t, g, a = imu.t.copy(), imu.gyro.copy(), imu.accel.copy()
    n = len(t)
    for arr in (t, g, a):
        idx = rng.choice(n, int(bad_fraction * n), replace=False)
        arr[idx] = rng.choice([np.nan, np.inf, -np.inf])
    perm = np.arange(n)
    sw = rng.choice(n - 1, int(bad_fraction * n), replace=False)
    perm[sw], perm[sw + 1] = perm[sw + 1], perm[sw]
    t, g, a = t[perm], g[perm], a[perm]
    cut = np.sort(rng.choice(n, size=rng.integers(1, 200), replace=False))
    pieces = np.split(np.arange(n), cut)
    others = split_chunk(chunk.with_streams(imu=None), [t[p[-1]] if len(p) and np.isfinite(t[p[-1]]) else 0.0
                                                         for p in pieces[:-1]])
    cfg = CarouselConfig(high_rate=high_rate, flip=FlipConfig(enabled=flip))
    demod = CarouselDemodulator(cfg)
    outs = []
    for p, o in zip(pieces, others):
        outs.append(demod.update(o.with_streams(imu=ImuSamples(t[p], g[p], a[p]))))
    outs.append(demod.flush())
    assert_finite(outs)
    recs = all_records(outs)
    assert recs
    ends = np.array([r.t_s for r in recs])
    starts = ends - np.array([r.duration_s for r in recs])
    assert np.all(np.diff(ends) > 0) and np.all(starts[1:] >= ends[:-1] - 1e-9)
    for o in outs:
        for m in o.bias_measurements:
            assert np.isfinite(m.bias_rad_s) and m.variance_rad2_s2 > 0
