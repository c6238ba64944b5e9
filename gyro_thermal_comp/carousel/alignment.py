"""Alignment: the main IMU waits for the encoder, the auxiliary IMU and (when an angle reference uses
it) the magnetometer, whose values are then interpolated to its stamps.

A stream is waited for only while it is alive (silent for at most its timeout, in IMU time), so a
missing encoder costs `encoder_timeout_s` of latency at start-up and nothing after. The magnetometer
is interpolated linearly like the encoder: a field turning at the spin rate between two mag samples
is shortened by the chord (at 2 Hz spin and 50 Hz mag ~0.5 % in strength, well inside the gate), and
its hard iron, constant in the sensor, passes exactly.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..samples import SensorChunk
from .blocks import AlignedBlock, EncoderBlock, ImuBlock, MagBlock
from .buffers import Columns
from .config import CarouselConfig

# Magnetometer stream (no settings: a mag is 10-100 Hz): silent this long (IMU time) -> not waited for,
# samples further apart are not interpolated across, s.
MAG_TIMEOUT_S = 0.5
MAG_MAX_GAP_S = 0.25


@dataclass(frozen=True)
class Bracket:
    """Where stamps fall in a sampled stream, for linear interpolation between its samples."""
    lower: np.ndarray     # index of the stream sample before each stamp (clipped to the stream)
    frac: np.ndarray      # position between samples lower and lower + 1, 0..1
    ok: np.ndarray        # bracketed by samples at most max_gap apart
    single: bool          # the stream has one sample: it is valid only at its own stamp

    @classmethod
    def locate(cls, stream_t: np.ndarray, t: np.ndarray, max_gap_s: float) -> Bracket:
        if len(stream_t) < 2:
            ok = t == stream_t[0] if len(stream_t) else np.zeros(len(t), bool)
            return cls(np.zeros(len(t), int), np.zeros(len(t)), ok, True)
        j = np.clip(np.searchsorted(stream_t, t, side='right') - 1, 0, len(stream_t) - 2)
        span = stream_t[j + 1] - stream_t[j]
        ok = (t >= stream_t[0]) & (t <= stream_t[-1]) & (span <= max_gap_s)
        return cls(j, np.clip((t - stream_t[j]) / span, 0.0, 1.0), ok, False)

    def at(self, values: np.ndarray) -> np.ndarray:
        """Stream column `values` interpolated at the stamps."""
        if self.single:
            return np.broadcast_to(values[0], (len(self.ok),) + values.shape[1:]).copy()
        j = self.lower
        f = self.frac.reshape((-1,) + (1,) * (values.ndim - 1))
        return values[j] + f * (values[j + 1] - values[j])


class StreamAligner:
    """Holds main-IMU samples until the encoder (and, with the flip, the aux IMU) covers them."""

    def __init__(self, config: CarouselConfig):
        self.config = config
        self._aux_to_platform = np.asarray(config.flip.aux_to_platform, dtype=float).reshape(3, 3)
        self._pending = Columns(ImuBlock)
        self._encoder = Columns(EncoderBlock)
        self._aux = Columns(ImuBlock)          # platform frame
        self._use_mag = config.reads_mag
        self._mag = Columns(MagBlock)
        self._imu_first_t = np.inf
        self._encoder_seen = False

    def add(self, clean: SensorChunk) -> None:
        """Guarded samples of the IMU, encoder and aux streams (an absent stream is None)."""
        if clean.imu is not None and len(clean.imu.t):
            self._imu_first_t = min(self._imu_first_t, float(clean.imu.t[0]))
            self._pending.append(ImuBlock(t=clean.imu.t, gyro=clean.imu.gyro, accel=clean.imu.accel))
        if clean.joint is not None and len(clean.joint.t):
            self._encoder_seen = True
            self._encoder.append(EncoderBlock(t=clean.joint.t, position=clean.joint.position,
                                              velocity=clean.joint.velocity))
        if clean.imu_aux is not None and len(clean.imu_aux.t):
            m = self._aux_to_platform
            self._aux.append(ImuBlock(t=clean.imu_aux.t, gyro=clean.imu_aux.gyro @ m.T,
                                      accel=clean.imu_aux.accel @ m.T))
        if self._use_mag and clean.mag is not None and len(clean.mag.t):
            self._mag.append(MagBlock(t=clean.mag.t, field=clean.mag.field))

    def batch_ready(self) -> bool:
        """Enough IMU time pending to be worth a pass through the pipeline (`min_batch_s`)."""
        t = self._pending.t
        return bool(len(t)) and t[-1] - t[0] >= self.config.min_batch_s

    def releasable(self, final: bool) -> int:
        """How many pending IMU samples every stream still waited for already covers."""
        cfg = self.config
        n = len(self._pending)
        if n == 0 or final:
            return n
        t = self._pending.t
        if cfg.angle_source == 'auto' and not self._encoder_seen:
            # Startup: give an encoder the chance to show up before settling for the gyro angle.
            if t[-1] - self._imu_first_t < cfg.encoder_timeout_s:
                return 0
        waited = [(self._encoder, cfg.encoder_timeout_s)]
        if cfg.flip.enabled:
            waited.append((self._aux, cfg.flip.aux_timeout_s))
        if self._use_mag:
            waited.append((self._mag, MAG_TIMEOUT_S))
        frontier = np.inf
        for stream, timeout in waited:
            if len(stream):
                last = stream.t[-1]
                if t[-1] - last <= timeout:      # stream alive: wait until it covers the IMU
                    frontier = min(frontier, last)
        return int(np.searchsorted(t, frontier, side='right'))

    def release(self, n: int) -> AlignedBlock:
        """The n oldest pending IMU samples with the encoder and aux values at their stamps."""
        imu = self._pending.take_front(n)
        t = imu.t
        angle, rate, encoder_ok = np.zeros(n), np.zeros(n), np.zeros(n, bool)
        encoder = self._encoder.view()
        at = Bracket.locate(encoder.t, t, self.config.encoder_max_gap_s)
        if np.any(at.ok):
            velocity = at.at(encoder.velocity)
            if len(encoder.t) >= 2:     # JointState velocity may be absent: use the position slope
                j = at.lower
                slope = (encoder.position[j + 1] - encoder.position[j]) / (encoder.t[j + 1] - encoder.t[j])
                velocity = np.where(np.isfinite(velocity), velocity, slope)
            else:
                velocity = np.where(np.isfinite(velocity), velocity, 0.0)
            angle = np.where(at.ok, at.at(encoder.position), 0.0)
            rate = np.where(at.ok, velocity, 0.0)
            encoder_ok = at.ok
        if len(self._encoder):
            self._encoder.drop_before(t[-1])
        aux_gyro, aux_accel, aux_ok = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros(n, bool)
        if self.config.flip.enabled:
            aux = self._aux.view()
            at = Bracket.locate(aux.t, t, self.config.flip.aux_max_gap_s)
            if np.any(at.ok):
                aux_gyro = np.where(at.ok[:, None], at.at(aux.gyro), 0.0)
                aux_accel = np.where(at.ok[:, None], at.at(aux.accel), 0.0)
                aux_ok = at.ok
            if len(self._aux):
                self._aux.drop_before(t[-1])
        mag, mag_ok = np.zeros((n, 3)), np.zeros(n, bool)
        if self._use_mag and len(self._mag):
            at = Bracket.locate(self._mag.t, t, MAG_MAX_GAP_S)
            if np.any(at.ok):
                mag = np.where(at.ok[:, None], at.at(self._mag.view().field), 0.0)
                mag_ok = at.ok
            self._mag.drop_before(t[-1])
        return AlignedBlock(t=t, gyro=imu.gyro, accel=imu.accel, encoder_angle=angle, encoder_rate=rate,
                            encoder_ok=encoder_ok, aux_gyro=aux_gyro, aux_accel=aux_accel, aux_ok=aux_ok,
                            mag=mag, mag_ok=mag_ok)
