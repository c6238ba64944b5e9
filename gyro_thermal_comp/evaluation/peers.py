"""Peers: the off-the-shelf AHRS filters a user would pick instead of the STKF.

Both implement the `HeadingMethod` protocol and see exactly what the STKF sees: raw gyro (rad/s),
accelerometer (m/s^2) and magnetometer (T) of each chunk. The magnetometer has its own rate: every
IMU sample is paired with the latest magnetometer sample at or before it (carried across chunks);
before the first one arrives the filters update without a magnetometer. Temperature is not used:
neither library models thermal drift, which is the point of the comparison.

Both filters are seeded at the first sample that has a magnetometer reading with the attitude
implied by that accelerometer/magnetometer pair (TRIAD, ENU). Otherwise their start-up transient
from the identity quaternion would leak into the 60-s reference mean of the heading error.

The libraries run one sample at a time in Python loops (neither has a streaming batch call), so
they are slow next to the vectorised cores; see docs/evaluation.md for measured speeds.
"""
from __future__ import annotations

import numpy as np

from ..angles import quat_from_euler, wrap_angle, yaw_from_quat
from ..constants import STANDARD_GRAVITY_M_S2
from ..heading_track import HeadingTrack
from ..samples import SensorChunk

_T_TO_UT = 1e6  # the filters normalise the field; microtesla keeps float32 (Fusion) comfortable


def empty_track() -> HeadingTrack:
    e = np.empty(0)
    return HeadingTrack(e, e, e, e, np.empty(0, dtype=bool))


def attitude_from_accel_mag(accel, mag) -> np.ndarray:
    """Body-to-ENU quaternion (x, y, z, w) from one accelerometer (specific force, any unit) and one
    magnetometer sample (any unit), both in the body frame (TRIAD: up first, then east).

    Up is the specific-force direction of a unit at rest; east = field x up (the field points north
    and, away from the equator, up or down; the cross product removes the vertical part).
    """
    up = np.asarray(accel, dtype=float) / np.linalg.norm(accel)
    east = np.cross(np.asarray(mag, dtype=float), up)
    east /= np.linalg.norm(east)
    north = np.cross(up, east)
    r = np.vstack([east, north, up])  # rows: world axes in body coordinates = body-to-world matrix
    roll = np.arctan2(r[2, 1], r[2, 2])
    pitch = np.arcsin(np.clip(-r[2, 0], -1.0, 1.0))
    yaw = np.arctan2(r[1, 0], r[0, 0])
    return quat_from_euler(roll, pitch, yaw)


class _Peer:
    """Shared plumbing: magnetometer pairing, sample periods, output assembly."""
    name = 'peer'

    def __init__(self, sample_rate_hz: float | None = None):
        self.sample_rate_hz = sample_rate_hz  # nominal; inferred from the first chunk if None
        self._mag_t: float | None = None
        self._mag_field: np.ndarray | None = None
        self._t_prev: float | None = None
        self._seeded = False

    def _nominal_rate(self, t: np.ndarray) -> float:
        if self.sample_rate_hz is None:
            dt = np.diff(t)
            dt = dt[dt > 0]
            self.sample_rate_hz = float(1.0 / np.median(dt)) if dt.size else 100.0
        return self.sample_rate_hz

    def _paired_mag(self, chunk: SensorChunk, t: np.ndarray):
        """(field per IMU sample in uT, has_mag mask) using the latest reading at or before each t."""
        mt, mf = np.empty(0), np.empty((0, 3))
        if self._mag_t is not None:
            mt, mf = np.array([self._mag_t]), self._mag_field[None, :]
        if chunk.mag is not None and chunk.mag.t.size:
            mt = np.concatenate([mt, chunk.mag.t])
            mf = np.concatenate([mf, chunk.mag.field])
            self._mag_t, self._mag_field = float(chunk.mag.t[-1]), chunk.mag.field[-1].copy()
        i = np.searchsorted(mt, t, side='right') - 1
        has = i >= 0
        field = np.zeros((t.size, 3))
        field[has] = mf[i[has]] * _T_TO_UT
        has &= np.linalg.norm(field, axis=1) > 0
        return field, has

    def _periods(self, t: np.ndarray) -> np.ndarray:
        prev = self._t_prev if self._t_prev is not None else t[0] - 1.0 / self._nominal_rate(t)
        dt = np.diff(np.concatenate([[prev], t]))
        self._t_prev = float(t[-1])
        return np.where(dt > 0, dt, 1.0 / self.sample_rate_hz)

    def update(self, chunk: SensorChunk) -> HeadingTrack:
        imu = chunk.imu
        if imu is None or imu.t.size == 0:
            return empty_track()
        self._nominal_rate(imu.t)
        mag, has_mag = self._paired_mag(chunk, imu.t)
        dt = self._periods(imu.t)
        quat_wxyz, drift, coasting = self._run(imu.gyro, imu.accel, mag, has_mag, dt)
        heading = wrap_angle(yaw_from_quat(quat_wxyz[:, [1, 2, 3, 0]]))
        return HeadingTrack(imu.t.copy(), heading, drift, np.full(imu.t.size, np.nan), coasting)

    def _run(self, gyro, accel, mag, has_mag, dt):
        raise NotImplementedError


class FusionPeer(_Peer):
    """x-io Fusion AHRS (imufusion 1.3.x) with its run-time gyroscope bias (offset) correction.

    Configuration, following the Fusion README ("a value of 0.5 is appropriate for most
    applications" for the gain; "10 degrees is appropriate for most applications" for acceleration
    and magnetic rejection; a recovery trigger / rejection timeout "of 5 seconds is appropriate";
    the gyroscope range "should be set to the range specified in the gyroscope datasheet"):

    * convention ENU (x east, y north, z up), so the quaternion's ZYX yaw is the ROS heading.
      imufusion 1.3.3 ignores `convention` passed to the `AhrsSettings` constructor, so it is set as
      an attribute and checked.
    * gain 0.5, gyroscope_range 150 deg/s (ADXRS623 full scale), acceleration_rejection 10 deg,
      magnetic_rejection 10 deg, rejection_timeout 5 s (1.3.x takes seconds, earlier versions a
      sample count), sample_rate = nominal IMU rate; `set_sample_period` gets each actual interval.
    * `imufusion.Bias` (the former `Offset`) with its defaults: stationary when every axis is under
      3 deg/s for 3 s, then the offset tracks the gyro with a 0.02 Hz low-pass. Its z offset is the
      reported `drift_rad_s`.
    * Units passed: gyro deg/s, accel g (m/s^2 / 9.80665), magnetometer uT.
    * `coasting` = no magnetometer yet or Fusion's `magnetometer_ignored` (magnetic rejection).
    """
    name = 'fusion'

    def __init__(self, *, sample_rate_hz: float | None = None, gain: float = 0.5,
                 gyroscope_range_deg_s: float = 150.0, acceleration_rejection_deg: float = 10.0,
                 magnetic_rejection_deg: float = 10.0, rejection_timeout_s: float = 5.0,
                 bias_stationary_threshold_deg_s: float = 3.0, bias_stationary_period_s: float = 3.0,
                 name: str | None = None):
        super().__init__(sample_rate_hz)
        self.name = name or self.name
        self._config = dict(gain=gain, gyroscope_range=gyroscope_range_deg_s,
                            acceleration_rejection=acceleration_rejection_deg,
                            magnetic_rejection=magnetic_rejection_deg,
                            rejection_timeout=rejection_timeout_s)
        self._bias_config = dict(stationary_threshold=bias_stationary_threshold_deg_s,
                                 stationary_period=bias_stationary_period_s)
        self._ahrs = self._bias = None

    def _make(self) -> None:
        import imufusion

        settings = imufusion.AhrsSettings()
        settings.sample_rate = self.sample_rate_hz
        settings.convention = imufusion.CONVENTION_ENU
        for key, value in self._config.items():
            setattr(settings, key, value)
        if settings.convention != imufusion.CONVENTION_ENU:
            raise RuntimeError('imufusion did not accept the ENU convention')
        self._ahrs = imufusion.Ahrs()
        self._ahrs.set_settings(settings)
        bias_settings = imufusion.BiasSettings()
        bias_settings.sample_rate = self.sample_rate_hz
        for key, value in self._bias_config.items():
            setattr(bias_settings, key, value)
        self._bias = imufusion.Bias()
        self._bias.set_settings(bias_settings)

    def _run(self, gyro, accel, mag, has_mag, dt):
        if self._ahrs is None:
            self._make()
        ahrs, bias = self._ahrs, self._bias
        n = gyro.shape[0]
        gyro_deg = np.degrees(gyro)
        accel_g = accel / STANDARD_GRAVITY_M_S2
        quat = np.empty((n, 4))
        drift = np.empty(n)
        coasting = np.empty(n, dtype=bool)
        for k in range(n):
            if not self._seeded and has_mag[k]:
                q = attitude_from_accel_mag(accel[k], mag[k])
                ahrs.set_quaternion(np.array([q[3], q[0], q[1], q[2]]))
                self._seeded = True
            ahrs.set_sample_period(float(dt[k]))
            g = bias.update(gyro_deg[k])
            if has_mag[k]:
                ahrs.update(g, accel_g[k], mag[k])
                coasting[k] = ahrs.get_internal_states().magnetometer_ignored
            else:
                ahrs.update_no_magnetometer(g, accel_g[k])
                coasting[k] = True
            quat[k] = ahrs.get_quaternion()
            drift[k] = bias.get_offset()[2]
        return quat, np.radians(drift), coasting


class MahonyPeer(_Peer):
    """Mahony explicit complementary filter from `ahrs` (ahrs.filters.Mahony, ahrs 0.4).

    Configuration: the library defaults k_P = 1.0, k_I = 0.3 ("following the experimental settings
    of the original article", ahrs docs), per-sample `updateMARG(q, gyr, acc, mag, dt)` with the
    actual sample interval (`updateIMU` while no magnetometer reading exists). Units: gyro rad/s,
    accel m/s^2, magnetometer uT (normalised inside). Its frame: the filter drives gravity to
    world +z and the horizontal field to world +y (north), i.e. ENU, quaternions w, x, y, z, so the
    ZYX yaw is the ROS heading (checked in the tests). The integral term `b` is its gyro bias
    estimate (it subtracts b from the gyro); b_z is the reported `drift_rad_s`. It has no
    magnetic disturbance rejection, so it never coasts.
    """
    name = 'mahony'

    def __init__(self, *, sample_rate_hz: float | None = None, k_P: float = 1.0, k_I: float = 0.3,
                 name: str | None = None):
        super().__init__(sample_rate_hz)
        self.name = name or self.name
        self.k_P, self.k_I = k_P, k_I
        self._filter = None
        self._q = np.array([1.0, 0.0, 0.0, 0.0])

    @property
    def bias_rad_s(self) -> np.ndarray:
        """Current integral term (gyro bias estimate), rad/s, sensor frame."""
        return np.zeros(3) if self._filter is None else self._filter.b.copy()

    def _run(self, gyro, accel, mag, has_mag, dt):
        if self._filter is None:
            from ahrs.filters import Mahony
            self._filter = Mahony(frequency=self.sample_rate_hz, k_P=self.k_P, k_I=self.k_I)
        f, q = self._filter, self._q
        n = gyro.shape[0]
        quat = np.empty((n, 4))
        drift = np.empty(n)
        for k in range(n):
            if not self._seeded and has_mag[k]:
                x, y, z, w = attitude_from_accel_mag(accel[k], mag[k])
                q = np.array([w, x, y, z])
                self._seeded = True
            if has_mag[k]:
                q = f.updateMARG(q, gyro[k], accel[k], mag[k], dt=float(dt[k]))
            else:
                q = f.updateIMU(q, gyro[k], accel[k], dt=float(dt[k]))
            quat[k] = q
            drift[k] = f.b[2]
        self._q = q
        return quat, drift, np.zeros(n, dtype=bool)


def default_peers(sample_rate_hz: float | None = None) -> list:
    """The peers every evaluation should include."""
    return [FusionPeer(sample_rate_hz=sample_rate_hz), MahonyPeer(sample_rate_hz=sample_rate_hz)]
