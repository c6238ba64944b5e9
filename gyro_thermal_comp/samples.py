"""Time-stamped sensor arrays: the one currency between the simulator, bag I/O and the cores.

Every field is a numpy array indexed by sample; `t` is the sample time (header.stamp) in s.
A `SensorChunk` holds whatever topics fall in one stretch of time; streams of chunks let hours
of data flow through the package without loading a whole bag.
"""
from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import Iterable

import numpy as np


def _as_time(t) -> np.ndarray:
    return np.ascontiguousarray(t, dtype=np.float64).reshape(-1)


def _as_rows(a, width: int) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64).reshape(-1, width)


@dataclass(frozen=True)
class ImuSamples:
    """Raw or compensated IMU samples in the sensor (imu_link) frame."""
    t: np.ndarray      # (N,) s
    gyro: np.ndarray   # (N, 3) angular rate, rad/s
    accel: np.ndarray  # (N, 3) specific force, m/s^2

    def __post_init__(self):
        object.__setattr__(self, 't', _as_time(self.t))
        object.__setattr__(self, 'gyro', _as_rows(self.gyro, 3))
        object.__setattr__(self, 'accel', _as_rows(self.accel, 3))


@dataclass(frozen=True)
class MagSamples:
    """Magnetometer samples in the sensor frame."""
    t: np.ndarray      # (N,) s
    field: np.ndarray  # (N, 3) magnetic flux density, T

    def __post_init__(self):
        object.__setattr__(self, 't', _as_time(self.t))
        object.__setattr__(self, 'field', _as_rows(self.field, 3))


@dataclass(frozen=True)
class TemperatureSamples:
    """Gyro temperature sensor readings."""
    t: np.ndarray       # (N,) s
    temp_c: np.ndarray  # (N,) degrees Celsius

    def __post_init__(self):
        object.__setattr__(self, 't', _as_time(self.t))
        object.__setattr__(self, 'temp_c', _as_time(self.temp_c))


@dataclass(frozen=True)
class PoseSamples:
    """Ground-truth odometry (nav_msgs/Odometry semantics: pose in ENU `odom`, twist in body)."""
    t: np.ndarray              # (N,) s
    quat: np.ndarray           # (N, 4) x, y, z, w; rotates body vectors into ENU
    position: np.ndarray       # (N, 3) m, ENU
    velocity_body: np.ndarray  # (N, 3) m/s, body frame
    rate_body: np.ndarray      # (N, 3) rad/s, body rate relative to the Earth (ENU), body frame

    def __post_init__(self):
        object.__setattr__(self, 't', _as_time(self.t))
        object.__setattr__(self, 'quat', _as_rows(self.quat, 4))
        object.__setattr__(self, 'position', _as_rows(self.position, 3))
        object.__setattr__(self, 'velocity_body', _as_rows(self.velocity_body, 3))
        object.__setattr__(self, 'rate_body', _as_rows(self.rate_body, 3))


@dataclass(frozen=True)
class VectorSamples:
    """Stamped 3-vectors (geometry_msgs/Vector3Stamped), e.g. the true gyro drift in rad/s."""
    t: np.ndarray    # (N,) s
    vec: np.ndarray  # (N, 3) unit given by the topic

    def __post_init__(self):
        object.__setattr__(self, 't', _as_time(self.t))
        object.__setattr__(self, 'vec', _as_rows(self.vec, 3))


@dataclass(frozen=True)
class JointSamples:
    """One revolute joint (carousel turntable or wheel): angle and rate of imu_link about its axis."""
    t: np.ndarray         # (N,) s
    position: np.ndarray  # (N,) rad, unwrapped (cumulative) angle
    velocity: np.ndarray  # (N,) rad/s

    def __post_init__(self):
        object.__setattr__(self, 't', _as_time(self.t))
        object.__setattr__(self, 'position', _as_time(self.position))
        object.__setattr__(self, 'velocity', _as_time(self.velocity))


_SAMPLE_TYPES = (ImuSamples, MagSamples, TemperatureSamples, PoseSamples, VectorSamples, JointSamples)


def concat_samples(parts):
    """Concatenate samples of one type along time; returns None for an empty sequence."""
    parts = [p for p in parts if p is not None]
    if not parts:
        return None
    kind = type(parts[0])
    return kind(**{f.name: np.concatenate([getattr(p, f.name) for p in parts]) for f in fields(kind)})


def slice_samples(samples, index):
    """Select samples by a boolean mask or index array (same type back)."""
    return type(samples)(**{f.name: getattr(samples, f.name)[index] for f in fields(samples)})


@dataclass(frozen=True)
class SensorChunk:
    """All samples of one stretch of time, one optional field per stream (see topics.py)."""
    imu: ImuSamples | None = None
    mag: MagSamples | None = None
    temperature: TemperatureSamples | None = None
    odom: PoseSamples | None = None
    gyro_bias: VectorSamples | None = None        # truth: total slow gyro error, rad/s, sensor frame
    mag_disturbance: VectorSamples | None = None  # truth: interference field added, T, sensor frame
    joint: JointSamples | None = None
    imu_aux: ImuSamples | None = None             # auxiliary IMU (carousel flip mechanism)

    def streams(self) -> dict:
        """Non-empty streams by field name."""
        return {f.name: getattr(self, f.name) for f in fields(self) if getattr(self, f.name) is not None}

    def with_streams(self, **streams) -> 'SensorChunk':
        return replace(self, **streams)


def concat_chunks(chunks: Iterable[SensorChunk]) -> SensorChunk:
    """Join chunks into one (for tests and small bags; streaming code should not need it)."""
    chunks = list(chunks)
    return SensorChunk(**{f.name: concat_samples([getattr(c, f.name) for c in chunks])
                          for f in fields(SensorChunk)})


assert all(t.__dataclass_params__.frozen for t in _SAMPLE_TYPES)
