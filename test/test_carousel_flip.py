"""Two-position flip with an auxiliary IMU standing in, on synthetic arrays."""
import numpy as np
import pytest

from gyro_thermal_comp.carousel import CarouselConfig, CarouselDemodulator, FlipConfig, flip_rotation
from gyro_thermal_comp.carousel.flip import FlipTracker, platform_axis_to_imu
from gyro_thermal_comp.carousel.synthetic import simulate, spin_rate_profile, split_chunk

G = 9.80665
MAIN_G = np.array([0.02, -0.03, 0.012])      # rad/s, imu frame
MAIN_A = np.array([0.1, -0.2, 0.3])          # m/s^2
AUX_G = np.array([0.05, 0.04, -0.02])
AUX_A = np.array([0.2, 0.1, -0.1])
FLIPS = [(10.0, 0.5, 1), (20.0, 0.5, -1), (30.0, 0.4, 1), (40.0, 0.6, -1)]
W_B = np.array([0.004, -0.006, 0.01])        # body rate, rad/s


@pytest.mark.parametrize('axis', ['x', 'y'])
def test_flip_rotation_and_axis_bookkeeping(axis):
    for k in range(4):
        r = flip_rotation(axis, k)
        np.testing.assert_array_equal(r @ r.T, np.eye(3))
        assert np.linalg.det(r) == 1
    np.testing.assert_array_equal(flip_rotation(axis, 1) @ flip_rotation(axis, 1), flip_rotation(axis, 2))
    # position 1 about x: imu y -> platform z, imu z -> platform -y; platform y is imu -z
    if axis == 'x':
        assert platform_axis_to_imu('x', 1, 1) == (2, -1.0)
        assert platform_axis_to_imu('x', 1, 0) == (0, 1.0)
    else:
        assert platform_axis_to_imu('y', 1, 0) == (2, 1.0)


def test_tracker_counts_quarter_turns_in_any_chunking():
    t = np.arange(0, 20, 0.01)
    r = np.zeros_like(t)
    for t0, d, steps in [(3.0, 0.5, 1), (9.0, 0.3, -1), (15.0, 0.8, 2)]:
        u = (t - t0) / d
        inside = (u > 0) & (u < 1)
        r[inside] += steps * (np.pi / 2) * 0.5 * np.pi * np.sin(np.pi * u[inside]) / d
    r += 0.01          # a bias difference between the IMUs does not trigger or distort much
    outs = []
    for parts in ([slice(0, len(t))], [slice(i, i + 7) for i in range(0, len(t), 7)]):
        tr = FlipTracker(0.5, 0.05)
        flips, pos = [], []
        for sl in parts:
            tr.push(t[sl], r[sl])
            decided = tr.release()
            flips.append(decided.flipping)
            pos.append(decided.position)
        decided = tr.release(final=True)
        flips.append(decided.flipping)
        pos.append(decided.position)
        outs.append((np.concatenate(flips), np.concatenate(pos), tr.events))
    (f1, p1, e1), (f2, p2, e2) = outs
    np.testing.assert_array_equal(f1, f2)
    np.testing.assert_array_equal(p1, p2)
    assert [(e.position_before, e.position_after) for e in e1] == [(0, 1), (1, 0), (0, 2)]
    assert not any(e.ambiguous for e in e1)
    assert p1[t.searchsorted(5.0)] == 1 and p1[-1] == 2
    assert f1[t.searchsorted(3.25)] and not f1[t.searchsorted(5.0)]


def _flip_run(encoder=True, aux=True, chunked=False, seed=3):
    chunk, truth = simulate(48.0, 100.0, spin_rate_profile(2.0, 0.05, 0.3), body_rate=W_B,
                            gyro_bias=MAIN_G, accel_bias=MAIN_A, flips=FLIPS,
                            aux_hz=100.0 if aux else None, aux_gyro_bias=AUX_G, aux_accel_bias=AUX_A,
                            encoder_hz=100.0 if encoder else None, seed=seed)
    demod = CarouselDemodulator(CarouselConfig(flip=FlipConfig(enabled=True)))
    chunks = split_chunk(chunk, np.arange(0.05, 48, 0.05)) if chunked else [chunk]
    outs = [demod.update(c) for c in chunks] + [demod.flush()]
    return [r for o in outs for r in o.records], [e for o in outs for e in o.flip_events], demod


@pytest.mark.parametrize('chunked', [False, True])
def test_flip_output_continuous_and_axial_bias_learned(chunked):
    recs, events, demod = _flip_run(chunked=chunked)
    assert [(e.position_before, e.position_after) for e in events] == [(0, 1), (1, 0), (0, 1), (1, 0)]
    starts = np.array([r.t_s - r.duration_s for r in recs])
    ends = np.array([r.t_s for r in recs])
    assert np.max(np.abs(starts[1:] - ends[:-1])) < 1e-9          # no holes, no overlaps
    assert all(r.mode == 'demodulated' for r in recs[1:-1])        # the flips never interrupt output
    stand_in = [r for r in recs if r.aux_fraction > 0]
    assert len(stand_in) >= 8 and max(r.aux_fraction for r in stand_in) > 0.75
    # all three imu biases known after both positions were visited
    np.testing.assert_allclose(demod.book.gyro, MAIN_G, atol=1e-9)
    np.testing.assert_allclose(demod.book.accel, MAIN_A, atol=1e-8)
    assert demod.book.known.all()
    # after the first flip the axial output is free of the axial bias, and stays smooth through
    # the later flips (aux offsets calibrated against the compensated main IMU)
    late = [r for r in recs if 12.0 < r.t_s < 47.0]
    rate = np.array([r.rate_body_rad_s for r in late])
    sf = np.array([r.specific_force_body_m_s2 for r in late])
    assert np.max(np.abs(rate - W_B)) < 1e-4
    assert np.max(np.abs(sf - [0, 0, G])) < 1e-3
    before = np.array([r.rate_body_rad_s[2] for r in recs if 2.0 < r.t_s < 9.5])
    np.testing.assert_allclose(before, W_B[2] + MAIN_G[2], atol=1e-4)   # axial bias still in


def test_flip_without_encoder_keeps_output_continuous():
    recs, events, demod = _flip_run(encoder=False)
    assert len(events) == 4
    assert all(r.mode == 'demodulated' for r in recs[1:-1])
    late = np.array([r.rate_body_rad_s for r in recs if 12.0 < r.t_s < 47.0])
    # in-plane magnitudes survive (frame turns with integrated yaw without an encoder)
    assert np.max(np.abs(np.hypot(late[:, 0], late[:, 1]) - np.hypot(*W_B[:2]))) < 1e-4
    np.testing.assert_allclose(demod.book.gyro[:2], MAIN_G[:2], atol=1e-6)


def test_flip_without_aux_is_reported_as_pass_through():
    recs, events, _ = _flip_run(aux=False)
    flagged = [r for r in recs if 'flip without auxiliary IMU' in r.reason]
    assert flagged and all(r.mode == 'pass_through' for r in flagged)
    for t0, d, _ in FLIPS:
        assert any(r.t_s - r.duration_s <= t0 + 0.5 * d <= r.t_s for r in flagged)
    assert all(np.all(np.isfinite(r.rate_body_rad_s)) for r in recs)
