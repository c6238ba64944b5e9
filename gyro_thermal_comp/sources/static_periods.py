"""Where a record is at rest, in which orientation, and the rotation that levels each rest period.

At rest the accelerometer reads the specific force, which points up (whatever sign convention a
logger's axes have: an axis pointing down reads about -9.8 m/s^2). A 1 s bin is *still* when its
mean specific force points within `STILL_DEG` of the median direction of the minute around it and
its norm is within `STILL_NORM_M_S2` of that minute's median norm (the norm of an uncalibrated
accelerometer is not 9.81, and drifts with temperature: only its steadiness is judged), and its
mean rate is within `STILL_RATE_DEG_S` of the minute's median rate (a turn about the vertical leaves
the specific force where it is; a gyro's bias moves over minutes, a hand turns it in seconds).
Consecutive still bins form a *static period* while their direction stays within `SAME_DEG` of the
period's own; a change of orientation ends it, and so does motion longer than `MAX_BUMP_S` after
which the magnetic field points more than `TURN_DEG` elsewhere in the sensor frame (the unit was
turned about the vertical, which the accelerometer cannot see; a knock or a vibration that leaves
the field where it was does not end a period; without a magnetometer any such motion does).
Periods shorter than `min_static_s` are handling, not periods.

Each period's `levelling_rotation` (frames.py) is the smallest proper rotation that takes its
mean specific force direction to +z: the vertical sensor axis becomes z, and the heading axis the
estimator uses is the vertical one.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import median_filter

from . import frames

BIN_S = 1.0
STILL_DEG = 2.0
STILL_NORM_M_S2 = 0.3
STILL_RATE_DEG_S = 1.0
SAME_DEG = 10.0
MAX_BUMP_S = 10.0
TURN_DEG = 3.0
CONTEXT_BINS = 61
MIN_STATIC_S = 600.0


class RecordBins:
    """Streaming 1 s bin means of a record's specific force, rate and magnetic field."""

    def __init__(self, bin_s: float = BIN_S):
        self.bin_s = bin_s
        self.t0: float | None = None
        self._parts: dict[str, list[tuple[np.ndarray, np.ndarray, np.ndarray]]] = {'accel': [], 'gyro': [], 'mag': []}

    def add(self, chunk) -> None:
        """Add a SensorChunk's imu and mag samples."""
        first = [s.t[0] for s in (chunk.imu, chunk.mag) if s is not None and len(s.t)]
        if not first:
            return
        if self.t0 is None:
            self.t0 = float(min(first))
        if chunk.imu is not None and len(chunk.imu.t):
            self._add('accel', chunk.imu.t, chunk.imu.accel)
            self._add('gyro', chunk.imu.t, chunk.imu.gyro)
        if chunk.mag is not None and len(chunk.mag.t):
            self._add('mag', chunk.mag.t, chunk.mag.field)

    def _add(self, name: str, t: np.ndarray, v: np.ndarray) -> None:
        k = np.floor((t - self.t0) / self.bin_s).astype(np.int64)
        idx, start = np.unique(k, return_index=True)
        self._parts[name].append((idx, np.add.reduceat(v, start, axis=0), np.diff(np.r_[start, len(k)])))

    def finish(self) -> dict[str, np.ndarray]:
        """{'t': bin start times s, 'accel', 'gyro', 'mag': (n, 3) means (NaN where a bin has none)}
        over the bins with IMU samples."""
        if not self._parts['accel']:
            return {'t': np.zeros(0), **{k: np.zeros((0, 3)) for k in self._parts}}
        grid = np.unique(np.concatenate([p[0] for p in self._parts['accel']]))
        out = {'t': self.t0 + grid * self.bin_s}
        for name, parts in self._parts.items():
            mean = np.full((len(grid), 3), np.nan)
            if parts:
                idx = np.concatenate([p[0] for p in parts])
                pos = np.searchsorted(grid, idx)
                ok = (pos < len(grid)) & (grid[np.minimum(pos, len(grid) - 1)] == idx)
                n = np.bincount(pos[ok], weights=np.concatenate([p[2] for p in parts])[ok], minlength=len(grid))
                total = np.column_stack([np.bincount(pos[ok], weights=np.concatenate([p[1][:, j] for p in parts])[ok],
                                                     minlength=len(grid)) for j in range(3)])
                has = n > 0
                mean[has] = total[has] / n[has, None]
            out[name] = mean
        return out


@dataclass(frozen=True)
class StaticPeriod:
    start_s: float            # first still bin, s (source time)
    end_s: float              # end of the last still bin
    up: tuple                 # mean specific force direction (unit), sensor frame
    specific_force_m_s2: float
    still_fraction: float     # of the bins inside the period

    @property
    def duration_s(self) -> float:
        return self.end_s - self.start_s

    def rotation(self) -> np.ndarray:
        return frames.levelling_rotation(self.up)

    def up_angle_deg(self) -> float:
        return frames.up_angle_deg(self.up)


def _angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.degrees(np.arccos(np.clip(np.sum(a * b, axis=-1), -1.0, 1.0)))


def still_bins(accel: np.ndarray, gyro: np.ndarray | None = None) -> np.ndarray:
    """(n,) bool: bins at rest (module docstring); without `gyro` the rate is not judged."""
    if not len(accel):
        return np.zeros(0, bool)
    norm = np.linalg.norm(accel, axis=1)
    d = accel / np.maximum(norm, 1e-12)[:, None]
    size = min(CONTEXT_BINS, len(d) - (1 - len(d) % 2))
    context = median_filter(d, size=(max(1, size), 1), mode='nearest')
    context /= np.maximum(np.linalg.norm(context, axis=1), 1e-12)[:, None]
    norm_context = median_filter(norm, size=max(1, size), mode='nearest')
    still = (_angle_deg(d, context) < STILL_DEG) & (np.abs(norm - norm_context) < STILL_NORM_M_S2)
    if gyro is not None:
        rate_context = median_filter(gyro, size=(max(1, size), 1), mode='nearest')
        still &= np.degrees(np.linalg.norm(gyro - rate_context, axis=1)) < STILL_RATE_DEG_S
    return still


def _direction(v: np.ndarray) -> np.ndarray | None:
    v = v[np.isfinite(v).all(axis=1)]
    if not len(v):
        return None
    m = (v / np.linalg.norm(v, axis=1)[:, None]).mean(axis=0)
    return m / np.linalg.norm(m)


def _turned(mag: np.ndarray | None, still: np.ndarray, before: int, after: int) -> bool:
    """Did the unit turn between still bin `before` and still bin `after`? The field direction in
    the sensor frame over the still minute on each side (a turn about the vertical moves it; the
    accelerometer cannot see it). Without a magnetometer any long motion counts as a turn."""
    if mag is None:
        return True
    lo = np.flatnonzero(still[:before + 1])[-CONTEXT_BINS:]
    hi = np.flatnonzero(still[after:])[:CONTEXT_BINS] + after
    a, b = _direction(mag[lo]), _direction(mag[hi])
    if a is None or b is None:
        return True
    return float(_angle_deg(a, b)) > TURN_DEG


def find_static_periods(bins: dict, *, bin_s: float = BIN_S, min_static_s: float = MIN_STATIC_S) -> list[StaticPeriod]:
    """Static periods of a record from its 1 s bins (`RecordBins.finish`)."""
    t, accel, gyro = bins['t'], bins['accel'], bins['gyro']
    mag = bins.get('mag')
    mag = mag if mag is not None and np.isfinite(mag).all(axis=1).mean() > 0.5 else None
    still = still_bins(accel, gyro)
    d = accel / np.maximum(np.linalg.norm(accel, axis=1), 1e-12)[:, None]
    periods, current, last_still = [], None, None
    for i in np.flatnonzero(still):
        if current is not None:
            ref = current['sum'] / np.linalg.norm(current['sum'])
            moved_s = t[i] - t[last_still] - bin_s
            if _angle_deg(d[i], ref) > SAME_DEG or (moved_s > MAX_BUMP_S and _turned(mag, still, last_still, i)):
                periods.append(current)
                current = None
        if current is None:
            current = {'first': i, 'sum': np.zeros(3), 'fsum': 0.0, 'n': 0}
        current['sum'] += d[i]
        current['fsum'] += float(np.linalg.norm(accel[i]))
        current['n'] += 1
        current['last'] = i
        last_still = i
    if current is not None:
        periods.append(current)
    out = []
    for p in periods:
        start, end = float(t[p['first']]), float(t[p['last']] + bin_s)
        if end - start < min_static_s:
            continue
        up = p['sum'] / np.linalg.norm(p['sum'])
        inside = (t >= start) & (t < end)
        out.append(StaticPeriod(start, end, tuple(float(v) for v in up), p['fsum'] / p['n'],
                                float(still[inside].mean())))
    return out


def rest_up_angle_deg(accel: np.ndarray, gyro: np.ndarray | None = None) -> tuple[float, int]:
    """(angle of +z from the mean still-bin specific force, deg; still bins used) of a record;
    (nan, 0) if it never rests."""
    still = still_bins(accel, gyro)
    if not still.any():
        return math.nan, 0
    d = accel[still] / np.linalg.norm(accel[still], axis=1)[:, None]
    return frames.up_angle_deg(d.mean(axis=0)), int(still.sum())
