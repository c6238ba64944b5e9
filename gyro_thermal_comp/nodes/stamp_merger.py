"""Put samples from several topics back into stamp order, as a bag would hold them (no ROS here).

DDS delivers each topic in order but interleaves topics arbitrarily. The merger is given samples its
owner's stream guards kept (input_guard.py: finite, each topic's stamps increasing except across a
time-base change the guard confirmed); it orders them and checks nothing else. The estimator is causal, so
feeding it in stamp order makes a live node produce exactly what an offline run over the bag does.
A sample is released once every topic has either delivered a later stamp or is not expected to
deliver one before it (its last stamp plus half its period lies beyond it: a driver's stamps jitter,
and a sample stamped earlier than expected would otherwise arrive after its time was released and
be dropped as late; the node's output does not wait for this, thermal/fast_path.py). A topic with no
publisher, or one that falls silent (nothing received for `max_latency_s`, or two of its periods if
longer), holds nobody back; a topic delayed longer than that in transport (a reliable writer
resending after a stall, say) has its late samples dropped and counted.

Start-up: a topic not heard from yet, or heard from once (its period unknown), would otherwise hold
every other topic back until its next sample: a 1 Hz temperature delayed the first outputs by up to
two seconds. Such a topic is taken to deliver within `first_sample_wait_s` of the others: once
samples stamped up to t have been received that long ago (awake time), it holds nothing at or
before t back. A topic whose period is known is waited for as before.

Silence is measured in *awake* wall time: time during which `pop_ready` was being called at its
normal pace. A process starved of CPU (a loaded machine) wakes with every topic apparently silent
while their messages still wait in the middleware queues; an executor runs timers before it takes
those messages, so measuring silence across the stall would release samples ahead of a topic that
is merely late, and then drop that topic's samples as late. Any pause between two polls longer
than `max_poll_gap_s` therefore restarts the silence clocks, which makes what is released depend on
the stamps delivered, not on when the process got the CPU. The buffer is bounded.
"""
from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from ..samples import ImuSamples, JointSamples, MagSamples, SensorChunk, TemperatureSamples


def poll_gap_s(process_period_s: float) -> float:
    """A node polling every `process_period_s` has stalled when a poll comes this much later, s."""
    return max(0.25, 10.0 * process_period_s)


@dataclass
class TopicState:
    queue: deque = field(default_factory=deque)  # (t, row) not yet released
    last_t: float = -np.inf                      # newest stamp received (late samples included), s
    last_wall: float = -np.inf                   # steady time of the newest sample, s
    period_s: float | None = None                # smoothed sample period
    received: int = 0
    dropped_late: int = 0                        # arrived after its time had already been released
    dropped_malformed: int = 0                   # bytes that are no message of the topic's type


class StampMerger:
    """Stamp-ordered release of rows from named topics.

    `push(topic, t, row)` buffers one sample; `pop_ready()` returns {topic: (t array, rows)} of
    everything that can be released in order. `clock` gives steady time in s (injectable for tests).
    """

    def __init__(self, topics, *, max_latency_s: float = 2.0, period_margin: float = 0.5,
                 max_buffered: int = 100_000, max_poll_gap_s: float = 0.25,
                 first_sample_wait_s: float | None = None, clock=time.monotonic):
        self.clock = clock
        # how long a topic whose period is unknown may lag the others in delivery (module docstring)
        self.first_sample_wait_s = max_latency_s if first_sample_wait_s is None else first_sample_wait_s
        self._arrivals: deque = deque()   # (steady time, stamp) whenever the newest stamp grew
        self._aged_t = -np.inf            # newest stamp received first_sample_wait_s ago (awake)
        self._first_wall: float | None = None  # when the first sample of any topic arrived
        self.max_poll_gap_s = max_poll_gap_s
        self._last_poll_wall: float | None = None
        self._awake_since = -np.inf   # steady time since which polls came at their normal pace
        self.stalls = 0               # polls that came more than max_poll_gap_s after the previous
        self.topics = {name: TopicState() for name in topics}
        self._before_jump: dict | None = None   # what was buffered when a clock jumped back
        self.max_latency_s = max_latency_s
        self.period_margin = period_margin
        self.max_buffered = max_buffered
        self.released_t = -np.inf     # everything at or before this has been released
        self.forced = 0               # releases forced by the buffer bound
        self.newest_t = -np.inf

    def arrived(self, topic: str) -> None:
        """Count one sample of `topic` received, before its guard decides on it."""
        self.topics[topic].received += 1

    def push(self, topic: str, t: float, row) -> bool:
        """Buffer one sample its stream's guard kept; False (and counted) if it came too late."""
        st = self.topics[topic]
        t_before = st.last_t
        st.last_t = t
        if t < t_before and t <= self.released_t:   # kept, yet back in time: the guard confirmed a new clock
            self._clock_went_back()
        if t <= self.released_t:
            st.dropped_late += 1
            return False
        if -np.inf < t_before < t:   # not the first sample, not across a jump back
            dt = t - t_before
            st.period_s = dt if st.period_s is None else 0.9 * st.period_s + 0.1 * min(dt, 10 * st.period_s)
        st.last_wall = self.clock()
        if self._first_wall is None:
            self._first_wall = st.last_wall
        st.queue.append((t, row))
        if t > self.newest_t:
            self._arrivals.append((st.last_wall, t))
            self.newest_t = t
        return True

    def malformed(self, topic: str) -> None:
        """Count a message of `topic` that could not be read at all (dropped before `push`)."""
        st = self.topics[topic]
        st.received += 1
        st.dropped_malformed += 1

    def _watermark(self, st: TopicState, now_wall: float) -> float:
        """No sample of this topic is expected at or before the returned stamp (unless it is late)."""
        heard_at = st.last_wall if st.last_t > -np.inf else (
            now_wall if self._first_wall is None else self._first_wall)
        heard_at = max(heard_at, self._awake_since)  # a stall is not silence (module docstring)
        # A slow topic (1 Hz temperature) is not silent between its samples: allow two periods.
        if now_wall - heard_at > max(self.max_latency_s, 2.0 * (st.period_s or 0.0)):
            return np.inf  # silent (or never heard from since start-up): holds nobody back
        if st.period_s is None:   # not heard from, or once: it delivers with the others (docstring)
            return max(st.last_t, self._aged_t)
        return st.last_t + self.period_margin * st.period_s

    def pop_ready(self, flush: bool = False, unpublished=()) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Release, in stamp order, every buffered sample no topic can still precede (all if flush).

        `unpublished`: topics that have no publisher now; nothing more can arrive on them, so they hold
        nobody back (a node passes its subscriptions with zero matched publishers)."""
        if self._before_jump is not None:   # the old time base first, as one release
            out, self._before_jump = self._before_jump, None
            return out
        buffered = sum(len(st.queue) for st in self.topics.values())
        if flush:
            limit = np.inf
        else:
            now_wall = self._poll()
            self._age_arrivals(now_wall)
            limit = min((np.inf if name in unpublished else self._watermark(st, now_wall))
                        for name, st in self.topics.items())
            if limit == np.inf:  # every topic silent: release what is there
                limit = self.newest_t
            if buffered > self.max_buffered:  # bound memory: release the oldest half by force
                stamps = np.sort(np.concatenate([[t for t, _ in st.queue] for st in self.topics.values()]))
                limit = max(limit, stamps[len(stamps) // 2])
                self.forced += 1
        out = {}
        for name, st in self.topics.items():
            taken = []
            while st.queue and st.queue[0][0] <= limit:
                taken.append(st.queue.popleft())
            if taken:
                out[name] = (np.array([t for t, _ in taken]), np.array([r for _, r in taken]))
                self.released_t = max(self.released_t, taken[-1][0])
        return out

    def _clock_went_back(self) -> None:
        """A topic's clock jumped back (bag loop, simulator reset; confirmed by its guard): release
        everything buffered on the old time base, then order the new one from scratch."""
        earlier, self._before_jump = self._before_jump or {}, None   # a second jump before the next pop
        old = self.pop_ready(flush=True)
        for name, (t, rows) in earlier.items():
            if name in old:
                old[name] = (np.concatenate((t, old[name][0])), np.concatenate((rows, old[name][1])))
            else:
                old[name] = (t, rows)
        self._before_jump = old or None
        self.released_t = -np.inf
        self.newest_t = -np.inf
        self._arrivals.clear()
        self._aged_t = -np.inf

    def _age_arrivals(self, now_wall: float) -> None:
        """Move stamps received `first_sample_wait_s` of awake time ago into `_aged_t` (a stall
        restarts the wait: the middleware may still hold what was sent meanwhile)."""
        horizon = now_wall - self.first_sample_wait_s
        if self._awake_since > horizon:
            return
        while self._arrivals and self._arrivals[0][0] <= horizon:
            self._aged_t = max(self._aged_t, self._arrivals.popleft()[1])

    def _poll(self) -> float:
        """Steady time now; a gap since the previous poll beyond `max_poll_gap_s` restarts silence."""
        now = self.clock()
        if self._last_poll_wall is not None and now - self._last_poll_wall > self.max_poll_gap_s:
            self._awake_since = now
            self.stalls += 1
        self._last_poll_wall = now
        return now

    def silent_streams(self, floor_s: float) -> dict[str, float]:
        """Topics heard from before that have been silent (in awake wall time) longer than
        max(floor_s, 5 of their periods): {topic: silent for, s}."""
        now = self.clock()
        out = {}
        for name, st in self.topics.items():
            if st.received == 0 or st.last_wall == -np.inf:
                continue
            quiet = now - max(st.last_wall, self._awake_since)
            if quiet > max(floor_s, 5.0 * (st.period_s or 0.0)):
                out[name] = quiet
        return out

    def counters(self) -> dict[str, int]:
        c = {'forced_releases': self.forced, 'stalls': self.stalls}
        for name, st in self.topics.items():
            c.update({f'{name}_received': st.received, f'{name}_dropped_late': st.dropped_late,
                      f'{name}_dropped_malformed': st.dropped_malformed, f'{name}_buffered': len(st.queue)})
        return c


# Row layouts the nodes push (see conversions.py) -> sample types of a SensorChunk field.
_ROWS_TO_SAMPLES = {
    'imu': lambda t, r: ImuSamples(t, r[:, :3], r[:, 3:]),
    'imu_aux': lambda t, r: ImuSamples(t, r[:, :3], r[:, 3:]),
    'mag': lambda t, r: MagSamples(t, r),
    'temperature': lambda t, r: TemperatureSamples(t, r[:, 0]),
    'joint': lambda t, r: JointSamples(t, r[:, 0], r[:, 1]),
}


def chunk_from_released(ready: dict[str, tuple[np.ndarray, np.ndarray]]) -> SensorChunk:
    """What `StampMerger.pop_ready` released (topic names = SensorChunk fields) -> a SensorChunk."""
    return SensorChunk(**{name: _ROWS_TO_SAMPLES[name](t, rows) for name, (t, rows) in ready.items()})
