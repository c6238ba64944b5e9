"""`CompassBlocks`: compass samples in short blocks through the magnetic gate and the heading filter.

Compass samples are grouped in blocks of `block_s` on the estimator's time grid; per block the gate
(magnetic_gate.py) decides open/closed and the heading filter (heading_filter.py) corrects the
output heading while open. Block results take effect at the block end (a causal delay of at most
one block). `heading_at` gives the output heading at IMU stamps from the record in force at each.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from ..angles import wrap_angle
from .heading_filter import HeadingFilter, heading_variance_growth
from .magnetic_gate import MagneticGate
from .reasons import REASON_BIT


@dataclass(frozen=True)
class _Samples:
    """Compass samples waiting for their block to end (M rows)."""
    t: np.ndarray             # s
    z: np.ndarray             # compass - gyro heading, rad (wrapped)
    psi_g: np.ndarray         # gyro heading, rad
    norm: np.ndarray          # |B|, T
    dip: np.ndarray           # rad
    accel: np.ndarray         # | |f| - g |, m/s^2
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
    def __init__(self, gate: MagneticGate, heading: HeadingFilter, block_s: float, heading_correction: bool):
        self.gate = gate
        self.heading = heading
        self.block_s = block_s
        self.heading_correction = heading_correction
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
            self.heading.initialize(float(t[0]), float(z[0]), float(psi_c[0]), compass_var_rad2, float(psi_g[0]))
            self._t_filter = float(t[0])
            self.latest = HeadingRecords.one(float(t[0]), float(z[0]), compass_var_rad2, 0.0, True, 0)
            self._new.append(self.latest)
        if t.size:
            self._waiting.append(_Samples(t, z, psi_g, norm, dip, accel, temp))

    def on_gap(self, var_rad2: float) -> None:
        """A time gap: heading variance inflated, mismatch history reset, next correction at once."""
        self.heading.inflate(var_rad2)
        self.gate.reset_mismatch()
        self._jump = True

    def close(self, t_seen: float, sigma_d: float, compass_var_rad2: float) -> None:
        """Gate and heading filter over every block that ended by `t_seen` (s)."""
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
        self._correct(t_block, z_block, compass_var_rad2 / counts, psi_g_block, res.open, res.reasons, sigma_d)

    def _correct(self, t_block, z_block, z_var, psi_g_block, is_open, reasons, sigma_d) -> None:
        """Heading filter over closed blocks; one output record per block."""
        use = is_open & self.heading_correction
        out = self.heading.run(t_block, z_block, z_var, psi_g_block, use, sigma_d, jump=self._jump)
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
