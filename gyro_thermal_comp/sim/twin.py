"""A simulated twin of a recording of a unit at rest, and where the two disagree.

The twin is the simulator's static unit configured from the record itself:
- the record's own sample rate and quantisation (the smallest step of the gyro and of the
  temperature);
- its own temperature series as the thermal profile (the twin lives through the same temperatures,
  at the same rates);
- the gyro's white noise per axis (from successive differences: what the stream carries, aliasing of
  point samples included) and, on the vertical (heading) axis, the paper's drift model
  D = c + a (T - 25) + b dT/dt fitted to the record by least squares over 60 s bins;
- the accelerometer and the magnetometer: their mean vector at rest and its temperature slope per
  axis, with their white noise: an uncalibrated magnetometer whose field moves with temperature.
Effects the discrepancy workflow names are added by their names in the simulator's effect library
(sim/effects.py EFFECTS): `rate_random_walk` (deg/s/sqrt(s)), `bias_instability` (deg/s, with
`bias_instability_tau_s`), `thermal_curvature` (deg/s/degC^2, the record's own fit), `thermal_lag`
(s: the drift follows a lagged temperature). The twin is then compared with the record by a few
named statistics (`disagreement`): the Allan deviation of the heading axis at 1 s to 3 h (the noise
and the wander), what is left of the heading-axis drift after the thermal model (its rms over 10 min
bins), and how far the compass heading moves with temperature.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from ..samples import ImuSamples, MagSamples, SensorChunk, TemperatureSamples
from ..thermal.compass import compass_heading
from .effects import EFFECTS

HEADING_AXIS = 2
BIN_S = 60.0                     # drift fit and residual bins, s
RESIDUAL_BIN_S = 600.0           # the residual's structure is judged over these, s
ALLAN_TAUS_S = (1.0, 10.0, 100.0, 1000.0, 10000.0)
TWIN_EFFECTS = ('rate_random_walk', 'bias_instability', 'thermal_curvature', 'thermal_lag')


@dataclass(frozen=True)
class TwinConfig:
    """What the twin takes from the record (SI units, sensor frame)."""
    rate_hz: float
    gyro_step_rad_s: float              # quantisation of the gyro (0: none seen)
    temp_step_c: float                  # quantisation of the temperature
    gyro_white_rad_s: np.ndarray        # (3,) per-sample white noise
    gyro_mean_rad_s: np.ndarray         # (3,) mean rate of the other axes (bias); z from the drift model
    drift: dict                         # {'c', 'a', 'b'[, 'k'] }: heading-axis drift model, rad/s, per degC, ...
    accel_mean: np.ndarray              # (3,) m/s^2 at the reference temperature
    accel_tc: np.ndarray                # (3,) m/s^2 per degC
    accel_white: np.ndarray             # (3,)
    mag_mean_t: np.ndarray              # (3,) T at the reference temperature
    mag_tc_t: np.ndarray                # (3,) T per degC
    mag_white_t: np.ndarray             # (3,)
    temperature_ref_c: float            # the record's mean temperature, degC
    effects: dict = field(default_factory=dict)   # effect name -> value (sim/effects.py units)
    params: dict = field(default_factory=dict)    # e.g. bias_instability_tau_s

    def with_effects(self, rec: 'Record | None' = None, **effects) -> 'TwinConfig':
        """The twin with named effects added (the library's names and units); a thermal structure
        (curvature, a lag) is fitted to the record `rec` again with it."""
        unknown = [k for k in effects if k not in TWIN_EFFECTS and k != 'bias_instability_tau_s']
        if unknown:
            raise ValueError(f'the twin takes {", ".join(TWIN_EFFECTS)}; not {", ".join(unknown)}')
        params = dict(self.params)
        if 'bias_instability_tau_s' in effects:
            params['bias_instability_tau_s'] = float(effects.pop('bias_instability_tau_s'))
        merged = {**self.effects, **{k: float(v) for k, v in effects.items()}}
        drift = self.drift
        if rec is not None and ('thermal_curvature' in merged or 'thermal_lag' in merged):
            drift = fit_drift(rec, curvature='thermal_curvature' in merged, lag_s=merged.get('thermal_lag', 0.0))
        return replace(self, effects=merged, params=params, drift=drift)


@dataclass(frozen=True)
class Record:
    """A static record as arrays on the IMU stamps (the twin's and the record's common shape)."""
    t: np.ndarray                # s
    gyro: np.ndarray             # (N, 3) rad/s
    accel: np.ndarray            # (N, 3) m/s^2
    mag: np.ndarray              # (N, 3) T (at the IMU stamps: nearest earlier sample)
    temp_c: np.ndarray           # (N,) degC (at the IMU stamps)

    @classmethod
    def from_chunks(cls, chunks) -> 'Record':
        imu, mag, temp = [], [], []
        for c in chunks:
            if c.imu is not None:
                imu.append(c.imu)
            if c.mag is not None:
                mag.append(c.mag)
            if c.temperature is not None:
                temp.append(c.temperature)
        if not imu or not mag or not temp:
            raise ValueError('a twin needs the gyro, the magnetometer and the temperature of the record')
        t = np.concatenate([s.t for s in imu])
        tm = np.concatenate([s.t for s in mag])
        tt = np.concatenate([s.t for s in temp])
        field_t = np.concatenate([s.field for s in mag])
        k = np.clip(np.searchsorted(tm, t, side='right') - 1, 0, tm.size - 1)
        return cls(t, np.concatenate([s.gyro for s in imu]), np.concatenate([s.accel for s in imu]), field_t[k],
                   np.interp(t, tt, np.concatenate([s.temp_c for s in temp])))

    def chunk(self) -> SensorChunk:
        return SensorChunk(imu=ImuSamples(self.t, self.gyro, self.accel), mag=MagSamples(self.t, self.mag),
                           temperature=TemperatureSamples(self.t, self.temp_c))


def _step(values: np.ndarray) -> float:
    """The quantisation step of a stream: its smallest non-zero change (0 if it looks continuous)."""
    d = np.abs(np.diff(values))
    d = d[d > 0]
    if not d.size:
        return 0.0
    q = float(np.min(d))
    # a continuous stream has no common step: most changes are then far from multiples of the smallest
    k = d / q
    return q if np.mean(np.abs(k - np.round(k)) < 0.05) > 0.9 else 0.0


def _white(x: np.ndarray) -> np.ndarray:
    return np.std(np.diff(x, axis=0), axis=0) / math.sqrt(2.0)


def _rate_c_s(t: np.ndarray, temp: np.ndarray, window_s: float = 60.0) -> np.ndarray:
    """dT/dt by a centred linear fit over `window_s` (cumulative sums, O(N)), degC/s."""
    n = t.size
    dt = float(np.median(np.diff(t))) if n > 1 else 1.0
    h = max(1, int(round(0.5 * window_s / dt)))
    c1, ct, ct2, cty = (np.concatenate(([0.0], np.cumsum(v))) for v in (np.ones(n), t, t * t, t * temp))
    cy = np.concatenate(([0.0], np.cumsum(temp)))
    i = np.arange(n)
    lo, hi = np.maximum(i - h, 0), np.minimum(i + h + 1, n)
    m, st, st2, sy, sty = (c[hi] - c[lo] for c in (c1, ct, ct2, cy, cty))
    den = m * st2 - st * st
    return np.where(den > 0, (m * sty - st * sy) / np.where(den > 0, den, 1.0), 0.0)


def _lag(temp: np.ndarray, t: np.ndarray, tau_s: float) -> np.ndarray:
    """First-order lag of the temperature (exact for a linear change between samples)."""
    if tau_s <= 0:
        return temp.copy()
    out = np.empty_like(temp)
    out[0] = temp[0]
    a = np.exp(-np.diff(t) / tau_s)
    for k in range(1, temp.size):
        out[k] = a[k - 1] * out[k - 1] + (1.0 - a[k - 1]) * temp[k]
    return out


def _bins(t: np.ndarray, bin_s: float) -> np.ndarray:
    return np.floor((t - t[0]) / bin_s).astype(np.int64)


def _binned(ids: np.ndarray, x: np.ndarray) -> np.ndarray:
    n = np.bincount(ids)
    ok = n > 0
    return (np.bincount(ids, weights=x)[ok] / n[ok]) if x.ndim == 1 else \
        np.column_stack([np.bincount(ids, weights=x[:, j])[ok] / n[ok] for j in range(x.shape[1])])


def _drift_rows(temp: np.ndarray, rate: np.ndarray, t_ref: float, curvature: bool) -> np.ndarray:
    cols = [np.ones_like(temp), temp - t_ref, rate] + ([(temp - t_ref) ** 2] if curvature else [])
    return np.column_stack(cols)


def fit_drift(rec: Record, curvature: bool = False, lag_s: float = 0.0) -> dict:
    """The heading-axis drift model fitted to the record over 60 s bins (temperature lagged by
    `lag_s` where a lag is named): {'c', 'a', 'b'[, 'k']} in rad/s, per degC, per degC/s, per degC^2."""
    temp = _lag(rec.temp_c, rec.t, lag_s)
    rate = _rate_c_s(rec.t, temp)
    ids = _bins(rec.t, BIN_S)
    t_ref = 25.0
    H = _drift_rows(_binned(ids, temp), _binned(ids, rate), t_ref, curvature)
    x, *_ = np.linalg.lstsq(H, _binned(ids, rec.gyro[:, HEADING_AXIS]), rcond=None)
    out = {'c': float(x[0]), 'a': float(x[1]), 'b': float(x[2])}
    if curvature:
        out['k'] = float(x[3])
    return out


def _vector_vs_temperature(v: np.ndarray, temp: np.ndarray, t_ref: float) -> tuple[np.ndarray, np.ndarray]:
    """Mean at t_ref and slope per degC of each axis (least squares)."""
    H = np.column_stack((np.ones_like(temp), temp - t_ref))
    x, *_ = np.linalg.lstsq(H, v, rcond=None)
    return x[0], x[1]


def twin_config(rec: Record) -> TwinConfig:
    """The twin of a static record: rate, quantisation, noise, drift and both field sensors against
    temperature, all measured from it."""
    t_ref = float(np.mean(rec.temp_c))
    accel_mean, accel_tc = _vector_vs_temperature(rec.accel, rec.temp_c, t_ref)
    mag_mean, mag_tc = _vector_vs_temperature(rec.mag, rec.temp_c, t_ref)
    return TwinConfig(
        rate_hz=1.0 / float(np.median(np.diff(rec.t))), gyro_step_rad_s=_step(rec.gyro[:, HEADING_AXIS]),
        temp_step_c=_step(rec.temp_c), gyro_white_rad_s=_white(rec.gyro), gyro_mean_rad_s=rec.gyro.mean(axis=0),
        drift=fit_drift(rec), accel_mean=accel_mean, accel_tc=accel_tc, accel_white=_white(rec.accel),
        mag_mean_t=mag_mean, mag_tc_t=mag_tc, mag_white_t=_white(rec.mag), temperature_ref_c=t_ref)


def _quantise(x: np.ndarray, step: float) -> np.ndarray:
    return x if step <= 0 else np.round(x / step) * step


def simulate_twin(cfg: TwinConfig, t: np.ndarray, temp_c: np.ndarray, seed: int = 0) -> Record:
    """The twin over the record's own stamps and temperature series."""
    rng = np.random.default_rng(seed)
    n = t.size
    eff = cfg.effects
    lag_s = eff.get('thermal_lag', 0.0)
    die = _lag(temp_c, t, lag_s)
    rate = _rate_c_s(t, die)
    d = cfg.drift
    drift = d['c'] + d['a'] * (die - 25.0) + d['b'] * rate
    if 'thermal_curvature' in eff:
        drift = drift + d.get('k', 0.0) * (die - 25.0) ** 2
    dt = np.diff(t, prepend=t[0])
    if eff.get('rate_random_walk', 0.0) > 0:
        k = math.radians(eff['rate_random_walk'])
        drift = drift + k * np.cumsum(np.sqrt(dt) * rng.standard_normal(n))
    if eff.get('bias_instability', 0.0) > 0:
        sigma, tau = math.radians(eff['bias_instability']), float(cfg.params.get('bias_instability_tau_s', 300.0))
        a = np.exp(-dt / tau)
        w = sigma * np.sqrt(1.0 - a * a) * rng.standard_normal(n)
        gm = np.empty(n)
        gm[0] = sigma * rng.standard_normal()
        for i in range(1, n):
            gm[i] = a[i] * gm[i - 1] + w[i]
        drift = drift + gm
    gyro = np.tile(cfg.gyro_mean_rad_s, (n, 1))
    gyro[:, HEADING_AXIS] = drift
    gyro = gyro + cfg.gyro_white_rad_s * rng.standard_normal((n, 3))
    gyro = _quantise(gyro, cfg.gyro_step_rad_s)
    u = (temp_c - cfg.temperature_ref_c)[:, None]
    accel = cfg.accel_mean + cfg.accel_tc * u + cfg.accel_white * rng.standard_normal((n, 3))
    mag = cfg.mag_mean_t + cfg.mag_tc_t * u + cfg.mag_white_t * rng.standard_normal((n, 3))
    return Record(t, gyro, accel, mag, _quantise(temp_c, cfg.temp_step_c))


def _allan(x: np.ndarray, rate_hz: float, taus_s) -> np.ndarray:
    """Overlapping Allan deviation of a rate series at the given averaging times (NaN where too long)."""
    import allantools
    m = np.array([max(1, int(round(tau * rate_hz))) for tau in taus_s])
    out = np.full(len(taus_s), np.nan)
    ok = m * 3 < x.size
    if np.any(ok):
        taus_out, dev, _, _ = allantools.oadev(x, rate=rate_hz, data_type='freq', taus=m[ok] / rate_hz)
        out[np.flatnonzero(ok)[:len(dev)]] = dev
    return out


def statistics(rec: Record, drift: dict | None = None) -> dict:
    """The named statistics of a record (deg, deg/s): the heading axis's Allan deviation, its drift
    residual after the thermal model (rms over 10 min bins; the paper's model fitted to this record,
    as to the other it is compared with, unless `drift` is given), the compass heading's swing."""
    drift = fit_drift(rec) if drift is None else drift
    rate_hz = 1.0 / float(np.median(np.diff(rec.t)))
    wz = rec.gyro[:, HEADING_AXIS]
    out = {f'allan_dev_{int(tau)}s_deg_s': float(math.degrees(v))
           for tau, v in zip(ALLAN_TAUS_S, _allan(wz, rate_hz, ALLAN_TAUS_S))}
    temp = rec.temp_c
    model = drift['c'] + drift['a'] * (temp - 25.0) + drift['b'] * _rate_c_s(rec.t, temp) + \
        drift.get('k', 0.0) * (temp - 25.0) ** 2
    ids = _bins(rec.t, RESIDUAL_BIN_S)
    resid = _binned(ids, wz - model)
    out['drift_residual_rms_deg_s'] = float(math.degrees(np.sqrt(np.mean((resid - resid.mean()) ** 2))))
    heading = np.unwrap(np.atleast_1d(compass_heading(rec.mag, rec.accel, 0.0).heading_rad))
    hourly = _binned(_bins(rec.t, 3600.0), heading)
    out['compass_swing_deg'] = float(math.degrees(np.ptp(hourly)))
    return out


def disagreement(record: dict, twin: dict) -> dict:
    """Per statistic, log10(twin / record) (0: they agree), and `total`: their rms."""
    d = {k: float(math.log10(twin[k] / record[k])) for k in record
         if record[k] > 0 and twin.get(k, 0) > 0 and math.isfinite(record[k]) and math.isfinite(twin[k])}
    d['total'] = float(math.sqrt(np.mean([v * v for v in d.values()]))) if d else math.nan
    return d


def effects_from_discovery(settings: dict, names) -> dict:
    """The twin's effects from what `discover` named and estimated (its settings, heading axis)."""
    out = {}
    z = HEADING_AXIS
    if 'rate_random_walk' in names and settings.get('rate_random_walk_dps_rts'):
        out['rate_random_walk'] = float(settings['rate_random_walk_dps_rts'][z])
    if 'bias_instability' in names and settings.get('bias_instability_dps'):
        out['bias_instability'] = float(settings['bias_instability_dps'][z])
        out['bias_instability_tau_s'] = float(settings['bias_instability_tau_s'][z] or 300.0)
    if 'thermal_lag' in names and settings.get('thermal_lag_tau_s'):
        out['thermal_lag'] = float(settings['thermal_lag_tau_s'])
    if 'thermal_curvature' in names:
        out['thermal_curvature'] = EFFECTS['thermal_curvature'].default
    return out
