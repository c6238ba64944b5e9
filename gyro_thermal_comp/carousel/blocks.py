"""Typed sample blocks handed from one pipeline stage to the next (docs/carousel.md, "Modules").

Every row is one main-IMU sample time. Stages: `ImuBlock` (held until the other streams cover it)
-> `AlignedBlock` (encoder, aux and magnetometer interpolated to it) -> `PlatformBlock` (flip resolved, platform
frame) -> `CoreBlock` (carousel angle and spin rate added; what the revolution core keeps).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .buffers import ColumnBlock, column

# Which sensor a row's values come from (HighRateSamples.source).
SOURCE_MAIN = 0               # the main IMU
SOURCE_AUX = 1                # the auxiliary IMU, standing in while the main one flips
SOURCE_FLIP_WITHOUT_AUX = 2   # the main IMU while it flips, no aux sample to stand in

# Where the carousel angle comes from (index into ANGLE_SOURCE_NAMES).
ENCODER, GYRO = 0, 1
ANGLE_SOURCE_NAMES = ('encoder', 'gyro')


@dataclass(frozen=True)
class ImuBlock(ColumnBlock):
    t: np.ndarray = column()           # s
    gyro: np.ndarray = column(3)       # rad/s
    accel: np.ndarray = column(3)      # m/s^2


@dataclass(frozen=True)
class EncoderBlock(ColumnBlock):
    t: np.ndarray = column()
    position: np.ndarray = column()    # rad, unwrapped
    velocity: np.ndarray = column()    # rad/s, NaN when the encoder does not report it


@dataclass(frozen=True)
class TemperatureBlock(ColumnBlock):
    t: np.ndarray = column()
    temp_c: np.ndarray = column()


@dataclass(frozen=True)
class AlignedBlock(ColumnBlock):
    """Main IMU (imu frame) with the encoder and the aux IMU (platform frame) at its stamps."""
    t: np.ndarray = column()
    gyro: np.ndarray = column(3)
    accel: np.ndarray = column(3)
    encoder_angle: np.ndarray = column()           # rad (0 where not encoder_ok)
    encoder_rate: np.ndarray = column()            # rad/s
    encoder_ok: np.ndarray = column(dtype=bool)    # bracketed by encoder samples
    aux_gyro: np.ndarray = column(3)
    aux_accel: np.ndarray = column(3)
    aux_ok: np.ndarray = column(dtype=bool)
    mag: np.ndarray = column(3)                    # magnetometer, imu frame, T (0 where not mag_ok)
    mag_ok: np.ndarray = column(dtype=bool)        # bracketed by magnetometer samples (only when in use)


@dataclass(frozen=True)
class MagBlock(ColumnBlock):
    t: np.ndarray = column()
    field: np.ndarray = column(3)      # T


@dataclass(frozen=True)
class PlatformBlock(AlignedBlock):
    """`AlignedBlock` with gyro/accel in the platform frame (the aux values where it stands in)."""
    source: np.ndarray = column(dtype=np.int8)     # SOURCE_*
    position: np.ndarray = column(dtype=np.int8)   # main IMU flip position, quarter turns


@dataclass(frozen=True)
class CoreBlock(ColumnBlock):
    """What the revolution core keeps per sample: platform-frame values, angle, spin, provenance."""
    t: np.ndarray = column()
    theta: np.ndarray = column()                   # carousel angle, rad, unwrapped
    spin: np.ndarray = column()                    # spin rate, rad/s
    gyro: np.ndarray = column(3)
    accel: np.ndarray = column(3)
    source: np.ndarray = column(dtype=np.int8)
    position: np.ndarray = column(dtype=np.int8)
    aux_gyro: np.ndarray = column(3)
    aux_accel: np.ndarray = column(3)
    aux_ok: np.ndarray = column(dtype=bool)
    mag: np.ndarray = column(3)                    # T, imu frame (= platform: the mag is not used with the flip)
    mag_ok: np.ndarray = column(dtype=bool)
