"""A wheel without an encoder: gravity less the road acceleration R dOmega/dt as the angle reference
(carousel/wheel_reference.py), the axle's tilt turning the body's yaw into the axial gyro, the radius learnt,
diagnostics and chunking. Short simulated runs of `carousel_wheel_drive` (pull away, turn, brake to a stop,
stand, back up; the hub on the body's centre line); the 5-seed figures: benchmarks/carousel_table3.py."""
from dataclasses import replace

import numpy as np
import pytest

from conftest import assert_same_records, random_batches
from gyro_thermal_comp.angles import euler_from_quat
from gyro_thermal_comp.carousel import CarouselConfig, CarouselDemodulator
from gyro_thermal_comp.evaluation.carousel import CAROUSEL_TO_BODY, Truth, record_truth_errors, run_demodulator, run_high_rate
from gyro_thermal_comp.carousel.synthetic import split_chunk
from gyro_thermal_comp.carousel import wheel_reference
from gyro_thermal_comp.carousel.wheel_reference import axle_tilt_rate, mean_spin_acceleration
from gyro_thermal_comp.sim import make_config, simulate

AXLE = tuple(map(tuple, CAROUSEL_TO_BODY['carousel_wheel']))
RADIUS_M = 0.32
# Not the scenario's defaults (speed 6, brake 4 s, radius 0.3, still 60 s): seed, speed, braking, radius.
PARAMS = {'still_s': 20.0, 'speed_mps': 7.0, 'wheel_radius_m': RADIUS_M, 'brake_s': 3.5}
GIVEN_M = RADIUS_M * 1.02          # the radius a user gives: 2 % off


def _wheel(**kw) -> CarouselConfig:
    return CarouselConfig.wheel(carousel_to_body=AXLE, **kw)


@pytest.fixture(scope='module')
def drive():
    """20 s still, then two and a bit laps (62 s each): two left turns, two hard stops, two reverses."""
    cfg = make_config('carousel_wheel_drive', seed=41, duration_s=160.0, params=PARAMS)
    return cfg, list(simulate(cfg))


def level_angle_errors_deg(truth: Truth, records, high, skip: int = 10) -> np.ndarray:
    """Per demodulated revolution after the first `skip`: mean(angle in use - (true wheel angle + body pitch)),
    deg. The body's pitch turns gravity as the wheel does and the gyro sees its rate: no wheel-mounted IMU
    can tell it from the wheel's angle (wheel_reference.py), so the angle is the wheel's against the level."""
    pitch = euler_from_quat(truth.world.motion.state(high.t).quat)[1]
    err = high.theta_rad - truth.joint_angle(high.t) - pitch
    out = [np.mean(err[(high.t > r.t_s - r.duration_s) & (high.t <= r.t_s)])
           for r in [r for r in records if r.mode == 'demodulated'][skip:]]
    return np.degrees(np.angle(np.exp(1j * np.array(out))))


def test_wheel_angle_follows_gravity_less_the_road_acceleration(drive, monkeypatch):
    """With the rolling relation and the axle's tilt the angle in use stays within 0.3 deg of the wheel's angle
    against the level; with gravity alone the vehicle's accelerations pull it by degrees, and without the
    axle-tilt rate the turns leave it lagging beyond 0.3 deg (`pytest -s` prints all three). The in-plane gyro
    is then as good as with the encoder (body frame), the radius given 2 % off is learnt to 1 %."""
    cfg, chunks = drive
    truth = Truth(cfg)
    recs, high, demod = run_high_rate(chunks, _wheel(high_rate=True, angle_source='gyro', wheel_radius_m=GIVEN_M))
    err = level_angle_errors_deg(truth, recs, high)
    assert len(err) > 150
    assert np.max(np.abs(err)) <= 0.3, np.max(np.abs(err))
    with monkeypatch.context() as m:
        m.setattr(wheel_reference, 'axle_tilt_rate', lambda *args: 0.0)
        no_tilt = level_angle_errors_deg(truth, *run_high_rate(chunks, _wheel(
            high_rate=True, angle_source='gyro', wheel_radius_m=GIVEN_M))[:2])
    assert np.max(np.abs(no_tilt)) > 0.3
    assert demod.angle_reference.startswith('gyro; wheel:'), demod.angle_reference
    learnt = GIVEN_M * (1.0 + demod.gravity.x[3])
    assert abs(learnt / RADIUS_M - 1.0) < 0.01, learnt

    recs_g, high_g, gravity_only = run_high_rate(chunks, _wheel(high_rate=True, angle_source='gyro'))
    gravity_err = level_angle_errors_deg(truth, recs_g, high_g)
    print(f'angle in use against the level, max: wheel {np.max(np.abs(err)):.3f} deg, without the axle tilt '
          f'{np.max(np.abs(no_tilt)):.3f}, gravity alone {np.max(np.abs(gravity_err)):.1f}')
    assert np.max(np.abs(gravity_err)) > 5.0
    assert gravity_only.gravity.rejected > gravity_only.gravity.measurements      # accelerations read as angle
    assert 'set wheel_radius_m' in gravity_only.angle_reference, gravity_only.angle_reference

    encoder, _, _, _ = run_demodulator(chunks, _wheel())
    dw, dw_enc, dw_g = (record_truth_errors(truth, r, 25.0, 160.0, carousel_axes=np.array(AXLE))[0]
                        for r in (recs, encoder, recs_g))
    assert np.linalg.norm(dw[:2]) < 1.5 * np.linalg.norm(dw_enc[:2]), (dw, dw_enc)
    assert np.linalg.norm(dw_g[:2]) > 10 * np.linalg.norm(dw_enc[:2]), (dw_g, dw_enc)


def test_without_a_still_start_the_wheel_reference_comes_from_the_first_revolution_less_its_road_acceleration():
    """The wheel pulls away at once (no still start): the first revolution, accelerating, gives the reference less
    its road acceleration, and its direction is learnt, so a constant axial gyro bias leaves the angle in use
    where it is. Against the level after 10 revolutions: mean error within 0.1 deg at 0 and at 0.5 deg/s of added
    axial bias, 0.5 deg/s moving it by < 0.05 deg; the radius learnt to 1 %."""
    cfg = make_config('carousel_wheel_drive', seed=41, duration_s=160.0, params={**PARAMS, 'still_s': 0.5})
    chunks, truth = list(simulate(cfg)), Truth(cfg)
    means = []
    for bias_dps in (0.0, 0.5):
        biased = []
        for c in chunks:
            gyro = c.imu.gyro.copy()
            gyro[:, 2] += np.radians(bias_dps)         # sensor z: the axle
            biased.append(c.with_streams(imu=replace(c.imu, gyro=gyro)))
        recs, high, demod = run_high_rate(biased, _wheel(high_rate=True, angle_source='gyro', wheel_radius_m=GIVEN_M))
        assert 'the first revolution (no still start' in demod.angle_reference, demod.angle_reference
        err = level_angle_errors_deg(truth, recs, high)
        assert len(err) > 150
        means.append(float(np.mean(err)))
        assert abs(GIVEN_M * (1.0 + demod.gravity.x[3]) / RADIUS_M - 1.0) < 0.01
    assert max(abs(m) for m in means) <= 0.1 and abs(means[1] - means[0]) < 0.05, means


def test_the_road_acceleration_of_a_revolution_comes_from_its_end_rates_whatever_the_profile():
    """(1/turn) integral dOmega/dt dtheta = (Omega_b^2 - Omega_a^2) / (2 turn), forward and in reverse."""
    for sign in (1.0, -1.0):
        t = np.linspace(0.0, 2.0, 200001)
        omega = sign * (3.0 + 2.5 * t ** 2 + 0.7 * np.sin(5.0 * t))          # rad/s, speeding up unevenly
        theta = np.concatenate(([0.0], np.cumsum(0.5 * (omega[1:] + omega[:-1]) * np.diff(t))))
        end = np.searchsorted(np.abs(theta), 2 * np.pi)
        t, omega, theta = t[:end], omega[:end], theta[:end]
        numeric = np.trapezoid(np.gradient(omega, t) * omega, t) / theta[-1]
        assert mean_spin_acceleration(omega[0], omega[-1], theta[-1]) == pytest.approx(numeric, rel=1e-5)


def test_axle_tilt_rate_is_the_yaw_rate_along_a_tilted_axle():
    """An axle rolled by r out of the level, the body yawing at psi_dot while rolling at speed v: the axial gyro
    sees psi_dot sin(r) of the yaw, which gravity does not see; the axial specific force holds g sin(r) and
    the turn's centripetal psi_dot v cos(r)."""
    g, up = 9.81, np.exp(0.7j)              # up's in-plane direction in the carousel frame (any angle)
    for r, yaw, v in ((0.02, 0.3, 7.0), (-0.05, -0.2, -3.0), (0.0, 0.4, 10.0)):
        zeta = axle_tilt_rate(g * np.cos(r) * up, yaw * np.cos(r) * up, g * np.sin(r) + yaw * v * np.cos(r), v)
        assert zeta == pytest.approx(yaw * np.sin(r), abs=1e-12)


def test_wheel_output_does_not_depend_on_chunking(drive):
    cfg, chunks = drive
    short = [chunks[0], split_chunk(chunks[1], [80.0])[0]]   # to 80 s: a turn, a stop, backing up
    config = _wheel(angle_source='gyro', wheel_radius_m=GIVEN_M)
    whole = run_demodulator(short, config).records
    pieces = run_demodulator(random_batches(short, seed=5, n=200), config).records
    assert len(whole) == len(pieces) > 150
    # to rounding of the magnitudes a wheel carries (spin 20 rad/s axial, gravity 9.8 m/s^2 in-plane): 1e-11
    for x, y in zip(whole, pieces):
        assert (x.mode, x.reason) == (y.mode, y.reason)
        assert x.t_s == pytest.approx(y.t_s, abs=1e-9)
        np.testing.assert_allclose(x.rate_body_rad_s, y.rate_body_rad_s, rtol=0, atol=1e-11)
        np.testing.assert_allclose(x.specific_force_body_m_s2, y.specific_force_body_m_s2, rtol=0, atol=1e-11)


def test_diagnostics_say_when_the_wheel_gives_no_reference(drive):
    """Standing at a stop there is no revolution: diagnostics say so and that the learnt gyro model holds the
    angle; driving again, the wheel reference is back. Reading them changes nothing."""
    cfg, chunks = drive
    demod = CarouselDemodulator(_wheel(angle_source='gyro', wheel_radius_m=GIVEN_M))
    stop = 20.0 + 8.0 + 12.0 + 10.0 + PARAMS['brake_s']       # the first stop of the lap starts here
    statuses = []                   # (last sample fed, the diagnostics line then)
    for c in chunks:
        for piece in split_chunk(c, np.array([stop + 6.0])):
            if len(piece.imu.t):
                demod.update(piece)
                statuses.append((float(piece.imu.t[-1]), demod.angle_reference))
    at_stop = [s for t, s in statuses if t < stop + 6.0][-1]
    assert 'no reference for' in at_stop and 'gyro model holds the angle' in at_stop, at_stop
    assert at_stop.startswith('gyro; wheel:')
    assert 'no reference' not in demod.angle_reference and 'radius' in demod.angle_reference


def test_a_vertical_axle_is_unobservable_with_the_wheel_radius_too():
    """wheel_radius_m with the spin axis vertical: gravity gives no angle, nothing is corrected (today's gyro
    angle, as angle_reference none) and the diagnostics say it is unobservable."""
    cfg = make_config('carousel_tilted', seed=42, duration_s=50.0,
                      params={'still_s': 10.0, 'roll_deg': 0.0, 'pitch_deg': 0.0, 'spin_hz': 0.9})
    chunks = list(simulate(cfg))
    recs, _, _, demod = run_demodulator(chunks, CarouselConfig.turntable(angle_source='gyro', wheel_radius_m=0.3,
                                                                      spin_coupling=False))
    plain, _, _, _ = run_demodulator(chunks, CarouselConfig.turntable(angle_source='gyro', angle_reference='none',
                                                                      spin_coupling=False))
    assert demod.angle_reference.startswith('gyro; unobservable'), demod.angle_reference
    assert len(recs) == len(plain) > 30
    assert_same_records(recs, plain, modes=False)
