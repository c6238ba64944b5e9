"""Carousel rotation-modulation demodulator (docs/design.md section 3; Kolesnyk & Chernyak, KPI 2023).

An IMU turns about its sensor z axis (the spin axis). Sensor-fixed in-plane errors then appear in the
body frame as a vector turning at the spin rate and average out over every whole revolution. This
core turns a stream of `SensorChunk`s into:

- one record per revolution (the paper's scheme): body-frame mean rate and specific force, the
  spin rate from the revolution period (subtracted from the axial gyro), the axial residual, and the
  current in-plane bias estimates; or pass-through records with a reason whenever rotation is too
  slow, irregular or interrupted, so output never stops;
- per-revolution in-plane gyro bias measurements for a thermal drift estimator (no compass needed);
- optionally every sample rotated into the body frame with the lock-in bias estimates removed.

Angle: the encoder (JointSamples.position, unwrapped rad, platform relative to body about +z) when
present, else the integrated axial gyro. Without an encoder the spin rate and the body's yaw rate
cannot be told apart from the axial gyro alone: the revolution period then includes body yaw and
the axial bias, and the axial output is ~0 unless `nominal_spin_rate_rad_s` is given (docs/carousel.md).

Pure numpy; no ROS imports. Pipeline, one module each: input hygiene (buffers.InputGuards) ->
alignment with the encoder/aux streams (alignment.StreamAligner: the main IMU waits for them,
bounded by timeouts) -> flip tracking (flip_stage.FlipStage, look-ahead guard_s) -> revolution core
(revolution_core.RevolutionCore) -> output records (record_assembly.RecordAssembler).
"""
from __future__ import annotations

from collections import Counter

import numpy as np

from ..samples import SensorChunk
from .alignment import StreamAligner
from .angle_reference import GravityAngleFilter
from .bias_book import SensorBiasBook
from .buffers import InputGuards
from .config import CarouselConfig
from .flip_stage import FlipStage
from .record_assembly import RecordAssembler
from .records import (DEMODULATED, PASS_THROUGH, DemodulatedOutput, GyroBiasMeasurement, HighRateSamples,
                      Outbox, RevolutionRecord, records_as_arrays)
from .revolution_core import RevolutionCore
from .spin_coupling import EARTH_AVERAGE_S, SpinCoupling
from .still_start import StillStart
from .temperature import TemperatureTrack

__all__ = ['CarouselDemodulator', 'DemodulatedOutput', 'GyroBiasMeasurement', 'HighRateSamples',
           'RevolutionRecord', 'records_as_arrays', 'DEMODULATED', 'PASS_THROUGH']


class CarouselDemodulator:
    """Streaming demodulator: `update(chunk)` with chunks of any size, in time order; `flush()` at
    the end of data. Bad samples are dropped and counted (`counts`); outputs never contain NaN."""

    def __init__(self, config: CarouselConfig | None = None):
        self.config = cfg = config or CarouselConfig()
        self.book = SensorBiasBook(cfg.flip.axis)     # current bias estimates, shared by the stages
        self._events: Counter = Counter()            # gaps, records and revolutions by kind, ...
        self._outbox = Outbox()
        self._guards = InputGuards(use_mag=cfg.reads_mag, use_joint=cfg.angle_source == 'auto',
                                   use_aux=cfg.flip.enabled)
        self._aligner = StreamAligner(cfg)
        self._flip = FlipStage(cfg.flip, self.book)
        self._temperature = TemperatureTrack(cfg.temperature_rate_window_s)
        self.gravity = GravityAngleFilter(cfg)         # gyro angle corrected from gravity (no encoder)
        self.coupling = SpinCoupling(cfg)              # in-plane gyro bias vs spin rate, for the output at rest
        self.still = StillStart(cfg)                   # the start-up still stretch teaches both
        self.still.on_close(self.gravity.on_still)
        self.still.on_close(self.coupling.on_still)
        self._records = RecordAssembler(cfg, self.book, self._temperature, self._outbox, self._events,
                                        flip_position=lambda: self._flip.position, gravity=self.gravity,
                                        coupling=self.coupling)
        self._core = RevolutionCore(cfg, self.book, self._records, self._outbox, self._events, self.gravity,
                                    self.still)

    def admit(self, stream: str, t: float, row) -> bool:
        """A node's one sample of `stream` (its row layout, nodes/conversions.py) past the stream's
        guard: True if kept. A chunk of kept samples then goes to `update(chunk, admitted=True)`."""
        return self._guards.admit(stream, t, row)

    def update(self, chunk: SensorChunk, admitted: bool = False) -> DemodulatedOutput:
        """`admitted`: every sample of `chunk` passed `admit` (it is not checked again)."""
        clean = self._guards.clean(chunk, admitted)
        self._aligner.add(clean)
        self._temperature.add(clean.temperature)
        if self._aligner.batch_ready():      # output does not depend on batching
            self._pump(final=False)
        return self._drain()

    def flush(self) -> DemodulatedOutput:
        """Process everything still held back (waiting for encoder/aux data or flip look-ahead) and
        close the last partial interval as a pass-through record."""
        self._pump(final=True)
        self._core.finish()
        return self._drain()

    @property
    def mode(self) -> str:
        return self._records.mode

    @property
    def reason(self) -> str:
        return self._records.reason

    @property
    def angle_reference(self) -> str:
        """Where the angle comes from and, without an encoder, whether gravity (or the magnetometer) corrects it."""
        if self._core.angle_source_name == 'encoder':
            return 'encoder'
        return f'gyro; {self.gravity.status}' if self.gravity.enabled else 'gyro (angle_reference none)'

    @property
    def spin_coupling(self) -> str:
        c = self.coupling
        if not self.config.spin_coupling or self.config.flip.enabled:
            return 'off'
        if not c.known and c.waiting_s is not None:
            return (f'learning: still start waits for the Earth-rate average ({c.waiting_s:.0f} of '
                    f'{max(self.still.duration_s, EARTH_AVERAGE_S):.0f} s of revolutions, or the first stop)')
        if not c.known:
            return (f'not learnt ({c.revolutions} revolutions; still start: {self.still.reason}; needs two spin '
                    'rates)')
        k = c.x[1]
        return (f'k = {k.real:.3g} / {k.imag:.3g} (x / y), sigma {np.sqrt(c.p[1, 1]):.2g}; removed at rest')

    @property
    def counts(self) -> Counter:
        """Cumulative diagnostics: input counters (`<stream>_dropped_nonfinite`, `<stream>_dropped_order`)
        and events (`gaps`, `angle_source_switches`, `revolutions_*`, `records_*`, `nonfinite_records`); with
        the gravity_mag angle reference also `mag_*` (the magnetometer gate: revolutions passed, rejected by reason)."""
        mag = self.gravity.mag.counts if self.gravity.mag.enabled else {}     # the magnetometer gate's reasons
        return Counter({**self._guards.counters(), **self._events, **mag})

    def _pump(self, final: bool) -> None:
        while True:
            n = min(self._aligner.releasable(final), self.config.max_block_samples)
            if n == 0:
                break
            self._core.ingest(self._flip.process(self._aligner.release(n), final=False))
        if final:
            self._core.ingest(self._flip.process(None, final=True))

    def _drain(self) -> DemodulatedOutput:
        return self._outbox.drain(flip_events=self._flip.new_events(), mode=self.mode, reason=self.reason,
                                  counts=dict(self.counts))
