"""`OutputRows` and `ThermalOutput`: one output row per input IMU sample, including dropped ones."""
from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from ..heading_track import HeadingTrack
from .compass_blocks import HeadingColumns
from .imu_stretch import ImuStretch
from .reasons import REASON_BIT
from .sampling import TIMEOUT_PERIODS


@dataclass(frozen=True)
class ThermalOutput:
    """Per IMU sample: the heading track plus what a ROS node publishes."""
    track: HeadingTrack
    gyro_compensated: np.ndarray   # (N, 3) rad/s: z minus D_hat, x/y minus still-period bias
    temperature_c: np.ndarray      # (N,) smoothed, NaN before any temperature arrived
    temperature_rate_c_s: np.ndarray
    roll_rad: np.ndarray
    pitch_rad: np.ndarray
    gate_open: np.ndarray          # (N,) bool
    reasons: np.ndarray            # (N,) bit mask over REASONS
    params: np.ndarray             # (N, n) drift-model parameters in force
    param_sigmas: np.ndarray       # (N, n)
    valid: np.ndarray              # (N,) False where the input row was dropped
    drift_per_rate: np.ndarray     # (N,) dD/dw of the measured z rate (scale-factor terms), 1
    drift_trend_rad_s2: np.ndarray  # (N,) how D_hat goes on with the temperature's trend, rad/s^2


@dataclass(frozen=True)
class OutputRows:
    """Per-sample output columns (N rows)."""
    heading: np.ndarray       # rad, wrapped
    sigma: np.ndarray         # rad
    d_hat: np.ndarray         # rad/s
    open: np.ndarray          # bool
    reasons: np.ndarray       # int64 mask over reasons.REASONS
    temp: np.ndarray          # degC, NaN before any reading
    temp_rate: np.ndarray     # degC/s
    roll: np.ndarray          # rad
    pitch: np.ndarray         # rad
    wc: np.ndarray            # (N, 3) rad/s
    params: np.ndarray        # (N, n)
    gap: np.ndarray           # bool
    k_rate: np.ndarray        # dD/dw, 1
    d_dot: np.ndarray         # rad/s^2

    @classmethod
    def of_stretch(cls, s: ImuStretch, h: HeadingColumns, k_rate: np.ndarray, d_dot: np.ndarray) -> 'OutputRows':
        return cls(heading=h.heading, sigma=h.sigma, d_hat=s.d_hat, open=h.open, reasons=h.reasons,
                   temp=np.where(s.temp_known, s.temp, np.nan), temp_rate=s.temp_rate, roll=s.roll,
                   pitch=s.pitch, wc=s.wc, params=s.params[None, :].repeat(len(s), axis=0), gap=s.gap,
                   k_rate=k_rate, d_dot=d_dot)

    @classmethod
    def concat(cls, parts: list['OutputRows']) -> 'OutputRows':
        if len(parts) == 1:
            return parts[0]
        return cls(*(np.concatenate([getattr(p, name) for p in parts]) for name in _ROW_FIELDS))

    @classmethod
    def initial(cls, params: np.ndarray) -> 'OutputRows':
        """What a sample dropped before any good one shows: unknown heading, no compass."""
        return cls(np.zeros(1), np.full(1, math.pi), np.zeros(1), np.zeros(1, bool), np.zeros(1, np.int64),
                   np.full(1, np.nan), np.zeros(1), np.zeros(1), np.zeros(1), np.zeros((1, 3)),
                   np.asarray(params, dtype=float).reshape(1, -1), np.zeros(1, bool), np.zeros(1), np.zeros(1))

    def __len__(self) -> int:
        return self.heading.size

    def last(self) -> 'OutputRows':
        return OutputRows(*(getattr(self, name)[-1:] for name in _ROW_FIELDS))

    def flagged(self, t: np.ndarray, last_mag_t: np.ndarray, mag_timeout_s: float, still_end_s: float,
                temperature_stuck: bool, first_temperature_t: float = np.inf) -> 'OutputRows':
        """With the estimator's own reasons added; no compass for `mag_timeout_s` closes the gate;
        no temperature after there had been one is `temperature_stale`."""
        if not t.size:
            return self
        # each flag only where it can be set (stamps increase): most chunks have none at all
        no_mag = t - last_mag_t > mag_timeout_s
        flags = [(no_mag, REASON_BIT['no_compass'])] if no_mag.any() else []
        if self.gap.any():
            flags.append((self.gap, REASON_BIT['time_gap']))
        if t[0] < still_end_s:
            flags.append((t < still_end_s, REASON_BIT['still_period']))
        if t[-1] >= first_temperature_t:
            stale = np.isnan(self.temp)
            if stale.any():
                flags.append((stale & (t >= first_temperature_t), REASON_BIT['temperature_stale']))
        if not flags and not temperature_stuck:
            return self
        reasons = self.reasons
        for flag, bit in flags:
            reasons = reasons | np.where(flag, bit, 0)
        if temperature_stuck:
            reasons = reasons | REASON_BIT['temperature_stuck']
        return _replace(self, reasons=reasons, open=self.open & ~no_mag)

    @staticmethod
    def fill_dropped(good: 'OutputRows | None', ok: np.ndarray, before: 'OutputRows') -> 'OutputRows':
        """Rows for every input sample (`ok` marks the accepted ones, whose rows are `good`): a
        dropped one holds the latest good row before it (from `good`, or `before`: one row),
        flagged `dropped_input`."""
        pos = np.cumsum(ok) - 1
        cols = {}
        for name in _ROW_FIELDS:
            fill = getattr(before, name)[0]
            if good is None:
                col = np.broadcast_to(fill, (ok.size,) + np.shape(fill)).copy()
            else:
                col = getattr(good, name)[np.maximum(pos, 0)]
                col[pos < 0] = fill
            cols[name] = col
        cols['reasons'] = np.where(ok, cols['reasons'], cols['reasons'] | REASON_BIT['dropped_input'])
        return OutputRows(**cols)


def _replace(rows: OutputRows, **changes) -> OutputRows:
    return OutputRows(**{name: changes.get(name, getattr(rows, name)) for name in _ROW_FIELDS})


_ROW_FIELDS = tuple(f.name for f in fields(OutputRows))   # once: dataclasses.fields is slow per call


class OutputAssembler:
    """Builds each call's `ThermalOutput`; remembers the latest good row for dropped samples."""

    def __init__(self, mag_timeout_s: float):
        self.mag_timeout_s = mag_timeout_s
        self._good: OutputRows | None = None   # the latest call's accepted rows
        self._last: OutputRows | None = None   # their last row (built when asked for)

    @property
    def latest(self) -> 'OutputRows | None':
        """The newest accepted sample's row (one row), None before any."""
        if self._last is None and self._good is not None:
            self._last = self._good.last()
        return self._last

    def assemble(self, parts: list[OutputRows], ok: np.ndarray, t_all: np.ndarray | None, t_good: np.ndarray,
                 last_mag_t: np.ndarray, still_end_s: float, temperature_stuck: bool, params: np.ndarray,
                 param_sigmas: np.ndarray, first_temperature_t: float = np.inf,
                 mag_period_s: np.ndarray | None = None) -> ThermalOutput:
        """`parts`: rows of the accepted samples (stamps `t_good`, s), `ok`: which input rows
        (stamps `t_all`) were accepted; `last_mag_t`: latest compass stamp at each accepted one, and
        the compass's sampling period there (s, NaN unknown): no compass for `TIMEOUT_PERIODS` of
        them, as well as for `mag_timeout_s`, is no compass."""
        n_rows, n_par = ok.size, params.size
        timeout = self.mag_timeout_s if mag_period_s is None else \
            np.fmax(self.mag_timeout_s, TIMEOUT_PERIODS * mag_period_s)
        good = OutputRows.concat(parts).flagged(t_good, last_mag_t, timeout, still_end_s,
                                                temperature_stuck, first_temperature_t) if parts else None
        if good is not None and len(good) == n_rows:
            rows = good  # nothing dropped: the common case
        else:
            rows = OutputRows.fill_dropped(good, ok, self.latest or OutputRows.initial(params))
        if good is not None:
            self._good, self._last = good, None
        track = HeadingTrack(t=np.empty(0) if t_all is None else t_all.copy(), heading_rad=rows.heading,
                             drift_rad_s=rows.d_hat, heading_sigma_rad=rows.sigma, coasting=~rows.open)
        return ThermalOutput(track=track, gyro_compensated=rows.wc.reshape(n_rows, 3), temperature_c=rows.temp,
                             temperature_rate_c_s=rows.temp_rate, roll_rad=rows.roll, pitch_rad=rows.pitch,
                             gate_open=rows.open, reasons=rows.reasons, params=rows.params.reshape(n_rows, n_par),
                             param_sigmas=param_sigmas[None, :].repeat(n_rows, axis=0), valid=ok.copy(),
                             drift_per_rate=rows.k_rate, drift_trend_rad_s2=rows.d_dot)
