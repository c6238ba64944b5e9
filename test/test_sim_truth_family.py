"""The second truth family (report only): family A untouched, family B drawn from the seed, each
shape behaving as named, outages on their labelled phases, the truth recorded, the CLI writes it."""
import json

import numpy as np
import pytest

from gyro_thermal_comp.bag_io import BagReader
from gyro_thermal_comp.cli import main
from gyro_thermal_comp.samples import concat_chunks
from gyro_thermal_comp.sim import EFFECTS, SCENARIOS, family_configs, make_config, make_family_config, simulate
from gyro_thermal_comp.sim.engine import build_world
from gyro_thermal_comp.sim.family_b import SHAPES
from gyro_thermal_comp.sim.family_b_drift import FamilyBDrift
from gyro_thermal_comp.sim.family_b_profiles import OUTAGE_KINDS, TURN_JITTER_S
from gyro_thermal_comp.sim.scenarios import SCENARIO_DEFS
from gyro_thermal_comp.topics import SIM_CONFIG

A_KEYS = {'scenario', 'description', 'seed', 'duration_s', 'rates_hz', 'effects', 'effect_units', 'params', 'sensor',
          'unit', 'episodes', 'outages'}
OFF = {name: 0.0 for name in EFFECTS}
LOW = dict(imu_rate_hz=1.0, mag_rate_hz=1.0, temp_rate_hz=1.0, truth_rate_hz=1.0)


def arrays(chunks):
    ch = concat_chunks(chunks)
    return {f'{n}.{f}': v for n, s in ch.streams().items() for f, v in vars(s).items() if v is not None}


# ------------------------------------------------------------------ family A untouched
def test_family_a_configs_have_no_new_keys():
    for name, sc in SCENARIO_DEFS.items():
        if sc.draw_truth is not None:
            continue
        cfg = make_config(name, seed=2, duration_s=60)
        assert cfg.family == 'A' and cfg.truth_family is None
        keys = set(cfg.to_dict())
        assert keys - {'aux_sensor', 'aux_unit'} == A_KEYS, name
    for kind, name in (('static', 'static_ramp'), ('outages', 'static_ramp_outages'), ('vehicle', 'vehicle_loop'),
                       ('null', 'null')):
        assert make_family_config('A', kind, 5).to_dict() == make_config(name, seed=5).to_dict()
    assert make_config('static_ramp_outages').outage_labels == ('heating_ramp', 'hold_to_cooling_turn', 'cooling_tail')
    assert make_config('vehicle_loop').outage_labels == (None, None, None)


# ------------------------------------------------------------------ drawn from the seed
def test_family_b_is_deterministic_by_seed_and_seeds_differ():
    kw = dict(duration_s=130.0, imu_rate_hz=5.0, mag_rate_hz=2.0, temp_rate_hz=1.0)
    a1, a2 = (make_family_config('B', 'outages', 11, **kw) for _ in range(2))
    assert a1.to_dict() == a2.to_dict() and a1.family == 'B'
    s1, s2 = arrays(simulate(a1)), arrays(simulate(a2))
    assert s1.keys() == s2.keys() and all(np.array_equal(s1[k], s2[k]) for k in s1)
    truths = [make_family_config('B', 'outages', s).to_dict()['truth_family'] for s in range(6)]
    assert len({json.dumps(t['shapes'], sort_keys=True) for t in truths}) == 6
    assert len({json.dumps(t['profile'], sort_keys=True) for t in truths}) == 6
    assert len({tuple(t['shape_names']) for t in truths}) > 1            # the shapes themselves differ
    same_unit = make_family_config('B', 'outages', 5, unit_seed=2).to_dict()['truth_family']   # unit: shapes, a, b, c
    assert _unit_part(same_unit['shapes']) == _unit_part(truths[2]['shapes'])
    assert same_unit['paper_model'] == truths[2]['paper_model']
    assert same_unit['profile'] == truths[5]['profile'] and same_unit['planned_outages'] == truths[5]['planned_outages']


def _unit_part(shapes):
    """A shapes record without what the run seed draws (periodic phase, step times)."""
    return {cat: {k: ([x['size_dps'] for x in v] if k == 'steps' else v) for k, v in rec.items() if k != 'phase_rad'}
            for cat, rec in shapes.items()}


def test_a_shorter_run_is_the_start_of_a_longer_one():
    short = arrays(simulate(make_family_config('B', 'vehicle', 4, duration_s=130.0, imu_rate_hz=10.0)))
    long = arrays(simulate(make_family_config('B', 'vehicle', 4, duration_s=250.0, imu_rate_hz=10.0)))
    for k, v in short.items():
        assert np.array_equal(v, long[k][:len(v)]), k


def test_switching_shapes_keeps_every_other_draw():
    full = make_family_config('B', 'static', 3, shapes=SHAPES[:1] + ('lag_second_order', 'curvature', 'periodic'))
    one = make_family_config('B', 'static', 3, shapes=['curvature'])
    f, o = full.to_dict()['truth_family'], one.to_dict()['truth_family']
    assert o['shape_names'] == ['curvature'] and f['shapes']['curvature'] == o['shapes']['curvature']
    assert f['profile'] == o['profile'] and f['paper_model'] == o['paper_model']
    big = make_family_config('B', 'static', 3, shapes=['curvature'], shape_scale=4.0).truth_family.shapes['curvature']
    assert np.allclose(big['k2_dps_per_c2'], 4 * np.array(o['shapes']['curvature']['k2_dps_per_c2']), rtol=1e-12)
    null = make_family_config('B', 'null', 3)
    assert null.truth_family.shapes == {} and all(v == 0 for v in null.effects.values())


def test_the_truth_is_recorded():
    cfg = make_family_config('B', 'outages', 8, shapes=['hysteresis_tanh', 'lag_first_order', 'bias_step'])
    d = json.loads(json.dumps(cfg.to_dict()))
    t = d['truth_family']
    assert t['family'] == 'B' and t['shape_names'] == ['hysteresis_tanh', 'lag_first_order', 'bias_step']
    assert set(t['shapes']['hysteresis']) == {'variant', 'size_dps', 'half_width_c', 'sharpness'}
    assert abs(abs(t['shapes']['hysteresis']['size_dps'][2]) / 4e-3 - 1.25) <= 0.75   # 0.5..2 x nominal
    assert t['profile']['kind'] in OUTAGE_KINDS and t['outage_labels'] == [o['label'] for o in t['planned_outages']]
    assert d['unit']['gyro_a_dps_per_c'] == t['paper_model']['a_dps_per_c']        # the unit carries family B's a
    assert all(d['effects'][n] == 0 for n in ('thermal_curvature', 'thermal_hysteresis', 'thermal_lag'))


# ------------------------------------------------------------------ shapes behave as named
RATE_HZ = 10.0


def _triangle():
    """25 degC, heat at 0.02 degC/s for 1000 s, hold 500 s, cool at 0.02 degC/s for 1000 s, hold."""
    t = np.arange(0.0, 4000.0, 1 / RATE_HZ)
    knots_t, knots_T = [0, 500, 1500, 2000, 3000, 4000], [25, 25, 45, 45, 25, 25]
    temp = np.interp(t, knots_t, knots_T)
    slope = np.select([(t >= 500) & (t < 1500), (t >= 2000) & (t < 3000)], [0.02, -0.02], 0.0)
    return t, temp, slope


def _drift_z(shapes, t, temp, slope, chunk=600):
    """z drift (deg/s) of a unit with a = 0.01, b = 0.2, c = 0.1 and `shapes`, streamed in chunks."""
    model = FamilyBDrift(shapes=shapes, a_dps_per_c=[0.0, 0.0, 0.01], b_dps_per_c_per_s=[0.0, 0.0, 0.2],
                         c_dps=[0.0, 0.0, 0.1], rate_hz=RATE_HZ, t_case0_c=float(temp[0]))
    out = [model.step(temp[i:i + chunk], slope[i:i + chunk], t[i:i + chunk])[0][:, 2] for i in range(0, len(t), chunk)]
    return np.degrees(np.concatenate(out))


def _shape(name, seed=1):
    return make_family_config('B', 'static', seed, shapes=[name]).truth_family.shapes


def _paper(die, ddie):
    return 0.01 * die + 0.2 * ddie + 0.1


def test_sign_hysteresis_flips_with_the_sign_of_the_temperature_rate():
    shapes = _shape('hysteresis_sign')
    h = shapes['hysteresis']['size_dps'][2]
    t, temp, slope = _triangle()
    d = _drift_z(shapes, t, temp, slope)
    m = (d - _paper(temp, slope)) / h
    expect = np.select([t < 500, t < 2000], [0.0, 1.0], -1.0)      # held through the hold, never relaxing
    assert np.max(np.abs(m - expect)) < 1e-9


def test_relaxation_hysteresis_builds_up_with_its_time_constant():
    shapes = _shape('hysteresis_relaxation', seed=2)
    rec = shapes['hysteresis']
    t, temp, slope = _triangle()
    d = _drift_z(shapes, t, temp, slope)
    m = (d - _paper(temp, slope)) / rec['size_dps'][2]
    tau = rec['tau_s']
    at = 500.0 + min(tau, 1000.0)
    i = np.searchsorted(t, at)
    assert abs(m[i] - (1 - np.exp(-(t[i] - 500.0) / tau))) < 0.01     # first-order rise (discrete lag: < 1 %)
    assert np.all(np.diff(m[(t > 500) & (t < 2000)]) >= 0)             # builds up while heating and holds
    assert m[-1] < m[np.searchsorted(t, 2000.0)]                         # heads to -1 once cooling
    assert rec['tau_s'] < 600 or rec['tau_s'] > 1500                     # not the first family's 900 s


def test_tanh_hysteresis_is_a_loop_in_temperature():
    shapes = _shape('hysteresis_tanh')
    rec = shapes['hysteresis']
    w = rec['half_width_c']
    t, temp, slope = _triangle()
    d = _drift_z(shapes, t, temp, slope)
    m = (d - _paper(temp, slope)) / rec['size_dps'][2]
    heat, cool = (t > 500) & (t < 1500), (t > 2000) & (t < 3000)
    assert abs(m[heat & (temp > 25 + 2 * w + 0.1)] - 1).max() < 1e-9     # saturated 2w after the reversal
    assert abs(m[cool & (temp < 45 - 2 * w - 0.1)] + 1).max() < 1e-9
    mid = np.argmin(np.abs(np.where(cool, temp, np.inf) - (45 - w)))     # half-way through the reversal
    assert abs(m[mid]) < 0.02
    assert np.all(np.diff(m[cool]) <= 1e-12)                              # monotone along the branch


def _step_response(shapes):
    t = np.arange(0.0, 1500.0, 1 / RATE_HZ)
    temp = np.where(t >= 100.0, 35.0, 25.0)
    model = FamilyBDrift(shapes=shapes, a_dps_per_c=[0.0] * 3, b_dps_per_c_per_s=[0.0] * 3, c_dps=[0.0] * 3,
                         rate_hz=RATE_HZ, t_case0_c=25.0)
    die, ddie = model.die_temperature(temp, np.zeros_like(t))
    return t, die, ddie


def test_second_order_lag_starts_with_zero_slope_and_first_order_does_not():
    t, die1, d1 = _step_response(_shape('lag_first_order'))
    t, die2, d2 = _step_response(_shape('lag_second_order'))
    k = np.searchsorted(t, 100.0)                                   # the step's first sample
    assert d1[k] == pytest.approx(d1.max()) and d1.max() > 0         # first order: steepest at once
    assert d2[k] < 0.05 * d2.max()                                   # second order: starts flat
    assert t[np.argmax(d2)] > 100.0 + 5.0
    for die, dd in ((die1, d1), (die2, d2)):                          # dT_die/dt is T_die's derivative
        num = np.gradient(die, t)
        assert np.max(np.abs(num[k + 5:] - dd[k + 5:])) < 0.01 * dd.max()
        assert die[-1] == pytest.approx(35.0, abs=0.05) and die[k - 1] == 25.0


def _residual(cfg):
    """gyro_bias z minus the paper model on the case temperature (no lag: shape off), deg/s, mean removed."""
    ch = concat_chunks(simulate(cfg))
    temp, slope = build_world(cfg).profile(ch.gyro_bias.t)
    u = cfg.unit
    paper = u.gyro_a_dps_per_c[2] * temp + u.gyro_b_dps_per_c_per_s[2] * slope + u.gyro_c_dps[2]
    r = np.degrees(ch.gyro_bias.vec[:, 2]) - paper           # + a constant Earth-rate projection
    return ch.gyro_bias.t, r - r[0]


def test_bias_step_and_periodic_are_in_the_recorded_truth_at_their_times():
    cfg = make_family_config('B', 'outages', 6, shapes=['bias_step'], effects=OFF, **LOW)
    t, r = _residual(cfg)
    expect = sum(s['size_dps'][2] * (t >= s['t_s']) for s in cfg.truth_family.shapes['bias_step']['steps'])
    assert np.max(np.abs(r - expect)) < 1e-9 * 0.3            # deg/s, float rounding of a 0.3 deg/s bias
    for s in cfg.truth_family.shapes['bias_step']['steps']:
        assert all(s['t_s'] < a - 100 or s['t_s'] > b + 100 for a, b in cfg.outages)   # not inside an outage
    cfg = make_family_config('B', 'static', 6, shapes=['periodic'], effects=OFF, **LOW)
    p = cfg.truth_family.shapes['periodic']
    t, r = _residual(cfg)
    wave = p['size_dps'][2] * np.sin(2 * np.pi * t / p['period_s'] + p['phase_rad'])
    assert 300 <= p['period_s'] <= 2400 and np.max(np.abs(r - (wave - wave[0]))) < 1e-9 * 0.3


def test_curvature_has_its_cubic_share():
    shapes = _shape('curvature', seed=4)
    c = shapes['curvature']
    t, temp, slope = _triangle()
    d = _drift_z(shapes, t, temp, slope)
    x = temp - 25.0
    assert np.max(np.abs(d - _paper(temp, slope) - c['k2_dps_per_c2'][2] * x ** 2 - c['k3_dps_per_c3'][2] * x ** 3)) \
        < 1e-12
    assert c['k3_dps_per_c3'][2] == pytest.approx(c['cubic_share'] * c['k2_dps_per_c2'][2] / 20.0, rel=1e-12)


# ------------------------------------------------------------------ outages at their phases
def test_outages_sit_at_their_labelled_phases():
    kinds = set()
    for seed in range(12):
        cfg = make_family_config('B', 'outages', seed)
        prof, ph = build_world(cfg).profile, cfg.truth_family.profile.phases
        kinds.add(cfg.truth_family.profile.kind)
        assert cfg.outage_labels == ('heating_ramp', 'hold_to_cooling_turn', 'cooling_tail')
        (h0, h1), (t0, t1), (c0, c1) = cfg.outages
        assert [round(b - a) for a, b in cfg.outages] == [300, 300, 600] and h1 < t0 and t1 < c0 and c1 < 7200
        assert np.all(prof(np.linspace(h0, h1, 100))[1] > 0.002)                  # heating, degC/s
        assert abs(t0 - ph['cool_start']) <= TURN_JITTER_S                        # at the turn
        before, after = prof(np.array([ph['cool_start'] - 10.0, ph['cool_start'] + 60.0]))[1]
        assert before >= 0 and after < 0                                           # heating stops, cooling starts
        assert np.all(prof(np.linspace(c0, c1, 100))[1] < -1e-4)                   # still cooling
    assert kinds == set(OUTAGE_KINDS)
    cfg = make_family_config('B', 'outages', 3, **LOW)                            # the field truth agrees
    ch = concat_chunks(simulate(cfg))
    on = np.any(ch.mag_disturbance.vec != 0, axis=1)
    inside = np.zeros_like(on)
    for a, b in cfg.outages:
        inside |= (ch.mag_disturbance.t >= a) & (ch.mag_disturbance.t < b)
    assert not np.any(on & ~inside) and on[inside].mean() > 0.95


def test_vehicle_variant_drives_with_a_family_b_profile():
    cfg = make_family_config('B', 'vehicle', 2, imu_rate_hz=10.0)
    d = cfg.to_dict()['truth_family']
    assert d['profile']['kind'] in ('steps', 'oscillating', 'cold_soak') and d['shape_names']
    assert cfg.outage_labels == ('vehicle',) * 3 and all(b - a <= 30 and b < 1800 for a, b in cfg.outages)
    ch = concat_chunks(simulate(make_family_config('B', 'vehicle', 2, imu_rate_hz=10.0, duration_s=300.0)))
    assert np.all(ch.odom.rate_body[ch.odom.t < 60] == 0) and np.abs(ch.odom.rate_body[:, 2]).max() > 0.1


# ------------------------------------------------------------------ benchmark helper and CLI
def test_family_configs_lists_the_bags_a_benchmark_runs():
    cases = family_configs('B', 'discover_effects', [0, 1], imu_rate_hz=5.0)
    assert len(cases) == 2 * (len(SHAPES) + 1)
    for c in cases:
        names = c.config.to_dict()['truth_family']['shape_names']
        assert names == ([] if c.shape == 'none' else [c.shape]) and c.config.imu_rate_hz == 5.0
        assert all(v == 0 for v in c.config.effects.values())          # nothing else hidden
        assert 'rate_random_walk' not in c.acceptable and 'bias_instability' not in c.acceptable
    static = family_configs('B', 'static', range(5))
    assert {c.config.truth_family.profile.kind for c in static} == {'fast_ramp', 'slow_ramp', 'steps', 'oscillating',
                                                                    'cold_soak'}
    assert [c.config.scenario for c in family_configs('A', 'outages', [1, 2])] == ['static_ramp_outages'] * 2
    with pytest.raises(ValueError, match='purpose'):
        family_configs('B', 'tuning', [0])
    with pytest.raises(ValueError, match='family'):
        make_family_config('C', 'static', 0)


def test_cli_writes_a_family_b_bag(tmp_path, capsys):
    assert 'b_static_ramp_outages' in SCENARIOS
    out = tmp_path / 'b'
    assert main(['simulate', 'b_static_ramp_outages', '--seed', '2', '--out', str(out), '--duration', '900',
                 '--imu-rate', '1', '--mag-rate', '1', '--temp-rate', '1', '--truth-rate', '1',
                 '--param', 'shape_periodic=0']) == 0
    with BagReader(out) as reader:
        recorded = json.loads(reader.text(SIM_CONFIG)[0])
    cfg = make_config('b_static_ramp_outages', seed=2, duration_s=900, params={'shape_periodic': 0}, **LOW)
    assert recorded == json.loads(json.dumps(cfg.to_dict()))
    assert 'periodic' not in recorded['truth_family']['shape_names']
    assert main(['simulate', 'b_static', '--out', str(tmp_path / 'x'), '--param', 'shape_lag=1.5']) == 2
    assert 'shape_lag' in capsys.readouterr().err
