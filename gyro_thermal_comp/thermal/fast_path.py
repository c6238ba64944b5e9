"""`FastPath`: each IMU sample compensated and its heading advanced the moment it arrives (no ROS).

The estimator (`ThermalDriftEstimator`, the slow path) needs every topic in stamp order, so it runs
behind the newest IMU sample by the slowest topic's period plus transport (100 ms for a 10 Hz
temperature). A node cannot make its IMU output wait for that. So the output is computed here from
the slow path's state at an earlier stamp, the *anchor*:

    anchor of a sample at stamp t = the slow path's latest accepted IMU row at or before t - delay

(integer ns, so the choice never depends on a float's rounding or on the time origin). Which state
compensates a sample is decided by stamps alone, never by when the slow path happened to run: a
model update (a window ending at t_w) reaches the output at t_w + delay. A live node must only hold
a sample until the slow path has processed up to t - delay (`SlowPathProgress`), which with the
default 1 s delay it has always done; an offline run has done it for the whole chunk. Both then
give the same numbers (to the last bits of the elementwise operations).

From the anchor row j, for sample i (age = t_i - t_j, clipped to `max_hold_s`):
  D_i   = d0_j + d_dot_j * age + k_j * w_z,i     drift: the temperature held with its trend (dT/dt);
                                                 k_j: the scale-factor terms' weight on the rate
  w_c,i = (w_x - b_x,j, w_y - b_y,j, w_z - D_i)
  psi_i = heading_j + (Psi_i - Psi(t_j))         Psi: this path's own integral of g_tilt_j w_c,z - earth
  var_i = heading_var_j + arw^2 * age            the age of the compass correction it starts from
Held from j: roll, pitch and any other columns the caller adds (variances, gate state).
Before the first anchor exists nothing is ready; samples earlier than the first anchor's stamp
plus the delay take the first anchor.
"""
from __future__ import annotations

import bisect
import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from ..angles import wrap_angle
from .sampling import SamplePeriod

NS_PER_S = 1_000_000_000


@dataclass(frozen=True)
class AnchorRows:
    """The slow path's state at its accepted IMU samples (N rows, stamp order)."""
    ns: np.ndarray            # (N,) int64 stamps, ns
    d0: np.ndarray            # (N,) drift at zero rate, rad/s
    d_dot: np.ndarray         # (N,) its trend from dT/dt, rad/s^2
    k_rate: np.ndarray        # (N,) drift per rad/s of measured z rate (scale-factor terms), 1
    bias_xy: np.ndarray       # (N, 2) x, y gyro biases, rad/s
    heading: np.ndarray       # (N,) rad (compass-corrected output heading)
    heading_var: np.ndarray   # (N,) rad^2
    g_tilt: np.ndarray        # (N,) heading rate per z rate, cos(roll) / cos(pitch)
    held: dict = field(default_factory=dict)   # name -> (N, ...) columns passed to the output as is

    def __len__(self) -> int:
        return self.ns.size

    @classmethod
    def empty(cls) -> 'AnchorRows':
        return cls(np.empty(0, np.int64), *(np.empty(0) for _ in range(3)), np.empty((0, 2)),
                   *(np.empty(0) for _ in range(3)))

    def take(self, idx) -> 'AnchorRows':
        return AnchorRows(*(getattr(self, n)[idx] for n in _COLUMNS),
                          held={k: v[idx] for k, v in self.held.items()})

    @classmethod
    def concat(cls, parts: list['AnchorRows']) -> 'AnchorRows':
        parts = [p for p in parts if p is not None]
        if len(parts) == 1:
            return parts[0]
        return cls(*(np.concatenate([getattr(p, n) for p in parts]) for n in _COLUMNS),
                   held={k: np.concatenate([p.held[k] for p in parts]) for k in parts[0].held})


_COLUMNS = ('ns', 'd0', 'd_dot', 'k_rate', 'bias_xy', 'heading', 'heading_var', 'g_tilt')


def anchor_rows(ns: np.ndarray, gyro: np.ndarray, out, held: dict | None = None) -> AnchorRows:
    """Anchors from a `ThermalOutput` of the estimator and the raw gyro rows (rad/s) it came from;
    dropped input rows are left out. The drift splits exactly as the slow path applied it:
    d0 + k w_z = D_hat at the row, with k and the trend the estimator gave for the row (its model
    inputs: die temperature, branch, ... stay inside it)."""
    # a row with anything unknown is no anchor (the node never publishes NaN, e.g. before any temperature)
    ok = np.asarray(out.valid, bool) & np.all(np.isfinite(gyro), axis=1) & np.isfinite(out.track.heading_rad) & \
        np.all(np.isfinite(out.gyro_compensated), axis=1) & np.isfinite(out.track.drift_rad_s)
    k, d_dot = out.drift_per_rate, out.drift_trend_rad_s2   # 0 in the still period (its running mean)
    roll, pitch = out.roll_rad, out.pitch_rad
    rows = AnchorRows(ns=np.asarray(ns, np.int64), d0=out.track.drift_rad_s - k * gyro[:, 2], d_dot=d_dot, k_rate=k,
                      bias_xy=gyro[:, :2] - out.gyro_compensated[:, :2], heading=out.track.heading_rad,
                      heading_var=np.square(out.track.heading_sigma_rad),
                      g_tilt=np.cos(np.nan_to_num(roll)) / np.cos(np.nan_to_num(pitch)), held=dict(held or {}))
    return rows.take(ok)


@dataclass(frozen=True)
class FastOutput:
    """Per IMU sample given to `FastPath.run` (n rows); rows with ok False must not be published."""
    ns: np.ndarray            # (n,) int64 stamps, as given
    ok: np.ndarray            # (n,) bool: finite, after the previous sample, an anchor exists
    gyro_compensated: np.ndarray   # (n, 3) rad/s
    heading: np.ndarray       # (n,) rad, wrapped
    heading_var: np.ndarray   # (n,) rad^2
    anchor_ns: np.ndarray     # (n,) int64, stamp of the anchor row used (-1: none)
    held: dict                # name -> (n, ...) columns of the anchor rows


class FastPath:
    """Per-sample output from the slow path's anchors (module docstring). `add_anchors` as the slow
    path produces rows, `run` on IMU samples in arrival order once `ready` says they are."""

    def __init__(self, delay_s: float, max_gap_s: float, earth_rate_up_rad_s: float, arw_rad_sqrt_s: float,
                 max_hold_s: float = 10.0):
        self.delay_ns = int(round(delay_s * NS_PER_S))
        self.max_gap_s = float(max_gap_s)
        self.earth_rate_up = float(earth_rate_up_rad_s)
        self.arw2 = float(arw_rad_sqrt_s) ** 2
        self.max_hold_s = float(max_hold_s)
        self.dropped = 0                 # samples not published: NaN, dropped by a guard, stamp not after
        self.reset()

    def reset(self) -> None:
        """Forget everything stamped (a clock that jumped back starts a new time base)."""
        self.anchors: AnchorRows | None = None
        self.processed_ns = -1 << 62     # the slow path has processed every IMU row stamped up to here
        self._hist_ns: list[int] = []    # this path's own samples: stamp, integral Psi (rad)
        self._hist_psi: list[float] = []
        self._last_ns = -1 << 62
        self._psi = 0.0
        self._period = SamplePeriod()    # this path's sampling period (gaps, as the slow path's)

    def add_anchors(self, rows: AnchorRows, processed_ns: int) -> None:
        """Slow-path rows (stamp order) and how far it has processed, ns (its newest IMU row's stamp,
        accepted or not). A stamp before the newest anchor means its clock went back: start over."""
        if len(rows) and self.anchors is not None and len(self.anchors) and rows.ns[0] <= self.anchors.ns[-1]:
            self.reset()
        if len(rows):
            self.anchors = rows if self.anchors is None else AnchorRows.concat([self.anchors, rows])
        self.processed_ns = max(self.processed_ns, int(processed_ns))

    def ready(self, ns: int) -> bool:
        """Whether the anchor of a sample stamped `ns` is final (nothing earlier can still come)."""
        return self.anchors is not None and len(self.anchors) > 0 and \
            self.processed_ns >= max(ns - self.delay_ns, int(self.anchors.ns[0]))

    def ready_many(self, ns: np.ndarray) -> np.ndarray:
        """`ready` for an array of stamps, ns."""
        if self.anchors is None or not len(self.anchors):
            return np.zeros(np.shape(ns), bool)
        return self.processed_ns >= np.maximum(np.asarray(ns, np.int64) - self.delay_ns, self.anchors.ns[0])

    def run(self, ns: np.ndarray, gyro: np.ndarray, keep: np.ndarray | None = None) -> FastOutput:
        """Outputs for IMU samples (stamps ns int64, rates rad/s (n, 3)) in arrival order, all ready;
        `keep` False: a sample an input guard dropped (not published, no effect). `run_one` is the
        same for one sample, in Python floats (a live node's per-sample cost)."""
        ns = np.asarray(ns, np.int64)
        n = ns.size
        finite = np.all(np.isfinite(gyro), axis=1) & (True if keep is None else keep)
        # newest stamp of an earlier finite sample: the same test sample by sample or in one batch
        prev = np.maximum.accumulate(np.concatenate(([self._last_ns], np.where(finite, ns, self._last_ns))))[:-1]
        ok = (ns > prev) & finite & (self.anchors is not None)
        self.dropped += int(np.count_nonzero(~ok))
        if self.anchors is None or not np.any(ok):
            return _empty(ns, self.anchors)
        a = self.anchors
        k = np.maximum(np.searchsorted(a.ns, ns - self.delay_ns, side='right') - 1, 0)
        age = np.clip((ns - a.ns[k]) * 1e-9, 0.0, self.max_hold_s)
        d = a.d0[k] + a.d_dot[k] * age + a.k_rate[k] * gyro[:, 2]
        wc = np.column_stack((gyro[:, :2] - a.bias_xy[k], gyro[:, 2] - d))
        # integral of the heading rate over this path's own accepted samples (none across a gap)
        t_ok = ns[ok]
        dt = np.diff(np.concatenate(([self._last_ns], t_ok))) * 1e-9
        first = self._last_ns == -1 << 62   # the first sample's dt, from the sentinel: no interval
        dt[int(first):][self._period.gaps(dt[int(first):], self.max_gap_s)] = 0.0
        if first:
            dt[0] = 0.0
        step = (a.g_tilt[k[ok]] * wc[ok, 2] - self.earth_rate_up) * dt
        psi_ok = np.cumsum(np.concatenate(([self._psi], step)))[1:]
        self._hist_ns += t_ok.tolist()
        self._hist_psi += psi_ok.tolist()
        hist_ns = np.array(self._hist_ns, np.int64)
        # Psi at the anchor's stamp; before the first anchor, at the sample itself (only samples
        # up to this one are known, whether they come one by one or in a batch)
        j = np.maximum(np.searchsorted(hist_ns, np.minimum(a.ns[k[ok]], t_ok), side='right') - 1, 0)
        heading = np.zeros(n)
        heading[ok] = wrap_angle(a.heading[k[ok]] + psi_ok - np.array(self._hist_psi)[j])
        var = a.heading_var[k] + self.arw2 * age
        self._last_ns, self._psi = int(t_ok[-1]), float(psi_ok[-1])
        self._trim(int(k[ok][-1]))
        return FastOutput(ns=ns, ok=ok, gyro_compensated=wc, heading=heading, heading_var=var,
                          anchor_ns=np.where(ok, a.ns[k], -1), held={name: col[k] for name, col in a.held.items()})

    def run_one(self, ns: int, gx: float, gy: float, gz: float, keep: bool = True):
        """`run` for one sample: None if it is not published, else (anchor index into `anchors`,
        compensated x, y, z rad/s, heading rad, heading variance rad^2). The same operations in the
        same order as `run`, so the same numbers."""
        if not (keep and math.isfinite(gx) and math.isfinite(gy) and math.isfinite(gz)) \
                or ns <= self._last_ns or self.anchors is None:
            self.dropped += 1
            return None
        a = self.anchors
        k = max(int(np.searchsorted(a.ns, ns - self.delay_ns, side='right')) - 1, 0)
        a_ns = int(a.ns[k])
        age = min(max((ns - a_ns) * 1e-9, 0.0), self.max_hold_s)
        d = float(a.d0[k]) + float(a.d_dot[k]) * age + float(a.k_rate[k]) * gz
        wx, wy, wz = gx - float(a.bias_xy[k, 0]), gy - float(a.bias_xy[k, 1]), gz - d
        if self._last_ns == -1 << 62:
            dt = 0.0
        else:
            dt = (ns - self._last_ns) * 1e-9
            if self._period.gap_one(dt, self.max_gap_s):
                dt = 0.0
        psi = self._psi + (float(a.g_tilt[k]) * wz - self.earth_rate_up) * dt
        self._hist_ns.append(ns)
        self._hist_psi.append(psi)
        j = max(bisect.bisect_right(self._hist_ns, min(a_ns, ns)) - 1, 0)
        heading = wrap_angle(float(a.heading[k]) + psi - self._hist_psi[j])
        var = float(a.heading_var[k]) + self.arw2 * age
        self._last_ns, self._psi = ns, psi
        if self._trim(k):
            k = 0
        return k, wx, wy, wz, heading, var

    def _trim(self, k_last: int) -> bool:
        """Drop anchors before the one in force (index k_last) and this path's samples before the
        last one at or before it: a later sample's anchor can only be that one or newer. Done in
        steps (what is kept beyond that changes no result). True if the anchors were cut."""
        cut = k_last > _TRIM_ROWS
        if cut:
            self.anchors = self.anchors.take(slice(k_last, None))
        if len(self._hist_ns) > 2 * _TRIM_ROWS:
            keep = max(bisect.bisect_right(self._hist_ns, int(self.anchors.ns[0])) - 1, 0)
            if keep > _TRIM_ROWS:
                del self._hist_ns[:keep], self._hist_psi[:keep]
        return cut


_TRIM_ROWS = 2048


def _empty(ns: np.ndarray, anchors: AnchorRows | None) -> FastOutput:
    n = ns.size
    held = {} if anchors is None else {k: np.zeros((n,) + v.shape[1:], v.dtype) for k, v in anchors.held.items()}
    return FastOutput(ns=ns, ok=np.zeros(n, bool), gyro_compensated=np.zeros((n, 3)), heading=np.zeros(n),
                      heading_var=np.zeros(n), anchor_ns=np.full(n, -1, np.int64), held=held)


class RowQueue:
    """FIFO of rows kept as blocks of column arrays (a sample at a time live, a chunk at a time in
    replay): `append` a block, `take(n)` the first n rows, `columns()` everything queued."""

    def __init__(self):
        self._blocks: deque = deque()
        self._n = 0

    def __len__(self) -> int:
        return self._n

    def append(self, *cols) -> None:
        if len(cols[0]):
            self._blocks.append(cols)
            self._n += len(cols[0])

    def columns(self) -> tuple:
        if len(self._blocks) != 1:
            self._blocks = deque([tuple(np.concatenate(c) for c in zip(*self._blocks))] if self._blocks else [])
        return self._blocks[0] if self._blocks else ()

    def take(self, n: int) -> tuple:
        cols = self.columns()
        self._blocks.clear()
        if n < self._n:
            self._blocks.append(tuple(c[n:] for c in cols))
        self._n -= n
        return tuple(c[:n] for c in cols)
