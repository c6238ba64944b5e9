"""What a heading method produces: the common output of the STKF, its baselines and the peers.

Every method consumes a time-ordered stream of `SensorChunk`s and returns, for each chunk, one
`HeadingTrack` row per IMU sample of that chunk, so evaluation can score them side by side.
"""
from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Iterable, Protocol

import numpy as np

from .samples import SensorChunk


@dataclass(frozen=True)
class HeadingTrack:
    t: np.ndarray                  # (N,) s, the IMU sample times
    heading_rad: np.ndarray        # (N,) yaw, ENU, CCW from east, wrapped to (-pi, pi]
    drift_rad_s: np.ndarray        # (N,) z-gyro drift removed from each sample; NaN if not modelled
    heading_sigma_rad: np.ndarray  # (N,) 1-sigma heading uncertainty; NaN if the method has none
    coasting: np.ndarray           # (N,) bool, True where magnetic updates were refused (gate shut)

    @classmethod
    def concat(cls, parts: Iterable['HeadingTrack']) -> 'HeadingTrack':
        parts = list(parts)
        return cls(**{f.name: np.concatenate([getattr(p, f.name) for p in parts]) for f in fields(cls)})


class HeadingMethod(Protocol):
    """A heading estimator fed chunk by chunk, in time order."""
    name: str

    def update(self, chunk: SensorChunk) -> HeadingTrack:
        """Consume one chunk; return one row per `chunk.imu` sample (empty arrays if none)."""
