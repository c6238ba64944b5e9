"""The one input-hygiene rule (input_guard.StreamGuard): what it keeps does not depend on chunking."""
import numpy as np
from hypothesis import given, settings, strategies as st

from gyro_thermal_comp.input_guard import StreamGuard

stamps = st.lists(st.one_of(st.floats(-5, 5), st.floats(-1e4, 1e4), st.just(np.nan), st.just(np.inf)),
                  min_size=1, max_size=40)


@settings(max_examples=300, deadline=None)
@given(stamps, st.lists(st.sampled_from(['ok', 'nan', 'huge']), min_size=40, max_size=40),
       st.lists(st.integers(1, 7), min_size=1), st.sampled_from([np.inf, 2.0]), st.integers(1, 4))
def test_same_samples_kept_in_any_chunking(t, bad_value, cuts, max_jump_s, confirm):
    t = np.array(t)
    kind = np.array(bad_value[:t.size])
    v = np.where((kind == 'nan')[:, None], np.nan, np.where((kind == 'huge')[:, None], 1e30, np.ones((t.size, 3))))

    def guard():
        return StreamGuard('imu', limits=((-10.0, 10.0),), max_jump_s=max_jump_s, confirm_samples=confirm)
    whole = guard()
    mask = whole.keep(t, v)
    parts, i, k = guard(), 0, 0
    pieces = []
    while i < t.size:
        j = min(t.size, i + cuts[k % len(cuts)])
        pieces.append(parts.keep(t[i:j], v[i:j]) if j - i > 1 else np.array([parts.keep_one(t[i], v[i])]))
        i, k = j, k + 1
    assert np.array_equal(np.concatenate(pieces), mask)
    assert parts.counters() == whole.counters()
    kept = t[mask]
    assert np.all(np.isfinite(kept)) and np.all(np.isfinite(v[mask])) and np.all(np.abs(v[mask]) <= 10.0)
    assert whole.dropped + int(np.count_nonzero(mask)) == t.size
    if whole.time_base_changes == 0:
        assert np.all(np.diff(kept) > 0) and np.all(np.diff(kept) <= max_jump_s)


def test_counters_name_the_stream_and_the_cause():
    g = StreamGuard('mag')
    assert list(g.keep(np.array([1.0, 1.0, 0.5, 2.0, np.nan]), np.array([1.0, 2.0, 3.0, np.inf, 1.0]))) == \
        [True, False, False, False, False]
    c = g.counters()
    assert c['mag_dropped_nonfinite'] == 2 and c['mag_dropped_order'] == 2
    assert g.keep_one(1.5, np.ones(3)) and not g.keep_one(1.5, np.ones(3))
    assert (g.first_t, g.last_t) == (1.0, 1.5)


def test_values_outside_the_declared_range_are_dropped_and_saturation_counted():
    g = StreamGuard('imu', limits=((-5.0, 5.0), None))
    ok = g.keep(np.arange(4.0), np.array([[0.0], [1e30], [-4.99], [6.0]]), np.array([[1e9]] * 4))
    assert list(ok) == [True, False, True, False]
    c = g.counters()
    assert c['imu_dropped_range'] == 2 and c['imu_saturated'] == 3   # 1e30, -4.99 and 6.0 are at or past 99 %


def test_a_few_samples_stamped_far_ahead_do_not_silence_the_stream():
    """Five IMU messages stamped one hour ahead must not make every later sample 'out of order'."""
    g = StreamGuard('imu', max_jump_s=5.0, confirm_samples=10)
    t = np.concatenate((np.arange(0.0, 10.0, 0.01), 3600.0 + np.arange(5) * 0.01, np.arange(10.0, 20.0, 0.01)))
    ok = g.keep(t, np.zeros((t.size, 3)))
    assert np.count_nonzero(~ok) == 5 and np.all(t[~ok] >= 3600.0)
    assert g.counters()['imu_dropped_jump'] == 5 and g.time_base_changes == 0


def test_a_clock_that_really_jumped_becomes_the_new_time_base():
    """A jump that the following samples continue (clock reset, bag loop) is taken after `confirm_samples`."""
    for offset in (3600.0, -3600.0):
        g = StreamGuard('imu', max_jump_s=5.0, confirm_samples=10)
        t = np.concatenate((np.arange(4000.0, 4010.0, 0.01), 4010.0 + offset + np.arange(0.0, 10.0, 0.01)))
        ok = g.keep(t, np.zeros((t.size, 3)))
        assert g.time_base_changes == 1 and np.count_nonzero(~ok) == 9
        assert np.all(ok[1000 + 9:]) and g.last_t == t[-1]


@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(st.integers(1, 20), st.sampled_from(['clean', 'nan', 'range', 'edge', 'repeat', 'back',
                                                                  'jump', 'norm'])), min_size=1, max_size=12),
       st.sampled_from([np.inf, 2.0]))
def test_the_clean_chunk_shortcut_decides_as_the_full_rule(chunks, max_jump_s):
    """`keep` answers a clean chunk with a few reductions (and a short one on Python floats); on every
    kind of chunk the answer and the counters are those of the full per-row rule."""
    rng = np.random.default_rng(len(chunks))
    limits = ((-10.0, 10.0), (-10.0, 10.0, 0.5))   # the second: with a minimum norm, like the compass

    def guard(shortcut):
        g = StreamGuard('imu', limits=limits, max_jump_s=max_jump_s, confirm_samples=3)
        if not shortcut:
            g._all_clean = lambda t, rows: False
        return g
    fast, full, t_next = guard(True), guard(False), 0.0
    for n, kind in chunks:
        t = t_next + 0.01 * np.arange(1, n + 1)
        a, b = rng.uniform(-5, 5, (n, 3)), rng.uniform(1, 5, (n, 3))
        k = int(rng.integers(n))
        if kind == 'nan':
            a[k, 1] = np.nan
        elif kind == 'range':
            b[k, 0] = 11.0
        elif kind == 'edge':
            a[k, 2] = 9.99   # near the end of the range: saturated
        elif kind == 'repeat' and n > 1:
            t[k] = t[k - 1] if k else t[1]
        elif kind == 'back':
            t = t - 1.0
        elif kind == 'jump':
            t = t + 10.0
        elif kind == 'norm':
            b[k] = 0.1
        assert np.array_equal(fast.keep(t, a, b), full.keep(t, a, b)), kind
        assert fast.counters() == full.counters() and fast.last_t == full.last_t
        t_next = float(np.nanmax(t))
