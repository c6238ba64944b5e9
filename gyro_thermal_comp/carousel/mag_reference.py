"""The magnetometer as the second angle reference of the encoder-free carousel.

With the spin axis vertical gravity has no in-plane component, but the Earth's field has its
horizontal part (~20 uT at mid latitudes). Demodulated with the angle in use exactly as the specific
force is (integrals.angle_integral over the revolution), a revolution gives
m = B_c * mean(e^{i(theta - theta_true)}), B_c the in-plane field in the carousel frame: the hard iron
is fixed in the sensor and cancels like a bias, soft iron mostly scales (its anisotropic part turns at
twice the angle and averages out). arg(m / m_ref) is then the same linear measurement of the gyro
angle's error as gravity's (angle_reference.GravityAngleFilter uses it while gravity is unobservable).

m_ref: the still start's mean field at `initial_angle_rad`, the in-plane hard iron removed and the
soft iron's anisotropic part undone (both long averages of per-revolution fits, as the accelerometer
bias behind the gravity reference), or without a still start the first revolution with mag data.

Gate (as the thermal side's magnetic gate with field norm and dip): a revolution whose in-plane field
strength differs from the reference's by more than `mag_ref_inplane_tol` (relative), or whose axial
field differs by more than `mag_ref_axial_tol` of the reference |B|, is not used; the reasons are
counted. A disturbance below both tolerances that turns the field passes and turns the reference.

Physics caveat: the field is fixed in the local-level / north frame, not in the body. If the body
yaws, the magnetometer sees body yaw as platform angle (gravity does not): the angle in use then
follows north and the in-plane outputs are expressed in a frame that does not turn with the body.
Units: T, rad, s.
"""
from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

import numpy as np

from .config import CarouselConfig
from .integrals import angle_integral

MIN_INPLANE_T = 1e-6            # in-plane field below this (spin axis along the field): unobservable, T
HARD_IRON_MEMORY_S = 600.0      # memory of the hard-iron average behind the still-start reference, s
MIN_RESIDUAL_VAR_T2 = 1e-24     # a revolution's fit residual variance never counts below this (1e-6 uT rms), T^2
COUNTERS = ('mag_revolutions_passed', 'mag_rejected_inplane', 'mag_rejected_axial', 'mag_missing', 'mag_unobservable')


@dataclass(frozen=True)
class MagRevolution:
    """One whole revolution of magnetometer data, demodulated with the angle in use."""
    inplane: complex        # demodulated in-plane field, carousel frame, T
    axial: float            # time mean of the axial field (hard iron in), T
    hard_iron: complex      # platform in-plane hard iron, least squares over the revolution, T
    soft_iron: complex      # anisotropic over isotropic in-plane soft iron, rho (see MagReference.reference)
    residual_var: float     # per-sample residual variance per in-plane component, T^2
    n: int                  # samples
    duration_s: float

    @classmethod
    def from_window(cls, window, turn_rad: float) -> MagRevolution | None:
        """From a revolution's `window.IntervalWindow` (None unless every sample has a mag value)."""
        s = window.signals
        if not window.mag_ok or len(s.t) < 4:
            return None
        m = complex(angle_integral(s.theta, s.mag_inplane) / turn_rad)
        # platform-frame samples: z = h + e^{-i theta} m1 + e^{i theta} m2: the hard iron fixed, the field
        # turning back, and the anisotropic soft iron A (A z = alpha conj(z)) turning the other way,
        # m2 = alpha conj(B_c) against m1 = iso B_c: rho = m2 / conj(m1) = alpha / iso, whatever the angle error
        rot = np.exp(-1j * s.theta)
        a = np.column_stack((np.ones(len(s.t)), rot, np.conj(rot)))
        x, *_ = np.linalg.lstsq(a, s.mag_inplane, rcond=None)
        resid = s.mag_inplane - a @ x
        rho = complex(x[2] / np.conj(x[1])) if abs(x[1]) > 0 else 0j
        return cls(inplane=m, axial=float(window.time_mean(s.mag_axial)), hard_iron=complex(x[0]), soft_iron=rho,
                   residual_var=0.5 * float(np.mean(np.abs(resid) ** 2)), n=len(s.t),
                   duration_s=float(window.duration_s))


class MagReference:
    """Reference field, hard-iron average and gate; `observe` gives (m_ref, measurement variance) or None."""

    def __init__(self, config: CarouselConfig):
        self.config = config
        self.enabled = config.reads_mag
        self._still: tuple[complex, float] | None = None   # still start's raw in-plane (platform) and axial mean
        self._first: tuple[complex, float] | None = None   # first revolution's (no still start)
        self._hi_sum, self._rho_sum, self._hi_weight = 0j, 0j, 0.0
        self.hard_iron = 0j             # platform in-plane hard iron in use, T
        self.soft_iron = 0j             # rho in use
        self.counts = Counter(dict.fromkeys(COUNTERS, 0))
        self.why = 'no revolution with magnetometer data yet'    # why the last revolution was not used

    def on_still(self, still) -> None:
        """The still start ended: if accepted with magnetometer samples, its mean is the reference."""
        mean = still.mag_mean
        if self.enabled and still.accepted and mean is not None:
            self._still = (complex(mean[0], mean[1]), float(mean[2]))

    def reference(self) -> tuple[complex, float] | None:
        """(in-plane field, carousel frame, T; axial field, T) the revolutions are compared with."""
        if self._still is not None:
            # still: v = z - h = u + rho conj(u), u = e^{-i theta0} m_ref the isotropic part the revolutions
            # demodulate (left in, the anisotropy turns the reference by a fixed angle of order |rho|)
            inplane, axial = self._still
            v, rho = inplane - self.hard_iron, self.soft_iron
            u = (v - rho * np.conj(v)) / (1.0 - abs(rho) ** 2)
            return complex(np.exp(1j * self.config.initial_angle_rad) * u), axial
        return self._first

    @property
    def from_first_revolution(self) -> bool:
        """The reference is a first revolution's (no still start): turned by the gyro angle's error then."""
        return self._still is None and self._first is not None

    @property
    def source(self) -> str:
        return 'the still start' if self._still is not None else 'the first revolution (no still start)'

    def observe(self, rev: MagRevolution | None) -> tuple[complex, float] | None:
        """Learn from a revolution; (m_ref, variance of its angle measurement, rad^2 before the floor)
        if it may be used, else None with `why` set and the reason counted."""
        if rev is None:
            self.counts['mag_missing'] += 1
            self.why = 'revolution without full magnetometer coverage'
            return None
        # each revolution's fit weighted by its samples over its residual variance: one whose angle in use was still
        # being slewed to the learnt model (the first after the still start, with a large axial bias) fits badly
        # and must not leave its hard iron in the average for the average's memory
        keep = np.exp(-rev.duration_s / HARD_IRON_MEMORY_S)
        weight = rev.n / max(rev.residual_var, MIN_RESIDUAL_VAR_T2)
        self._hi_sum = keep * self._hi_sum + weight * rev.hard_iron
        self._rho_sum = keep * self._rho_sum + weight * rev.soft_iron
        self._hi_weight = keep * self._hi_weight + weight
        self.hard_iron = self._hi_sum / self._hi_weight
        self.soft_iron = self._rho_sum / self._hi_weight
        if self._still is None and self._first is None:
            self._first = (rev.inplane, rev.axial)      # defines the frame
        ref, axial_ref = self.reference()
        cfg = self.config
        if abs(ref) < MIN_INPLANE_T:
            self.counts['mag_unobservable'] += 1
            self.why = f'in-plane field {abs(ref) * 1e6:.3g} uT < {MIN_INPLANE_T * 1e6:g} (spin axis along the field)'
            return None
        strength = abs(rev.inplane) / abs(ref) - 1.0
        if abs(strength) > cfg.mag_ref_inplane_tol:
            self.counts['mag_rejected_inplane'] += 1
            self.why = (f'in-plane field strength off the reference by {100 * strength:+.1f} % (tolerance '
                        f'{100 * cfg.mag_ref_inplane_tol:g} %)')
            return None
        axial = (rev.axial - axial_ref) / np.hypot(abs(ref), axial_ref)
        if abs(axial) > cfg.mag_ref_axial_tol:
            self.counts['mag_rejected_axial'] += 1
            self.why = (f'axial field off the reference by {100 * axial:+.1f} % of |B| (tolerance '
                        f'{100 * cfg.mag_ref_axial_tol:g} %)')
            return None
        self.counts['mag_revolutions_passed'] += 1
        self.why = ''
        return ref, rev.residual_var / rev.n / abs(ref) ** 2

    def rejections(self) -> str:
        """The gate's counts in words."""
        c = self.counts
        return (f"{c['mag_revolutions_passed']} revolutions passed the gate, rejected: in-plane strength "
                f"{c['mag_rejected_inplane']}, axial field {c['mag_rejected_axial']}, no mag data {c['mag_missing']}")
