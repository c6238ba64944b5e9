"""Revolution core: platform-frame samples -> carousel angle -> revolution boundaries -> intervals.

Output intervals tile time: each closes at a revolution boundary, or every `pass_through_period_s`
while no boundary comes (a stall), or before a data gap, or at the end of data. A data gap or a
change of angle source restarts boundary tracking, since the angle cannot be continued across it.
"""
from __future__ import annotations

from collections import Counter
import numpy as np

from .angle import CarouselAngle
from .angle_reference import GravityAngleFilter
from .applied_correction import STEP_S
from .bias_book import SensorBiasBook
from .blocks import ANGLE_SOURCE_NAMES, ENCODER, GYRO, CoreBlock, PlatformBlock
from .buffers import Columns
from .config import CarouselConfig
from .record_assembly import RecordAssembler
from .records import HighRateSamples, Outbox
from .revolutions import Crossing, RevolutionLadder
from .still_start import StillStart

MIN_INTERVAL_S = 1e-9          # shorter intervals are not reported


class RevolutionCore:
    """Decides where output intervals end; `RecordAssembler` turns each into a record."""

    def __init__(self, config: CarouselConfig, book: SensorBiasBook, records: RecordAssembler, outbox: Outbox,
                 counts: Counter, gravity: GravityAngleFilter, still: StillStart):
        self.config = config
        self._gravity = gravity                  # corrects the gyro angle (no encoder)
        self._still = still                      # the start-up still stretch
        self._book = book
        self._records = records
        self._outbox = outbox
        self._counts = counts
        self._carousel_to_body = np.asarray(config.carousel_to_body, dtype=float).reshape(3, 3)
        self._samples = Columns(CoreBlock)       # from the start of the open interval on
        self._ladder = RevolutionLadder(config.boundary_phase_rad)
        self._angle = CarouselAngle(config)
        self._last_t: float | None = None         # newest sample ingested
        self._angle_source: int | None = None     # ENCODER | GYRO of the newest sample
        self._t_open: float | None = None         # start of the interval not yet reported
        self._revolution_start: Crossing | None = None
        self._stalled = False
        self._restart_reason = ''

    @property
    def angle_source_name(self) -> str | None:
        return None if self._angle_source is None else ANGLE_SOURCE_NAMES[self._angle_source]

    def ingest(self, block: PlatformBlock | None) -> None:
        """Samples in time order, cut into runs of one angle source without data gaps."""
        if block is None or len(block) == 0:
            return
        t = block.t
        angle_source = np.where(block.encoder_ok, ENCODER, GYRO).astype(np.int8)
        prev_t = -np.inf if self._last_t is None else self._last_t
        prev_source = angle_source[0] if self._angle_source is None else self._angle_source
        dt = np.diff(np.concatenate(([prev_t], t)))
        gap = dt > self.config.max_gap_s
        switch = angle_source != np.concatenate(([prev_source], angle_source[:-1]))
        if self._last_t is None:
            gap[0] = False
        cuts = np.flatnonzero(gap | switch)
        bounds = np.concatenate(([0], cuts[cuts > 0], [len(t)]))
        for s, e in zip(bounds[:-1], bounds[1:]):
            if s in cuts and self._last_t is not None:
                if gap[s]:
                    self._counts['gaps'] += 1
                    self._gravity.reset(float(dt[s]))
                    self._still.close()
                    self._restart(f'data gap of {dt[s]:.3f} s', gap=True)
                else:
                    self._counts['angle_source_switches'] += 1
                    names = ANGLE_SOURCE_NAMES
                    self._restart(f'angle source changed ({names[self._angle_source]} -> {names[angle_source[s]]})',
                                  gap=False)
            self._append_run(block.rows(slice(s, e)), int(angle_source[s]))

    def finish(self) -> None:
        """End of data: close the last partial interval as a pass-through record."""
        if self._t_open is not None and self._last_t is not None and self._last_t - self._t_open > MIN_INTERVAL_S:
            self._pass_through(self._t_open, self._last_t, 'end of data: partial revolution')
            self._t_open = self._last_t

    def _pass_through(self, ta: float, tb: float, reason: str) -> None:
        source = ENCODER if self._angle_source is None else self._angle_source
        self._records.report_pass_through(self._samples.view(), ta, tb, reason, source)

    def _restart(self, reason: str, gap: bool) -> None:
        """Forget the revolution in progress. After a gap the data before it is closed as a pass-through
        record (the gap itself is not covered); after an angle-source switch the samples stay and the
        next record simply spans the switch (the angle may jump, so no revolution can straddle it)."""
        if gap:
            if self._t_open is not None and self._last_t - self._t_open > MIN_INTERVAL_S:
                self._pass_through(self._t_open, self._last_t, reason)
            self._t_open = None
            self._samples.clear()
        self._ladder.reset()
        self._revolution_start = None
        self._stalled = False
        self._angle.reset()
        self._restart_reason = reason

    def _append_run(self, run: PlatformBlock, angle_source: int) -> None:
        if angle_source == GYRO and self._gravity.enabled:
            # the angle depends on what earlier revolutions taught the filter: step on a fixed time grid
            cut = np.flatnonzero(np.diff(np.floor(run.t / STEP_S)) > 0) + 1
            for s, e in zip(np.concatenate(([0], cut)), np.concatenate((cut, [len(run.t)]))):
                self._append_piece(run.rows(slice(int(s), int(e))), angle_source)
        else:
            self._append_piece(run, angle_source)

    def _append_piece(self, run: PlatformBlock, angle_source: int) -> None:
        t = run.t
        if angle_source == ENCODER:
            angle = self._angle.from_encoder(run.encoder_angle, run.encoder_rate)
        else:
            bias = self._book.per_sample(run.source, run.position)
            axial = run.gyro[:, 2] - bias.gyro[:, 2]
            angle = self._angle.from_gyro(t, axial, self._gravity.correction if self._gravity.enabled else None)
        self._still.add(t, run.gyro, run.accel, angle.raw, run.mag, run.mag_ok)
        samples = CoreBlock(t=t, theta=angle.theta, spin=angle.spin, gyro=run.gyro, accel=run.accel,
                            source=run.source, position=run.position, aux_gyro=run.aux_gyro,
                            aux_accel=run.aux_accel, aux_ok=run.aux_ok, mag=run.mag, mag_ok=run.mag_ok)
        self._samples.append(samples)
        self._last_t, self._angle_source = float(t[-1]), angle_source
        if self._t_open is None:
            self._t_open = float(t[0])
        done = 0
        for crossing in self._ladder.process(t, angle.theta):
            # Samples up to a boundary get the estimates known before it, however the data is chunked.
            upto = int(np.searchsorted(t, crossing.t_s, side='right'))
            self._emit_high_rate(samples, done, upto)
            done = upto
            self._advance_stall(crossing.t_s)
            self._on_boundary(crossing)
        self._emit_high_rate(samples, done, len(t))
        self._advance_stall(float(t[-1]))

    def _emit_high_rate(self, run: CoreBlock, i0: int, i1: int) -> None:
        if not self.config.high_rate or i1 <= i0:
            return
        samples = run.rows(slice(i0, i1))
        bias = self._book.per_sample(samples.source, samples.position)
        self._outbox.high_rate.append(HighRateSamples.from_platform(
            samples.t, samples.theta, samples.spin, samples.gyro - bias.gyro, samples.accel - bias.accel,
            samples.source, self._carousel_to_body))

    def _advance_stall(self, t_data: float) -> None:
        """Without a boundary for max_revolution_period_s, report pass-through intervals up to t_data."""
        cfg = self.config
        if self._t_open is None:
            return
        if not self._stalled and t_data - self._t_open > cfg.max_revolution_period_s:
            self._stalled = True
        if self._stalled:
            if self._revolution_start is None:
                why = (f'no revolution boundary within {cfg.max_revolution_period_s:g} s: '
                       'rotation too slow or stopped')
                if self._restart_reason:
                    why += f' (after {self._restart_reason})'
            else:
                why = f'rotation too slow: no full revolution within {cfg.max_revolution_period_s:g} s'
            while self._t_open + cfg.pass_through_period_s <= t_data + MIN_INTERVAL_S:
                t_end = self._t_open + cfg.pass_through_period_s
                self._pass_through(self._t_open, t_end, why)
                self._t_open = t_end
            self._samples.drop_before(self._t_open)

    def _on_boundary(self, crossing: Crossing) -> None:
        if self._revolution_start is None:
            why = 'acquiring first revolution' + (f' after {self._restart_reason}' if self._restart_reason else '')
            if crossing.t_s - self._t_open > MIN_INTERVAL_S:
                self._pass_through(self._t_open, crossing.t_s, why)
        elif self._stalled:
            if crossing.t_s - self._t_open > MIN_INTERVAL_S:
                self._pass_through(self._t_open, crossing.t_s, 'rotation resumed: last revolution spanned a stall')
        else:
            self._records.report_revolution(self._samples.view(), self._revolution_start, crossing, self._angle_source)
        self._revolution_start = crossing
        self._t_open = crossing.t_s
        self._stalled = False
        self._samples.drop_before(self._t_open)
