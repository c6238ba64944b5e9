"""The fast path: its output is decided by stamps, so one sample at a time equals one batch."""
from __future__ import annotations

import math

import numpy as np
import pytest

from gyro_thermal_comp.angles import wrap_angle
from gyro_thermal_comp.thermal.fast_path import AnchorRows, FastPath

NS = 1_000_000_000
TOL = 1e-12   # elementwise operations may round differently in the last bits on another CPU


def _anchors(ns, rng):
    n = ns.size
    return AnchorRows(ns=ns, d0=1e-3 + 1e-5 * rng.standard_normal(n), d_dot=1e-6 * rng.standard_normal(n),
                      k_rate=1e-3 * rng.standard_normal(n), bias_xy=1e-4 * rng.standard_normal((n, 2)),
                      heading=np.cumsum(0.01 * rng.standard_normal(n)), heading_var=np.full(n, 1e-4),
                      g_tilt=1.0 + 1e-3 * rng.standard_normal(n), held={'gate': rng.integers(0, 2, n)})


def _stream(rng, n=3000, rate_hz=200.0):
    """Jittered stamps with a gap, a repeated stamp, one going back and a NaN."""
    ns = (np.arange(n) * NS / rate_hz + rng.normal(0, 0.1e-3 * NS, n)).astype(np.int64) + 1_700_000_000 * NS
    ns[1500:] += 3 * NS          # a 3 s gap
    ns[700] = ns[699]            # repeated
    ns[900] = ns[899] - 1000     # out of order
    gyro = 0.05 * rng.standard_normal((n, 3))
    gyro[1200, 2] = np.nan
    return ns, gyro


def _run(ns, gyro, anchors, batches, delay_s=0.5):
    """Feed anchors as a slow path would (up to each batch's last stamp), then the samples."""
    fp = FastPath(delay_s, max_gap_s=1.0, earth_rate_up_rad_s=5e-5, arw_rad_sqrt_s=1e-3)
    outs, i = [], 0
    for size in batches:
        sl = slice(i, min(i + size, ns.size))
        new = anchors.ns <= ns[sl][-1]
        fresh = new & (anchors.ns > (fp.processed_ns if fp.anchors is not None else -1))
        fp.add_anchors(anchors.take(np.flatnonzero(fresh)), int(ns[sl][-1]))
        assert all(fp.ready(int(t)) for t in ns[sl] if t > anchors.ns[0])
        outs.append(fp.run(ns[sl], gyro[sl]))
        i = sl.stop
        if i >= ns.size:
            break
    return outs


def _run_one(ns, gyro, anchors, delay_s=0.5):
    """As `_run` with one-sample batches, through `run_one` (Python floats)."""
    fp = FastPath(delay_s, max_gap_s=1.0, earth_rate_up_rad_s=5e-5, arw_rad_sqrt_s=1e-3)
    ok, wc, heading, var = [], [], [], []
    for i in range(ns.size):
        fresh = (anchors.ns <= ns[i]) & (anchors.ns > (fp.processed_ns if fp.anchors is not None else -1))
        fp.add_anchors(anchors.take(np.flatnonzero(fresh)), int(ns[i]))
        r = fp.run_one(int(ns[i]), *map(float, gyro[i]))
        ok.append(r is not None)
        wc.append(r[1:4] if r else (0.0, 0.0, 0.0))
        heading.append(r[4] if r else 0.0)
        var.append(r[5] if r else 0.0)
    return np.array(ok), np.array(wc), np.array(heading), np.array(var)


def _cat(outs, name):
    return np.concatenate([getattr(o, name) for o in outs])


def test_one_sample_at_a_time_equals_one_batch():
    rng = np.random.default_rng(3)
    ns, gyro = _stream(rng)
    anchors = _anchors(np.sort(np.unique(ns[::3])), rng)
    one = _run(ns, gyro, anchors, [1] * ns.size)
    rng2 = np.random.default_rng(5)
    mixed = _run(ns, gyro, anchors, rng2.integers(1, 400, ns.size))
    for name in ('ok', 'anchor_ns'):
        np.testing.assert_array_equal(_cat(one, name), _cat(mixed, name))
    ok = _cat(one, 'ok')
    assert ok.sum() == ns.size - 3 - np.count_nonzero(ns < anchors.ns[0])   # repeated, back, NaN
    for name in ('gyro_compensated', 'heading', 'heading_var'):
        np.testing.assert_allclose(_cat(one, name)[ok], _cat(mixed, name)[ok], rtol=0, atol=TOL, err_msg=name)
    scalar = _run_one(ns, gyro, anchors)
    np.testing.assert_array_equal(scalar[0], ok)
    for got, name in zip(scalar[1:], ('gyro_compensated', 'heading', 'heading_var')):
        np.testing.assert_allclose(got[ok], _cat(mixed, name)[ok], rtol=0, atol=TOL, err_msg=f'run_one {name}')


def test_anchor_is_the_slow_row_a_fixed_delay_earlier():
    rng = np.random.default_rng(4)
    ns = (np.arange(2000) * NS // 100).astype(np.int64)
    gyro = np.zeros((ns.size, 3))
    anchors = _anchors(ns, rng)
    out = _run(ns, gyro, anchors, [2000], delay_s=0.5)[0]
    later = ns >= 50 * NS // 100
    np.testing.assert_array_equal(out.anchor_ns[later], ns[later] - NS // 2)
    k = np.searchsorted(anchors.ns, out.anchor_ns[later])
    age = 0.5
    np.testing.assert_allclose(out.gyro_compensated[later, 2],
                               -(anchors.d0[k] + anchors.d_dot[k] * age), rtol=0, atol=1e-15)
    np.testing.assert_array_equal(out.held['gate'][later], anchors.held['gate'][k])


def test_heading_follows_the_anchor_and_integrates_the_rest():
    """A turn at a known rate: heading = anchor heading + the integral since the anchor's stamp."""
    ns = (np.arange(3000) * NS // 100).astype(np.int64)
    rate = 0.2
    gyro = np.zeros((ns.size, 3))
    gyro[:, 2] = rate
    truth = rate * ns * 1e-9
    anchors = AnchorRows(ns=ns, d0=np.zeros(ns.size), d_dot=np.zeros(ns.size), k_rate=np.zeros(ns.size),
                         bias_xy=np.zeros((ns.size, 2)), heading=truth, heading_var=np.zeros(ns.size),
                         g_tilt=np.ones(ns.size))
    fp = FastPath(1.0, max_gap_s=1.0, earth_rate_up_rad_s=0.0, arw_rad_sqrt_s=0.0)
    fp.add_anchors(anchors, int(ns[-1]))
    out = fp.run(ns, gyro)
    err = np.angle(np.exp(1j * (out.heading - truth)))
    assert np.max(np.abs(err[200:])) < 1e-9
    assert math.isclose(out.heading_var[-1], 0.0)


def test_clock_going_back_in_the_slow_path_starts_over():
    rng = np.random.default_rng(1)
    ns = (np.arange(400) * NS // 100).astype(np.int64)
    fp = FastPath(0.5, max_gap_s=1.0, earth_rate_up_rad_s=0.0, arw_rad_sqrt_s=0.0)
    fp.add_anchors(_anchors(ns, rng), int(ns[-1]))
    assert fp.run(ns, np.zeros((400, 3))).ok.all()
    fp.add_anchors(_anchors(ns[:100], rng), int(ns[99]))   # a bag loop: stamps from the start again
    assert fp.ready(int(ns[99])) and not fp.ready(int(ns[200]))
    assert fp.run(ns[:100], np.zeros((100, 3))).ok.all()


def test_not_ready_before_any_anchor():
    fp = FastPath(0.5, max_gap_s=1.0, earth_rate_up_rad_s=0.0, arw_rad_sqrt_s=0.0)
    assert not fp.ready(10 * NS)
    out = fp.run(np.array([10 * NS]), np.zeros((1, 3)))
    assert not out.ok.any()


@pytest.mark.parametrize('bad', [np.nan, np.inf])
def test_non_finite_sample_is_not_published_and_does_not_move_time(bad):
    rng = np.random.default_rng(2)
    ns = (np.arange(200) * NS // 100).astype(np.int64)
    fp = FastPath(0.5, max_gap_s=1.0, earth_rate_up_rad_s=0.0, arw_rad_sqrt_s=0.0)
    fp.add_anchors(_anchors(ns, rng), int(ns[-1]))
    gyro = np.zeros((200, 3))
    gyro[50, 0] = bad
    out = fp.run(ns, gyro)
    assert not out.ok[50] and out.ok.sum() == 199 and fp.dropped == 1



def _window(chunk, lo, hi):
    from gyro_thermal_comp.samples import SensorChunk, slice_samples
    return SensorChunk(**{k: slice_samples(v, (v.t > lo) & (v.t <= hi)) for k, v in chunk.streams().items()})


def test_compensator_live_order_equals_offline_chunks():
    """The estimator run at arbitrary moments (a node's timer) while samples arrive one by one gives
    the outputs of one offline pass in 10 s chunks, to 1e-12: which state compensates a sample is
    decided by stamps, not by when the slow path ran."""
    from conftest import BAGS
    from gyro_thermal_comp.bag_io import BagReader
    from gyro_thermal_comp.nodes.parameters import all_specs, config_from_params
    from gyro_thermal_comp.stamps import ns_at
    from gyro_thermal_comp.thermal.compensator import QUEUED, ThermalCompensator

    cfg = config_from_params({s.name: s.default for s in all_specs()})
    with BagReader(BAGS / 'vehicle_loop') as reader:
        whole = next(iter(reader.chunks(40.0, streams=['imu', 'mag', 'temperature'])))
        origin = reader.time_origin_ns
    t_end = float(whole.imu.t[-1])

    def outputs(comp, results):
        comp.finish()
        results.append(comp.take_ready()[1])
        results = [o for o in results if o is not None]
        return {name: np.concatenate([getattr(o, name) for o in results]) for name in
                ('ns', 'ok', 'gyro_compensated', 'heading', 'heading_var', 'anchor_ns')}

    offline = ThermalCompensator(cfg)
    ref = outputs(offline, [offline.run(_window(whole, lo, lo + 10.0), origin) for lo in np.arange(-1.0, t_end, 10.0)])

    live, got = ThermalCompensator(cfg), []
    rng = np.random.default_rng(0)
    t_done, next_run = -1.0, int(rng.integers(1, 80))
    rows = []   # (ns, wc x, y, z, heading, variance) of every published sample, as a live node makes them

    def take():
        n, out, _ = live.take_ready()
        if out is not None:
            rows.extend(zip(out.ns[out.ok].tolist(), *out.gyro_compensated[out.ok].T, out.heading[out.ok],
                            out.heading_var[out.ok]))

    for i, (t, g, a) in enumerate(zip(whole.imu.t.tolist(), whole.imu.gyro, whole.imu.accel)):
        ns = ns_at(t, origin)
        _, r = live.push(ns, g, a)         # the node's callback
        if r is not QUEUED and r is not None:
            rows.append((ns, *r[1:]))
        if i == next_run:    # the timer: the estimator on everything stamped up to now
            live.estimate(_window(whole, t_done, t), origin)
            t_done, next_run = t, i + int(rng.integers(1, 80))
            take()
    live.estimate(_window(whole, t_done, np.inf), origin)
    live.finish()
    take()
    got = np.array(rows)
    assert live.waited > 0 and len(got) > 0.95 * whole.imu.t.size
    ok = ref['ok']
    np.testing.assert_array_equal(got[:, 0].astype(np.int64), ref['ns'][ok])
    np.testing.assert_allclose(got[:, 1:4], ref['gyro_compensated'][ok], rtol=0, atol=TOL)
    np.testing.assert_allclose(got[:, 4], ref['heading'][ok], rtol=0, atol=TOL)
    np.testing.assert_allclose(got[:, 5], ref['heading_var'][ok], rtol=0, atol=TOL)


def test_a_bag_loop_starts_the_fast_path_over_the_same_one_by_one_or_in_a_block():
    """Stamps that jump back 100 s (a bag played in a loop, confirmed by 10 samples as the
    estimator confirms it): what was queued from before is not published, the new record is."""
    from gyro_thermal_comp.nodes.parameters import all_specs, config_from_params
    from gyro_thermal_comp.thermal.compensator import ThermalCompensator

    cfg = config_from_params({s.name: s.default for s in all_specs()})
    rng = np.random.default_rng(7)
    n = 3000
    ns = np.concatenate((np.arange(n) * NS // 100 + 100 * NS, np.arange(n) * NS // 100)).astype(np.int64)
    gyro = 1e-3 * rng.standard_normal((2 * n, 3))
    accel = np.tile([0.0, 0.0, 9.81], (2 * n, 1)) + 0.01 * rng.standard_normal((2 * n, 3))

    def run(one_by_one):
        comp, outs = ThermalCompensator(cfg), []
        from gyro_thermal_comp.samples import ImuSamples, SensorChunk
        previous = None
        for lo in range(0, 2 * n, 250):   # the estimator one block behind: samples wait in the queue
            sl = slice(lo, lo + 250)
            if one_by_one:
                for k in range(sl.start, sl.stop):
                    comp.add_many(ns[k:k + 1], gyro[k:k + 1], accel[k:k + 1])
            else:
                comp.add_many(ns[sl], gyro[sl], accel[sl])
            if previous is not None:
                comp.estimate(SensorChunk(imu=ImuSamples(ns[previous] * 1e-9, gyro[previous], accel[previous])), 0)
            previous = sl
            outs.append(comp.take_ready()[1])
        comp.estimate(SensorChunk(imu=ImuSamples(ns[previous] * 1e-9, gyro[previous], accel[previous])), 0)
        comp.finish()
        outs.append(comp.take_ready()[1])
        outs = [o for o in outs if o is not None]
        return comp, {k: np.concatenate([getattr(o, k) for o in outs]) for k in ('ns', 'ok', 'gyro_compensated')}

    (a, one), (b, block) = run(True), run(False)
    np.testing.assert_array_equal(one['ok'], block['ok'])
    np.testing.assert_allclose(one['gyro_compensated'], block['gyro_compensated'], rtol=0, atol=TOL)
    assert a.dropped_at_clock_change == b.dropped_at_clock_change > 0
    after = one['ns'] < 100 * NS
    assert one['ok'][after].sum() > 0.9 * n      # the new record is published
    assert one['ok'][~after].sum() > 0.9 * n     # and most of the first one was


def test_a_row_with_an_unknown_drift_is_no_anchor():
    """The estimator's rows before it knows the drift (NaN) must not reach an output."""
    from types import SimpleNamespace
    from gyro_thermal_comp.thermal.fast_path import anchor_rows

    n = 4
    drift = np.array([np.nan, 1e-3, 1e-3, 1e-3])
    gyro = np.zeros((n, 3))
    comp = np.column_stack((np.zeros((n, 2)), -drift))
    out = SimpleNamespace(valid=np.ones(n, bool), reasons=np.zeros(n, np.int64), temperature_c=np.full(n, 30.0),
                          temperature_rate_c_s=np.zeros(n), params=np.zeros((n, 3)), gyro_compensated=comp,
                          roll_rad=np.zeros(n), pitch_rad=np.zeros(n), drift_per_rate=np.zeros(n),
                          drift_trend_rad_s2=np.zeros(n),
                          track=SimpleNamespace(drift_rad_s=drift, heading_rad=np.zeros(n), heading_sigma_rad=np.ones(n)))
    rows = anchor_rows(np.arange(n, dtype=np.int64) * NS, gyro, out)
    np.testing.assert_array_equal(rows.ns, np.arange(1, n) * NS)
    assert np.all(np.isfinite(rows.d0))


def test_published_rate_heading_and_variance_are_the_documented_formulas():
    """An independent account of what the fast path publishes, from hand-set anchors: per sample i
    anchored on row j (the newest at or before t_i - delay) at age = t_i - t_j (at most max_hold_s),
        w_c,z = w_z - (d0_j + d_dot_j age + k_j w_z)     (the drift held with its trend)
        var   = heading_var_j + ARW^2 age                (angle random walk since the anchor)
        psi   = heading_j + sum over this path's samples after t_j of (g_tilt w_c,z - earth) dt.
    A positive trend d_dot must make the compensated rate fall with age."""
    arw, earth, delay, hold = 2e-3, 5e-5, 0.5, 1.6
    anchors = AnchorRows(ns=np.array([0, NS, 2 * NS], np.int64), d0=np.array([1e-3, 2e-3, 3e-3]),
                         d_dot=np.array([1e-4, -2e-4, 4e-4]), k_rate=np.array([0.01, 0.02, 0.03]),
                         bias_xy=np.array([[1e-3, -1e-3], [2e-3, -2e-3], [3e-3, -3e-3]]),
                         heading=np.array([0.1, 0.2, 0.3]), heading_var=np.array([1e-4, 2e-4, 3e-4]),
                         g_tilt=np.array([1.0, 0.9, 1.1]))
    t_s = np.array([0.5, 0.75, 1.0, 1.25, 1.5, 1.75, 2.5, 3.0, 3.5, 4.0, 4.5])
    ns = np.round(t_s * NS).astype(np.int64)
    gyro = np.column_stack((np.full(t_s.size, 0.01), np.full(t_s.size, -0.02), 0.1 + 0.01 * np.arange(t_s.size)))
    # by hand: the anchor and its age (the last two samples are held at max_hold_s)
    j = np.array([0, 0, 0, 0, 1, 1, 2, 2, 2, 2, 2])
    age = np.minimum(t_s - np.array([0.0, 1.0, 2.0])[j], hold)
    np.testing.assert_array_equal(age[-2:], [hold, hold])
    d = anchors.d0[j] + anchors.d_dot[j] * age + anchors.k_rate[j] * gyro[:, 2]
    wc = np.column_stack((gyro[:, :2] - anchors.bias_xy[j], gyro[:, 2] - d))
    var = anchors.heading_var[j] + arw ** 2 * age
    # Psi: this path's integral (0 at its first sample); at an anchor's stamp it is taken at this
    # path's last sample at or before that stamp (at the first sample if none): by hand, k
    psi = np.concatenate(([0.0], np.cumsum((anchors.g_tilt[j] * wc[:, 2] - earth)[1:] * np.diff(t_s))))
    k = np.array([0, 0, 0, 0, 2, 2, 5, 5, 5, 5, 5])
    heading = wrap_angle(anchors.heading[j] + psi - psi[k])
    for one_by_one in (False, True):
        fp = FastPath(delay, max_gap_s=1.0, earth_rate_up_rad_s=earth, arw_rad_sqrt_s=arw, max_hold_s=hold)
        fp.add_anchors(anchors, int(ns[-1]))
        if one_by_one:
            rows = [fp.run_one(int(n), *map(float, g)) for n, g in zip(ns, gyro)]
            got_wc, got_heading, got_var = (np.array([r[1:4] for r in rows]), np.array([r[4] for r in rows]),
                                            np.array([r[5] for r in rows]))
        else:
            out = fp.run(ns, gyro)
            assert out.ok.all()
            np.testing.assert_array_equal(out.anchor_ns, anchors.ns[j])
            got_wc, got_heading, got_var = out.gyro_compensated, out.heading, out.heading_var
        np.testing.assert_allclose(got_wc, wc, rtol=0, atol=1e-15)
        np.testing.assert_allclose(got_var, var, rtol=1e-12, atol=0)
        np.testing.assert_allclose(wrap_angle(got_heading - heading), 0.0, rtol=0, atol=1e-12)
    # the trend's sign: on anchor 2 (d_dot > 0) the published rate, less what the measured rate's own
    # change gives, falls by d_dot per second of age
    same = (j == 2) & (age < hold)
    fall = np.diff(got_wc[same, 2] - (1 - anchors.k_rate[2]) * gyro[same, 2])
    np.testing.assert_allclose(fall, -anchors.d_dot[2] * np.diff(age[same]), rtol=1e-9)



def test_drift_trend_is_the_models_change_one_second_along_the_temperature_rate():
    """The trend the fast path extrapolates with (`DriftModel.response`), by hand: for
    D = a (T - T_ref) + b dT/dt + c + a2 (T - T_ref)^2 + k1 w (T - T_ref) + k0 w the drift goes on,
    as the temperature continues along its rate for 1 s, by a dT/dt + a2 ((u + dT/dt)^2 - u^2) with
    u = T - T_ref (secant, the rate held); its weight on the measured rate is k1 u + k0."""
    from gyro_thermal_comp.thermal.drift_model import CURVATURE_TERMS, SCALE_FACTOR_TERMS, DriftModel

    model = DriftModel(CURVATURE_TERMS + SCALE_FACTOR_TERMS, temperature_ref_c=25.0)
    a, b, c, a2, k1, k0 = -1e-4, 7e-3, 2e-3, -3e-7, 1e-4, 5e-3
    x = np.array([a, b, c, a2, k1, k0])
    temp, rate = np.array([25.0, 35.0, 45.0, 35.0]), np.array([0.05, 0.05, -0.02, 0.0])
    u = temp - 25.0
    k, trend = model.response(x, model.neutral_inputs(temp, rate, rate_rad_s=0.3))
    np.testing.assert_allclose(trend, a * rate + a2 * ((u + rate) ** 2 - u ** 2), rtol=1e-9, atol=1e-18)
    np.testing.assert_allclose(k, k1 * u + k0, rtol=1e-9)
    assert trend[0] < 0 < trend[2] and trend[3] == 0.0    # a < 0: warming lowers the drift


def _warming_record():
    """A level, motionless unit warming at 0.05 degC/s from 60 s to 660 s, drift a (T - 25) + b dT/dt + c."""
    from test_thermal_estimator import stream

    def profile(t):
        return 25.0 + 0.05 * np.clip(t - 60.0, 0.0, 600.0), np.where((t > 60.0) & (t < 660.0), 0.05, 0.0)
    return stream(duration_s=700.0, chunk_s=10.0, profile=profile)


def test_published_outputs_follow_the_slow_path_by_the_trend_and_the_random_walk():
    """The compensator as the node runs it, on a warming record. Against the slow path's own rows:
    - the published heading variance is the anchor's plus ARW^2 x age (node defaults);
    - the published drift (gyro - compensated z) is the slow path's at the anchor carried on by the
      trend: on the ramp it misses the slow path's drift at the sample by under a fifth of how far
      that drift moved since the anchor (held without a trend it would miss by all of it; with the
      trend's sign wrong, by twice that), and the trend has the sign of a x dT/dt."""
    from gyro_thermal_comp.nodes.parameters import all_specs, config_from_params
    from gyro_thermal_comp.stamps import ns_at
    from gyro_thermal_comp.thermal.compensator import ThermalCompensator
    from test_thermal_estimator import A

    values = {s.name: s.default for s in all_specs()}
    cfg = config_from_params(values)
    comp = ThermalCompensator(cfg, values['output_delay_s'])
    slow, fast = [], []
    for chunk in _warming_record():
        comp.add_many(ns_at(chunk.imu.t, 0), chunk.imu.gyro, chunk.imu.accel)
        out = comp.estimate(chunk, 0)
        slow.append((ns_at(out.track.t, 0), out.track.drift_rad_s, out.track.heading_sigma_rad ** 2,
                     out.drift_trend_rad_s2))
        fast.append(comp.take_ready()[1])
    comp.finish()
    fast = [f for f in fast + [comp.take_ready()[1]] if f is not None]
    s_ns, s_drift, s_var, s_trend = (np.concatenate(c) for c in zip(*slow))
    ok = np.concatenate([f.ok for f in fast])
    f_ns, f_anchor, f_var = (np.concatenate([getattr(f, n) for f in fast])[ok] for n in ('ns', 'anchor_ns', 'heading_var'))
    f_drift = (np.concatenate([f.gyro_compensated[:, 2] for f in fast]) * -1.0)[ok]
    gyro_z = np.concatenate([c.imu.gyro[:, 2] for c in _warming_record()])
    i, j = np.searchsorted(s_ns, f_ns), np.searchsorted(s_ns, f_anchor)
    assert ok.sum() > 0.95 * s_ns.size and np.array_equal(s_ns[i], f_ns) and np.array_equal(s_ns[j], f_anchor)
    age = (f_ns - f_anchor) * 1e-9
    assert np.all(age[f_ns >= s_ns[0] + values['output_delay_s'] * NS] >= values['output_delay_s'] - 1e-9)
    np.testing.assert_allclose(f_var, s_var[j] + cfg.arw_rad_sqrt_s ** 2 * age, rtol=1e-9)
    f_drift = f_drift + gyro_z[i]                       # gyro - compensated = the drift applied
    ramp = (f_ns > 200 * NS) & (f_ns < 650 * NS)       # the windows have seen the ramp by then
    missed = np.median(np.abs(f_drift - s_drift[i])[ramp])
    moved = np.median(np.abs(s_drift[i] - s_drift[j])[ramp])
    assert moved > 0.5 * abs(A * 0.05) and missed < 0.2 * moved, (missed, moved)
    # the trend has the sign of a x dT/dt, or is 0 where the coast does not follow the model's change
    trend = s_trend[j][ramp]
    assert np.all(np.sign(trend) * np.sign(A * 0.05) >= 0) and np.mean(trend != 0.0) > 0.5
