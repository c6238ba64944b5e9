"""`ThermalCompensator`: the estimator (slow path) and the fast path together, as the node runs them.

The node and an offline run use this one class, so "the node computes what the core computes"
holds by construction: `estimate` runs the estimator on stamp-ordered samples and hands its state
to the fast path; `push` (live) or `add_many` + `take_ready` give each IMU sample its output
(thermal/fast_path.py). Offline, `run` does both for a chunk.

Each input stream has one guard (thermal/inputs.py), applied here as its samples come in: IMU
samples in `push`/`add_many`, compass and temperature samples in `admit`/`admitted`. The estimator
gets only what they kept, so both paths drop the same samples and nothing is checked twice.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from ..samples import SensorChunk, slice_samples
from ..stamps import ns_at
from .estimator import EstimatorConfig, ThermalDriftEstimator, ThermalOutput
from .fast_path import AnchorRows, FastOutput, FastPath, RowQueue, anchor_rows
from .inputs import input_guards
from .imu_stretch import earth_rate_up

QUEUED = 'queued'   # `push`: the sample waits in the queue for the estimator

# Default of the node's output_delay_s: above the period of a 1 Hz temperature sensor plus transport.
OUTPUT_DELAY_S = 1.0


class ThermalCompensator:
    """`held(out, chunk)` may add per-row columns the outputs carry from their anchor (a node's
    orientation variances); roll and pitch are always held."""

    def __init__(self, cfg: EstimatorConfig, output_delay_s: float = OUTPUT_DELAY_S,
                 held: Callable[[ThermalOutput, SensorChunk], dict] | None = None):
        self.guards = input_guards(cfg)   # one per stream, applied here (module docstring)
        self.estimator = ThermalDriftEstimator(cfg, guards=self.guards)
        self.fast = FastPath(output_delay_s, cfg.max_gap_s, earth_rate_up(cfg.latitude_deg),
                             cfg.arw_rad_sqrt_s)
        self._held = held
        self._pending = RowQueue()       # (stamp ns, gyro (n, 3), kept, *carry) not yet output
        self._void = 0                   # queued rows from before a clock went back
        self.waited = 0                  # times a queued sample waited for the estimator
        self.guard = self.guards['imu']
        self._ns0: int | None = None     # first stamp of any stream: the guards' times are s since it
        self._newest_ns = -1 << 62       # newest kept stamp
        self.dropped_at_clock_change = 0

    def _seconds(self, ns) -> np.ndarray | float:
        """Stamps (ns) as the guards see them: s since the first stamp given here."""
        if self._ns0 is None:
            self._ns0 = int(np.ravel(ns)[0])
        return (ns - self._ns0) * 1e-9

    def admit(self, stream: str, ns: int, row) -> bool:
        """One compass (row = field, T) or temperature (row = [degC]) sample as it arrives: True if its
        guard keeps it (only kept samples may then reach `estimate`)."""
        return self.guards[stream].keep_one(self._seconds(int(ns)), row)

    def admitted(self, chunk: SensorChunk, origin_ns: int, imu_kept: np.ndarray) -> SensorChunk:
        """What `estimate` may be given of an offline chunk (times in s since `origin_ns`): the IMU rows
        `add_many` kept, and the compass and temperature samples their guards keep."""
        mag, temp = chunk.mag, chunk.temperature
        if mag is not None and mag.t.size:
            mag = slice_samples(mag, self.guards['mag'].keep(self._seconds(ns_at(mag.t, origin_ns)), mag.field))
        if temp is not None and temp.t.size:
            temp = slice_samples(temp, self.guards['temperature'].keep(self._seconds(ns_at(temp.t, origin_ns)),
                                                                       temp.temp_c))
        imu = chunk.imu if imu_kept.all() else slice_samples(chunk.imu, imu_kept)
        return SensorChunk(imu=imu, mag=mag, temperature=temp)

    def estimate(self, chunk: SensorChunk, origin_ns: int) -> ThermalOutput:
        """The slow path over stamp-ordered samples its guards kept (times in s since `origin_ns`)."""
        out = self.estimator.process(chunk, admitted=True)
        self.fast.arw2 = self.estimator.arw_rad_sqrt_s ** 2   # measured over the still period where larger
        if len(out.track.t):
            tilt_known = np.isfinite(out.roll_rad) & np.isfinite(out.pitch_rad)
            held = {'roll': np.where(tilt_known, out.roll_rad, 0.0), 'pitch': np.where(tilt_known, out.pitch_rad, 0.0)}
            if self._held is not None:
                held.update(self._held(out, chunk))
            ns = ns_at(out.track.t, origin_ns)
            rows = anchor_rows(ns, chunk.imu.gyro, out, held)
            # rows stamped after the newest sample here came before a clock went back (see add)
            self.fast.add_anchors(rows.take(rows.ns <= self._newest_ns), min(int(ns[-1]), self._newest_ns))
        return out

    def push(self, ns: int, gyro, accel, carry: tuple = ()) -> tuple[bool, object]:
        """Live, one sample as it arrives (stamp ns, rates rad/s, specific force m/s^2): whether the
        IMU guard kept it (only kept samples may then reach `estimate`), and its output now if
        nothing waits before it and its anchor is final (`FastPath.run_one`'s tuple, or None if it
        is not published), else QUEUED: it comes out of `take_ready` later, with the caller's
        `carry` (values it needs to publish the sample: a header, the specific force). Same
        numbers as `add_many` + `take_ready`."""
        if len(self._pending):
            kept = self.add_many(np.array([ns], np.int64), np.reshape(gyro, (1, 3)), np.reshape(accel, (1, 3)),
                                 _one_row(carry))
            return bool(kept[0]), QUEUED
        ns = int(ns)
        changes = self.guard.time_base_changes
        kept = self.guard.keep_one(self._seconds(ns), gyro, accel)
        if kept and self.guard.time_base_changes > changes and ns < self._newest_ns:
            self.fast.reset()      # the clock went back; nothing was queued
            self._newest_ns = -1 << 62
        if kept:
            self._newest_ns = max(self._newest_ns, ns)
            if not self.fast.ready(ns):
                self._pending.append(np.array([ns], np.int64), np.array([gyro], float).reshape(1, 3), np.ones(1, bool),
                                     *_one_row(carry))
                if self.fast.anchors is not None:
                    self.waited += 1
                return True, QUEUED
        return kept, self.fast.run_one(ns, float(gyro[0]), float(gyro[1]), float(gyro[2]), kept)

    def add_many(self, ns: np.ndarray, gyro: np.ndarray, accel: np.ndarray, carry: tuple = ()) -> np.ndarray:
        """IMU samples in arrival order, queued for `take_ready` with the caller's `carry` columns (one
        row per sample, as in `push`); returns the rows the IMU guard kept (only those may reach
        `estimate`). A clock that went back (a bag loop, confirmed by the guard) starts the fast path
        over; the samples still queued from before are not published."""
        ns = np.asarray(ns, np.int64)
        if not ns.size:
            return np.zeros(0, dtype=bool)
        changes = self.guard.time_base_changes
        guarded = kept = self.guard.keep(self._seconds(ns), gyro, accel)
        start = 0
        while self.guard.time_base_changes > changes:   # rare: find where the clock went back
            newest = np.maximum.accumulate(np.concatenate(([self._newest_ns], np.where(kept, ns, -1 << 62))))
            back = np.flatnonzero(kept[start:] & (ns[start:] < newest[start:-1]))
            if not back.size:
                break
            i = start + int(back[0])
            self.dropped_at_clock_change += int(np.count_nonzero(kept[:i])) + self._queued_kept()
            self._void = len(self._pending) + i      # everything queued before it: not published
            kept = kept.copy()
            kept[:i] = False
            self.fast.reset()
            self._newest_ns, start = -1 << 62, i
        if np.any(kept):
            self._newest_ns = max(self._newest_ns, int(ns[kept].max()))
        self._pending.append(ns, np.asarray(gyro, float), kept, *carry)
        return guarded

    def _queued_kept(self) -> int:
        cols = self._pending.columns()
        return int(np.count_nonzero(cols[2][self._void:])) if cols else 0

    def finish(self) -> None:
        """Nothing more reaches the estimator: every anchor is final, every queued sample ready."""
        self.fast.add_anchors(AnchorRows.empty(), 1 << 62)

    def take_ready(self) -> tuple[int, FastOutput | None, tuple]:
        """Outputs for the queued samples whose anchor is final, in arrival order: (how many were
        taken from the queue, their outputs, their `carry` columns). A sample that had to wait
        counts in `waited`."""
        if not len(self._pending):
            return 0, None, ()
        ns, gyro, kept, *_ = self._pending.columns()
        kept = kept.copy()
        kept[:self._void] = False
        ready = ~kept | self.fast.ready_many(ns)
        n = ns.size if ready.all() else int(np.argmin(ready))
        if n < ns.size and self.fast.anchors is not None:
            self.waited += 1
        if n == 0:
            return 0, None, ()
        carried = self._pending.take(n)[3:]
        self._void = max(self._void - n, 0)
        return n, self.fast.run(ns[:n], gyro[:n], kept[:n]), carried

    @property
    def anchor_held(self) -> dict:
        """The columns held from the anchors (roll, pitch and the caller's `held`), name -> array
        indexed by the anchor index `push` returns with a sample's output."""
        return self.fast.anchors.held

    @property
    def not_published(self) -> int:
        """IMU samples given no output: NaN, dropped by the input guard, stamp not after the previous."""
        return self.fast.dropped

    def run(self, chunk: SensorChunk, origin_ns: int) -> FastOutput | None:
        """Offline, what a node does with a chunk: queue its IMU samples, `estimate` on what the
        guards kept, take the ready."""
        kept = self.add_many(ns_at(chunk.imu.t, origin_ns), chunk.imu.gyro, chunk.imu.accel)
        self.estimate(self.admitted(chunk, origin_ns, kept), origin_ns)
        return self.take_ready()[1]


def _one_row(values: tuple) -> tuple:
    """One sample's carried values as one-row columns (bytes or None: an object column)."""
    cols = []
    for v in values:
        if v is None or isinstance(v, (bytes, bytearray, memoryview)):
            col = np.empty(1, object)
            col[0] = v
        else:
            col = np.asarray([v], float)
        cols.append(col)
    return tuple(cols)
