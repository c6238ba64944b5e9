"""Restarts from a saved state: what was learned survives a start in motion or without a still
period, and the published heading 2-sigma stays honest in the 10 min after a restart."""
import json
import math

import numpy as np
import pytest

from conftest import BAGS, Capture
from gyro_thermal_comp.bag_io import BagReader, read_chunks
from gyro_thermal_comp.evaluation.restarts import node_values, restart, saved_state
from gyro_thermal_comp.nodes.compose import make_stkf_node
from gyro_thermal_comp.nodes.state_store import StateStore
from gyro_thermal_comp.samples import SensorChunk, slice_samples
from gyro_thermal_comp.thermal.drift_model import DriftModel
from gyro_thermal_comp.thermal.model_state import after_power_cycle
from gyro_thermal_comp.thermal.still_period import StillPeriod, initial_state

VEHICLE = BAGS / 'vehicle_loop'


def _declination_rad(bag) -> float:
    with BagReader(bag) as reader:
        return math.radians(json.loads(next(iter(reader.text('/sim/config'))))['params']['declination_deg'])


@pytest.fixture(scope='module')
def vehicle_state():
    """What a node saves after the whole drive (declination set, as a robot team sets it)."""
    values = node_values(declination_rad=_declination_rad(VEHICLE))
    return values, saved_state(VEHICLE, values)


@pytest.fixture
def state_file(tmp_path, vehicle_state):
    path = tmp_path / 'stkf.json'
    with StateStore(path) as store:
        store.save(vehicle_state[1])
    return path


def _feed(node, start_s, end_s):
    """The node gets the drive from `start_s` on, as after a restart there; returns (t, raw z,
    published z, true z rate) at the IMU stamps that have a truth sample."""
    raw, t_truth, w_truth = [], [], []
    for chunk in read_chunks(VEHICLE, 10.0, streams=['imu', 'mag', 'temperature', 'odom']):
        if chunk.imu.t[0] >= end_s:
            break
        if chunk.imu.t[-1] < start_s:
            continue
        keep = {k: v for k, v in chunk.streams().items() if k != 'odom'}
        part = SensorChunk(**{k: slice_samples(v, v.t >= start_s) for k, v in keep.items()})
        node.process_chunk(part)
        raw.append(np.column_stack((part.imu.t, part.imu.gyro[:, 2])))
        odom = slice_samples(chunk.odom, chunk.odom.t >= start_s)
        t_truth.append(odom.t)
        w_truth.append(odom.rate_body[:, 2])
    node.shutdown()
    raw = np.concatenate(raw)
    out = np.array([m.angular_velocity.z for m in node.pubs['imu'].msgs])
    t_truth, w_truth = np.concatenate(t_truth), np.concatenate(w_truth)
    k = np.searchsorted(raw[:, 0], t_truth)
    ok = (k < len(out)) & (raw[np.minimum(k, len(raw) - 1), 0] == t_truth)
    return t_truth[ok], raw[k[ok], 1], out[k[ok]], w_truth[ok]


def _constant(x, names):
    return float(np.asarray(x)[list(names).index('constant')])


def test_a_restart_in_motion_keeps_the_learned_constant(ros, state_file, vehicle_state):
    """Started from the saved state 100 s into the drive: the still period is cut short after 11 s
    (the car turns), and its mean rate carries that motion. It must not replace the constant."""
    values, saved = vehicle_state
    node = make_stkf_node({'state_file': str(state_file), 'declination_rad': values['declination_rad']})
    node.pubs = {name: Capture() for name in node.pubs}
    assert node.state_status.startswith('warm start')
    t, raw, published, truth = _feed(node, 100.0, 200.0)
    est = node.estimator
    node.destroy_node()
    assert est.still.cut_short
    sigma_c = math.sqrt(np.asarray(saved['P'])[saved['terms'].index('constant')][saved['terms'].index('constant')])
    c_saved = _constant(saved['x'], saved['terms'])
    c_now = _constant(est.params, est.model.names)
    print(f'constant saved {c_saved:.6f}, after the restart {c_now:.6f} rad/s (saved 1-sigma {sigma_c:.2g})')
    assert abs(c_now - c_saved) < 2 * sigma_c
    # the compensated rate is closer to the truth than the raw one over the first 80 s after the
    # still period (the raw rate's error is the drift itself: 0.1-0.2 deg/s here)
    after = (t > est.still_end_s) & (t < est.still_end_s + 80.0)
    raw_err, comp_err = np.mean(raw[after] - truth[after]), np.mean(published[after] - truth[after])
    print(f'mean rate error over 80 s: raw {math.degrees(raw_err):.3f}, compensated {math.degrees(comp_err):.3f} deg/s')
    assert abs(comp_err) < 0.25 * abs(raw_err)


def test_no_still_period_keeps_the_learned_state(ros, state_file, vehicle_state):
    """`still_period_s: 0`: nothing is measured at the start, so the saved parameters and their
    covariance are the ones in force, and the drift is compensated from the first sample."""
    values, saved = vehicle_state
    node = make_stkf_node({'state_file': str(state_file), 'still_period_s': 0.0,
                           'declination_rad': values['declination_rad']})
    node.pubs = {name: Capture() for name in node.pubs}
    t, raw, published, truth = _feed(node, 100.0, 130.0)
    est = node.estimator
    node.destroy_node()
    assert est.still_use == 'none'
    np.testing.assert_allclose(est.params, saved['x'], rtol=0, atol=5 * math.sqrt(np.max(np.diag(saved['P']))))
    c = saved['terms'].index('constant')
    assert math.sqrt(est.learner.P[c, c]) < 2 * math.sqrt(saved['P'][c][c])
    first = t < 115.0                                        # the first 15 s
    raw_err, comp_err = np.mean(raw[first] - truth[first]), np.mean(published[first] - truth[first])
    print(f'mean rate error over the first 15 s: raw {math.degrees(raw_err):.3f}, '
          f'compensated {math.degrees(comp_err):.3f} deg/s')
    assert abs(comp_err) < 0.25 * abs(raw_err)


# ---------------------------------------------------------------- the still period's measurement
MODEL = DriftModel(('temperature', 'constant'))
PRIOR = np.array([3e-4, 1e-2])


def _still(n_s: float, cut_at_s: float | None = None, rate=2e-3, temp=30.0):
    """A still period of `n_s` planned seconds at 10 Hz, the gyro at `rate` rad/s; motion at `cut_at_s`."""
    period = StillPeriod(n_s, math.radians(2.0), 1e-8)
    period.begin(0.0)
    n = int(round((cut_at_s if cut_at_s is not None else n_s) * 10))
    if n:
        g = np.zeros((n, 3))
        g[:, 2] = rate
        period.add_imu(np.arange(n) / 10.0, g, np.full(n, temp), np.ones(n, bool), np.zeros(n))
    if cut_at_s is not None:
        period.end_s = cut_at_s
    return period.finish(math.radians(0.04), 2e-5)


def test_a_cold_start_is_set_by_the_still_period_as_before():
    still = _still(30.0)
    x, P, use = initial_state(MODEL, still, 30.0, PRIOR, None, 6.0)
    assert use == 'measured' and not still.cut_short
    assert float(MODEL.rows(MODEL.neutral_inputs(30.0))[0] @ x) == pytest.approx(2e-3, rel=1e-12)
    assert still.drift_var_rad2_s2 == pytest.approx(math.radians(0.04) ** 2 / 30.0 + 2e-5 ** 2, rel=1e-12)


def test_a_warm_start_combines_the_still_period_by_its_variance():
    warm = {'x': [1e-4, 1.5e-3], 'P': np.diag([1e-10, 4e-8]).tolist()}
    h = MODEL.rows(MODEL.neutral_inputs(30.0))[0]
    predicted = float(h @ warm['x'])
    for length_s in (30.0, 5.0):
        still = _still(length_s, rate=predicted + 1e-4)
        x, P, use = initial_state(MODEL, still, 30.0, PRIOR, warm, 6.0)
        s = float(h @ np.asarray(warm['P']) @ h)
        weight = s / (s + still.drift_var_rad2_s2)          # how much of the disagreement is taken
        assert use == 'combined'
        assert float(h @ x) - predicted == pytest.approx(weight * 1e-4, rel=1e-9)
        assert float(h @ P @ h) == pytest.approx(s * (1 - weight), rel=1e-9)
    # cut short by motion: the rotation under way is in the mean, so it counts for little
    cut = _still(30.0, cut_at_s=5.0, rate=predicted + 3e-3)
    x, _, use = initial_state(MODEL, cut, 30.0, PRIOR, warm, 6.0)
    assert cut.cut_short and use == 'combined'
    assert abs(float(h @ x) - predicted) < 0.05 * 3e-3
    # a mean rate the learned model calls impossible (a steady turn): left out
    x, P, use = initial_state(MODEL, _still(30.0, rate=predicted + 0.05), 30.0, PRIOR, warm, 6.0)
    assert use == 'refused' and np.array_equal(x, warm['x']) and np.array_equal(P, warm['P'])
    # nothing measured: as saved
    x, P, use = initial_state(MODEL, _still(0.0), 30.0, PRIOR, warm, 6.0)
    assert use == 'none' and np.array_equal(x, warm['x']) and np.array_equal(P, warm['P'])


def test_after_a_power_cycle_the_still_period_sets_the_constant_and_the_slope_is_kept():
    """A state carried to another power-up (a bench calibration) has its constant's variance widened
    by the turn-on repeatability: a full still period then measures the constant as a cold start
    would, while the learned slope and its variance stay."""
    warm = {'terms': list(MODEL.names), 'x': [1e-4, 1.5e-3], 'P': np.diag([1e-10, 4e-8]).tolist()}
    carried = after_power_cycle(warm, 1e-2)
    assert np.array_equal(np.diag(carried['P']), [1e-10, 4e-8 + 1e-4]) and warm['P'][1][1] == 4e-8
    h = MODEL.rows(MODEL.neutral_inputs(30.0))[0]
    turned_on = float(h @ warm['x']) + 3e-3                  # this power-up's bias is elsewhere
    x, P, use = initial_state(MODEL, _still(30.0, rate=turned_on), 30.0, PRIOR, carried, 6.0)
    assert use == 'combined'
    assert float(h @ x) == pytest.approx(turned_on, abs=0.01 * 3e-3)
    assert x[0] == pytest.approx(1e-4, rel=1e-3) and P[0, 0] == pytest.approx(1e-10, rel=1e-3)
    # the same bias against the state as saved: refused as impossible (the in-run variance is tight)
    assert initial_state(MODEL, _still(30.0, rate=turned_on), 30.0, PRIOR, warm, 6.0)[2] == 'refused'
    assert after_power_cycle({'x': [1.0], 'terms': ['constant']}, 1e-2) == {'x': [1.0], 'terms': ['constant']}


def test_a_cold_start_without_a_still_period_keeps_the_prior():
    x, P, use = initial_state(MODEL, _still(0.0), 30.0, PRIOR, None, 6.0)
    assert use == 'none' and np.array_equal(x, [0.0, 0.0]) and np.array_equal(np.diag(P), PRIOR ** 2)


# ---------------------------------------------------------------- the published heading after a restart
def _pooled_coverage(bag, starts, values, state) -> tuple[float, list[str]]:
    covered, report = [], []
    for start in starts:
        r = restart(bag, float(start), state, values)
        covered.append(r.covered())
        report.append(f'{start:.0f} s: {100 * covered[-1].mean():.0f} %')
    return float(np.concatenate(covered).mean()), report


def test_the_heading_two_sigma_covers_the_error_after_restarts_on_a_drive(vehicle_state):
    """Restarts every 60 s of the drive (still, straight, turning, in and after disturbances), 10 min
    each: the published 2-sigma covers 90-99 % of the yaw errors (benchmarks/restart_coverage.py)."""
    values, state = vehicle_state
    pooled, report = _pooled_coverage(VEHICLE, np.arange(60.0, 1201.0, 60.0), values, state)
    print(f'vehicle_loop restarts: {100 * pooled:.1f} % pooled; ' + ', '.join(report))
    assert 0.90 <= pooled <= 0.99, report


@pytest.mark.xfail(strict=True, reason='a restart inside a magnetic disturbance takes the disturbed compass for '
                                       'the heading: the gate has no reference of the clean field yet (0 % covered '
                                       'at 1200 s of static_ramp_outages, 24 deg off)')
def test_the_heading_two_sigma_covers_the_error_after_a_restart_inside_a_magnetic_disturbance():
    bag = BAGS / 'static_ramp_outages'      # disturbed 1000-1300 s
    values = node_values(declination_rad=_declination_rad(bag))
    r = restart(bag, 1200.0, saved_state(bag, values), values)
    print(f'restart at 1200 s: {100 * r.covered().mean():.1f} % covered, max |e| '
          f'{math.degrees(np.max(np.abs(r.error_rad))):.1f} deg')
    assert r.covered().mean() >= 0.90


def test_replay_live_from_a_start_offset_keeps_the_learned_state(state_file, vehicle_state, tmp_path):
    """The restart as a robot sees it: the node in its own process with the saved state, the drive
    published over DDS from 100 s on at 2x (`replay --live --start 100 --rate 2`). The state the
    node saves on Ctrl-C still holds the learned constant."""
    from gyro_thermal_comp.bag_io import BagReader
    from gyro_thermal_comp.nodes.replay import replay
    values, saved = vehicle_state
    params = tmp_path / 'robot.yaml'
    params.write_text(f"/**/stkf_drift_estimator:\n  ros__parameters:\n    state_file: '{state_file}'\n"
                      f"    declination_rad: {values['declination_rad']!r}\n")
    summary = []
    counts = replay(VEHICLE, tmp_path / 'live', live=True, rate=2.0, start_s=100.0, duration_s=40.0,
                    params_file=params, summary=summary)
    assert counts['/imu/data'] == counts['/imu/data_raw'] == 2000
    with BagReader(tmp_path / 'live') as reader:
        first = next(iter(reader.chunks(10.0, streams=['imu'])))
    assert first.imu.t[0] == pytest.approx(100.0, abs=0.021)      # from the start asked for
    [line] = summary
    assert line.startswith('stkf_node: ') and ('learning: ' in line)
    after = json.loads(state_file.read_text())
    c = after['terms'].index('constant')
    assert abs(after['x'][c] - saved['x'][c]) < 2 * math.sqrt(saved['P'][c][c])


def test_the_compass_deviation_map_carries_over_anchored_where_it_was_learned():
    """A restart at another heading: the offset is the compass reading less the deviation the map
    predicts there (relative to the heading where the map was anchored), not the raw reading."""
    from gyro_thermal_comp.thermal.heading_filter import HeadingFilter
    first = HeadingFilter()
    first.initialize(0.0, 0.1, 0.5, 1e-5)
    d = slice(first.i_d, first.i_d + 4)
    first.x[d] = [0.05, -0.08, 0.01, 0.02]                  # a learned hard and soft iron map, rad
    first.P[d, d] = np.diag([1e-6] * 4)
    learned = json.loads(json.dumps(first.learned()))       # through a state file
    again = HeadingFilter()
    again.carry_over(learned)
    again.initialize(100.0, 0.7, 2.0, 1e-5)                 # the compass says 2.0 rad now
    h = again._measurement_rows(np.array([2.0]))[0]
    assert again.psi0 == 0.5 and np.array_equal(again.x[d], first.x[d])
    assert again.x[0] == pytest.approx(0.7 - float(h[d] @ first.x[d]), abs=1e-15)
    assert again.x[0] != pytest.approx(0.7, abs=1e-3) and again.out_off == again.x[0]
    assert again.P[0, 0] == pytest.approx(1e-5 + float(h[d] @ first.P[d, d] @ h[d]), rel=1e-12)
    for bad in ({**learned, 'x': learned['x'][:-1]}, {**learned, 'psi0_rad': float('nan')}):
        with pytest.raises(ValueError, match='heading map'):
            HeadingFilter().carry_over(bad)
