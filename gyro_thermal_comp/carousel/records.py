"""What the carousel core returns: per-interval records, bias measurements, high-rate samples.

`Outbox` collects them as the stages produce them; `CarouselDemodulator` drains it into one
`DemodulatedOutput` per update.
"""
from __future__ import annotations

from dataclasses import dataclass, field, fields

import numpy as np

from .integrals import inplane

DEMODULATED, PASS_THROUGH = 'demodulated', 'pass_through'


@dataclass(frozen=True)
class RevolutionRecord:
    """One output interval [t_s - duration_s, t_s]. Vectors are body frame (REP 103)."""
    t_s: float                               # end of the revolution / interval, s
    duration_s: float
    rate_body_rad_s: np.ndarray              # (3,) mean angular rate, spin removed
    specific_force_body_m_s2: np.ndarray     # (3,) mean specific force
    spin_rate_rad_s: float                   # Omega estimate (signed, CCW about spin axis +)
    axial_residual_rad_s: float              # mean axial gyro - bias estimate - Omega (carousel z)
    gyro_bias_inplane_rad_s: np.ndarray      # (2,) platform x, y bias used (lock-in window)
    accel_bias_inplane_m_s2: np.ndarray      # (2,)
    gyro_bias_variance: float                # (rad/s)^2 per component of the lock-in estimate; inf if none
    mode: str                                # 'demodulated' | 'pass_through'
    reason: str                              # '' when demodulated
    angle_source: str                        # 'encoder' | 'gyro'
    flip_position: int                       # main IMU quarter turns about the flip axis
    aux_fraction: float                      # share of samples from the auxiliary IMU
    n_samples: int
    temperature_c: float | None              # mean gyro temperature over the interval
    # without an encoder, from the gravity (or magnetometer) angle reference: the axial gyro's drift as that
    # filter has learnt it by the interval's end, rad/s (angle_reference.GravityAngleFilter.axial_bias), and its
    # variance, (rad/s)^2; inf: no estimate (encoder, flip mechanism, no reference yet)
    axial_gyro_bias_rad_s: float = 0.0
    axial_gyro_bias_variance: float = float('inf')


@dataclass(frozen=True)
class GyroBiasMeasurement:
    """A gyro bias measured over one whole clean revolution, imu_link axes; independent of other
    revolutions (no overlapping windows), so a Kalman filter may use each as one measurement.
    y = bias_rad_s with R = variance_rad2_s2 is the drift D of docs/design.md eq. (1) for that axis,
    averaged over [t_s - duration_s, t_s]; H = [temperature_c, temperature_rate_c_s, 1]."""
    t_s: float                        # revolution end, s
    duration_s: float
    axis: str                         # 'x' | 'y' | 'z' of imu_link
    bias_rad_s: float
    variance_rad2_s2: float
    temperature_c: float | None       # mean over the revolution, deg C (None: no temperature stream)
    temperature_rate_c_s: float | None
    flip_position: int


@dataclass(frozen=True)
class HighRateSamples:
    """Every processed sample rotated into the body frame with the current bias estimates removed."""
    t: np.ndarray                     # (N,) s
    rate_body_rad_s: np.ndarray       # (N, 3)
    specific_force_body_m_s2: np.ndarray  # (N, 3)
    theta_rad: np.ndarray             # (N,) carousel angle used, unwrapped
    source: np.ndarray                # (N,) 0 main IMU, 1 auxiliary, 2 flip without auxiliary

    @classmethod
    def from_platform(cls, t, theta, spin, gyro, accel, source, carousel_to_body: np.ndarray) -> HighRateSamples:
        """Platform-frame samples (bias removed) turned by theta into the body frame, spin removed."""
        turned = np.exp(1j * theta)
        gyro_c, accel_c = turned * inplane(gyro), turned * inplane(accel)
        rate = np.column_stack((gyro_c.real, gyro_c.imag, gyro[:, 2] - spin)) @ carousel_to_body.T
        specific_force = np.column_stack((accel_c.real, accel_c.imag, accel[:, 2])) @ carousel_to_body.T
        return cls(t=t.copy(), rate_body_rad_s=rate, specific_force_body_m_s2=specific_force, theta_rad=theta.copy(),
                   source=source.astype(np.int8))

    @classmethod
    def concatenate(cls, parts: list[HighRateSamples]) -> HighRateSamples:
        return cls(**{f.name: np.concatenate([getattr(p, f.name) for p in parts]) for f in fields(cls)})


@dataclass(frozen=True)
class DemodulatedOutput:
    records: tuple = ()               # RevolutionRecord, time order
    bias_measurements: tuple = ()     # GyroBiasMeasurement
    high_rate: HighRateSamples | None = None
    flip_events: tuple = ()           # FlipEvent completed during this update
    mode: str = PASS_THROUGH          # state after this update
    reason: str = 'no data yet'
    counts: dict = field(default_factory=dict)   # cumulative diagnostics counters


@dataclass
class Outbox:
    """Outputs produced since the last drain, in time order per kind."""
    records: list = field(default_factory=list)
    bias_measurements: list = field(default_factory=list)
    high_rate: list = field(default_factory=list)

    def drain(self, *, flip_events: tuple, mode: str, reason: str, counts: dict) -> DemodulatedOutput:
        """Everything collected as one DemodulatedOutput, with the demodulator's state after it."""
        high_rate = HighRateSamples.concatenate(self.high_rate) if self.high_rate else None
        out = DemodulatedOutput(records=tuple(self.records), bias_measurements=tuple(self.bias_measurements),
                                high_rate=high_rate, flip_events=flip_events, mode=mode, reason=reason,
                                counts=counts)
        self.records, self.bias_measurements, self.high_rate = [], [], []
        return out


def records_as_arrays(records) -> dict:
    """Column view of records (for nodes, plots, evaluation)."""
    records = list(records)
    out = {name: np.array([getattr(r, name) for r in records])
           for name in ('t_s', 'duration_s', 'spin_rate_rad_s', 'axial_residual_rad_s', 'mode', 'reason',
                        'flip_position', 'n_samples', 'axial_gyro_bias_rad_s', 'axial_gyro_bias_variance')}
    for name, width in (('rate_body_rad_s', 3), ('specific_force_body_m_s2', 3),
                        ('gyro_bias_inplane_rad_s', 2), ('accel_bias_inplane_m_s2', 2)):
        out[name] = np.array([getattr(r, name) for r in records]).reshape(-1, width)
    return out
