"""On a wheel without an encoder: the vehicle's own acceleration, known from the wheel's rate, taken out of the
gravity reference.

With the axle horizontal, gravity lies in the wheel's plane and its in-plane specific force is the reference
of angle_reference.GravityAngleFilter; but the hub also accelerates with the vehicle. Rolling without slip,
the hub moves at R * Omega along (axle x up) (R: rolling radius, m; Omega: the wheel's rate about the axle,
the axial gyro, rad/s), so its acceleration along the road is R dOmega/dt: in the carousel frame along
i * u, u the unit vector up (the still start's in-plane specific force) and i a quarter turn about the axle
(carousel +z). The hub's other acceleration, a turn's centripetal speed x yaw rate, lies along the axle
(axial). A revolution's angle-domain mean of the road acceleration is exact from the wheel's rate at its two
ends, whatever the speed does inside:

    (1/turn) integral R dOmega/dt dtheta = (1/turn) integral R Omega dOmega = R (Omega_b^2 - Omega_a^2) / (2 turn)

The revolution's predicted in-plane specific force is w_ref + i u R (1 + rho) A, rho the radius's relative
error, a state of the filter (a rolling radius is rarely known better than a few %; a steady speed teaches
nothing about it, accelerating and braking do).

The axle tilted out of the level (a rolled body, a cambered road) turns part of the body's yaw rate into the
axial gyro: a rotation about the vertical that gravity does not see. The rate of it, zeta = (gravity's
axial share) x (yaw rate), is known from the revolution's means: the yaw rate from the demodulated in-plane
gyro along u, gravity's axial share from the axial specific force less the turn's centripetal acceleration
(speed R Omega x yaw rate, along the axle). `AxleTilt` integrates it (piecewise linear, each revolution's
rate for as long as that revolution lasted) and the filter takes it out of the gyro angle, as a known part
of its error: otherwise the filter fights it and lags in every turn. An accelerometer axial bias reads as a
tilt of the axle (bias / g of the yaw turned).

Not separable from the wheel turning: the body's pitch (suspension, slope) turns gravity in the body, and the
gyro sees it as wheel rotation too. The angle found is the wheel's against the level, so the output frame is
the body's pitched back to level about the axle (docs/carousel.md, Limitations). Slip (a spinning or locked
wheel) breaks the relation: the filter's innovation gate refuses those revolutions. Units: m, rad, rad/s, m/s^2.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class RollingPrediction:
    specific_force: complex     # predicted in-plane specific force, carousel frame, m/s^2
    d_angle_d_rho: float        # d arg(specific_force) / d rho, rad per unit relative radius error
    angle_var: float            # variance of arg(specific_force) from the gyro noise at the two ends, rad^2
    accel_m_s2: float           # the revolution's mean road acceleration R (1 + rho) A, m/s^2 (signed: along i u)


def mean_spin_acceleration(spin_a: float, spin_b: float, turn_rad: float) -> float:
    """Angle-domain mean of dOmega/dt over a revolution from the rates at its ends, rad/s^2."""
    return (spin_b ** 2 - spin_a ** 2) / (2.0 * turn_rad)


def predict(w_ref: complex, radius_m: float, rho: float, spin_a: float, spin_b: float, turn_rad: float,
            spin_var: float) -> RollingPrediction:
    """The revolution's in-plane specific force: gravity's (w_ref) plus the road acceleration, from the wheel's
    true rate at the revolution's ends (rad/s, each with variance spin_var)."""
    accel = radius_m * mean_spin_acceleration(spin_a, spin_b, turn_rad)     # m/s^2 per unit (1 + rho)
    a_unit = 1j * w_ref / abs(w_ref) * accel
    w = w_ref + (1.0 + rho) * a_unit
    var_accel = (radius_m * (1.0 + rho) / turn_rad) ** 2 * (spin_a ** 2 + spin_b ** 2) * spin_var
    return RollingPrediction(specific_force=complex(w), d_angle_d_rho=float((a_unit / w).imag),
                             angle_var=float(var_accel / abs(w) ** 2), accel_m_s2=float(accel * (1.0 + rho)))


@dataclass(frozen=True)
class WheelRevolution:
    """What a revolution tells about the wheel's motion: the axial gyro's rate at its two ends (the book's
    axial bias removed, rad/s), its demodulated in-plane gyro (carousel frame, rad/s) and the time mean of
    its axial specific force (m/s^2)."""
    spin_a: float
    spin_b: float
    rate_inplane: complex
    accel_axial: float


def axle_tilt_rate(w_ref: complex, rate_inplane: complex, accel_axial: float, speed_m_s: float) -> float:
    """zeta, rad/s: the body's yaw rate seen by the axial gyro through the axle's tilt out of the level (with
    the axle level it is zero). Gravity's in-plane direction u = w_ref / |w_ref| is up; the turn's
    centripetal acceleration, speed x yaw rate, lies along the axle."""
    g = abs(w_ref)
    yaw = float((rate_inplane * np.conj(w_ref / g)).real)     # body rate about up (its in-plane part)
    up_axial = (accel_axial - yaw * speed_m_s) / g            # gravity's axial share: the axle's tilt
    return up_axial * yaw


class AxleTilt:
    """K(t) = the integral of zeta, rad: piecewise linear and continuous; each revolution's rate applies
    from where it is activated for as long as that revolution lasted (no revolution: no rate)."""

    def __init__(self):
        self._t_a, self._k_a, self._rate, self._span = 0.0, 0.0, 0.0, 0.0

    def at(self, t):
        return self._k_a + self._rate * np.clip(t - self._t_a, 0.0, self._span)

    def activate(self, t_a: float, rate_rad_s: float, span_s: float) -> None:
        self._k_a = float(self.at(t_a))
        self._t_a, self._rate, self._span = float(t_a), float(rate_rad_s), float(span_s)


class Wheel:
    """The wheel's side of GravityAngleFilter (which holds rho, its fourth state): the revolution's predicted
    specific force, the axle-tilt integral, and the words for the diagnostics."""

    def __init__(self, radius_m: float):
        self.radius_m = float(radius_m)
        self.tilt = AxleTilt()
        self.road_accel_m_s2 = 0.0      # the last revolution's mean road acceleration, m/s^2
        self.tilt_rate_rad_s = 0.0      # the last revolution's zeta, rad/s

    def predict(self, w_ref: complex, rho: float, spin_a: float, spin_b: float, turn_rad: float,
                spin_var: float) -> RollingPrediction:
        roll = predict(w_ref, self.radius_m, rho, spin_a, spin_b, turn_rad, spin_var)
        self.road_accel_m_s2 = roll.accel_m_s2
        return roll

    def tilt_rate(self, w_ref: complex, rev: WheelRevolution, rho: float, spin_rad_s: float) -> float:
        """zeta of the revolution (axle_tilt_rate), its speed from the learnt radius."""
        speed = self.radius_m * (1.0 + rho) * spin_rad_s
        self.tilt_rate_rad_s = axle_tilt_rate(w_ref, rev.rate_inplane, rev.accel_axial, speed)
        return self.tilt_rate_rad_s

    def describe(self, gravity: str, rho: float, rho_sigma: float, refused: int) -> str:
        return (f'wheel: {gravity} less the road acceleration R dOmega/dt ({self.road_accel_m_s2:+.2f} m/s^2 last '
                f'revolution; radius {self.radius_m * (1 + rho):.4g} m, {100 * rho:+.1f} +- {100 * rho_sigma:.1f} % '
                f'learnt on {self.radius_m:g}; {refused} revolutions refused: slip, bumps)')
