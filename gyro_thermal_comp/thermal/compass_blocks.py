"""`CompassBlocks`: compass samples in short blocks through the magnetic gate and the heading filter.

Compass samples are grouped in blocks of `block_s` on the estimator's time grid; per block the gate
(magnetic_gate.py) decides open/closed and the heading filter (heading_filter.py) corrects the
output heading while open. Block results take effect at the block end (a causal delay of at most
one block). `heading_at` gives the output heading at IMU stamps from the record in force at each.

A disturbance that grows slowly is in the compass before the field tests can see it: the drift
windows wait `confirm_s` for that reason (drift_learning.py), and the heading filter must not keep
what it took in meanwhile (0.4-0.8 deg at the start of simulated outages, carried through them).
So when the gate shuts after being open and the field is seen to be disturbed, the filter goes back
to its state `confirm_s` before (snapshots at whole seconds of the block grid) and replays the
blocks since with the compass refused over those `confirm_s`: the coast, and its growing sigma,
start there. Rows already published stand; the output slews to the restored offset. The same in
any chunking. "Seen to be disturbed": the field's strength or dip changed, or the compass turned
while the gyro did not, on a platform that has not turned or manoeuvred for `QUIET_S`, and kept the
gate shut past its hold-off (a lone mismatch is a false alarm: rolling those back on the clean
bundled static bags cost 0.04-0.8 deg of max error). A reopen after a shut in which the field was
seen disturbed is on probation for `probation_s`: the coast has made the heading uncertain, so a
compass that a breathing disturbance holds still for a while can pass for the gyro's (simulated: a
20-deg rotation breathing at 130 s reopened the gate in its valley, and the filter took 9 deg of it
before the field moved again). If the field is seen disturbed again within the probation, the
rollback goes back to the reopen, not only `confirm_s`. A reopen after a false alarm (no rollback
in its shut) is not on probation. On a moving
vehicle the heading-rate test alone also fires on the compass's own errors in manoeuvres (26 of 28
closures on a simulated 30-min drive, where rolling back cost each straight its last seconds of
compass: the error after the first lap rose from 3.7 to 4.6 deg in the median of 5 runs).
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, fields

import numpy as np

from ..angles import wrap_angle
from .heading_filter import HeadingFilter, heading_variance_growth
from .magnetic_gate import MagneticGate
from .reasons import REASON_BIT

# gate reasons that say the field itself changed; the heading-rate test says so only on a quiet platform
FIELD_CHANGED = REASON_BIT['field_norm'] | REASON_BIT['dip_angle']
MISMATCH = REASON_BIT['heading_rate_mismatch']
MOTION = REASON_BIT['turn_rate'] | REASON_BIT['accel_norm']
QUIET_S = 60.0            # no turn or manoeuvre for this long: a compass turning alone is the field, s
SNAPSHOT_BLOCKS = 10      # heading-filter snapshots once per this many blocks of the grid (1 s at 0.1 s)


@dataclass(frozen=True)
class _Samples:
    """Compass samples waiting for their block to end (M rows)."""
    t: np.ndarray             # s
    z: np.ndarray             # compass - gyro heading, rad (wrapped)
    psi_g: np.ndarray         # gyro heading, rad
    norm: np.ndarray          # |B|, T
    dip: np.ndarray           # rad
    accel: np.ndarray         # |f|, m/s^2
    temp: np.ndarray          # degC

    def split(self, n: int) -> tuple['_Samples', '_Samples']:
        cols = [getattr(self, k) for k in _SAMPLE_FIELDS]
        return _Samples(*(v[:n] for v in cols)), _Samples(*(v[n:] for v in cols))

    @staticmethod
    def concat(parts: list['_Samples']) -> '_Samples':
        if len(parts) == 1:
            return parts[0]
        return _Samples(*(np.concatenate([getattr(p, k) for p in parts]) for k in _SAMPLE_FIELDS))


_SAMPLE_FIELDS = tuple(f.name for f in fields(_Samples))   # (dataclasses.fields is slow in a hot path)


@dataclass(frozen=True)
class HeadingRecords:
    """Heading-filter output per block (K rows): in force from t until the next record."""
    t: np.ndarray             # block end, s
    off: np.ndarray           # output heading - gyro heading, rad
    var: np.ndarray           # offset variance, rad^2
    tau: np.ndarray           # coasting time at t, s
    open: np.ndarray          # bool: the compass was used
    reasons: np.ndarray       # int64 reason mask

    @classmethod
    def one(cls, t, off, var, tau, is_open, reasons) -> 'HeadingRecords':
        return cls(np.array([t], dtype=float), np.array([off], dtype=float), np.array([var], dtype=float),
                   np.array([tau], dtype=float), np.array([is_open], dtype=bool),
                   np.array([reasons], dtype=np.int64))

    def last(self) -> 'HeadingRecords':
        return HeadingRecords(*(getattr(self, k)[-1:] for k in _RECORD_FIELDS))

    @staticmethod
    def concat(parts: list['HeadingRecords']) -> 'HeadingRecords':
        if len(parts) == 1:
            return parts[0]
        return HeadingRecords(*(np.concatenate([getattr(p, k) for p in parts]) for k in _RECORD_FIELDS))


_RECORD_FIELDS = tuple(f.name for f in fields(HeadingRecords))


@dataclass(frozen=True)
class HeadingColumns:
    """Output heading at IMU stamps (N rows)."""
    heading: np.ndarray       # rad, wrapped
    sigma: np.ndarray         # rad
    open: np.ndarray          # bool
    reasons: np.ndarray       # int64


class CompassBlocks:
    def __init__(self, gate: MagneticGate, heading: HeadingFilter, block_s: float, heading_correction: bool,
                 confirm_s: float = 0.0, probation_s: float = 0.0):
        self.gate = gate
        self.heading = heading
        self.block_s = block_s
        self.heading_correction = heading_correction
        self.confirm_s = confirm_s              # corrections this recent are undone when the field is disturbed, s
        self.probation_s = probation_s          # ... and all since a reopen after a disturbance this recent, s
        self._t_reopen = -math.inf              # the latest reopen after a disturbance, s
        self._shut_disturbed = False            # a rollback was made in the current shut
        self._recent: deque = deque()           # (t, z, z_var, psi_g, use, |B_h|) of the latest blocks
        self._snaps: deque = deque()            # (t, heading-filter state) at whole snapshot blocks
        self._was_open = False                  # the gate at the latest block
        self._cell = -1                         # grid second of the latest block (snapshots)
        self._pending: float | None = None      # a shut awaiting confirmation (compass turning alone), s
        self._t_motion = -math.inf              # the latest block the gate shut for a turn or manoeuvre, s
        self.rollbacks = 0                      # field disturbances whose lead-in was undone
        self.probation_rollbacks = 0            # ... of them, back to a reopen on probation
        self.t_origin: float | None = None
        self._waiting: list[_Samples] = []      # joined when a block ends (not at every `add`)
        self.closed_until = -np.inf             # end of the latest processed block, s
        self.t_last_closed = -np.inf            # end of the latest gate-closed block, s
        self.coasting_s = 0.0                   # total time with the compass refused, s
        self._t_filter: float | None = None     # heading filter propagated to this time, s
        self._jump = False                      # the next correction moves the output at once
        self.latest = HeadingRecords.one(-np.inf, 0.0, math.pi ** 2, 0.0, False, 0)
        self._new: list[HeadingRecords] = []    # records not yet used by `heading_at`
        self._in_force = self.latest            # the latest record `heading_at` used

    def add(self, t, z, psi_g, psi_c, norm, dip, accel, temp, compass_var_rad2: float) -> None:
        """Compass samples (M,) of one stretch: the first one ever defines the heading."""
        if not self.heading.initialized:
            # the first compass sample defines the heading (and the deviation anchor psi0)
            self.heading.initialize(float(t[0]), float(z[0]), float(psi_c[0]), compass_var_rad2, float(psi_g[0]),
                                    float(norm[0] * math.cos(dip[0])))
            self._t_filter = float(t[0])
            self.latest = HeadingRecords.one(float(t[0]), float(self.heading.x[0]), float(self.heading.P[0, 0]),
                                             0.0, True, 0)
            self._new.append(self.latest)
            # that sample is in the filter now: in its block too, it would count twice
            t, z, psi_g, norm, dip, accel, temp = (v[1:] for v in (t, z, psi_g, norm, dip, accel, temp))
        if t.size:
            self._waiting.append(_Samples(t, z, psi_g, norm, dip, accel, temp))

    def on_gap(self, var_rad2: float) -> None:
        """A time gap: heading variance inflated, mismatch history reset, next correction at once."""
        self.heading.inflate(var_rad2)
        self.gate.reset_mismatch()
        self._jump = True
        self._recent.clear()   # no replay across a gap
        self._snaps.clear()

    def close(self, t_seen: float, sigma_d: float, sigma_heading: float, compass_var_rad2: float) -> None:
        """Gate and heading filter over every block that ended by `t_seen` (s); the drift 1-sigmas
        (rad/s) each uses (drift_sigma.py)."""
        if not self._waiting:
            return
        bs, t0 = self.block_s, self.t_origin
        if t0 + (math.floor((float(self._waiting[0].t[0]) - t0) / bs + 1e-9) + 1) * bs > t_seen:
            return  # the oldest open block has not ended yet
        buf = _Samples.concat(self._waiting)
        block_id = np.floor((buf.t - t0) / bs + 1e-9).astype(np.int64)
        n_done = int(np.count_nonzero(t0 + (block_id + 1) * bs <= t_seen))  # a prefix: time order
        if n_done == 0:
            self._waiting = [buf]
            return
        done, rest = buf.split(n_done)
        self._waiting = [rest] if rest.t.size else []
        # block ids never decrease (time order): block starts without np.unique's sort
        step = np.diff(block_id[:n_done], prepend=block_id[0] - 1)
        if step.min() >= 0:
            first = np.flatnonzero(step)
            ids = block_id[first]
        else:   # (not reached: the waiting samples are in time order)
            ids, first = np.unique(block_id[:n_done], return_index=True)
        counts = np.diff(np.append(first, n_done))

        def mean(a):
            return np.add.reduceat(a, first) / counts
        z_ref = done.z[first]
        z_block = z_ref + np.add.reduceat(np.atleast_1d(wrap_angle(done.z - np.repeat(z_ref, counts))), first) / counts
        t_block = t0 + (ids + 1) * bs
        psi_g_block = mean(done.psi_g)
        res = self.gate.update(t_block, mean(done.norm), mean(done.dip), wrap_angle(psi_g_block + z_block),
                               psi_g_block, mean(done.accel), mean(done.temp), sigma_d,
                               compass_var_rad2=compass_var_rad2 / counts)
        self.closed_until = float(t_block[-1])
        for _, var in self.gate.take_drift_lines():   # before the batch: its blocks up to the line are shut
            if self.heading_correction:
                self.heading.inflate(var)
        b_h_block = mean(done.norm * np.cos(done.dip))   # horizontal field strength, T
        self._correct(t_block, z_block, compass_var_rad2 / counts, psi_g_block, b_h_block, res.open, res.reasons,
                      sigma_heading)

    def _correct(self, t_block, z_block, z_var, psi_g_block, b_h_block, is_open, reasons, sigma_d) -> None:
        """Heading filter over closed blocks; one output record per block."""
        use = is_open & self.heading_correction
        if self.confirm_s > 0:
            out = self._run_confirmed(t_block, z_block, z_var, psi_g_block, b_h_block, use, is_open, reasons, sigma_d)
        else:
            out = self.heading.run(t_block, z_block, z_var, psi_g_block, use, sigma_d, jump=self._jump, b_h_t=b_h_block)
        self._jump = False
        # a refused compass block is coasting for the output heading. The drift windows follow the
        # gate only: after a long coast with a poor drift estimate the heading filter refuses the
        # compass until the drift is re-learned, and that must not wait for the heading filter (the
        # learner has its own innovation test)
        if np.any(~is_open):
            self.t_last_closed = float(t_block[~is_open][-1])
        refused = use & (out[:, 3] == 0.0)
        if np.any(refused):
            reasons = reasons | np.where(refused, REASON_BIT['heading_innovation'], 0)
            is_open = is_open & ~refused
        closed = ~is_open
        if np.any(closed):
            dts = np.diff(np.concatenate(([self._t_filter], t_block)))
            self.coasting_s += float(np.sum(dts[closed]))
        self._t_filter = float(t_block[-1])
        records = HeadingRecords(t_block, out[:, 0], out[:, 1], out[:, 2], is_open, reasons)
        self._new.append(records)
        self.latest = records.last()

    def _run_confirmed(self, t, z, z_var, psi_g, b_h, use, is_open, reasons, sigma_d) -> np.ndarray:
        """The heading filter over the blocks, cut where a snapshot is due (after the block) and
        where a rollback is (before the block)."""
        m = t.size
        z_var = np.broadcast_to(np.asarray(z_var, dtype=float), (m,))
        # a snapshot after the first block of each grid second that has one (a 5 Hz compass fills
        # only some blocks)
        cells = np.rint((t - self.t_origin) / self.block_s).astype(np.int64) // SNAPSHOT_BLOCKS
        snap_after = np.flatnonzero(cells != np.concatenate(([self._cell], cells[:-1]))) + 1
        rollbacks = self._rollbacks_due(t, is_open, reasons)
        cuts = np.unique(np.concatenate(([0, m], snap_after, np.fromiter(rollbacks, np.int64))))
        out = np.empty((m, 4))
        snap_set = set(snap_after.tolist())
        for a, b in zip(cuts[:-1], cuts[1:]):
            if a in rollbacks:
                self._rollback(*rollbacks[a], float(t[a]), sigma_d)
            out[a:b] = self.heading.run(t[a:b], z[a:b], z_var[a:b], psi_g[a:b], use[a:b], sigma_d,
                                        jump=self._jump and a == 0, b_h_t=b_h[a:b])
            self._recent.extend(zip(t[a:b].tolist(), z[a:b].tolist(), z_var[a:b].tolist(), psi_g[a:b].tolist(),
                                    use[a:b].tolist(), b_h[a:b].tolist()))
            if b in snap_set:
                self._snaps.append((float(t[b - 1]), self.heading.state()))
        self._cell = int(cells[-1])
        keep = min(float(t[-1]), self._pending if self._pending is not None else math.inf) - self.confirm_s
        if float(t[-1]) - self._t_reopen <= self.probation_s:
            keep = min(keep, self._t_reopen)   # a reopen on probation may still be undone
        keep -= 2.0 * SNAPSHOT_BLOCKS * self.block_s
        while self._recent and self._recent[0][0] < keep:
            self._recent.popleft()
        while len(self._snaps) > 1 and self._snaps[1][0] <= keep:
            self._snaps.popleft()
        return out

    def _rollbacks_due(self, t, is_open, reasons) -> dict[int, tuple[float, bool]]:
        """{block index: (the time from which the compass is refused, back to a reopen on
        probation?)} for the rollbacks to make before those blocks: `confirm_s` before the gate
        shut, or the reopen on probation. A changed field strength or dip is one at once; the
        compass turning alone on a quiet platform is one if it keeps the gate shut past the hold-off
        (a lone mismatch block, then the hold-off: a false alarm, on the bundled static bags 2-3
        times in 2 h)."""
        was_open = np.concatenate(([self._was_open], is_open[:-1]))
        moving = (reasons & MOTION) != 0
        last_motion = np.maximum.accumulate(np.where(moving, t, self._t_motion))   # at or before each block
        quiet = t - np.concatenate(([self._t_motion], last_motion[:-1])) > QUIET_S
        self._t_motion = float(last_motion[-1])
        self._was_open = bool(is_open[-1])
        starts = np.flatnonzero(was_open & ~is_open)
        # the first block that can matter: a shut, a pending one, or the reopen after a disturbance
        first = min(int(starts[0]) if starts.size else t.size, 0 if self._pending is not None else t.size)
        if self._shut_disturbed:
            reopens = np.flatnonzero(~was_open & is_open)
            first = min(first, int(reopens[0]) if reopens.size else t.size)
        if first == t.size:
            return {}
        changed = (reasons & FIELD_CHANGED) != 0
        active = (reasons & (FIELD_CHANGED | MISMATCH)) != 0
        mismatch_alone = ((reasons & MISMATCH) != 0) & quiet & ~moving
        due, pending = {}, self._pending
        t_reopen, disturbed = self._t_reopen, self._shut_disturbed
        for b in range(first, t.size):
            if was_open[b] and not is_open[b]:
                pending, disturbed = (float(t[b]) if (changed[b] or mismatch_alone[b]) else None), False
                if changed[b]:
                    due[b], pending, disturbed = self._cut(pending, t_reopen), None, True
            elif is_open[b] and not was_open[b]:
                if disturbed:   # this reopen is on probation
                    t_reopen = float(t[b])
                pending, disturbed = None, False
            elif pending is not None:
                if moving[b]:
                    pending = None
                elif changed[b] or (active[b] and t[b] - pending > self.gate.cfg.holdoff_s):
                    due[b], pending, disturbed = self._cut(pending, t_reopen), None, True
        self._pending, self._t_reopen, self._shut_disturbed = pending, t_reopen, disturbed
        return due

    def _cut(self, t_shut: float, t_reopen: float) -> tuple[float, bool]:
        """Refuse the compass from here (s): `confirm_s` before the shut, or the reopen on probation."""
        cut = t_shut - self.confirm_s
        on_probation = t_shut - t_reopen <= self.probation_s and t_reopen < cut
        return (t_reopen if on_probation else cut), on_probation

    def _rollback(self, cut: float, on_probation: bool, t_now: float, sigma_d: float) -> None:
        """Back to the latest snapshot at or before `cut` (s), the blocks since (to `t_now`)
        replayed without the compass from `cut` on; the output offset stays where it is."""
        older = [snap for snap in self._snaps if snap[0] <= cut]
        if not older:
            return
        t_snap, state = older[-1]
        out_off = self.heading.out_off
        self.heading.restore(state)
        replay = [r for r in self._recent if t_snap < r[0] < t_now]
        if replay:
            t, z, z_var, psi_g, use, b_h = (np.array(c) for c in zip(*replay))
            self.heading.run(t, z, z_var, psi_g, use & (t < cut), sigma_d, b_h_t=b_h)
        self.heading.out_off = out_off
        self.rollbacks += 1
        self.probation_rollbacks += int(on_probation)

    def heading_at(self, t: np.ndarray, psi_g: np.ndarray, arw_rad_sqrt_s: float, sigma_d: float) -> HeadingColumns:
        """Output heading at IMU stamps (s) from the record in force at each, its uncertainty grown
        since (docs/design.md eq. 13)."""
        if not self._new and t.size and t[0] >= self._in_force.t[0] > -np.inf:
            r = self._in_force  # no new record: one record for all stamps (the live path)
            var = r.var[0] + heading_variance_growth(arw_rad_sqrt_s, sigma_d, r.tau[0], t - r.t[0])
            var = np.fmin(var, math.pi ** 2)   # var >= 0: NaN or inf -> pi^2 too
            is_open, reasons = bool(r.open[0]), int(r.reasons[0])
            return HeadingColumns(wrap_angle(psi_g + r.off[0]), np.sqrt(var),
                                  (np.ones if is_open else np.zeros)(t.size, dtype=bool),
                                  np.full(t.size, reasons, dtype=np.int64) if reasons else np.zeros(t.size, np.int64))
        # the latest record already in force, then those added since
        rec = HeadingRecords.concat([self._in_force] + self._new)
        idx = np.searchsorted(rec.t, t, side='right') - 1  # records at or before each stamp
        have = idx >= 0
        j = np.maximum(idx, 0)
        t_rec = rec.t[j]
        finite = np.isfinite(t_rec)
        age = np.where(have & finite, np.maximum(t - np.where(finite, t_rec, 0.0), 0.0), 0.0)
        var = rec.var[j] + heading_variance_growth(arw_rad_sqrt_s, sigma_d, rec.tau[j], age)
        var = np.where(have, np.fmin(var, math.pi ** 2), math.pi ** 2)   # var >= 0: NaN or inf -> pi^2 too
        self._new = []
        self._in_force = self.latest  # later stamps only need the latest record
        return HeadingColumns(np.atleast_1d(wrap_angle(psi_g + np.where(have, rec.off[j], 0.0))), np.sqrt(var),
                              rec.open[j].astype(bool) & have, np.where(have, rec.reasons[j], 0).astype(np.int64))
