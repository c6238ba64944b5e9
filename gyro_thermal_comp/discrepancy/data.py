"""Stream a bag (or SensorChunks) into regular time bins: the only data the discrepancy workflow fits.

Hour-long bags at 100 Hz-1 kHz are far too many samples to fit candidate models to one by one, and
most of each sample is white noise. Every `bin_s` (1 s) bin keeps:

* the mean raw gyro and accelerometer (rad/s, m/s^2, sensor frame) and the IMU stamp span;
* the bin's own white-noise estimate: the within-bin sample variance of (gyro - reference rate),
  pooled over the record per axis (`gyro_noise_var`), so a bin mean of n samples has variance
  `gyro_noise_var / n` whatever the model; significance tests and noise-debiased RMS use it;
* the mean temperature reading (degC);
* with `reference='odom'`: the truth body rate as the bin mean over the IMU sample span (through
  the running integral of the rate, so the same bins can be re-formed for a time-shifted reference),
  the Earth-north direction in the sensor frame, and, when a
  magnetometer is present, the mean compass-minus-truth heading (tilt compensated with the truth
  roll/pitch) and its within-bin variance.

Never read: /ground_truth/gyro_bias, /sim/config (a real bag has neither). Everything is vectorised
per chunk (numpy bincount); Python loops run over chunks only.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable

import numpy as np
from scipy import stats
from scipy.interpolate import CubicSpline

from ..angles import euler_from_quat, rotation_matrix_from_quat, wrap_angle
from ..samples import SensorChunk
from ..thermal.compass import compass_heading

REFERENCES = ('static', 'odom')
# reference 'static' refuses a record whose gyro turns: bins this far (deg/s, or 10 bin-noise sigmas
# if more) from their running median (MOTION_WINDOW_S), in more than MOTION_SHARE of the bins. A
# thermal drift changes by far less within a minute; a turning vehicle by tens of deg/s.
MOTION_RATE_DPS = 1.0
MOTION_WINDOW_S = 61.0
MOTION_SHARE = 0.01
STREAMS = ('imu', 'temperature', 'mag', 'odom')   # what the workflow reads; truth drift never
_THETA_RATE_HZ = 25.0   # the rate integral is stored at about this rate (smooth: cubic interpolation)


class DiscoveryInputError(ValueError):
    """Input the workflow cannot use (no IMU, no temperature, no odom for reference='odom')."""


@dataclass
class BinnedData:
    """Regular bins of `bin_s` from `t0` (bag time of the first message). Empty bins have n_imu 0."""
    reference: str
    bin_s: float
    t0: float
    t: np.ndarray              # (N,) bin centres, s since t0
    n_imu: np.ndarray          # (N,) IMU samples per bin
    gyro: np.ndarray           # (N, 3) mean raw gyro, rad/s
    accel: np.ndarray          # (N, 3) mean specific force, m/s^2
    t_first: np.ndarray        # (N,) first / last IMU stamp in the bin, s since t0
    t_last: np.ndarray
    imu_dt: float              # nominal IMU sample interval, s
    gyro_noise_var: np.ndarray  # (3,) white-noise variance of one IMU sample, (rad/s)^2
    temp_c: np.ndarray         # (N,) mean temperature reading, degC (NaN: none in the bin)
    n_temp: np.ndarray
    has_odom: bool = False
    ref_rate: np.ndarray | None = None      # (N, 3) truth body rate over the IMU span, rad/s
    theta_t: np.ndarray | None = None       # (M,) s since t0 ...
    theta: np.ndarray | None = None         # (M, 3) ... running integral of the truth rate, rad
    earth_north: np.ndarray | None = None   # (N, 3) unit north vector in the sensor frame
    has_compass: bool = False
    n_mag: np.ndarray | None = None
    compass: np.ndarray | None = None       # (N,) mean wrap(psi_compass - psi_truth), rad
    compass_heading: np.ndarray | None = None  # (N,) truth heading at the mag stamps, rad (wrapped)
    compass_noise_var: float = float('nan')  # variance of one compass heading sample, rad^2
    mag_norm_t: np.ndarray | None = None    # (N,) mean |B|, T
    notes: list = field(default_factory=list)
    _spline: object = None

    @property
    def valid(self) -> np.ndarray:
        """Bins with IMU samples (and, for the odom reference, a truth rate)."""
        ok = self.n_imu > 0
        if self.reference == 'odom':
            ok &= np.isfinite(self.ref_rate).all(axis=1)
        return ok

    @property
    def duration_s(self) -> float:
        v = np.flatnonzero(self.n_imu > 0)
        return float(self.t[v[-1]] - self.t[v[0]] + self.bin_s) if v.size else 0.0

    def gyro_bin_var(self) -> np.ndarray:
        """(N, 3) white-noise variance of each bin mean, (rad/s)^2 (inf for empty bins)."""
        n = np.where(self.n_imu > 0, self.n_imu, np.nan)
        return np.nan_to_num(self.gyro_noise_var[None, :] / n[:, None], nan=np.inf)

    def compass_bin_var(self) -> np.ndarray:
        n = np.where(self.n_mag > 0, self.n_mag, np.nan)
        return np.nan_to_num(self.compass_noise_var / n, nan=np.inf)

    def reference_rate(self, shift_s: float = 0.0) -> np.ndarray:
        """(N, 3) truth rate averaged over each bin's IMU span, evaluated `shift_s` earlier: the bin
        mean of w(t - shift) that a gyro whose samples are stamped `shift_s` late would see."""
        if not self.has_odom:
            return np.zeros((len(self.t), 3))
        if shift_s == 0.0 and self.ref_rate is not None:
            return self.ref_rate
        return self._span_mean(shift_s)

    def _span_mean(self, shift_s: float) -> np.ndarray:
        if self._spline is None:
            self._spline = CubicSpline(self.theta_t, self.theta, axis=0, extrapolate=True)
        h = self.imu_dt
        lo = self.t_first - 0.5 * h - shift_s
        hi = self.t_last + 0.5 * h - shift_s
        ok = (self.n_imu > 0) & (lo >= self.theta_t[0] - h) & (hi <= self.theta_t[-1] + h)
        out = np.full((len(self.t), 3), np.nan)
        if np.any(ok):
            out[ok] = (self._spline(hi[ok]) - self._spline(lo[ok])) / (hi[ok] - lo[ok])[:, None]
        return out


class _BinSums:
    """Per-bin accumulator of one quantity (sums, counts or extrema) that grows with the record:
    (bins,) for a scalar, (bins, width) for a vector; bins never touched hold `fill`."""

    def __init__(self, width: int = 0, fill: float = 0.0):
        self.fill = fill
        self.values = np.full((0, width) if width else (0,), fill)

    def _ensure(self, n: int):
        size = self.values.shape[0]
        if n <= size:
            return
        new = np.full((max(n, 2 * size, 1024),) + self.values.shape[1:], self.fill)
        new[:size] = self.values
        self.values = new

    def add(self, idx: np.ndarray, values: np.ndarray | None = None):
        """Sum `values` (N,) or (N, w) (ones if None) into bins `idx` (non-negative ints)."""
        if idx.size == 0:
            return
        lo, hi = int(idx.min()), int(idx.max())
        self._ensure(hi + 1)
        local = idx - lo
        a = self.values
        if values is None:
            a[lo:hi + 1] += np.bincount(local, minlength=hi - lo + 1)
        elif values.ndim == 1:
            a[lo:hi + 1] += np.bincount(local, weights=values, minlength=hi - lo + 1)
        else:
            for j in range(values.shape[1]):
                a[lo:hi + 1, j] += np.bincount(local, weights=values[:, j], minlength=hi - lo + 1)

    def extreme(self, idx: np.ndarray, values: np.ndarray, fn):
        """Fold `values` into bins `idx` with the ufunc `fn` (np.minimum, np.maximum)."""
        if idx.size == 0:
            return
        self._ensure(int(idx.max()) + 1)
        fn.at(self.values, idx, values)

    def take(self, n: int | None = None) -> np.ndarray:
        """A copy of the first n bins (default: every bin allocated so far)."""
        n = self.values.shape[0] if n is None else n
        self._ensure(n)
        return self.values[:n].copy()


def _vector_sums() -> _BinSums:
    return _BinSums(width=3)


@dataclass
class _BinAccumulators:
    """What `_Binner` sums per bin."""
    n_imu: _BinSums = field(default_factory=_BinSums)           # IMU samples
    gyro: _BinSums = field(default_factory=_vector_sums)         # raw gyro, rad/s
    accel: _BinSums = field(default_factory=_vector_sums)        # specific force, m/s^2
    rate_dev: _BinSums = field(default_factory=_vector_sums)     # gyro - reference rate - a fixed offset
    rate_dev_sq: _BinSums = field(default_factory=_vector_sums)  # ... squared (within-bin variance)
    t_first: _BinSums = field(default_factory=lambda: _BinSums(fill=np.inf))    # first IMU stamp - t0
    t_last: _BinSums = field(default_factory=lambda: _BinSums(fill=-np.inf))    # last IMU stamp - t0
    n_temp: _BinSums = field(default_factory=_BinSums)          # temperature readings
    temp: _BinSums = field(default_factory=_BinSums)            # degC
    n_odom: _BinSums = field(default_factory=_BinSums)          # truth samples
    north: _BinSums = field(default_factory=_vector_sums)        # ENU north in the sensor frame
    n_mag: _BinSums = field(default_factory=_BinSums)           # magnetometer samples
    compass_err: _BinSums = field(default_factory=_BinSums)     # wrap(compass - truth heading - offset), rad
    compass_err_sq: _BinSums = field(default_factory=_BinSums)
    heading_sin: _BinSums = field(default_factory=_BinSums)     # sin / cos of the truth heading at the
    heading_cos: _BinSums = field(default_factory=_BinSums)     # magnetometer stamps
    mag_norm: _BinSums = field(default_factory=_BinSums)        # |B|, T


class _OdomTrack:
    """Recent truth samples for interpolation at IMU / magnetometer stamps, plus the running
    integral of the body rate (stored decimated for time-shifted bin means)."""

    def __init__(self):
        self.t = np.empty(0)
        self.rate = np.empty((0, 3))
        self.yaw = np.empty(0)
        self.roll = np.empty(0)
        self.pitch = np.empty(0)
        self.theta_last = np.zeros(3)
        self.theta_t: list[np.ndarray] = []
        self.theta: list[np.ndarray] = []
        self.stride = None
        self.count = 0

    @property
    def covered_until(self) -> float:
        return float(self.t[-1]) if self.t.size else -np.inf

    def extend(self, t, quat, rate):
        roll, pitch, yaw = euler_from_quat(quat)
        prev_yaw = self.yaw[-1] if self.yaw.size else None
        if prev_yaw is not None:
            yaw = np.unwrap(np.concatenate(([prev_yaw], yaw)))[1:]
        else:
            yaw = np.unwrap(yaw)
        # running integral of the rate (trapezoid), continued from the previous chunk
        if self.t.size:
            tt = np.concatenate(([self.t[-1]], t))
            rr = np.concatenate((self.rate[-1:], rate))
        else:
            tt, rr = t, rate
        steps = 0.5 * (rr[1:] + rr[:-1]) * np.diff(tt)[:, None]
        theta = np.concatenate((self.theta_last[None, :], self.theta_last + np.cumsum(steps, axis=0)))
        if self.t.size:
            theta = theta[1:]
        if theta.shape[0]:
            self.theta_last = theta[-1]
        if self.stride is None and t.size > 1:
            dt = float(np.median(np.diff(t)))
            self.stride = max(1, int(round(1.0 / (_THETA_RATE_HZ * dt)))) if dt > 0 else 1
        stride = self.stride or 1
        keep = (np.arange(self.count, self.count + t.size) % stride) == 0
        if t.size:
            keep[-1] = True   # chunk ends too: the spline then spans every stamp we have
        self.theta_t.append(t[keep])
        self.theta.append(theta[keep])
        self.count += t.size
        # short interpolation buffer
        self.t = np.concatenate((self.t, t))
        self.rate = np.concatenate((self.rate, rate))
        self.yaw = np.concatenate((self.yaw, yaw))
        self.roll = np.concatenate((self.roll, roll))
        self.pitch = np.concatenate((self.pitch, pitch))

    def trim(self, t_keep_from: float):
        i = max(0, int(np.searchsorted(self.t, t_keep_from)) - 2)
        self.t, self.rate, self.yaw = self.t[i:], self.rate[i:], self.yaw[i:]
        self.roll, self.pitch = self.roll[i:], self.pitch[i:]

    def interp(self, tq):
        f = lambda v: np.interp(tq, self.t, v)
        return (np.stack([f(self.rate[:, j]) for j in range(3)], axis=1), f(self.yaw), f(self.roll), f(self.pitch))

    def theta_series(self):
        t = np.concatenate(self.theta_t) if self.theta_t else np.empty(0)
        th = np.concatenate(self.theta) if self.theta else np.empty((0, 3))
        t, idx = np.unique(t, return_index=True)
        return t, th[idx]


class _Binner:
    def __init__(self, reference: str, bin_s: float, use_mag: bool):
        self.reference, self.bin_s, self.use_mag = reference, float(bin_s), use_mag
        self.t0 = None
        self.acc = _BinAccumulators()
        self.odom = _OdomTrack() if reference == 'odom' else None
        self.pending_imu: list = []
        self.pending_mag: list = []
        self.gyro_offset = None
        self.comp_offset = None
        self.imu_dt = None
        self.seen = {s: 0 for s in STREAMS}

    def _idx(self, t):
        return np.floor((t - self.t0) / self.bin_s + 1e-9).astype(np.int64)

    def add(self, chunk: SensorChunk):
        streams = {k: v for k, v in chunk.streams().items() if k in STREAMS and v is not None and len(v.t)}
        if not streams:
            return
        if self.t0 is None:
            self.t0 = min(float(s.t[0]) for s in streams.values())
        for k, s in streams.items():
            self.seen[k] += len(s.t)
        if 'temperature' in streams:
            s = streams['temperature']
            ok = np.isfinite(s.temp_c) & (s.t >= self.t0)
            i = self._idx(s.t[ok])
            self.acc.n_temp.add(i)
            self.acc.temp.add(i, s.temp_c[ok])
        if 'imu' in streams:
            s = streams['imu']
            ok = np.isfinite(s.gyro).all(1) & np.isfinite(s.accel).all(1) & (s.t >= self.t0)
            self.pending_imu.append((s.t[ok], s.gyro[ok], s.accel[ok]))
            if self.imu_dt is None and ok.sum() > 2:
                self.imu_dt = float(np.median(np.diff(s.t[ok])))
        if 'mag' in streams and self.use_mag and self.odom is not None:
            s = streams['mag']
            ok = np.isfinite(s.field).all(1) & (s.t >= self.t0)
            self.pending_mag.append((s.t[ok], s.field[ok]))
        if 'odom' in streams and self.odom is not None:
            s = streams['odom']
            ok = np.isfinite(s.rate_body).all(1) & np.isfinite(s.quat).all(1)
            t, q, w = s.t[ok], s.quat[ok], s.rate_body[ok]
            if self.odom.t.size:
                new = t > self.odom.t[-1]
                t, q, w = t[new], q[new], w[new]
            if t.size:
                self.odom.extend(t, q, w)
                i = self._idx(t)
                ok_i = i >= 0
                self.acc.n_odom.add(i[ok_i])
                north = rotation_matrix_from_quat(q[ok_i])[:, 1, :]   # R^T e_north: ENU north in the sensor frame
                self.acc.north.add(i[ok_i], north)
        self._flush(final=False)

    def _flush(self, final: bool):
        until = np.inf if (final or self.odom is None) else self.odom.covered_until
        self.pending_imu = self._drain(self.pending_imu, until, self._add_imu)
        self.pending_mag = self._drain(self.pending_mag, until, self._add_mag)
        if self.odom is not None and not final:
            firsts = [p[0][0] for p in self.pending_imu + self.pending_mag if len(p[0])]
            self.odom.trim(min(firsts) if firsts else self.odom.covered_until)

    @staticmethod
    def _drain(pending, until, fn):
        if not pending:
            return pending
        parts = [np.concatenate(cols) for cols in zip(*pending)]
        ready = parts[0] <= until
        if np.any(ready):
            fn(*(p[ready] for p in parts))
        rest = ~ready
        return [tuple(p[rest] for p in parts)] if np.any(rest) else []

    def _add_imu(self, t, gyro, accel):
        if self.odom is not None:
            if self.odom.t.size == 0:
                return   # no truth at all yet (only possible at the very end): cannot reference
            ref, _, _, _ = self.odom.interp(t)
        else:
            ref = np.zeros_like(gyro)
        d = gyro - ref
        if self.gyro_offset is None:
            self.gyro_offset = np.median(d, axis=0)   # shift before summing squares (cancellation)
        d = d - self.gyro_offset
        i = self._idx(t)
        self.acc.n_imu.add(i)
        self.acc.gyro.add(i, gyro)
        self.acc.accel.add(i, accel)
        self.acc.rate_dev.add(i, d)
        self.acc.rate_dev_sq.add(i, d * d)
        self.acc.t_first.extreme(i, t - self.t0, np.minimum)
        self.acc.t_last.extreme(i, t - self.t0, np.maximum)

    def _add_mag(self, t, field_t):
        if self.odom.t.size == 0:
            return
        _, yaw, roll, pitch = self.odom.interp(t)
        psi_c = compass_heading(field_t, roll_pitch=(roll, pitch)).heading_rad
        if self.comp_offset is None:
            self.comp_offset = float(np.angle(np.mean(np.exp(1j * (psi_c - yaw)))))
        # the residual is wrapped around its first-chunk circular mean, so a declination near
        # +-180 deg never straddles the wrap
        r = wrap_angle(psi_c - yaw - self.comp_offset)
        i = self._idx(t)
        self.acc.n_mag.add(i)
        self.acc.compass_err.add(i, r)
        self.acc.compass_err_sq.add(i, r * r)
        self.acc.heading_sin.add(i, np.sin(yaw))
        self.acc.heading_cos.add(i, np.cos(yaw))
        self.acc.mag_norm.add(i, np.linalg.norm(field_t, axis=1))

    def finish(self) -> BinnedData:
        self._flush(final=True)
        if self.t0 is None or self.seen['imu'] == 0:
            raise DiscoveryInputError('the bag has no IMU samples (imu/data_raw)')
        if self.seen['temperature'] == 0:
            raise DiscoveryInputError('the bag has no temperature samples (imu/temperature)')
        if self.reference == 'odom' and self.seen['odom'] == 0:
            raise DiscoveryInputError("reference 'odom' needs /ground_truth/odom, which the bag does not have")
        a = self.acc
        n_bins = int(np.flatnonzero(a.n_imu.take())[-1]) + 1
        n_imu = a.n_imu.take(n_bins)
        safe = np.maximum(n_imu, 1)[:, None]
        gyro = a.gyro.take(n_bins) / safe
        accel = a.accel.take(n_bins) / safe
        d, d2 = a.rate_dev.take(n_bins), a.rate_dev_sq.take(n_bins)
        notes = []
        noise_var = _pooled_variance(n_imu, d, d2)
        if not np.all(np.isfinite(noise_var)):
            # one sample per bin: fall back to first differences of the bin means (white noise)
            # (a mean of squares with the chi-square tail cut, not a median: the median of quantised
            # differences moves in whole LSB steps, ~10 % of the noise for an ADXRS623 at 1 Hz)
            dm = d / safe
            good = (n_imu[1:] > 0) & (n_imu[:-1] > 0)
            sq = np.diff(dm, axis=0)[good] ** 2 / 2.0
            cut = stats.chi2.isf(1e-4, 1) * np.median(sq, axis=0) / stats.chi2.median(1)
            keep = sq <= cut[None, :]
            noise_var = np.sum(sq * keep, axis=0) / np.maximum(np.sum(keep, axis=0), 1)
            noise_var *= np.median(n_imu[n_imu > 0])
            notes.append('gyro white noise estimated from bin-to-bin differences (one sample per bin)')
        n_temp = a.n_temp.take(n_bins)
        temp = np.where(n_temp > 0, a.temp.take(n_bins) / np.maximum(n_temp, 1), np.nan)
        t_first, t_last = a.t_first.take(n_bins), a.t_last.take(n_bins)
        if self.reference == 'static' and (moved := _turned(gyro, n_imu, noise_var, self.bin_s)):
            raise DiscoveryInputError(f"reference 'static', but the unit turned: {moved}; give a record of the "
                                      "unit at rest, or reference 'odom' with /ground_truth/odom")
        data = BinnedData(
            reference=self.reference, bin_s=self.bin_s, t0=float(self.t0),
            t=(np.arange(n_bins) + 0.5) * self.bin_s, n_imu=n_imu, gyro=gyro, accel=accel,
            t_first=np.where(n_imu > 0, t_first, np.nan), t_last=np.where(n_imu > 0, t_last, np.nan),
            imu_dt=float(self.imu_dt or self.bin_s), gyro_noise_var=noise_var, temp_c=temp, n_temp=n_temp,
            notes=notes)
        if self.odom is not None:
            data.has_odom = True
            th_t, th = self.odom.theta_series()
            data.theta_t, data.theta = th_t - self.t0, th
            data.ref_rate = data._span_mean(0.0)
            n_odom = a.n_odom.take(n_bins)
            north = a.north.take(n_bins) / np.maximum(n_odom, 1)[:, None]
            data.earth_north = np.where(n_odom[:, None] > 0, north, np.nan)
            n_mag = a.n_mag.take(n_bins)
            if n_mag.sum() > 0:
                data.has_compass = True
                m = np.maximum(n_mag, 1)
                data.n_mag = n_mag
                comp = a.compass_err.take(n_bins) / m
                data.compass = np.where(n_mag > 0, comp + self.comp_offset, np.nan)
                data.compass_heading = np.where(
                    n_mag > 0, np.arctan2(a.heading_sin.take(n_bins), a.heading_cos.take(n_bins)), np.nan)
                data.mag_norm_t = np.where(n_mag > 0, a.mag_norm.take(n_bins) / m, np.nan)
                var = _pooled_variance(n_mag, a.compass_err.take(n_bins)[:, None],
                                       a.compass_err_sq.take(n_bins)[:, None])[0]
                data.compass_noise_var = float(var) if np.isfinite(var) else float('nan')
                if not np.isfinite(var):
                    notes.append('compass noise unknown (one magnetometer sample per bin)')
        return data


def _turned(gyro: np.ndarray, n_imu: np.ndarray, noise_var: np.ndarray, bin_s: float) -> str | None:
    """What says the unit turned (None: it did not): the share of bins whose mean gyro (rad/s) lies
    beyond the motion limit from the running median of its neighbours, on any axis."""
    from scipy.ndimage import median_filter
    ok = n_imu > 0
    if np.count_nonzero(ok) < 3:
        return None
    g = gyro[ok]
    size = max(3, int(round(MOTION_WINDOW_S / bin_s)) | 1)
    dev = np.abs(g - median_filter(g, size=(size, 1), mode='nearest'))
    noise = np.sqrt(np.nan_to_num(noise_var, nan=0.0) / max(float(np.median(n_imu[ok])), 1.0))
    limit = np.maximum(np.radians(MOTION_RATE_DPS), 10.0 * noise)
    moving = np.any(dev > limit[None, :], axis=1)
    share = float(np.mean(moving))
    if share <= MOTION_SHARE:
        return None
    return (f'{share * 100:.0f} % of the {bin_s:g} s bins are more than {np.degrees(limit.min()):.2g} deg/s '
            f'from their neighbours (up to {np.degrees(dev.max()):.3g} deg/s)')


def _pooled_variance(n, s1, s2) -> np.ndarray:
    """White-noise variance of one sample per column, from per-bin counts, sums and sums of squares.

    Pooled over bins (dof-weighted mean of the bins' own variances), leaving out only bins whose
    variance is beyond the 1e-4 upper tail of chi2(dof)/dof around a robust (median-based) scale:
    bins where the signal itself changes (a turn inside a bin with a scale-factor error, a glitch).
    With white Gaussian noise that cut removes 0.01 % of bins, so the estimate stays unbiased for any
    number of samples per bin (a plain median would not be: quantised samples make it jump)."""
    ok = n >= 2
    if not np.any(ok):
        return np.full(s1.shape[1], np.nan)
    nn = n[ok][:, None].astype(float)
    dof = nn - 1.0
    var = (s2[ok] - s1[ok] ** 2 / nn) / dof
    k = int(np.median(n[ok]))
    scale = np.median(var, axis=0) / (stats.chi2.median(k - 1) / (k - 1))
    limit = stats.chi2.isf(1e-4, dof) / dof * scale[None, :]
    keep = var <= limit
    return np.sum(var * dof * keep, axis=0) / np.maximum(np.sum(dof * keep, axis=0), 1.0)


def bin_chunks(chunks: Iterable[SensorChunk], reference: str = 'static', bin_s: float = 1.0,
               use_mag: bool = True) -> BinnedData:
    """Bin a time-ordered stream of SensorChunks (only imu, temperature, mag, odom are used)."""
    if reference not in REFERENCES:
        raise DiscoveryInputError(f'unknown reference {reference!r}; use one of {", ".join(REFERENCES)}')
    if not bin_s > 0:
        raise DiscoveryInputError('bin_s must be > 0')
    binner = _Binner(reference, bin_s, use_mag)
    for chunk in chunks:
        binner.add(chunk)
    return binner.finish()


def load_bins(source, reference: str = 'static', bin_s: float = 1.0, chunk_s: float = 60.0,
              topic_map=None) -> BinnedData:
    """Bin a bag folder / .mcap path, or an iterable of SensorChunks. Only the imu, temperature,
    mag and (for reference='odom') odom streams are read."""
    if isinstance(source, (str, Path)):
        from ..bag_io import read_chunks
        streams = ['imu', 'temperature', 'mag'] + (['odom'] if reference == 'odom' else [])
        return bin_chunks(read_chunks(source, chunk_s, streams=streams, topic_map=topic_map), reference, bin_s)
    return bin_chunks(source, reference, bin_s)
