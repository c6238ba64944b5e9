"""StampMerger: any interleaving of in-order topics comes out in stamp order, nothing lost."""
import numpy as np
from hypothesis import given, settings, strategies as st

from gyro_thermal_comp.input_guard import StreamGuard
from gyro_thermal_comp.nodes.stamp_merger import StampMerger


class FakeClock:
    def __init__(self):
        self.now = 0.0

    def __call__(self):
        return self.now


def guarded(merger, **rule):
    """The merger behind one guard per topic, as its owner (a node's pipeline) puts it: push, guards."""
    guards = {name: StreamGuard(name, **rule) for name in merger.topics}

    def push(topic, t, row):
        merger.arrived(topic)
        return guards[topic].keep_one(t, row) and merger.push(topic, t, row)
    return push, guards


def streams():
    t = {'imu': np.arange(0, 5, 0.01), 'mag': np.arange(0, 5, 0.05), 'temperature': np.arange(0, 5, 1.0)}
    return {k: [(float(x), [float(x)]) for x in v] for k, v in t.items()}


@settings(max_examples=60, deadline=None)
@given(st.randoms(use_true_random=False))
def test_any_interleaving_is_released_in_stamp_order(rnd):
    clock = FakeClock()
    merger = StampMerger(('imu', 'mag', 'temperature'), max_latency_s=1.5, clock=clock)  # > 1 s temp period
    pending = {k: list(v) for k, v in streams().items()}
    batches = []
    while any(pending.values()):
        # any topic whose next sample is within 0.3 s of the earliest pending one:
        # arbitrary interleaving, with the delivery skew a live system has
        earliest = min(v[0][0] for v in pending.values() if v)
        topic = rnd.choice([k for k, v in pending.items() if v and v[0][0] <= earliest + 0.3])
        for _ in range(rnd.randint(1, 20)):           # bursts, as an executor delivers them
            if pending[topic] and pending[topic][0][0] <= earliest + 0.3:
                t, row = pending[topic].pop(0)
                clock.now = max(clock.now, t)          # wall time follows the data (rate 1)
                assert merger.push(topic, t, row)
        batches.append(merger.pop_ready())
    batches.append(merger.pop_ready(flush=True))
    stamps = [np.concatenate([t for t, _ in b.values()]) for b in batches if b]
    assert sum(len(s) for s in stamps) == sum(len(v) for v in streams().values())   # nothing lost
    for earlier, later in zip(stamps, stamps[1:]):   # a release never precedes an earlier one
        assert later.min() >= earlier.max()
    assert sum(merger.counters()[f'{k}_dropped_late'] for k in ('imu', 'mag', 'temperature')) == 0


def test_silent_topic_stops_holding_others_back_and_bad_samples_are_counted():
    clock = FakeClock()
    merger = StampMerger(('imu', 'mag', 'temperature'), max_latency_s=0.5, clock=clock)
    push, guards = guarded(merger)
    push('temperature', 0.0, [20.0])
    for i in range(10):
        push('imu', i * 0.01, [0.0])
    assert 'imu' not in merger.pop_ready()             # waiting for mag (never heard from yet)
    released = 0
    for _ in range(6):                                 # mag and temperature silent for > 0.5 s
        clock.now += 0.1                               # of polls at the node's pace
        released += len(merger.pop_ready().get('imu', ((),))[0])
    push('imu', 0.1, [0.0])
    assert released + len(merger.pop_ready()['imu'][0]) == 11
    assert not push('imu', 0.05, [0.0])                # out of order
    assert not push('imu', 0.2, [float('nan')])        # NaN
    c = guards['imu'].counters()
    assert c['imu_dropped_order'] == 1 and c['imu_dropped_nonfinite'] == 1
    assert merger.counters()['imu_received'] == 13 and merger.counters()['imu_buffered'] == 0


def test_buffer_is_bounded():
    merger = StampMerger(('imu', 'mag'), max_buffered=1000, clock=FakeClock())
    merger.push('mag', 0.0, [0.0])
    merger.push('mag', 1.0, [0.0])  # mag period 1 s: holds imu up to 1.9 s...
    for i in range(5000):
        merger.push('imu', 1.0 + i * 0.001, [0.0])
        if i % 100 == 0:
            merger.pop_ready()
    assert merger.counters()['imu_buffered'] <= 1100 and merger.forced > 0


def test_a_stalled_process_is_not_silence():
    """A process frozen for 3 s (loaded CPU) wakes with its timer first, before the executor takes the
    messages that arrived meanwhile: nothing may be released ahead of them, nothing dropped late."""
    clock = FakeClock()
    merger = StampMerger(('imu', 'temperature'), max_latency_s=2.0, max_poll_gap_s=0.25, clock=clock)
    merger.push('temperature', 0.0, [20.0])
    merger.push('temperature', 1.0, [20.0])
    for i in range(101):
        merger.push('imu', i * 0.01, [0.0])
    assert merger.pop_ready()['imu'][0].max() < 1.0 + 0.9   # up to the temperature's watermark
    clock.now += 3.0                                   # frozen; temperature 2.0 waits in the middleware
    assert 'imu' not in merger.pop_ready()             # the timer runs first after the stall: holds
    merger.push('temperature', 2.0, [20.0])            # then the executor delivers what waited
    assert merger.counters()['temperature_dropped_late'] == 0 and merger.counters()['stalls'] == 1


def test_a_topic_without_publisher_holds_nobody_back():
    merger = StampMerger(('imu', 'imu_aux'), clock=FakeClock())
    for i in range(10):
        merger.push('imu', i * 0.01, [0.0])
    assert not merger.pop_ready()                      # imu_aux may still deliver an earlier stamp
    assert len(merger.pop_ready(unpublished={'imu_aux'})['imu'][0]) == 10


def test_a_clock_jump_back_releases_the_old_time_base_then_orders_the_new_one():
    """A bag loop / simulator reset. Once the guard confirms the jump, what was buffered on
    the old time base is released, and the new one is ordered from scratch (nothing dropped as late);
    a few messages stamped an hour ahead are dropped instead of silencing the topic."""
    clock = FakeClock()
    merger = StampMerger(('imu', 'mag'), max_latency_s=1.0, clock=clock)
    push, guards = guarded(merger, max_jump_s=5.0, confirm_samples=5)
    released = []
    for k in range(200):                      # 2 s, both topics, then the clock jumps back by 100 s
        t = 100.0 + 0.01 * k if k < 100 else 0.01 * k
        clock.now = 0.01 * k
        push('imu', t, [t])
        if k % 5 == 0:
            push('mag', t, [t])
        if k == 50:
            for j in range(4):
                assert not push('imu', 3700.0 + 0.01 * j, [0.0])
        ready = merger.pop_ready()
        released += [float(x) for x in ready.get('imu', (np.empty(0), None))[0]]
    released += [float(x) for x in merger.pop_ready(flush=True).get('imu', (np.empty(0), None))[0]]
    c = {**merger.counters(), **guards['imu'].counters()}
    assert c['imu_dropped_jump'] == 4 + 4 and c['imu_time_base_changes'] == 1     # 4: confirming the jump
    assert c['imu_dropped_late'] == 0 and c['mag_dropped_late'] == 0
    old, new = [t for t in released if t >= 100.0], [t for t in released if t < 100.0]
    assert len(old) == 100 and len(new) == 96 and np.all(np.diff(old) > 0) and np.all(np.diff(new) > 0)
    assert released.index(new[0]) == len(old)                                  # old time base first


def test_a_slow_topic_does_not_delay_the_first_outputs():
    """A 1 Hz temperature must not hold every other topic back until its first sample and again until
    its second (its period unknown), up to 2 s of silence: a topic whose period is not known yet is
    waited for `first_sample_wait_s` behind the others, not until its next sample; once known, as any
    topic with a known period. Nothing is dropped as late when it delivers within that wait."""
    clock = FakeClock()
    merger = StampMerger(('imu', 'temperature'), max_latency_s=2.0, first_sample_wait_s=0.25, clock=clock)
    latency = []
    for k in range(400):                                   # 4 s at 100 Hz, wall time = stamps
        t = 0.01 * k
        clock.now = t
        if k % 100 == 50:                                  # temperature at 0.5, 1.5, ... s
            merger.push('temperature', t, [20.0])
        merger.push('imu', t, [0.0])
        for s in merger.pop_ready().get('imu', (np.empty(0), None))[0]:
            latency.append(clock.now - s)
    c = merger.counters()
    assert c['temperature_dropped_late'] == 0 and c['imu_dropped_late'] == 0
    latency = np.array(latency)
    assert latency[:50].max() <= 0.25 + 0.01 + 1e-9        # before the first temperature: the wait (+ a poll)
    assert latency.max() <= 1.0                            # after: up to the temperature period, as before


def test_the_first_sample_of_a_slow_topic_at_an_equal_stamp_is_not_overtaken():
    """Offline, a temperature at the IMU's stamp goes first; live it may arrive a moment later: the
    IMU sample waits for it (the wait is in awake time, so a stall does not count)."""
    clock = FakeClock()
    merger = StampMerger(('imu', 'temperature'), max_latency_s=2.0, first_sample_wait_s=0.25, clock=clock)
    merger.push('imu', 0.0, [0.0])
    clock.now = 0.1
    assert not merger.pop_ready()                          # the temperature may still come
    merger.push('temperature', 0.0, [20.0])
    clock.now = 0.2
    ready = merger.pop_ready()
    assert list(ready['imu'][0]) == [0.0] and list(ready['temperature'][0]) == [0.0]
