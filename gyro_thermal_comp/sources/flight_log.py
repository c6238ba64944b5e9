"""What PX4 ULog and ArduPilot DataFlash readers share: several IMUs to choose from, each with its own
temperature, accel and gyro at their own stamps, FRD axes, boot-time stamps that GPS may date.

A reader collects `ImuCandidate`s (one per IMU instance) and magnetometers, then `FlightLogSource`
picks one (`--imu N`, default the first with a usable temperature), says which and what the others
were, puts the accelerometer on the gyro's stamps (linear interpolation: the two are sampled by one
chip, microseconds apart), converts FRD to FLU (a proper rotation, det +1) and cleans the streams.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..samples import ImuSamples, MagSamples, TemperatureSamples
from . import checks, frames
from .base import ArraySource, SourceError
from .cleaning import clean, decimate_temperature
from .timebase import format_utc

FRD = frames.axes_matrix('FRD')


@dataclass
class ImuCandidate:
    instance: int
    origin: str                     # e.g. 'sensor_gyro[1]', 'IMU I=0'
    t_us: np.ndarray                # gyro stamps, us since boot
    gyro: np.ndarray                # (n, 3) rad/s, FRD
    accel_t_us: np.ndarray
    accel: np.ndarray               # (m, 3) m/s^2, FRD
    temp_t_us: np.ndarray | None = None
    temp_c: np.ndarray | None = None

    def temperature_usable(self) -> bool:
        """A temperature that exists, is finite somewhere and is not a constant placeholder (a
        simulated IMU logs 0)."""
        if self.temp_c is None or not len(self.temp_c):
            return False
        finite = self.temp_c[np.isfinite(self.temp_c)]
        return finite.size > 0 and float(np.ptp(finite)) > 0.0

    def summary(self) -> str:
        rate = (len(self.t_us) - 1) / ((self.t_us[-1] - self.t_us[0]) * 1e-6) if len(self.t_us) > 1 and \
            self.t_us[-1] > self.t_us[0] else 0.0
        text = f'{self.origin} {rate:.4g} Hz'
        if self.temperature_usable():
            finite = self.temp_c[np.isfinite(self.temp_c)]
            text += f', {finite.min():.1f}..{finite.max():.1f} degC'
        else:
            text += ', no temperature'
        return text


class FlightLogSource(ArraySource):
    """Streams of one chosen IMU and one magnetometer of a flight log (FLU, SI, s since the first)."""

    def __init__(self, path, imus: list[ImuCandidate], mags: list[tuple[str, np.ndarray, np.ndarray]],
                 imu: int | None, utc_offset_us: int | None, metadata: dict):
        super().__init__(path)
        self.metadata = metadata
        if not imus:
            raise SourceError(f'{self.label} {self.path} has no IMU with both gyro and accelerometer data')
        chosen = self._choose(imus, imu)
        others = [c.summary() for c in imus if c is not chosen]
        self.notes.append(f'IMU {chosen.instance} of {len(imus)}: {chosen.summary()}'
                          + (f'; others: {"; ".join(others)} (choose with --imu N)' if others else ''))
        offset_us = 0 if utc_offset_us is None else int(utc_offset_us)
        if utc_offset_us is None:
            self.notes.append('no GPS time in the log: stamps are time since boot')
        to_ns = lambda t_us: (np.asarray(t_us, np.int64) + offset_us) * 1000   # noqa: E731
        t_ns = to_ns(chosen.t_us)
        self.time_origin_ns = int(t_ns[0]) if len(t_ns) else 0
        sec = lambda ns: (ns - self.time_origin_ns) * 1e-9   # noqa: E731
        accel = np.column_stack([np.interp(chosen.t_us, chosen.accel_t_us, chosen.accel[:, k]) for k in range(3)])
        inside = (chosen.t_us >= chosen.accel_t_us[0]) & (chosen.t_us <= chosen.accel_t_us[-1])
        self.dropped.add('imu', 'gyro outside the accelerometer span', int((~inside).sum()))
        imu_s = ImuSamples(sec(t_ns[inside]), frames.rotate_rows(FRD, chosen.gyro[inside]),
                           frames.rotate_rows(FRD, accel[inside]))
        temp_s = None
        if chosen.temperature_usable():
            temp_s, note = decimate_temperature(clean('temperature', TemperatureSamples(
                sec(to_ns(chosen.temp_t_us)), chosen.temp_c), self.dropped))
            if note:
                self.notes.append(note)
        else:
            self.notes.append(f'IMU {chosen.instance} logs no usable temperature: no temperature stream')
        mag_s = None
        if mags:
            origin, m_t_us, m_field = mags[0]
            mag_s = MagSamples(sec(to_ns(m_t_us)), frames.rotate_rows(FRD, m_field))
            self.notes.append(f'magnetometer {origin}' + (f' (first of {len(mags)})' if len(mags) > 1 else ''))
        self.streams = {'imu': clean('imu', imu_s, self.dropped), 'mag': clean('mag', mag_s, self.dropped),
                        'temperature': temp_s}
        if self.streams['imu'] is None:
            raise SourceError(f'{self.label} {self.path}: IMU {chosen.instance} has no finite sample')
        self.origins = {'imu': chosen.origin, 'temperature': chosen.origin + ' temperature'}
        if mags:
            self.origins['mag'] = mags[0][0]
        checks.check_streams(self.streams['imu'], self.streams['mag'], temp_s, where=f'{self.label} {self.path}')
        self.notes.append(f'axes FRD -> FLU; {format_utc(self.time_origin_ns)} + {self.duration_s:.1f} s')

    def _choose(self, imus: list[ImuCandidate], wanted: int | None) -> ImuCandidate:
        if wanted is not None:
            for c in imus:
                if c.instance == wanted:
                    return c
            raise SourceError(f'{self.label} {self.path} has no IMU {wanted} (it has: '
                              f'{", ".join(str(c.instance) for c in imus)})')
        usable = [c for c in imus if c.temperature_usable()]
        return usable[0] if usable else imus[0]
