"""`ThermalCompensator`: the estimator (slow path) and the fast path together, as the node runs them.

The node and an offline run use this one class, so "the node computes what the core computes"
holds by construction: `estimate` runs the estimator on stamp-ordered samples and hands its state
to the fast path; `compensate` gives each IMU sample its output (thermal/fast_path.py). Offline,
`run` does both for a chunk; a live node calls `estimate` from its timer and `compensate` as
samples arrive, once `ready` says their anchor is final.
"""
from __future__ import annotations

import math
from typing import Callable

import numpy as np

from ..input_guard import StreamGuard
from ..samples import SensorChunk
from ..stamps import ns_at
from .estimator import EstimatorConfig, ThermalDriftEstimator, ThermalOutput
from .fast_path import AnchorRows, FastOutput, FastPath, RowQueue, anchor_rows
from .imu_stretch import earth_rate_up

QUEUED = 'queued'   # `push`: the sample waits in the queue for the estimator

# Default of the node's output_delay_s: above the period of a 1 Hz temperature sensor plus transport.
OUTPUT_DELAY_S = 1.0


class ThermalCompensator:
    """`held(out, chunk)` may add per-row columns the outputs carry from their anchor (a node's
    orientation variances); roll and pitch are always held."""

    def __init__(self, cfg: EstimatorConfig, output_delay_s: float = OUTPUT_DELAY_S,
                 held: Callable[[ThermalOutput, SensorChunk], dict] | None = None):
        self.estimator = ThermalDriftEstimator(cfg)
        self.fast = FastPath(output_delay_s, cfg.max_gap_s, earth_rate_up(cfg.latitude_deg),
                             math.radians(cfg.arw_deg_sqrt_s))
        self._held = held
        self._pending = RowQueue()       # (stamp ns, gyro (n, 3), kept) not yet output
        self._void = 0                   # queued rows from before a clock went back
        self.waited = 0                  # times a queued sample waited for the estimator
        # the estimator's own IMU rule (input_guard.py), so both paths drop the same samples
        self.guard = StreamGuard('imu', ((-cfg.gyro_range_rad_s, cfg.gyro_range_rad_s),
                                         (-cfg.accel_range_m_s2, cfg.accel_range_m_s2)),
                                 max_jump_s=cfg.max_time_jump_s, confirm_samples=cfg.time_jump_confirm_samples)
        self._ns0: int | None = None     # first stamp: the guard's times are s since it
        self._newest_ns = -1 << 62       # newest kept stamp
        self.dropped_at_clock_change = 0

    def estimate(self, chunk: SensorChunk, origin_ns: int) -> ThermalOutput:
        """The slow path over stamp-ordered samples (times in s since `origin_ns`)."""
        out = self.estimator.process(chunk)
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

    def add(self, ns: int, gyro, accel) -> None:
        """An IMU sample as it arrives (stamp ns, rates rad/s, specific force m/s^2)."""
        self.add_many(np.array([ns], np.int64), np.reshape(gyro, (1, 3)), np.reshape(accel, (1, 3)))

    def push(self, ns: int, gyro, accel):
        """Live, one sample as it arrives (stamp ns, rates rad/s, specific force m/s^2): its output
        now if nothing waits before it and its anchor is final (`FastPath.run_one`'s tuple, or None
        if it is not published), else QUEUED (it comes out of `take_ready` later). Same numbers as
        `add` + `take_ready`."""
        if len(self._pending):
            self.add(ns, gyro, accel)
            return QUEUED
        ns = int(ns)
        if self._ns0 is None:
            self._ns0 = ns
        changes = self.guard.time_base_changes
        kept = self.guard.keep_one((ns - self._ns0) * 1e-9, gyro, accel)
        if kept and self.guard.time_base_changes > changes and ns < self._newest_ns:
            self.fast.reset()      # the clock went back; nothing was queued
            self._newest_ns = -1 << 62
        if kept:
            self._newest_ns = max(self._newest_ns, ns)
            if not self.fast.ready(ns):
                self._pending.append(np.array([ns], np.int64), np.array([gyro], float).reshape(1, 3), np.ones(1, bool))
                if self.fast.anchors is not None:
                    self.waited += 1
                return QUEUED
        return self.fast.run_one(ns, float(gyro[0]), float(gyro[1]), float(gyro[2]), kept)

    def add_many(self, ns: np.ndarray, gyro: np.ndarray, accel: np.ndarray) -> None:
        """IMU samples in arrival order, queued for `take_ready`. A clock that went back (a bag loop,
        confirmed as the estimator confirms it) starts the fast path over; the samples still queued
        from before are not published."""
        ns = np.asarray(ns, np.int64)
        if not ns.size:
            return
        if self._ns0 is None:
            self._ns0 = int(ns[0])
        changes = self.guard.time_base_changes
        kept = self.guard.keep((ns - self._ns0) * 1e-9, gyro, accel)
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
        self._pending.append(ns, np.asarray(gyro, float), kept)

    def _queued_kept(self) -> int:
        cols = self._pending.columns()
        return int(np.count_nonzero(cols[2][self._void:])) if cols else 0

    def finish(self) -> None:
        """Nothing more reaches the estimator: every anchor is final, every queued sample ready."""
        self.fast.add_anchors(AnchorRows.empty(), 1 << 62)

    def take_ready(self) -> tuple[int, FastOutput | None]:
        """Outputs for the queued samples whose anchor is final, in arrival order: (how many were
        taken from the queue, their outputs). A sample that had to wait counts in `waited`."""
        if not len(self._pending):
            return 0, None
        ns, gyro, kept = self._pending.columns()
        kept = kept.copy()
        kept[:self._void] = False
        ready = ~kept | self.fast.ready_many(ns)
        n = ns.size if ready.all() else int(np.argmin(ready))
        if n < ns.size and self.fast.anchors is not None:
            self.waited += 1
        if n == 0:
            return 0, None
        self._pending.take(n)
        self._void = max(self._void - n, 0)
        return n, self.fast.run(ns[:n], gyro[:n], kept[:n])

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
        """Offline, what a node does with a chunk: queue its IMU samples, `estimate`, take the ready."""
        self.add_many(ns_at(chunk.imu.t, origin_ns), chunk.imu.gyro, chunk.imu.accel)
        self.estimate(chunk, origin_ns)
        return self.take_ready()[1]
