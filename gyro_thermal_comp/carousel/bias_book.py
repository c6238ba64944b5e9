"""The current 3-axis bias estimates of the main IMU and the auxiliary IMU's offset against it.

In-plane lock-in results fill two imu axes at a time; after a flip the other axes follow, so the
axial bias of one position is known from the other (it is then as old as the last flip: thermal
drift since then is not seen here).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .blocks import SOURCE_AUX
from .flip import flip_rotation, platform_axis_to_imu


@dataclass(frozen=True)
class ImuBias:
    """A gyro and an accelerometer bias: (3,) vectors, or (N, 3) per sample."""
    gyro: np.ndarray      # rad/s
    accel: np.ndarray     # m/s^2


class SensorBiasBook:
    """Main IMU biases (imu frame) and the aux IMU's offset (platform frame)."""

    def __init__(self, axis: str = 'x'):
        self.axis = axis
        self.gyro = np.zeros(3)
        self.accel = np.zeros(3)
        self.gyro_var = np.full(3, np.inf)
        self.accel_var = np.full(3, np.inf)
        self.known = np.zeros(3, bool)
        self.t_updated = np.full(3, np.nan)
        # Raw (aux - main) platform-frame means, per main position; combined with the *current*
        # main estimate at use, so learning a main bias later does not leave the aux inconsistent.
        self._aux_raw: dict[int, ImuBias] = {}
        self._aux_position: int | None = None

    def update_inplane(self, k: int, gyro_xy: complex, accel_xy: complex, gyro_var: float,
                       accel_var: float, t_s: float) -> None:
        for p_axis, g, a in ((0, gyro_xy.real, accel_xy.real), (1, gyro_xy.imag, accel_xy.imag)):
            j, sign = platform_axis_to_imu(self.axis, k, p_axis)
            self.gyro[j], self.accel[j] = sign * g, sign * a
            self.gyro_var[j], self.accel_var[j] = gyro_var, accel_var
            self.known[j] = True
            self.t_updated[j] = t_s

    def main_platform(self, k: int) -> ImuBias:
        """Platform-frame bias of the main IMU in position k (0 where unknown)."""
        rot = flip_rotation(self.axis, k)
        return ImuBias(rot @ self.gyro, rot @ self.accel)

    def update_aux(self, k: int, gyro_diff_p: np.ndarray, accel_diff_p: np.ndarray, weight: float) -> None:
        """Blend in one interval's mean of (aux - raw main) in platform frame, main in position k."""
        if k not in self._aux_raw:
            self._aux_raw[k] = ImuBias(np.array(gyro_diff_p, dtype=float), np.array(accel_diff_p, dtype=float))
        else:
            raw = self._aux_raw[k]
            raw.gyro[:] += weight * (gyro_diff_p - raw.gyro)      # in place: the arrays are the state
            raw.accel[:] += weight * (accel_diff_p - raw.accel)
        self._aux_position = k

    def aux_offset(self) -> ImuBias:
        """What to subtract from aux platform-frame samples so they match the compensated main IMU
        (aux bias minus whatever main bias is still unknown), from the latest position."""
        if self._aux_position is None:
            return ImuBias(np.zeros(3), np.zeros(3))
        raw = self._aux_raw[self._aux_position]
        main = self.main_platform(self._aux_position)
        return ImuBias(raw.gyro + main.gyro, raw.accel + main.accel)

    def per_sample(self, source: np.ndarray, position: np.ndarray) -> ImuBias:
        """(N, 3) platform-frame biases to subtract from samples of these sources and positions."""
        n = len(source)
        if n and position.min() == position.max() and not np.any(source == SOURCE_AUX):   # the common case
            main = self.main_platform(int(position[0]))
            return ImuBias(np.broadcast_to(main.gyro, (n, 3)), np.broadcast_to(main.accel, (n, 3)))
        gyro, accel = np.zeros((n, 3)), np.zeros((n, 3))
        for k in np.unique(position):
            sel = (position == k) & (source != SOURCE_AUX)
            if np.any(sel):
                main = self.main_platform(int(k))
                gyro[sel], accel[sel] = main.gyro, main.accel
        aux = source == SOURCE_AUX
        if np.any(aux):
            offset = self.aux_offset()
            gyro[aux], accel[aux] = offset.gyro, offset.accel
        return ImuBias(gyro, accel)
