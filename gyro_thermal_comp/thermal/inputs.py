"""`EstimatorInputs`: what the STKF estimator accepts of its three input streams, on one time base.

- Each stream has one `StreamGuard` with the sensor's ranges (input_guard.py; `input_guards`): a
  value no sensor of that range can produce, a dead (all-zero) magnetometer, a repeated or
  out-of-order stamp, or an unconfirmed stamp jump is dropped and counted by name. The guards see
  each stream's own stamps. The estimator applies them to every chunk it is given, except a chunk
  whose samples already passed them (`admitted`): a node's pipeline applies them once, where each
  sample comes in (thermal/compensator.py), and shares them with the estimator.
- Stamps are mapped to one increasing internal time (`TimeBase`): a clock that jumps back (bag loop,
  simulator reset) reads as a short time gap; the learned model is untouched. A compass or
  temperature sample still on a time base the IMU has left maps before the stream's newest sample
  and is dropped (`<stream>_dropped_old_time_base`).
- Temperature: smoothed T and dT/dt at the IMU stamps (temperature_rate.py). Before the first
  reading the reference temperature is used; after readings stop for `temperature_timeout_s` the
  last one is held, marked stale (no learning from then), and the drift uncertainty grows with
  the held reading's age (`drift_sigma`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..input_guard import StreamGuard
from ..samples import SensorChunk, TemperatureSamples
from .drift_model import DriftModel
from .estimator_config import EstimatorConfig
from .sampling import SamplePeriod
from .temperature_rate import TemperatureRateEstimator
from .time_base import TimeBase


@dataclass(frozen=True)
class AcceptedSamples:
    """One chunk's accepted samples; stamps in internal time, s."""
    imu_ok: np.ndarray      # (N,) bool over the chunk's IMU rows
    t_imu: np.ndarray       # (n,)
    gyro: np.ndarray        # (n, 3) rad/s
    accel: np.ndarray       # (n, 3) m/s^2
    t_mag: np.ndarray       # (m,)
    field: np.ndarray       # (m, 3) T
    t_mag_before: float     # the newest compass stamp before this chunk
    mag_period: np.ndarray  # (m,) the compass's sampling period at each of its samples, s (NaN: unknown)
    mag_period_before: float  # ... at the newest compass sample before this chunk


@dataclass(frozen=True)
class TemperatureAtImu:
    temp_c: np.ndarray      # degC (held or reference where unknown)
    rate_c_s: np.ndarray    # degC/s (0 where unknown)
    known: np.ndarray       # bool: a fresh reading is in force


def input_guards(cfg: EstimatorConfig) -> dict[str, StreamGuard]:
    """The one guard of each input stream (module docstring), on the stream's own stamps, s."""
    jump = {'max_jump_s': cfg.max_time_jump_s, 'confirm_samples': cfg.time_jump_confirm_samples}
    return {'imu': StreamGuard('imu', ((-cfg.gyro_range_rad_s, cfg.gyro_range_rad_s),
                                       (-cfg.accel_range_m_s2, cfg.accel_range_m_s2)), **jump),
            'mag': StreamGuard('mag', ((-cfg.field_range_t, cfg.field_range_t, cfg.field_norm_min_t),), **jump),
            'temperature': StreamGuard('temperature', ((cfg.temperature_min_c, cfg.temperature_max_c),), **jump)}


def _after(t: np.ndarray, last: float) -> np.ndarray:
    """Stamps after `last` and after every earlier stamp of `t` (a stream's internal time increases)."""
    if t.size and t[0] > last and (t.size == 1 or bool((t[1:] > t[:-1]).all())):
        return np.ones(t.size, dtype=bool)
    prev_max = np.maximum.accumulate(np.concatenate(([last], t)))[:-1]
    return t > prev_max


class EstimatorInputs:
    """`guards`: the streams' guards (input_guards), shared with a pipeline that applies them as
    samples come in; None: built here."""

    def __init__(self, cfg: EstimatorConfig, guards: dict[str, StreamGuard] | None = None):
        self.cfg = cfg
        self.guards = input_guards(cfg) if guards is None else guards
        self.time_base = TimeBase(gap_s=2.0 * cfg.max_gap_s, max_jump_s=cfg.max_time_jump_s)
        self.temp = TemperatureRateEstimator(
            cfg.temp_window_s, stuck_after_s=cfg.temp_stuck_s, hold_max_s=cfg.temp_hold_max_s,
            timeout_s=cfg.temperature_timeout_s, max_rate_c_s=cfg.temperature_max_rate_c_s,
            checked=True, confirm_samples=cfg.time_jump_confirm_samples)
        self._last_t = {'mag': -math.inf, 'temperature': -math.inf}   # newest kept sample, internal time s
        self.dropped_old_time_base = {'mag': 0, 'temperature': 0}
        self.temp_fallback_c = cfg.temperature_ref_c   # the newest known temperature, degC
        self.mag_period = SamplePeriod()               # the compass's own sampling period
        self._mag_period_last = math.nan

    def _kept(self, admitted: bool, stream: str, t: np.ndarray, *values: np.ndarray) -> np.ndarray:
        """The rows of a stream's samples its guard keeps (all, when they were `admitted` by it)."""
        if admitted:
            return np.ones(t.size, dtype=bool)
        return self.guards[stream].keep(t, *values)

    def _internal(self, admitted: bool, stream: str, t: np.ndarray, *values: np.ndarray) -> tuple:
        """A compass or temperature stream's kept samples in internal time (the IMU's time base)."""
        keep = self._kept(admitted, stream, t, *values)
        t_in = self.time_base.other(stream, t[keep] if not keep.all() else t)
        values = tuple(v[keep] if not keep.all() else v for v in values)
        after = _after(t_in, self._last_t[stream])
        if not after.all():
            self.dropped_old_time_base[stream] += int(after.size - np.count_nonzero(after))
            t_in, values = t_in[after], tuple(v[after] for v in values)
        if t_in.size:
            self._last_t[stream] = float(t_in[-1])
        return (t_in,) + values

    def accept(self, chunk: SensorChunk, admitted: bool = False) -> AcceptedSamples:
        """`admitted`: every sample of `chunk` already passed its guard."""
        imu, mag = chunk.imu, chunk.mag
        if imu is not None:
            ok = self._kept(admitted, 'imu', imu.t, imu.gyro, imu.accel)
            # every sample kept (the usual chunk): the arrays as they are (read only downstream)
            t_imu, gyro, accel = (imu.t, imu.gyro, imu.accel) if ok.all() else (imu.t[ok], imu.gyro[ok], imu.accel[ok])
            t_imu = self.time_base.imu(t_imu)
        else:
            ok, t_imu, gyro, accel = np.zeros(0, bool), np.empty(0), np.empty((0, 3)), np.empty((0, 3))
        t_mag_before, period_before = self._last_t['mag'], self._mag_period_last
        t_mag, field = np.empty(0), np.empty((0, 3))
        if mag is not None and mag.t.size:
            t_mag, field = self._internal(admitted, 'mag', mag.t, mag.field)
        period = np.full(t_mag.size, np.nan)
        if t_mag.size:
            first = t_mag_before is not None and math.isfinite(t_mag_before)
            intervals = np.diff(np.concatenate(([t_mag_before], t_mag)) if first else t_mag)
            period[t_mag.size - intervals.size:] = self.mag_period.periods(intervals)
            period[:t_mag.size - intervals.size] = period_before
            self._mag_period_last = float(period[-1])
        return AcceptedSamples(ok, t_imu, gyro, accel, t_mag, field, t_mag_before, period, period_before)

    def temperature_at(self, samples: TemperatureSamples | None, t_imu: np.ndarray,
                       admitted: bool = False) -> TemperatureAtImu:
        """Temperature at the IMU stamps (s, internal time), causally (`admitted`: as in `accept`)."""
        if samples is not None and samples.t.size:
            samples = TemperatureSamples(*self._internal(admitted, 'temperature', samples.t, samples.temp_c))
        temp_c, rate, known = self.temp.update_at(samples, t_imu)
        if known.all():   # the usual case: a reading in force at every stamp
            if known.size:
                self.temp_fallback_c = float(temp_c[-1])
            return TemperatureAtImu(temp_c, rate, known)
        temp_c = np.where(known, temp_c, self.temp_fallback_c)
        if np.any(known):
            self.temp_fallback_c = float(temp_c[known][-1])
        return TemperatureAtImu(temp_c, rate, known)

    def age_s(self, t_now: float) -> float:
        """Time since the newest temperature reading at internal time t_now, s (inf: none yet)."""
        return math.inf if self.temp.last is None else max(t_now - self.temp.last[0], 0.0)

    def drift_sigma(self, sigma_d: float, t_now: float, temp_c: float, model: DriftModel, params: np.ndarray) -> float:
        """`sigma_d` (rad/s, docs/design.md eq. 14) widened while the temperature is stale: the held
        reading may be off by `temperature_drift_c_s` x its age, which reaches D through dD/dT."""
        age_s = self.age_s(t_now)
        if not self.cfg.temperature_timeout_s < age_s < math.inf:
            return sigma_d
        rows = model.rows(model.neutral_inputs([temp_c - 0.5, temp_c + 0.5]))
        d_dt = float((rows[1] - rows[0]) @ params)          # rad/s per degC
        return math.hypot(sigma_d, d_dt * self.cfg.temperature_drift_c_s * age_s)

    def counters(self) -> dict[str, int]:
        return {**self.guards['imu'].counters(), **self.guards['mag'].counters(),
                **self.guards['temperature'].counters(),
                'mag_dropped_old_time_base': self.dropped_old_time_base['mag'],
                'temperature_dropped_old_time_base': self.dropped_old_time_base['temperature'],
                'temperature_dropped_rate': self.temp.dropped_rate, 'time_base_changes': self.time_base.changes}
