"""Settings of the carousel demodulator (all units SI: s, rad, rad/s, m/s^2).

Frames used throughout `carousel/`:
- imu frame (imu_link): the main IMU's own axes; raw samples arrive in it.
- platform frame: the turntable (or wheel) plate; z is the spin axis. Without the flip mechanism the
  main IMU is the platform (identity). With it, the main IMU sits in one of four 90 deg positions
  about an in-plane flip axis of the platform.
- carousel frame: fixed to the body, z = spin axis; the encoder angle `theta` turns the platform
  about +z relative to it (CCW positive): v_carousel = Rz(theta) v_platform.
- body frame (base_link): v_body = carousel_to_body @ v_carousel (identity for a vertical table).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

IDENTITY3 = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))


@dataclass(frozen=True)
class FlipConfig:
    """Two-position mechanism: the main IMU turns 90 deg about an in-plane platform axis so its axial
    sensor is modulated too; an auxiliary IMU fixed to the platform stands in while it moves."""
    enabled: bool = False
    axis: str = 'x'                          # platform (= imu) axis the main IMU flips about: 'x' | 'y'
    initial_position: int = 0                # quarter turns about `axis` at start (0: imu = platform)
    aux_to_platform: tuple = IDENTITY3       # 3x3, v_platform = M v_aux
    rate_threshold_rad_s: float = 0.5        # |main - aux| rate about the flip axis that means "moving"
    guard_s: float = 0.05                    # aux also stands in this long before/after detected motion
    max_angle_error_rad: float = 0.35        # flip angle further than this from k*90 deg is reported
    aux_timeout_s: float = 0.2               # aux silent this long (IMU time) -> main stops waiting for it
    aux_max_gap_s: float = 0.1               # aux samples further apart than this cannot be interpolated
    aux_calibration_tau_s: float = 20.0      # time constant of the aux-vs-main offset average


@dataclass(frozen=True)
class CarouselConfig:
    # --- angle and revolutions -------------------------------------------------------------------
    angle_source: str = 'auto'               # 'auto': encoder when JointSamples arrive, else gyro | 'gyro'
    boundary_phase_rad: float = 0.0          # revolutions end where theta = phase + 2*pi*n
    initial_angle_rad: float = 0.0           # gyro-integrated theta at the first sample
    carousel_to_body: tuple = IDENTITY3      # 3x3, v_body = M v_carousel
    encoder_timeout_s: float = 0.5           # encoder silent this long (IMU time) -> stop waiting, use gyro
    encoder_max_gap_s: float = 0.1           # encoder samples further apart cannot be interpolated
    # --- whole-revolution validity (else pass-through) -------------------------------------------
    max_revolution_period_s: float = 4.0     # slower rotation cannot be averaged per revolution
    min_samples_per_revolution: int = 6
    max_rate_deviation: float = 0.5          # |segment rate / revolution mean rate - 1| allowed
    pass_through_period_s: float = 0.5       # record length while rotation is too slow or stopped
    max_gap_s: float = 0.1                   # larger IMU stamp gaps restart revolution tracking
    # --- spin rate without encoder ---------------------------------------------------------------
    nominal_spin_rate_rad_s: float | None = None  # known motor rate; keeps body yaw in the axial output
    gyro_spin_window_s: float = 1.0          # high-rate/pass-through spin estimate: axial mean over this
    # --- angle without encoder: gyro corrected from gravity (angle_reference.py), else the magnetometer
    # (gravity_mag, mag_reference.py: used only while gravity is unobservable, spin axis vertical) ----
    angle_reference: str = 'gravity'         # 'gravity': gyro angle corrected from gravity | 'gravity_mag': else mag | 'none'
    still_rate_rad_s: float = 0.05           # the start-up still stretch ends at the first faster axial rate
    still_accel_tol_m_s2: float = 0.05       # ... and counts only if specific force moved less (body at rest)
    angle_ref_min_inplane_m_s2: float = 0.05  # in-plane specific force below this (tilt < ~0.3 deg): unobservable
    angle_ref_gyro_noise_rad_s_rthz: float = 3e-4  # axial gyro angle random walk (process noise), rad/s/sqrt(Hz)
    angle_ref_bias_sigma_rad_s: float = 0.1   # prior 1-sigma of the axial (and in-plane) gyro bias, rad/s (MEMS turn-on: up to ~5 deg/s)
    angle_ref_scale_sigma: float = 0.01      # prior 1-sigma of the axial gyro scale-factor error
    angle_ref_bias_walk_rad_s_rts: float = 3e-6   # axial bias random walk (MEMS: bias instability), rad/s/sqrt(s)
    angle_ref_floor_rad: float = 1e-3        # per-revolution angle measurement 1-sigma floor (model errors), rad
    angle_ref_gate_sigma: float = 5.0        # innovations beyond this many sigma are rejected (3 in a row: accepted)
    mag_ref_inplane_tol: float = 0.02        # |in-plane field| off the reference's by more than this fraction: rejected
    mag_ref_axial_tol: float = 0.02          # axial field off the reference's by more than this fraction of |B|: rejected
    wheel_radius_m: float | None = None      # on a wheel: rolling radius, m; the road acceleration R dOmega/dt leaves the gravity reference
    wheel_radius_sigma: float = 0.05         # prior 1-sigma of the rolling radius's relative error (learnt from accelerating and braking)
    # --- spin coupling of the in-plane gyro biases (spin_coupling.py) ----------------------------
    spin_coupling: bool = True               # remove b0 + k*Omega (learnt) instead of the spinning bias at rest
    spin_coupling_sigma: float = 0.01        # prior 1-sigma of k, rad/s per rad/s
    spin_coupling_rest_sigma_rad_s: float = 2e-4  # b0 + k*Omega replaces the spinning bias once b0's sigma is below
    spin_coupling_bias_walk_rad_s_rts: float = 3e-6   # in-plane bias random walk (MEMS: bias instability), rad/s/sqrt(s)
    # --- lock-in (synchronous least squares) -----------------------------------------------------
    lockin_revolutions: int = 4              # sliding window length, whole revolutions
    lockin_poly_order: int = 1               # body-frame in-plane signal modelled as a polynomial in t
    lockin_max_span_s: float = 30.0          # revolutions older than this (to the newest) leave the window
    measurement_poly_order: int = 1          # single-revolution bias measurements: body-signal model order
                                             # (1 keeps a manoeuvre's linear trend out of the bias, ~20 % more noise)
    bias_variance_floor: float = 1e-12       # (rad/s)^2 or (m/s^2)^2: reported variances never below
    # --- outputs ---------------------------------------------------------------------------------
    high_rate: bool = False                  # also return every sample rotated into the body frame
    temperature_rate_window_s: float = 20.0  # dT/dt of bias measurements: LS slope over this window
    max_block_samples: int = 8192            # long chunks are processed in blocks of this many samples
    min_batch_s: float = 0.01                # process once this much IMU time is pending: a 1 kHz node
                                             # calling update() per sample pays the pipeline per 10 samples
    flip: FlipConfig = field(default_factory=FlipConfig)

    @property
    def reads_mag(self) -> bool:
        """Whether the core reads the magnetometer: the gravity_mag angle reference, without the flip."""
        return self.angle_reference == 'gravity_mag' and not self.flip.enabled

    def __post_init__(self):
        if self.angle_source not in ('auto', 'gyro'):
            raise ValueError(f"angle_source must be 'auto' or 'gyro', not {self.angle_source!r}")
        if self.angle_reference not in ('gravity', 'gravity_mag', 'none'):
            raise ValueError(f"angle_reference must be 'gravity', 'gravity_mag' or 'none', not {self.angle_reference!r}")
        if self.flip.axis not in ('x', 'y'):
            raise ValueError(f"flip.axis must be 'x' or 'y', not {self.flip.axis!r}")
        if self.max_revolution_period_s <= 0 or self.pass_through_period_s <= 0:
            raise ValueError('max_revolution_period_s and pass_through_period_s must be > 0')
        if self.lockin_revolutions < 1 or self.lockin_poly_order not in (0, 1, 2) \
                or self.measurement_poly_order not in (0, 1):
            raise ValueError('lockin_revolutions >= 1, lockin_poly_order in {0, 1, 2} and '
                             'measurement_poly_order in {0, 1} required')

    @classmethod
    def turntable(cls, **overrides) -> 'CarouselConfig':
        """Motor-driven table, 0.5-15 Hz (the paper's rig): steady rate, tight validity checks."""
        return replace(cls(max_rate_deviation=0.3), **overrides)

    @classmethod
    def wheel(cls, **overrides) -> 'CarouselConfig':
        """IMU on a non-steered wheel: rate follows vehicle speed, varies, stops and reverses.

        Set `carousel_to_body` to map the axle (carousel z) onto base_link, e.g. for a left wheel
        with carousel z along body +y: ((1,0,0), (0,0,1), (0,-1,0)) read as rows of M."""
        # No spin coupling: a wheel's revolutions carry the vehicle's own motion, which changes with
        # speed, so k learnt from them is wrong (bags/carousel_wheel at stops: 2.6e-3 -> 1.1e-2 rad/s).
        return replace(cls(max_rate_deviation=0.6, max_revolution_period_s=3.0,
                           pass_through_period_s=0.25, lockin_revolutions=8, spin_coupling=False), **overrides)

    def problems(self) -> list[str]:
        """Why this configuration cannot run, one sentence per problem naming the fields (empty: it
        can). What only the whole config can tell (each number's own range is in the node's
        parameter table, nodes/parameters.py; `__post_init__` refuses the rest)."""
        out = []
        for key, m in (('carousel_to_body', self.carousel_to_body),
                       ('flip.aux_to_platform', self.flip.aux_to_platform)):
            rows = [list(r) for r in m] if all(isinstance(r, (tuple, list)) for r in m) else []
            if len(rows) != 3 or any(len(r) != 3 for r in rows) or \
                    not all(isinstance(v, (int, float)) and v == v and abs(v) < float('inf') for r in rows for v in r):
                out.append(f'{key} must be 9 finite numbers (a 3x3 matrix, row by row)')
                continue
            gram = [[sum(rows[i][k] * rows[j][k] for k in range(3)) for j in range(3)] for i in range(3)]
            if any(abs(gram[i][j] - (i == j)) > 1e-3 for i in range(3) for j in range(3)):
                out.append(f'{key} must be a rotation matrix (orthonormal rows, to 1e-3)')
        return out
