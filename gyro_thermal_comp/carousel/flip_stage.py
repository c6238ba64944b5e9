"""Flip tracking stage: aligned main-IMU samples -> platform-frame samples (flip.py has the geometry).

Each sample is rotated by the main IMU's flip position; while the main IMU moves, the auxiliary
IMU's sample stands in (its own offsets are removed later, per output interval). Deciding whether
a sample belongs to a flip needs `guard_s` of look-ahead, so samples are held that long.
"""
from __future__ import annotations

import numpy as np

from .bias_book import SensorBiasBook
from .blocks import SOURCE_AUX, SOURCE_FLIP_WITHOUT_AUX, SOURCE_MAIN, AlignedBlock, PlatformBlock
from .buffers import Columns
from .config import FlipConfig
from .flip import AXIS_INDEX, FlipTracker, flip_rotation


class FlipStage:
    """Aligned samples in, platform-frame samples out (unchanged, position 0, without the flip)."""

    def __init__(self, config: FlipConfig, book: SensorBiasBook):
        self.config = config
        self._book = book
        self.tracker = FlipTracker(config.rate_threshold_rad_s, config.guard_s, config.initial_position,
                                   config.max_angle_error_rad)
        self._held = Columns(AlignedBlock)    # pushed to the tracker, not yet released
        self._events_reported = 0

    @property
    def position(self) -> int:
        """The main IMU's newest known position (ahead of the released samples by the look-ahead)."""
        return self.tracker.position if self.config.enabled else 0

    def new_events(self) -> tuple:
        """FlipEvents completed since the last call."""
        events = tuple(self.tracker.events[self._events_reported:])
        self._events_reported = len(self.tracker.events)
        return events

    def process(self, block: AlignedBlock | None, final: bool) -> PlatformBlock | None:
        """Platform-frame samples now decided (None: none); `final` releases everything held."""
        if not self.config.enabled:
            if block is None:
                return None
            n = len(block)
            return _platform_block(block, block.gyro, block.accel, np.zeros(n, np.int8), np.zeros(n, np.int8))
        if block is not None and len(block):
            axis = AXIS_INDEX[self.config.axis]
            main_rate = block.gyro[:, axis] - self._book.gyro[axis]
            aux_rate = block.aux_gyro[:, axis] - self._book.aux_offset().gyro[axis]
            self.tracker.push(block.t, main_rate - np.where(block.aux_ok, aux_rate, 0.0))
            self._held.append(block)
        decided = self.tracker.release(final)
        n = len(decided.flipping)
        if n == 0:
            return None
        held = self._held.take_front(n)
        position = decided.position
        source = np.where(decided.flipping, np.where(held.aux_ok, SOURCE_AUX, SOURCE_FLIP_WITHOUT_AUX),
                          SOURCE_MAIN).astype(np.int8)
        gyro, accel = held.gyro.copy(), held.accel.copy()
        for k in np.unique(position):
            sel = position == k
            rot = flip_rotation(self.config.axis, k)
            gyro[sel], accel[sel] = held.gyro[sel] @ rot.T, held.accel[sel] @ rot.T
        aux = source == SOURCE_AUX
        # Aux samples keep their own offsets; they are calibrated against the main IMU per interval.
        gyro[aux], accel[aux] = held.aux_gyro[aux], held.aux_accel[aux]
        return _platform_block(held, gyro, accel, source, position.astype(np.int8))


def _platform_block(block: AlignedBlock, gyro, accel, source, position) -> PlatformBlock:
    return PlatformBlock(t=block.t, gyro=gyro, accel=accel, encoder_angle=block.encoder_angle,
                         encoder_rate=block.encoder_rate, encoder_ok=block.encoder_ok, aux_gyro=block.aux_gyro,
                         aux_accel=block.aux_accel, aux_ok=block.aux_ok, mag=block.mag, mag_ok=block.mag_ok,
                         source=source, position=position)
