"""`CompassIntake`: each compass sample against the gyro state at its stamp.

Per sample: the roll and pitch, gyro heading psi_g and drift integrals there (interpolated in the
IMU stretch it falls in), the tilt-compensated compass heading psi_c (compass.py), its offset
z = psi_c - psi_g for the heading filter, and psi_g + integral of D_hat - psi_c for the drift window
(drift_learning.py); during the still period z also measures the compass noise (still_period.py).
Compass samples before any IMU sample wait for the first one and take the start of the
integration (psi_g = 0) with its gravity.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..angles import wrap_angle
from .compass import compass_heading
from .imu_stretch import ImuStretch, context_before_imu


class CompassIntake:
    def __init__(self, declination_rad: float, learning, still, blocks, startup):
        self.declination_rad = declination_rad   # true minus magnetic north, rad
        self.learning = learning
        self.still = still
        self.blocks = blocks
        self.startup = startup
        self._waiting = (np.empty(0), np.empty((0, 3)))   # compass before the first IMU sample

    @property
    def waiting(self) -> bool:
        """Compass samples wait for the first IMU sample."""
        return bool(self._waiting[0].size)

    def take(self, t_mag, field, stretch: ImuStretch | None, before: ImuStretch | None) -> None:
        """Compass samples (stamps s, field T) of one stretch; `before`: the stretch before (its last
        row is the IMU state before `stretch`), None before the first IMU sample."""
        if before is None and stretch is None:
            self._waiting = (np.concatenate((self._waiting[0], t_mag)), np.concatenate((self._waiting[1], field)))
            return
        if before is None:
            t_mag = np.concatenate((self._waiting[0], t_mag))
            field = np.concatenate((self._waiting[1], field))
            self._waiting = (np.empty(0), np.empty((0, 3)))
            # at or before the first IMU sample: the start of the integration, its gravity
            before = replace(stretch.row(0), t=t_mag[:1].copy(), rate=np.zeros(1))
        ctx = stretch.at_stamps(t_mag, before) if stretch is not None else context_before_imu(before, t_mag)
        i_d, i_h = self.learning.integrals_from_window_start(t_mag, ctx)
        reading = compass_heading(field, None, self.declination_rad, roll_pitch=(ctx.roll, ctx.pitch))
        psi_c = np.atleast_1d(reading.heading_rad)
        self.learning.add_compass(t_mag, ctx.psi_g + i_d - psi_c, i_h)
        z = np.atleast_1d(wrap_angle(psi_c - ctx.psi_g))
        if not self.startup.started:
            self.still.add_compass(t_mag, z)
        self.blocks.add(t_mag, z, ctx.psi_g, psi_c, reading.field_norm_t, reading.dip_rad, ctx.accel, ctx.temp,
                        self.startup.compass_var_rad2)
