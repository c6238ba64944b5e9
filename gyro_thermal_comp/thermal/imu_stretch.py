"""Vectorised gyro work between filter events: heading rate, tilt, integrals (docs/design.md 2).

`ImuStretch` holds the per-sample columns of one stretch of IMU samples integrated with fixed
drift-model parameters; `at_stamps` reads the gyro state at compass stamps from it.
"""
from __future__ import annotations

import copy
import math
from collections import deque
from dataclasses import dataclass, fields

import numpy as np

from ..constants import EARTH_RATE_RAD_S
from .compass import roll_pitch_from_accel
from .sampling import SamplePeriod


@dataclass(frozen=True)
class ImuStretch:
    """Columns (N rows) of accepted IMU samples integrated with one set of parameters."""
    t: np.ndarray             # (N,) s
    psi_g: np.ndarray         # (N,) gyro heading, continuous, rad
    d_hat: np.ndarray         # (N,) drift removed from the z gyro, rad/s
    wc: np.ndarray            # (N, 3) compensated rates, rad/s
    rate: np.ndarray          # (N,) heading rate, rad/s
    roll: np.ndarray          # (N,) rad, from the long-term gravity average
    pitch: np.ndarray         # (N,) rad
    g_tilt: np.ndarray        # (N,) heading rate per z rate: cos(roll) / cos(pitch)
    accel: np.ndarray         # (N,) |f|, m/s^2 (the gate's tilt test)
    temp: np.ndarray          # (N,) degC used in H (last reading or t_ref before any)
    temp_rate: np.ndarray     # (N,) degC/s
    temp_known: np.ndarray    # (N,) bool: a temperature reading was in force
    gap: np.ndarray           # (N,) bool: stamp after a time gap (nothing integrated across it)
    h: np.ndarray             # (N, n) drift-model regressor rows
    i_d: np.ndarray           # (N,) int g D_hat dt since the drift window start, rad
    i_h: np.ndarray           # (N, n) int g H dt since the drift window start
    params: np.ndarray        # (n,) parameters in force

    def __len__(self) -> int:
        return self.t.size

    def row(self, i: int) -> 'ImuStretch':
        """Sample i as a one-row stretch (the latest: the state a later compass sample starts from)."""
        sl = slice(i, i + 1) if i != -1 else slice(-1, None)
        return ImuStretch(**{name: getattr(self, name)[sl] for name in _ROW_FIELDS}, params=self.params)

    def at_stamps(self, t_mag: np.ndarray, before: 'ImuStretch | None') -> 'CompassContext':
        """Gyro state at compass stamps: each takes the IMU sample strictly before it (so at equal
        stamps the compass goes first, in any chunking), from this stretch or, before its first
        sample, the last row of `before` (the stretch before), extrapolated with that sample's
        heading rate."""
        k = np.searchsorted(self.t, t_mag, side='left') - 1
        return _context(self, before, k, t_mag)


_ROW_FIELDS = tuple(f.name for f in fields(ImuStretch) if f.name != 'params')   # per-sample columns


@dataclass(frozen=True)
class CompassContext:
    """The gyro's state at each compass stamp (M rows)."""
    psi_g: np.ndarray         # gyro heading extrapolated to the stamp, rad
    i_d: np.ndarray           # window integral of g D_hat up to the stamp, rad
    i_h: np.ndarray           # (M, n) window integral of g H up to the stamp
    t_imu: np.ndarray         # stamp of the IMU sample used, s
    g_tilt: np.ndarray
    d_hat: np.ndarray
    h: np.ndarray             # (M, n)
    roll: np.ndarray
    pitch: np.ndarray
    accel: np.ndarray
    temp: np.ndarray


def _context(stretch: ImuStretch | None, before: ImuStretch | None, k: np.ndarray,
             t_mag: np.ndarray) -> CompassContext:
    # the rows to take, once for all columns: k >= 0 from the stretch, k = -1 the row `before`
    # (k does not decrease: the compass stamps increase)
    if stretch is not None:
        inside = k.size == 0 or k[0] >= 0
        if inside:
            idx = k
        elif before is None:   # no IMU sample before the stretch: its first
            inside, idx = True, np.maximum(k, 0)
        else:
            idx = k + 1

    def at(name):
        if stretch is None:
            v = getattr(before, name)[-1]
            return np.broadcast_to(v, (t_mag.size,) + np.shape(v)).copy()
        if inside:
            return getattr(stretch, name)[idx]
        return np.concatenate((getattr(before, name)[-1:], getattr(stretch, name)))[idx]
    t_imu = at('t')
    age = t_mag - t_imu
    rate, g_tilt, d_hat, h = at('rate'), at('g_tilt'), at('d_hat'), at('h')
    return CompassContext(psi_g=at('psi_g') + rate * age, i_d=at('i_d') + g_tilt * d_hat * age,
                          i_h=at('i_h') + (g_tilt * age)[:, None] * h, t_imu=t_imu, g_tilt=g_tilt,
                          d_hat=d_hat, h=h, roll=at('roll'), pitch=at('pitch'), accel=at('accel'),
                          temp=at('temp'))


def context_before_imu(before: ImuStretch, t_mag: np.ndarray) -> CompassContext:
    """Gyro state at compass stamps with no IMU sample in their stretch: all from the last row of
    `before`."""
    return _context(None, before, np.full(t_mag.size, -1), t_mag)


def integration_steps(t: np.ndarray, t_prev: float, max_gap_s: float,
                      period: SamplePeriod) -> tuple[np.ndarray, np.ndarray]:
    """Sample intervals dt (s; 0 before the first sample, t_prev = -inf) and the time-gap flags:
    beyond `max_gap_s` and beyond a few of the stream's own periods (sampling.py), which takes the
    intervals in. The stamps are finite (input_guard.py)."""
    dt = np.empty(t.size)
    if not t.size:
        return dt, np.zeros(0, bool)
    first = math.isfinite(t_prev)
    dt[0] = t[0] - t_prev if first else 0.0
    np.subtract(t[1:], t[:-1], out=dt[1:])
    if first:
        return dt, period.gaps(dt, max_gap_s)
    return dt, np.concatenate(([False], period.gaps(dt[1:], max_gap_s)))


def compensate(gyro: np.ndarray, d_hat: np.ndarray, bias_xy: np.ndarray) -> np.ndarray:
    """Rates (N, 3) rad/s with the drift estimate off z and the still-period bias off x, y."""
    wc = gyro.copy()
    wc[:, :2] -= bias_xy
    wc[:, 2] -= d_hat
    return wc


def heading_rate(wc_z: np.ndarray, roll: np.ndarray, pitch: np.ndarray,
                 earth_rate_up_rad_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Heading rate (rad/s) and g_tilt from the compensated z rate and the tilt (docs/design.md).

    ZYX yaw rate is (sin(roll) w_y + cos(roll) w_z) / cos(pitch). The w_y term is dropped: it
    carries the y gyro's own thermal drift (only its start bias is known) into the heading,
    sin(1 deg) x 0.5 deg/s = 0.01 deg/s, while the true sin(roll) w_y is second order in roll."""
    g_tilt = np.cos(roll) / np.cos(pitch)
    return g_tilt * wc_z - earth_rate_up_rad_s, g_tilt


def specific_force_norm(acc: np.ndarray) -> np.ndarray:
    """|f|, m/s^2, for the gate's tilt test (judged against |f| at rest: an uncalibrated
    accelerometer reads 10.4 m/s^2 there, not g). The test is blind to the level accelerations a car
    makes all the time; those are averaged out of the tilt by the long gravity window instead."""
    # np.linalg.norm(acc, axis=1) as that computes it, without its Python-level dispatch
    return np.sqrt(np.add.reduce(acc * acc, axis=1))


class GravityAverage:
    """Mean specific force over roughly the trailing `window_s` (the gravity direction for roll and
    pitch), from `bin_s` bins on a grid from the first sample so chunking cannot change it (and the
    time of day a record starts cannot either): the completed bins of the window plus the current
    partial bin up to each sample. O(1) state per bin."""

    def __init__(self, window_s: float, bin_s: float = 1.0):
        self.bin_s = float(bin_s)
        self.n_bins = max(1, int(round(window_s / bin_s)))
        self.bins: deque = deque()            # (sum (3,), count) of completed bins
        self.total = np.zeros(3)
        self.count = 0.0
        self.cur_id = None
        self.cur_sum = np.zeros(3)
        self.cur_n = 0.0
        self.t0: float | None = None          # grid origin: the first sample, s

    def tilt(self, t: np.ndarray, acc: np.ndarray, use: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Roll and pitch (rad) at each sample; rows with use == False (turning: centripetal
        force) stay out of the average."""
        return roll_pitch_from_accel(self.update(t, acc, use))

    def probe_tilt(self, t: np.ndarray, acc: np.ndarray, use: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """`tilt` without keeping the samples in the average (a look ahead)."""
        saved = (list(self.bins), self.total.copy(), self.count, self.cur_id, self.cur_sum.copy(), self.cur_n, self.t0)
        try:
            return self.tilt(t, acc, use)
        finally:
            bins, self.total, self.count, self.cur_id, self.cur_sum, self.cur_n, self.t0 = saved
            self.bins = deque(bins)

    def update(self, t: np.ndarray, v: np.ndarray, use: np.ndarray) -> np.ndarray:
        """Means at each sample (a sample with nothing usable yet gets its own value)."""
        w = use.astype(float)
        vw = v * w[:, None]
        out = v.copy()
        if t.size == 0:
            return out
        if self.t0 is None:
            self.t0 = float(t[0])
        id_first = math.floor((float(t[0]) - self.t0) / self.bin_s)
        if id_first == math.floor((float(t[-1]) - self.t0) / self.bin_s):
            bounds = [0, t.size]  # one bin: the usual case for small chunks
            first_ids = [id_first]
        else:
            ids = np.floor((t - self.t0) / self.bin_s).astype(np.int64)
            starts = np.flatnonzero(np.diff(ids, prepend=ids[0] - 1) != 0)
            bounds, first_ids = starts.tolist() + [t.size], ids[starts].tolist()
        for k in range(len(bounds) - 1):
            i0, i1 = bounds[k], bounds[k + 1]
            if self.cur_id is not None and first_ids[k] != self.cur_id:
                self._complete()
            self.cur_id = first_ids[k]
            cs = np.cumsum(vw[i0:i1], axis=0) + self.cur_sum
            cn = self.cur_n + np.cumsum(w[i0:i1])
            den = cn + self.count
            if den[0] > 0:   # den never decreases inside a bin: every row has a mean
                out[i0:i1] = (cs + self.total) / den[:, None]
            else:
                ok = den > 0
                out[i0:i1][ok] = (cs[ok] + self.total) / den[ok, None]
            self.cur_sum, self.cur_n = cs[-1].copy(), float(cn[-1])
        return out

    def _complete(self) -> None:
        self.bins.append((self.cur_sum, self.cur_n))
        self.total = self.total + self.cur_sum
        self.count += self.cur_n
        if len(self.bins) > self.n_bins:
            s, n = self.bins.popleft()
            self.total = self.total - s
            self.count -= n
        self.cur_sum = np.zeros_like(self.cur_sum)
        self.cur_n = 0.0


class GyroIntegrator:
    """Integrates the gyro heading psi_g (rad, continuous) over stretches of accepted IMU samples,
    with the tilt from the long-term gravity average; nothing is integrated across a time gap."""

    def __init__(self, max_gap_s: float, tilt_window_s: float, tilt_max_rate_rad_s: float,
                 earth_rate_up_rad_s: float):
        self.max_gap_s = max_gap_s
        self.period = SamplePeriod()                     # the IMU's own sampling period (gaps)
        self.gravity = GravityAverage(tilt_window_s)
        self.tilt_max_rate_rad_s = tilt_max_rate_rad_s   # faster turns stay out of the gravity average
        self.earth_rate_up_rad_s = earth_rate_up_rad_s
        self.psi_g = 0.0
        self.latest: ImuStretch | None = None            # the latest stretch
        self.t_last = -math.inf                          # its last stamp, s
        self.temp_last = math.nan                        # its last temperature, degC

    def probe_heading(self, t, gyro, acc, d_hat, bias_xy) -> np.ndarray:
        """psi_g (rad) over these samples without integrating them (a look ahead)."""
        dt, gap = integration_steps(t, self.t_last, self.max_gap_s, copy.deepcopy(self.period))
        wc = compensate(gyro, d_hat, bias_xy)
        roll, pitch = self.gravity.probe_tilt(t, acc, np.abs(wc[:, 2]) < self.tilt_max_rate_rad_s)
        rate, _ = heading_rate(wc[:, 2], roll, pitch, self.earth_rate_up_rad_s)
        return self.psi_g + np.cumsum(rate * np.where(gap, 0.0, dt))

    def integrate(self, t, gyro, acc, d_hat, bias_xy, H, temp_c, temp_rate, temp_known, params,
                  window_t0: float | None, i_d0: float, i_h0: np.ndarray) -> tuple[ImuStretch, float | None]:
        """The stretch's columns, and the length (s) of its last time gap (None: no gap). The window
        integrals continue from i_d0, i_h0 and start at the window start, not at the sample before."""
        dt, gap = integration_steps(t, self.t_last, self.max_gap_s, self.period)
        wc = compensate(gyro, d_hat, bias_xy)
        # gravity = long-term mean specific force, without turning samples (centripetal force)
        roll, pitch = self.gravity.tilt(t, acc, np.abs(wc[:, 2]) < self.tilt_max_rate_rad_s)
        rate, g_tilt = heading_rate(wc[:, 2], roll, pitch, self.earth_rate_up_rad_s)
        any_gap = bool(gap.any())
        dt_int = np.where(gap, 0.0, dt) if any_gap else dt
        psi_g = self.psi_g + np.cumsum(rate * dt_int)
        dt_win = dt_int if window_t0 is None else np.minimum(dt_int, np.maximum(t - window_t0, 0.0))
        i_d = i_d0 + np.cumsum(g_tilt * d_hat * dt_win)
        i_h = i_h0 + np.cumsum((g_tilt * dt_win)[:, None] * H, axis=0)
        stretch = ImuStretch(t=t, psi_g=psi_g, d_hat=d_hat, wc=wc, rate=rate, roll=roll, pitch=pitch,
                             g_tilt=g_tilt, accel=specific_force_norm(acc), temp=temp_c, temp_rate=temp_rate,
                             temp_known=temp_known, gap=gap, h=H, i_d=i_d, i_h=i_h, params=params)
        self.psi_g = float(psi_g[-1])
        self.latest = stretch
        self.t_last, self.temp_last = float(t[-1]), float(temp_c[-1])
        return stretch, (float(dt[gap][-1]) if any_gap else None)


def earth_rate_up(latitude_deg: float | None) -> float:
    """Vertical Earth rate, rad/s (0 when the latitude is unknown: it then ends up in `constant`)."""
    return 0.0 if latitude_deg is None else EARTH_RATE_RAD_S * math.sin(math.radians(latitude_deg))
