"""The one input-hygiene rule (input_guard.StreamGuard): what it keeps does not depend on chunking."""
import numpy as np
from hypothesis import given, settings, strategies as st

from gyro_thermal_comp.input_guard import StreamGuard

stamps = st.lists(st.one_of(st.floats(-5, 5), st.just(np.nan), st.just(np.inf)), min_size=1, max_size=40)


@settings(max_examples=200, deadline=None)
@given(stamps, st.lists(st.booleans(), min_size=40, max_size=40), st.lists(st.integers(1, 7), min_size=1))
def test_same_samples_kept_in_any_chunking(t, bad_value, cuts):
    t = np.array(t)
    v = np.where(np.array(bad_value[:t.size])[:, None], np.nan, np.ones((t.size, 3)))
    whole = StreamGuard('imu')
    mask = whole.keep(t, v)
    parts, i, k = StreamGuard('imu'), 0, 0
    pieces = []
    while i < t.size:
        j = min(t.size, i + cuts[k % len(cuts)])
        pieces.append(parts.keep(t[i:j], v[i:j]))
        i, k = j, k + 1
    assert np.array_equal(np.concatenate(pieces), mask)
    assert parts.counters() == whole.counters()
    kept = t[mask]
    assert np.all(np.isfinite(kept)) and np.all(np.diff(kept) > 0)
    assert np.all(np.isfinite(v[mask]))
    assert whole.dropped + int(np.count_nonzero(mask)) == t.size


def test_counters_name_the_stream_and_the_cause():
    g = StreamGuard('mag')
    assert list(g.keep(np.array([1.0, 1.0, 0.5, 2.0, np.nan]), np.array([1.0, 2.0, 3.0, np.inf, 1.0]))) == \
        [True, False, False, False, False]
    assert g.counters() == {'mag_dropped_nonfinite': 2, 'mag_dropped_order': 2}
    assert g.keep_one(1.5, np.ones(3)) and not g.keep_one(1.5, np.ones(3))
    assert (g.first_t, g.last_t) == (1.0, 1.5)
