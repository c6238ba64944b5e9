"""The optional error effects of the simulator: one stable name each, shared with the discovery library.

VALUE (``effects={NAME: VALUE}``, CLI ``--effect NAME=VALUE``) is the effect's physical size in the
unit below; 0 switches it off. Per-axis coefficients are VALUE times a factor drawn per unit from the
seed (see unit.py): on the heading axis z the factor is exactly +-1, so |coefficient_z| = VALUE; on
x and y it is +-U(0.5, 1.5). Row effects (cross_axis, g_sensitivity) draw a random direction per row,
with row norm VALUE on z. Scalar effects (thermal_lag, time_offset) take VALUE as is.

How each enters (w: true sensor rate w.r.t. inertial space = rate w.r.t. ENU + Earth rate, rad/s;
f: specific force, m/s^2; T: die temperature, degC; g0 = 9.80665 m/s^2; i: sensor axis):

  gyro_i = w_i + D_i + sf_i(T)*w_i + sum_j C_ij w_j + sum_j G_ij f_j/g0 + rrw_i + bi_i + noise + quantisation
  D_i    = a_i*T + b_i*dT/dt + c_i                 (the paper's model, always on, drawn per unit)
         + k_i*(T - 25)^2                          thermal_curvature
         + h_i*m(t)                                thermal_hysteresis
  sf_i(T) = s0_i + s1_i*(T - 25)                   scale_factor (s0), scale_factor_thermal (s1)

  mag = (1 + k_mag*(T_case - 25)) * (M @ (B_earth + B_interference) + h_hard) + noise + quantisation
        with M = I + soft iron and h_hard the hard iron (compass_deviation).
"""
from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class EffectSpec:
    name: str
    unit: str
    default: float          # the size used by the reference scenario static_ramp (0: off there)
    description: str
    minimum: float = 0.0
    maximum: float = math.inf


_SPECS = (
    EffectSpec(
        'thermal_curvature', 'deg/s/degC^2', 6e-5,
        'Quadratic bias term k_i*(T_die - 25 degC)^2 added to D_i; |k_z| = VALUE. Sized so that the '
        'non-linear residual of one global linear fit over 23..58 degC is a few 1e-3 deg/s.', maximum=1e-2),
    EffectSpec(
        'thermal_hysteresis', 'deg/s', 4e-3,
        'Heating/cooling branch offset h_i*m(t) added to D_i; |h_z| = VALUE. m is a first-order lag '
        '(param hysteresis_tau_s) of tanh((dT_die/dt)/0.002 degC/s): +1 after heating, -1 after '
        'cooling, relaxing to 0 at a constant temperature.', maximum=1.0),
    EffectSpec(
        'thermal_lag', 's', 60.0,
        'Time constant by which the die temperature T_die driving every thermal term (D, sf) lags the '
        'case temperature that the temperature sensor reads; dT_die/dt = (T_case - T_die)/VALUE.',
        maximum=3600.0),
    EffectSpec(
        'g_sensitivity', 'deg/s/g', 0.03,
        'Linear-acceleration effect: gyro_i += sum_j G_ij f_j/g0, f the sensor-frame specific force '
        '(1 g up when level and still); row norm |G_z.| = VALUE.', maximum=10.0),
    EffectSpec(
        'scale_factor', 'fraction', 0.01,
        'Scale-factor error s0_i at 25 degC: gyro_i += s0_i*w_i (w including the Earth rate); '
        '|s0_z| = VALUE.', maximum=0.5),
    EffectSpec(
        'scale_factor_thermal', '1/degC', 2e-4,
        'Temperature coefficient of the scale factor: gyro_i += s1_i*(T_die - 25)*w_i; |s1_z| = VALUE '
        '(the paper\'s k(T) = k1*T + k0).', maximum=0.05),
    EffectSpec(
        'cross_axis', 'fraction', 0.01,
        'Cross-axis sensitivity/misalignment: gyro_i += sum_{j!=i} C_ij w_j; row norm |C_z.| = VALUE.',
        maximum=0.5),
    EffectSpec(
        'time_offset', 's', 0.0,
        'IMU (gyro and accel) samples stamped t carry the physics of time t - VALUE (motion and '
        'thermal drift), against the temperature, magnetometer and truth streams. Signed.',
        minimum=-1.0, maximum=1.0),
    EffectSpec(
        'compass_deviation', 'uT', 1.0,
        'Hard iron of norm VALUE (random direction, sensor frame) plus a symmetric soft-iron matrix '
        'M = I + (VALUE/50 uT)*E, E entries U(-0.25, 0.25); fixed to the magnetometer.', maximum=200.0),
    EffectSpec(
        'rate_random_walk', 'deg/s/sqrt(s)', 5e-5,
        'Rate random walk: bias_i(t) = K_i*W(t) (W a standard Wiener process, 0 at t=0); K_z = VALUE.',
        maximum=0.1),
    EffectSpec(
        'bias_instability', 'deg/s', 2e-3,
        'Stationary first-order Gauss-Markov bias of standard deviation sigma_i (sigma_z = VALUE), '
        'correlation time param bias_instability_tau_s.', maximum=1.0),
)

EFFECTS: dict[str, EffectSpec] = {spec.name: spec for spec in _SPECS}
