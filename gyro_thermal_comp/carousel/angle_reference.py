"""Carousel angle without an encoder: the integrated axial gyro, corrected from gravity.

The integrated axial gyro `raw` (rad) drifts from the true platform angle by what it cannot tell from
spin: axial bias, scale factor, body yaw. Its error is modelled as

    err(t) = raw(t) - theta_true(t) = off + b * (t - t0) + s * (raw(t) - raw0)      (+ random walk)

and a Kalman filter learns x = [off rad, b rad/s, s] from what is fixed in the body: when the
spin axis is tilted, specific force has an in-plane component w (g sin(tilt)) fixed in the carousel
frame. A revolution demodulated with the angle in use, theta = raw - corr, gives c = w * mean(e^{i(theta -
theta_true)}), so arg(c / w_ref) is the revolution's mean of theta - theta_true, i.e. a linear
measurement of mean(err) - mean(corr). w_ref, the direction of w in the carousel frame, comes from the
still start (platform at `initial_angle_rad`, sensor-fixed accelerometer bias from the lock-in), or
without a still start from the first revolution. The still start also says the platform did not turn:
a measurement of b. The correction is slewed in over one revolution (never a jump of theta), and what
was applied is remembered, so measurements stay exact whatever the slew.

The frame is fixed by the first sample: the platform is at `initial_angle_rad` there, so off = 0 is known
(its variance grows only with the angle random walk). A reference taken from the first revolution is
turned from the true w by the gyro angle's error over that revolution, b * (its mean time - t0) + s * (its
mean raw - raw0) with b and s not yet known (at 0.5 Hz and 0.5 deg/s of axial bias: 0.026 rad). Its
direction is therefore a state of the filter, phi (rad; one for gravity, one for the magnetometer), with an
uninformative prior: every revolution measures mean(err) + phi, and once the revolutions have taught b and
s, phi follows from off = 0 at the first sample. Taking the first revolution's reference as exact instead
(and off as unknown) puts that revolution's error, which grows with the axial bias, into the output frame
for good. A still-start reference is exact in this sense (phi's variance 0): the platform did not turn.

On a wheel (`wheel_radius_m` set) the hub's road acceleration, R dOmega/dt from the axial gyro, is taken out
of the measured specific force first (wheel_reference.py; a first-revolution reference too), and a fourth
state learns the radius's relative error. When |w| is too small (spin axis near vertical) nothing is corrected
(the gyro angle, as before) and `status` says so, as it says when no revolution has given a reference for a
while (the learnt model holds the angle). Units: rad, rad/s, s, m/s^2.

This module holds the filter: its states, the measurements the still start and each revolution give (gravity,
or the magnetometer standing in), and the status line. Its parts: the Kalman filter and its innovation gate
(gated_kalman.py), the correction as applied, its update grid and slew (applied_correction.py), gravity's
reference w_ref (gravity_reference.py), the magnetometer's (mag_reference.py) and the wheel's rolling model
(wheel_reference.py).
"""
from __future__ import annotations

import numpy as np

from ..angles import wrap_angle
from . import wheel_reference
from .applied_correction import AppliedCorrection
from .config import CarouselConfig
from .gated_kalman import GatedKalman
from .gravity_reference import GravityReference
from .mag_reference import MagRevolution, MagReference

GYRO_NOISE_MEMORY_S = 600.0   # memory of the axial gyro's measured white-noise density, s
REFERENCE_PRIOR_RAD2 = 1.0    # prior variance of a first-revolution reference's direction, rad^2 (uninformative)


class GravityAngleFilter:
    """State of the gyro-angle error; `correction(t, raw)` is what to subtract from the raw integral."""

    def __init__(self, config: CarouselConfig):
        self.config = config
        self.enabled = config.angle_reference in ('gravity', 'gravity_mag') and not config.flip.enabled
        self.mag = MagReference(config)     # gravity_mag: the second reference, while gravity is unobservable
        self.gravity_ref = GravityReference(config.initial_angle_rad)
        # on a wheel: the road acceleration leaves the gravity reference, x[3] = the radius's relative error
        on_wheel = self.enabled and bool(config.wheel_radius_m)
        self.wheel = wheel_reference.Wheel(config.wheel_radius_m) if on_wheel else None
        wheel = [config.wheel_radius_sigma ** 2] if on_wheel else []
        # states: off rad, b rad/s, s, (wheel) rho, then the directions of the gravity and magnetometer
        # references, rad (variance 0 unless taken from a first revolution)
        self.i_rho = 3 if on_wheel else None
        self.i_ref = {'gravity': 3 + len(wheel), 'mag': 4 + len(wheel)}
        self.kalman = GatedKalman([0.0, config.angle_ref_bias_sigma_rad_s ** 2, config.angle_ref_scale_sigma ** 2]
                                  + wheel + [0.0, 0.0], config.angle_ref_gate_sigma)
        self.applied = AppliedCorrection(len(self.x), 3.0 * config.max_revolution_period_s,
                                         self.wheel.tilt if on_wheel else None)
        self._t_reference: float | None = None   # end of the last revolution that gave a measurement
        self._opened: set = set()           # references whose direction is a learnt state (first revolution)
        self._noise_sum, self._noise_weight = 0.0, 0.0     # the axial gyro's white-noise density^2, rad^2/s
        self.inplane_m_s2 = 0.0             # |w| last seen
        self.observable = False             # a revolution has shown enough in-plane specific force
        self.measurements = 0
        self._status = 'acquiring: no revolution yet' if self.enabled else 'off'

    @property
    def x(self) -> np.ndarray:
        """The filter's estimate: off rad, b rad/s, s, (wheel) rho, the references' directions rad."""
        return self.kalman.x

    @property
    def rejected(self) -> int:
        """Measurements the innovation gate refused."""
        return self.kalman.rejected

    @property
    def status(self) -> str:
        """Where the angle's correction comes from, in one line; says when no revolution has given a
        reference for longer than a revolution may take (standing, creeping, irregular rotation)."""
        last_t = self.applied.last_t
        if not (self.enabled and self._t_reference is not None and last_t is not None):
            return self._status
        silent = last_t - self._t_reference
        if silent <= self.config.max_revolution_period_s:
            return self._status
        return (f'{self._status}; no reference for {silent:.0f} s (no clean revolution: standing, creeping or '
                'irregular rotation), the learnt gyro model holds the angle')

    # ------------------------------------------------------------------ the angle
    def correction(self, t: np.ndarray, raw: np.ndarray) -> np.ndarray:
        """Correction to subtract from raw angles at times t (rad); remembered as applied."""
        if self.enabled and self.applied.t0 is None and len(t):
            self.applied.t0, self.applied.raw0 = float(t[0]), float(raw[0])     # the frame: the first sample
        if self.enabled and self.observable:
            corr, tilt = self.applied.follow(t, raw)
        else:       # nothing to correct from (yet): the gyro angle, as without the filter
            corr, tilt = np.zeros(len(t)), np.zeros(len(t))
        self.applied.remember(t, raw, corr, tilt)
        return corr

    def true_spin(self, spin_raw: float) -> float:
        """The platform's rate from the axial gyro's (bias removed as the book has it), with the learnt
        axial bias and scale factor taken out: d(raw - err)/dt, rad/s."""
        return spin_raw * (1.0 - self.x[2]) - self.x[1]

    def reset(self, gap_s: float) -> None:
        """Data gap: the platform may have turned meanwhile; forget where it is (not b, s)."""
        if self.enabled:
            self.kalman.p[0, 0] += min((gap_s * 2 * np.pi / self.config.max_revolution_period_s) ** 2, np.pi ** 2)

    # ------------------------------------------------------------------ start-up still stretch
    def on_still(self, still) -> None:
        """The start-up still stretch ended (still_start.StillStart): if the body was at rest, gravity's
        in-plane direction at the initial angle is the reference, and the platform did not turn: the
        integrated axial gyro over it is all error (a measurement of b)."""
        self.mag.on_still(still)
        if not (self.enabled and still.accepted and self.applied.t0 is not None):
            return
        self.gravity_ref.on_still(still)
        # the platform at rest until the spin-up's onset (still_start: it turns a little before the threshold)
        t_rest, raw1 = still.rest_end
        raw0 = still.raw_angle[0]
        dur = t_rest - still.t0
        self._predict(still.t1)
        dt = still.duration_s / max(still.n - 1, 1)
        r = max(float(still.gyro_var[2]) * dt * dur, 1e-12)      # angle random walk over the stretch
        h = np.array([0.0, dur, raw1 - raw0] + [0.0] * (len(self.x) - 3))
        if self.kalman.update(h, raw1 - raw0, r, wrap=False):
            self.applied.schedule(still.t1, self.x.copy(), 1.0)

    # ------------------------------------------------------------------ revolutions
    def observe_revolution(self, t: np.ndarray, theta: np.ndarray, accel_carousel: complex,
                           accel_residual_var: float, accel_bias: complex, mag: MagRevolution | None = None,
                           wheel: wheel_reference.WheelRevolution | None = None,
                           gyro_noise_rad2_s: float = 0.0) -> float:
        """A demodulated revolution: its samples' times and angles in use, the demodulated in-plane
        specific force (carousel frame, bias removed), the per-sample residual variance per component,
        the platform in-plane accel bias in use, (gravity_mag) its magnetometer data, (wheel) its
        wheel_reference.WheelRevolution and the axial gyro's white-noise density^2 measured over it (rad^2/s,
        0: not measured; `gyro_noise_density`). Returns the
        estimated mean of (angle in use - true angle) over the revolution after this update, rad (0 when
        not observable): rotating the revolution's in-plane outputs by -that removes the filter's lag."""
        if not self.enabled or self.applied.t0 is None or len(t) < 2:
            return 0.0
        cfg = self.config
        extra = np.zeros(len(self.x) - 3)        # the measurement's rho (wheel, gravity only) and reference columns
        duration = float(t[-1] - t[0])
        self.gravity_ref.average_bias(accel_bias, duration)
        if gyro_noise_rad2_s > 0.0:
            keep = np.exp(-duration / GYRO_NOISE_MEMORY_S)
            self._noise_sum = keep * self._noise_sum + duration * gyro_noise_rad2_s
            self._noise_weight = keep * self._noise_weight + duration
        if self.gravity_ref.wanted:
            # no still start: the first revolution gives the reference, turned by the gyro angle's error over
            # it (not known yet): its direction is learnt (the frame itself stays fixed by the first sample)
            rolling = self.wheel is not None and wheel is not None
            road = self._rolling(accel_carousel, t, theta, wheel).accel_m_s2 if rolling else None
            self.gravity_ref.take_first(accel_carousel, road)
            self._open_reference('gravity')
        w_ref = self.gravity_ref.reference()
        self.inplane_m_s2 = abs(accel_carousel)
        mag_ref = self.mag.observe(mag) if self.mag.enabled else None
        if self.mag.from_first_revolution:
            self._open_reference('mag')
        if abs(w_ref) < cfg.angle_ref_min_inplane_m_s2 or abs(accel_carousel) < cfg.angle_ref_min_inplane_m_s2:
            # (once observable the learnt model keeps correcting; only the measurements stop)
            unobservable = (f'in-plane specific force {abs(accel_carousel):.3g} m/s^2 < '
                            f'{cfg.angle_ref_min_inplane_m_s2:g} (spin axis near vertical)')
            if mag_ref is None and self.mag.enabled and self.observable:
                self._status = (f'magnetometer (gravity unobservable): revolution not used, {self.mag.why}; the learnt '
                                f'gyro model holds the angle ({self.mag.rejections()})')
            elif mag_ref is None:
                self._status = f'unobservable: {unobservable}; gyro angle, the output frame drifts with the axial gyro'
                if self.mag.enabled:
                    self._status += f'; magnetometer not used: {self.mag.why} ({self.mag.rejections()})'
            if mag_ref is None:
                return 0.0
            # the magnetometer stands in: the same measurement from the in-plane field
            ref, var = mag_ref
            e = wrap_angle(float(np.angle(mag.inplane / ref)))
            extra[self.i_ref['mag'] - 3] = 1.0
            r = max(var, cfg.angle_ref_floor_rad ** 2)
            label = f'magnetometer (gravity unobservable): in-plane field {abs(ref) * 1e6:.3g} uT'
            tail = (f', reference from {self.mag.source}; {self.mag.rejections()}; body yaw reads as platform '
                    'angle (the field is fixed to north, not to the body)')
        else:
            w_pred, r_wheel, label = w_ref, 0.0, f'gravity: in-plane specific force {abs(w_ref):.3g} m/s^2'
            if self.wheel is not None and wheel is not None:
                roll = self._rolling(w_ref, t, theta, wheel)
                w_pred, r_wheel = roll.specific_force, roll.angle_var
                extra[self.i_rho - 3] = roll.d_angle_d_rho
            extra[self.i_ref['gravity'] - 3] = 1.0
            # mean(theta - theta_true) (+ the reference's direction), plus the radius term's linearisation point
            e = wrap_angle(float(np.angle(accel_carousel / w_pred)))
            if self.i_rho is not None:
                e += extra[self.i_rho - 3] * self.x[self.i_rho]
            r = max(accel_residual_var / len(t) / abs(w_ref) ** 2 + r_wheel, cfg.angle_ref_floor_rad ** 2)
            tail = ', reference from ' + ('the still start' if self.gravity_ref.from_still else
                                          'the first revolution (no still start; its direction learnt, sigma '
                                          f'{np.degrees(self.kalman.sigma(self.i_ref["gravity"])):.2g} deg)')
            if self.wheel is None and self.rejected > self.measurements:
                tail += (f'; {self.rejected} revolutions refused, {self.measurements} used: the body accelerates? '
                         '(on a wheel set wheel_radius_m)')
        self.observable = True
        corr, tilt = self.applied.at(t)     # the axle-tilt integral is known, not the model's: out of y
        raw = theta + corr
        dth = np.abs(np.diff(theta))
        wgt = np.concatenate(([0.0], dth)) + np.concatenate((dth, [0.0]))   # angle-domain (trapezoid) weights
        if wgt.sum() <= 0:
            return 0.0
        mean = lambda v: float(np.sum(wgt * v) / np.sum(wgt))   # noqa: E731
        self._predict(float(t[-1]))
        h = np.array([1.0, mean(t) - self.applied.t0, mean(raw) - self.applied.raw0, *extra])
        # A field turned by a disturbance keeps its strength (to second order) and passes the mag gate: the
        # magnetometer re-anchors only on refused measurements that agree (a fade-in or -out moves them).
        accepted = self.kalman.update(h, e + mean(corr) - mean(tilt), r, wrap=True, agree=mag_ref is not None)
        if accepted:
            self.measurements += 1
            self._t_reference = float(t[-1])
            if self.wheel is not None and mag_ref is None:
                i = self.i_rho
                label = self.wheel.describe(label, self.x[i], np.sqrt(self.kalman.p[i, i]), self.rejected)
            self._status = f'{label}, angle sigma {np.degrees(self._angle_sigma(t[-1], raw[-1])):.2g} deg{tail}'
        zeta = None
        if self.wheel is not None and wheel is not None and mag_ref is None:
            zeta = self.wheel.tilt_rate(w_ref, wheel, self.x[self.i_rho],
                                        self.true_spin(float(theta[-1] - theta[0]) / duration))
        if accepted or zeta is not None:
            self.applied.schedule(float(t[-1]), self.x.copy() if accepted else None, duration, zeta)
        return float(h[:3] @ self.x[:3]) - mean(corr) + mean(tilt)

    def _rolling(self, w_ref: complex, t: np.ndarray, theta: np.ndarray, wheel: wheel_reference.WheelRevolution):
        """The revolution's predicted specific force on a wheel (wheel_reference.predict), from the true spin."""
        dt = float(t[-1] - t[0]) / max(len(t) - 1, 1)
        spin_var = self.gyro_noise_density ** 2 / max(dt, 1e-6)    # per sample, (rad/s)^2
        return self.wheel.predict(w_ref, float(self.x[self.i_rho]), self.true_spin(wheel.spin_a),
                                  self.true_spin(wheel.spin_b), float(theta[-1] - theta[0]), spin_var)

    def _open_reference(self, name: str) -> None:
        """A reference taken from a first revolution: its direction is not known (rad^2 prior, once)."""
        i = self.i_ref[name]
        if name not in self._opened:
            self._opened.add(name)
            self.kalman.p[i, i] = REFERENCE_PRIOR_RAD2

    @property
    def gyro_noise_density(self) -> float:
        """The gyro angle's random walk in use, rad/s/sqrt(Hz): the axial gyro's white noise as measured on the
        revolutions (long average), never below `angle_ref_gyro_noise_rad_s_rthz` (which also covers what the
        model leaves out). A filter that assumes a quieter gyro than it has trusts its model too long."""
        measured = np.sqrt(self._noise_sum / self._noise_weight) if self._noise_weight > 0 else 0.0
        return float(max(self.config.angle_ref_gyro_noise_rad_s_rthz, measured))

    def _angle_sigma(self, t_s: float, raw: float) -> float:
        """1-sigma of the gyro angle's modelled error at (t_s, raw), rad."""
        h = np.zeros(len(self.x))
        h[:3] = 1.0, t_s - self.applied.t0, raw - self.applied.raw0
        return float(np.sqrt(max(h @ self.kalman.p @ h, 0.0)))

    @property
    def axial_bias(self) -> tuple[float, float] | None:
        """(b, its 1-sigma), rad/s: the axial gyro's drift (less the book's axial bias) as the angle reference
        has learnt it, plus the body's inertial rate about the spin axis (a static body: the Earth's, <= 7.3e-5);
        None before a revolution gave a reference."""
        if not (self.enabled and self.observable):
            return None
        return float(self.x[1]), self.kalman.sigma(1)

    def _predict(self, t: float) -> None:
        """The covariance to t: the angle walks with the gyro's white noise, the axial bias with its random walk."""
        self.kalman.predict(t, (self.gyro_noise_density ** 2, self.config.angle_ref_bias_walk_rad_s_rts ** 2))
