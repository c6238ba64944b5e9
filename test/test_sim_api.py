"""The simulator's contract: determinism, streaming, validation, interference placement, config record."""
import json

import numpy as np
import pytest

from gyro_thermal_comp.samples import concat_chunks
from gyro_thermal_comp.sim import CHUNK_S, EFFECTS, SCENARIOS, SimConfig, make_config, simulate
from gyro_thermal_comp.sim.engine import build_world

STREAMS = ('imu', 'mag', 'temperature', 'odom', 'gyro_bias', 'mag_disturbance')


def arrays(chunk):
    return {f'{name}.{field}': value for name, s in chunk.streams().items() for field, value in vars(s).items()}


def test_every_scenario_runs_and_starts_still():
    for name in SCENARIOS:
        cfg = make_config(name, duration_s=70, imu_rate_hz=20, mag_rate_hz=10, temp_rate_hz=2)
        ch = concat_chunks(simulate(cfg))
        assert all(getattr(ch, s) is not None and len(getattr(ch, s).t) for s in STREAMS), name
        assert (ch.joint is not None) == name.startswith('carousel'), name
        still = ch.odom.t < 30
        assert np.all(ch.odom.rate_body[still] == 0) and np.all(ch.odom.velocity_body[still] == 0), name
        if ch.joint is not None:
            assert np.all(ch.joint.velocity[still] == 0), name
        json.dumps(cfg.to_dict())


def test_same_seed_is_bit_identical_and_seeds_draw_different_units():
    kw = dict(duration_s=130, imu_rate_hz=50)
    a = [arrays(c) for c in simulate(make_config('vehicle_loop', seed=11, **kw))]
    b = [arrays(c) for c in simulate(make_config('vehicle_loop', seed=11, **kw))]
    assert len(a) == len(b) == 3
    for ca, cb in zip(a, b):
        assert ca.keys() == cb.keys()
        assert all(np.array_equal(ca[k], cb[k]) for k in ca)
    u1, u2 = make_config('static_ramp', seed=1).unit, make_config('static_ramp', seed=2).unit
    for name in ('gyro_a_dps_per_c', 'gyro_b_dps_per_c_per_s', 'gyro_c_dps', 'gyro_curvature_dps_per_c2'):
        assert not np.allclose(getattr(u1, name), getattr(u2, name)), name
    assert make_config('static_ramp', seed=1).to_dict() != make_config('static_ramp', seed=2).to_dict()


def test_a_longer_run_starts_with_the_shorter_one():
    short = concat_chunks(simulate(make_config('carousel_wheel', seed=5, duration_s=130)))
    long = concat_chunks(simulate(make_config('carousel_wheel', seed=5, duration_s=250)))
    for name, value in arrays(short).items():
        stream, field = name.split('.')
        assert np.array_equal(value, getattr(getattr(long, stream), field)[:len(value)]), name


def test_switching_an_effect_keeps_the_unit_and_the_noise():
    kw = dict(seed=3, duration_s=60, imu_rate_hz=50)
    c0 = make_config('static_ramp', **kw)
    c1 = make_config('static_ramp', effects={'thermal_hysteresis': 0.0, 'rate_random_walk': 1e-4}, **kw)
    assert np.array_equal(c0.unit.gyro_a_dps_per_c, c1.unit.gyro_a_dps_per_c)
    assert np.all(c1.unit.gyro_hysteresis_dps == 0) and c1.unit.gyro_rrw_dps_rts[2] == 1e-4
    m0, m1 = (concat_chunks(simulate(c)).mag.field for c in (c0, c1))
    assert np.array_equal(m0, m1)                      # magnetometer noise stream untouched


def test_chunks_are_contiguous_time_ordered_and_about_a_minute():
    cfg = make_config('carousel_vertical', duration_s=200.5, imu_rate_hz=100, mag_rate_hz=30,
                      temp_rate_hz=7, truth_rate_hz=25)
    chunks = list(simulate(cfg))
    assert len(chunks) == 4
    rates = {'imu': 100, 'mag': 30, 'temperature': 7, 'odom': 25, 'gyro_bias': 25, 'mag_disturbance': 25,
             'joint': 100}  # the encoder is sampled with the IMU
    for stream, rate in rates.items():
        parts = [getattr(c, stream).t for c in chunks]
        t = np.concatenate(parts)
        k = np.arange(len(t))
        assert np.array_equal(t, k / rate), stream                   # exact stamps, no gaps or repeats
        assert t[-1] < cfg.duration_s <= t[-1] + 1 / rate + 1e-12, stream
        for j, p in enumerate(parts[:-1]):
            assert p[0] >= j * CHUNK_S and p[-1] < (j + 1) * CHUNK_S, stream
    imu_t = np.concatenate([c.imu.t for c in chunks])
    assert np.all(np.isin(np.concatenate([c.odom.t for c in chunks]), imu_t))   # truth on IMU stamps


def test_streaming_matches_across_chunk_boundaries():
    """Filter states carry over: the lagged drift has no seam at a chunk boundary."""
    cfg = make_config('static_ramp', duration_s=2000, imu_rate_hz=10, effects={'thermal_lag': 120.0})
    d = np.concatenate([c.gyro_bias.vec[:, 2] for c in simulate(cfg)])
    step = np.abs(np.diff(d))
    seams = np.arange(1, 2000 // 60 + 1) * 600 - 1
    assert step[seams].max() < 5 * np.median(step) + 1e-9


@pytest.mark.parametrize('kwargs, words', [
    (dict(scenario='nope'), ['unknown scenario', 'static_ramp', 'carousel_wheel']),
    (dict(effects={'thermal_lagg': 1}), ['unknown effect', 'thermal_lag', 'compass_deviation']),
    (dict(effects={'thermal_lag': -1}), ['thermal_lag', 'out of range']),
    (dict(effects={'scale_factor': float('nan')}), ['scale_factor', 'finite']),
    (dict(effects={'g_sensitivity': 'big'}), ['g_sensitivity', 'number']),
    (dict(duration_s=0), ['duration_s', '> 0']),
    (dict(duration_s=-5), ['duration_s', '> 0']),
    (dict(duration_s=float('inf')), ['duration_s', 'finite']),
    (dict(params={'spin_hz': 2}), ['unknown param', 'latitude_deg']),
    (dict(params={'latitude_deg': 95}), ['latitude_deg', 'out of range']),
    (dict(imu_rate_hz=0), ['imu_rate_hz', '> 0']),
    (dict(imu_rate_hz=100, truth_rate_hz=30), ['whole number']),
    (dict(seed=-1), ['seed']),
    (dict(seed=1.5), ['seed']),
])
def test_make_config_rejects_bad_input_with_one_line(kwargs, words):
    scenario = kwargs.pop('scenario', 'static_ramp')
    with pytest.raises(ValueError) as err:
        make_config(scenario, **kwargs)
    message = str(err.value)
    assert '\n' not in message
    assert all(w in message for w in words), message


def test_effect_and_rate_overrides_are_recorded():
    cfg = make_config('null', effects={'thermal_curvature': 1e-5}, params={'latitude_deg': 10},
                      imu_rate_hz=200)
    d = cfg.to_dict()
    assert d['effects']['thermal_curvature'] == 1e-5 and d['params']['latitude_deg'] == 10
    assert d['rates_hz'] == {'imu': 200, 'mag': 50, 'temperature': 10, 'truth': 200}
    assert set(d['effects']) == set(EFFECTS)
    assert all(v == 0 for k, v in make_config('null').effects.items())
    assert isinstance(cfg, SimConfig) and set(SCENARIOS) >= {
        'static_ramp', 'static_ramp_outages', 'vehicle_loop', 'carousel_vertical', 'carousel_horizontal',
        'carousel_wheel', 'null'}


def test_outage_episodes_are_placed_and_zero_outside():
    cfg = make_config('static_ramp_outages', seed=4, imu_rate_hz=2, mag_rate_hz=1, temp_rate_hz=1)
    eps = cfg.episodes
    assert [round(e.duration_s) for e in eps] == [300, 300, 600]
    assert {e.kind for e in eps} == {'strength', 'rotate'}
    assert cfg.to_dict()['outages'] == [[e.start_s, e.end_s] for e in eps]
    ch = concat_chunks(simulate(cfg))
    profile = build_world(cfg).profile
    t = ch.mag_disturbance.t
    on = np.any(ch.mag_disturbance.vec != 0, axis=1)
    inside = np.zeros_like(on)
    for e in eps:
        inside |= (t >= e.start_s) & (t < e.end_s)
    assert not np.any(on & ~inside) and on[inside].mean() > 0.99
    heating, turn, tail = eps
    _, d_heat = profile(np.linspace(heating.start_s, heating.end_s, 50))
    assert np.all(d_heat > 0.005)                                   # on the heating ramp
    t_hold_end = 3300.0
    assert turn.start_s == t_hold_end and np.all(profile(np.array([t_hold_end - 60]))[1] == 0)
    assert profile(np.array([turn.end_s]))[1][0] < -0.005           # cooling under way by its end
    _, d_tail = profile(np.linspace(tail.start_s, tail.end_s, 50))
    assert tail.start_s > 5000 and np.all(d_tail < 0)                # on the cooling tail
    # the two kinds: 'rotate' keeps the field norm (a norm-watcher misses it), 'strength' does not
    field = build_world(cfg).field_enu
    f0 = np.linalg.norm(field)
    total = np.linalg.norm(ch.mag_disturbance.vec + _sensor_field(cfg, ch), axis=1)
    for e in eps:
        mid = (t > e.start_s + 30) & (t < e.end_s - 30)
        change = np.abs(total[mid] - f0).max() / f0
        heading_like = np.linalg.norm(ch.mag_disturbance.vec[mid], axis=1).max() / f0
        if e.kind == 'rotate':
            assert change < 0.02 and heading_like > 0.1
        else:
            assert change > 0.1


def _sensor_field(cfg, ch):
    from gyro_thermal_comp.angles import rotation_matrix_from_quat
    rot = rotation_matrix_from_quat(ch.odom.quat)
    return np.einsum('nji,j->ni', rot, build_world(cfg).field_enu)


def test_vehicle_interference_is_short_and_inside_the_run():
    cfg = make_config('vehicle_loop')
    assert len(cfg.episodes) == 3 and all(e.duration_s <= 30 for e in cfg.episodes)
    assert all(e.end_s <= cfg.duration_s for e in cfg.episodes)
    short = make_config('vehicle_loop', duration_s=410)
    assert [(e.start_s, e.end_s) for e in short.episodes] == [(400.0, 410.0)]
