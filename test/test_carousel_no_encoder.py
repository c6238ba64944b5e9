"""The carousel without an encoder. The gyro angle corrected from gravity (tilted spin axis),
diagnostics and today's behaviour when it is not observable, chunking invariance, the start-up still
check and the spin coupling removed at rest. Short simulated runs (seconds); the bundled-bag
acceptance is in test_carousel_node_bags.py, the 10-seed numbers in benchmarks/carousel_table3.py."""
import numpy as np
import pytest

from conftest import assert_same_records, random_batches
from gyro_thermal_comp.carousel import CarouselConfig, CarouselDemodulator
from gyro_thermal_comp.evaluation.carousel import Truth, angle_in_use_errors, record_truth_errors, run_high_rate
from gyro_thermal_comp.carousel.still_start import StillStart
from gyro_thermal_comp.carousel.synthetic import split_chunk
from gyro_thermal_comp.sim import make_config, simulate

# Independent of the bundled bag (seed 8, roll 2 / pitch -1.5 deg, 0.5 Hz): other seed, tilt, rate.
PARAMS = {'still_s': 20.0, 'roll_deg': -1.2, 'pitch_deg': 3.1, 'spin_hz': 0.8, 'wobble_pct': 4.0, 'wobble_hz': 0.11,
          'spin_stop_s': 100.0}


def _run(chunks, **cfg):
    return run_high_rate(chunks, CarouselConfig.turntable(high_rate=True, **cfg))


@pytest.fixture(scope='module')
def tilted():
    cfg = make_config('carousel_tilted', seed=31, duration_s=130.0, params=PARAMS)
    return cfg, list(simulate(cfg))


def test_tilted_axis_angle_follows_gravity(tilted):
    """Without an encoder the angle in use stays within 0.5 deg of the true platform angle after the
    first 10 revolutions (the angle target), where the plain gyro angle drifts by degrees; the in-plane
    specific force comes out in the body frame (far closer to truth than with the drifting gyro angle)."""
    cfg, chunks = tilted
    truth = Truth(cfg)
    recs, high, demod = _run(chunks, angle_source='gyro')
    err = angle_in_use_errors(truth, recs, high)
    assert len(err) > 40
    assert np.max(np.abs(np.degrees(err))) <= 0.5, np.degrees(err)
    assert demod.angle_reference.startswith('gyro; gravity:'), demod.angle_reference
    recs_plain, high_plain, plain = _run(chunks, angle_source='gyro', angle_reference='none')
    drift = angle_in_use_errors(truth, recs_plain, high_plain)
    assert np.max(np.abs(np.degrees(drift))) > 2.0          # the uncorrected gyro angle drifts
    assert 'none' in plain.angle_reference
    _, da, _ = record_truth_errors(truth, recs, 35.0, 100.0)
    _, da_plain, _ = record_truth_errors(truth, recs_plain, 35.0, 100.0)
    assert np.linalg.norm(da[:2]) * 5 < np.linalg.norm(da_plain[:2]), (da, da_plain)


def test_level_axis_is_unobservable_and_keeps_todays_behaviour():
    cfg = make_config('carousel_tilted', seed=32, duration_s=60.0,
                      params={**PARAMS, 'roll_deg': 0.0, 'pitch_deg': 0.0, 'spin_stop_s': 1e4})
    chunks = list(simulate(cfg))
    recs, _, demod = _run(chunks, angle_source='gyro', spin_coupling=False)
    plain, _, _ = _run(chunks, angle_source='gyro', angle_reference='none', spin_coupling=False)
    assert demod.angle_reference.startswith('gyro; unobservable'), demod.angle_reference
    assert len(recs) == len(plain) > 50
    assert_same_records(recs, plain, modes=False)


def test_no_encoder_output_does_not_depend_on_chunking(tilted):
    cfg, chunks = tilted
    pieces = random_batches(chunks, seed=1, n=400)
    assert len(pieces) > 200
    a, _, _ = _run(chunks, angle_source='gyro')
    b, _, _ = _run(pieces, angle_source='gyro')
    assert len(a) == len(b) > 50
    assert_same_records(a, b)


@pytest.mark.parametrize('angle_source', ['gyro', 'auto'])
def test_spin_coupling_removed_at_rest(tilted, angle_source):
    """At rest after spinning the in-plane rate error is <= 2x the gyro's bias instability (the
    at-rest target); removing the spinning bias instead (k * Omega left in) is > 10x worse."""
    cfg, chunks = tilted
    truth = Truth(cfg)
    instability = np.radians(cfg.unit.gyro_bias_instability_dps[:2])
    rest = (110.0, 130.0)                      # braking ends at 100 + spinup_s
    recs, _, demod = _run(chunks, angle_source=angle_source)
    dw, _, _ = record_truth_errors(truth, recs, *rest, mode='pass_through')
    assert np.all(np.abs(dw[:2]) <= 2 * instability), (dw, instability)
    assert 'removed at rest' in demod.spin_coupling
    old, _, off = _run(chunks, angle_source=angle_source, spin_coupling=False)
    dw_old, _, _ = record_truth_errors(truth, old, *rest, mode='pass_through')
    assert np.linalg.norm(dw_old[:2]) > 10 * np.linalg.norm(dw[:2]), (dw_old, dw)
    assert off.spin_coupling == 'off'


def _still_samples(turn_rate_rad_s: float, n: int = 500, dt: float = 0.01):
    """Still platform; the body turns about x at turn_rate (gravity turns in the sensor frame)."""
    t = np.arange(n) * dt
    phi = turn_rate_rad_s * t
    accel = np.column_stack((np.zeros(n), 9.81 * np.sin(phi), 9.81 * np.cos(phi)))
    gyro = np.column_stack((np.full(n, turn_rate_rad_s), np.zeros(n), np.zeros(n)))
    moving = np.column_stack((np.zeros(5), np.zeros(5), np.full(5, 1.0)))     # then the platform turns
    return (np.concatenate((t, t[-1] + dt * np.arange(1, 6))), np.vstack((gyro, moving)),
            np.vstack((accel, np.tile(accel[-1], (5, 1)))))


@pytest.mark.parametrize('turn_rate, accepted', [(0.0, True), (0.02, False)])
def test_still_start_needs_the_body_at_rest(turn_rate, accepted):
    still = StillStart(CarouselConfig())
    seen = []
    still.on_close(seen.append)
    t, gyro, accel = _still_samples(turn_rate)
    still.add(t, gyro, accel)
    assert seen == [still] and still.accepted == accepted, still.reason
    assert still.duration_s == pytest.approx(4.99, abs=1e-9)
    if not accepted:
        assert 'body moved' in still.reason


def test_spin_rate_step_teaches_the_coupling_without_a_still_start():
    """No still start (1 s): k comes from a rate step (0.5 -> 1.5 Hz, 100 s each) alone; after the stop
    the in-plane rate error is <= 2x the bias instability. (40 s each side was not enough: 2.9x.)"""
    cfg = make_config('carousel_tilted', seed=42, duration_s=240.0,
                      params={'still_s': 1.0, 'spin_step_s': 100.0, 'spin_step_hz': 1.5, 'spin_stop_s': 200.0})
    chunks = list(simulate(cfg))
    recs, _, demod = _run(chunks)
    assert demod.still.reason.startswith('no still start')
    assert 'removed at rest' in demod.spin_coupling
    dw, _, _ = record_truth_errors(Truth(cfg), recs, 210.0, 240.0, mode='pass_through')
    assert np.all(np.abs(dw[:2]) <= 2 * np.radians(cfg.unit.gyro_bias_instability_dps[:2])), dw


def test_coupling_measurement_is_exact_through_a_spin_up():
    """A revolution whose rate ramps (spin-up: 6 -> 9 rad/s within the turn) has the in-plane bias
    b0 + k * Omega(t): the coupling's measurement is b0 + k * (time-mean Omega) to rounding, with the
    body's rate in the samples. The lock-in's constant-bias-plus-body-trend fit, which the coupling used
    before, is off by a fraction of k * dOmega (it gave 1e-4 rad/s on a simulated spin-up)."""
    from types import SimpleNamespace
    from gyro_thermal_comp.carousel.bias_book import SensorBiasBook
    from gyro_thermal_comp.carousel.lockin import RevolutionStats, solve
    from gyro_thermal_comp.carousel.record_assembly import RecordAssembler
    from gyro_thermal_comp.carousel.window import IntervalSignals, IntervalWindow
    t = np.linspace(0.0, 0.84, 85)                  # 9 rad/s at the end: one turn in 0.84 s
    spin = 6.0 + 3.0 * t / t[-1]
    theta = np.concatenate(([0.0], np.cumsum(0.5 * (spin[1:] + spin[:-1]) * np.diff(t))))
    b0, k, body = 2e-3 - 1e-3j, 5e-4 + 8e-4j, 4e-5 + 2e-5j
    gyro = b0 + k * spin + np.exp(-1j * theta) * body
    z = np.zeros(len(t))
    signals = IntervalSignals(t=t, theta=theta, gyro_inplane=gyro, accel_inplane=z.astype(complex), gyro_axial=z,
                              accel_axial=z, spin=spin)
    window = IntervalWindow(signals, inside=None)
    fake = SimpleNamespace(_book=SensorBiasBook(), config=CarouselConfig())
    value, variance = RecordAssembler._coupling_measurement(fake, window)
    expected = b0 + k * window.time_mean(spin)
    assert abs(value - expected) < 1e-12, (value, expected)
    assert 0 < variance <= CarouselConfig().bias_variance_floor      # noise-free: the floor
    stats = RevolutionStats.from_samples(t, theta, gyro[:, None], 1, 0.5 * t[-1])
    lockin = solve([stats], 1, 0.5 * t[-1], 1e-30)[0].bias
    assert abs(lockin - expected) > 1e-6         # what the old measurement took up of the ramp


def test_diagnostics_do_not_change_the_output(tilted):
    """The node reads `spin_coupling` / `angle_reference` for /diagnostics at wall-clock moments; reading
    them must not change any record (the spin coupling once applied a pending still-start measurement when
    asked whether it was learnt: 5.7e-5 rad/s at rest with 0.5 s batches)."""
    cfg, chunks = tilted
    pieces = [p for c in chunks for p in split_chunk(c, np.arange(np.ceil(c.imu.t[0]), c.imu.t[-1], 0.5)[1:])]
    quiet, _, _ = _run(pieces, angle_source='gyro')
    demod = CarouselDemodulator(CarouselConfig.turntable(high_rate=True, angle_source='gyro'))
    asked = []
    for c in pieces:
        asked.append(demod.update(c))
        _ = (demod.spin_coupling, demod.angle_reference)
    recs = [r for o in asked + [demod.flush()] for r in o.records]
    assert len(recs) == len(quiet) > 50
    for a, b in zip(recs, quiet):
        np.testing.assert_array_equal(a.rate_body_rad_s, b.rate_body_rad_s)
