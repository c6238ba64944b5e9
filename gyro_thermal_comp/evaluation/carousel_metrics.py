"""Error-growth measures of the seed paper and the residuals carouseling cannot remove.

The paper judges an IMU by how fast constant sensor errors grow into navigation errors:

    eps(t) = dw * t                      attitude error, rad
    dV(t)  = da * t + dw * g * t^2 / 2   velocity error, m/s (tilt eps couples gravity in)
    dS(t)  = integral_0^t dV = da t^2/2 + dw g t^3/6     position error, m

and reports them at t = 300 s per axis for a static IMU and for modulation about a vertical and a
horizontal axis (Table 3). Units here are SI throughout (rad, m/s, m); `format_table3` converts eps
to degrees only for display. (The paper's dS unit, "km/h", is a typo for a length.)
"""
from __future__ import annotations

import numpy as np

from ..constants import STANDARD_GRAVITY_M_S2

TABLE3_T_S = 300.0
PAPER_G_M_S2 = 9.81           # the paper's value of g
TABLE3_COLUMNS = ('static', 'vertical_axis', 'horizontal_axis')
# carousel frame -> body for a spin axis along body x: carousel (x, y, z) = body (y, z, x)
HORIZONTAL_X_CAROUSEL_TO_BODY = ((0.0, 0.0, 1.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0))


def error_growth(dw_rad_s, da_m_s2, t_s=TABLE3_T_S, g_m_s2: float = PAPER_G_M_S2) -> dict:
    """Closed-form eps (rad), dV (m/s), dS (m) for constant errors dw, da (per axis), at time(s) t_s."""
    dw, da = np.asarray(dw_rad_s, dtype=float), np.asarray(da_m_s2, dtype=float)
    t = np.asarray(t_s, dtype=float)
    t = t.reshape(t.shape + (1,) * dw.ndim)
    return {'eps_rad': dw * t,
            'dv_m_s': da * t + dw * g_m_s2 * t ** 2 / 2,
            'ds_m': da * t ** 2 / 2 + dw * g_m_s2 * t ** 3 / 6}


def integrated_error_growth(t_s, dw_rad_s, da_m_s2, g_m_s2: float = PAPER_G_M_S2) -> dict:
    """The same measures for time-varying errors sampled at t_s (N,), dw/da (N,) or (N, k):
    eps = int dw, dV = int (da + g*eps), dS = int dV (trapezoid, starting at zero at t_s[0]).
    Equals `error_growth` for constant errors up to integration error."""
    t = np.asarray(t_s, dtype=float)
    dt = np.diff(t).reshape((-1,) + (1,) * (np.ndim(dw_rad_s) - 1))

    def cum(v):
        v = np.asarray(v, dtype=float)
        return np.concatenate((np.zeros((1,) + v.shape[1:]), np.cumsum(0.5 * (v[1:] + v[:-1]) * dt, axis=0)))
    eps = cum(dw_rad_s)
    dv = cum(np.asarray(da_m_s2, dtype=float) + g_m_s2 * eps)
    return {'eps_rad': eps, 'dv_m_s': dv, 'ds_m': cum(dv)}


def table3(errors: dict, t_s: float = TABLE3_T_S, g_m_s2: float = PAPER_G_M_S2) -> dict:
    """errors: column name -> (dw (3,) rad/s, da (3,) m/s^2), body axes x, y, z.
    Returns column -> {'eps_rad', 'dv_m_s', 'ds_m'} -> (3,) at t_s (the paper's Table 3 shape)."""
    return {col: error_growth(dw, da, t_s, g_m_s2) for col, (dw, da) in errors.items()}


def format_table3(table: dict) -> str:
    """Plain-text Table 3: eps in degrees (display only), dV in m/s, dS in km."""
    cols = list(table)
    lines = ['measure   axis ' + ''.join(f'{c:>17s}' for c in cols)]
    for key, label, display in (('eps_rad', 'eps [deg]', np.degrees), ('dv_m_s', 'dV [m/s]', float),
                                ('ds_m', 'dS [km]', lambda m: m * 1e-3)):
        for i, ax in enumerate('XYZ'):
            lines.append(f'{label:10s}{ax:>4s} ' + ''.join(f'{display(table[c][key][i]):17.4g}' for c in cols))
    return '\n'.join(lines)


def record_errors(records, true_rate_body_rad_s=(0.0, 0.0, 0.0), true_specific_force_body_m_s2=None,
                  mode: str = 'demodulated') -> tuple[np.ndarray, np.ndarray]:
    """Mean (dw, da) of records of `mode` against a constant body-frame truth (3,) each."""
    f_true = (0.0, 0.0, STANDARD_GRAVITY_M_S2) if true_specific_force_body_m_s2 is None \
        else true_specific_force_body_m_s2
    sel = [r for r in records if r.mode == mode]
    if not sel:
        raise ValueError(f'no {mode} records')
    w = np.array([r.duration_s for r in sel])
    rate = np.array([r.rate_body_rad_s for r in sel])
    sf = np.array([r.specific_force_body_m_s2 for r in sel])
    return (np.average(rate, axis=0, weights=w) - np.asarray(true_rate_body_rad_s, dtype=float),
            np.average(sf, axis=0, weights=w) - np.asarray(f_true, dtype=float))


def _rx(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _ry(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def unremoved_residuals(spin_rate_rad_s: float, *, axial_gyro_bias_rad_s: float = 0.0,
                        axial_accel_bias_m_s2: float = 0.0, scale_factor_pos: float = 0.0,
                        scale_factor_neg: float = 0.0, alternating_direction: bool = False,
                        inplane_scale_factor=(0.0, 0.0), spin_axis_tilt_rad=(0.0, 0.0),
                        sensor_axis_tilt_rad: float = 0.0, body_rate_rad_s=(0.0, 0.0, 0.0),
                        specific_force_body_m_s2=None, carousel_to_body=None) -> dict:
    """Errors a perfect whole-revolution demodulator with an encoder still leaves, each separately,
    as body-frame (dw rad/s (3,), da m/s^2 (3,)); key 'total' is their sum.

    - axial_bias: sensors along the spin axis are not modulated (the flip mechanism addresses it).
    - scale_factor: the axial gyro reads (1 + s) * rate, s = scale_factor_pos for positive rates and
      scale_factor_neg for negative ones, so a spin Omega leaves s*Omega after subtracting the encoder
      rate. Alternating the direction cancels the symmetric part and leaves the asymmetry
      (s_pos - s_neg)/2 * |Omega|.
    - inplane_scale_factor: the mean in-plane scale error (s_x + s_y)/2 scales the body in-plane
      signal (e.g. gravity with a horizontal spin axis); the (s_x - s_y)/2 part is modulated at
      2*Omega and averages out.
    - spin_axis_misalignment: spin axis tilted from the assumed body axis by (about x, about y):
      outputs come out in the tilted frame, e.g. gravity leaks g*tilt into the in-plane accel.
    - sensor_axis_misalignment: sensor z tilted from the spin axis by mu: the in-plane leak
      Omega*sin(mu) is sensor-fixed and removed, the axial gyro reads Omega*cos(mu): -Omega(1-cos mu).
    Truth vectors and results are body frame; `carousel_to_body` (3x3) maps the carousel frame
    (z = spin axis) to the body (identity: vertical axis)."""
    m = np.eye(3) if carousel_to_body is None else np.asarray(carousel_to_body, dtype=float)
    f_b = np.array((0.0, 0.0, STANDARD_GRAVITY_M_S2) if specific_force_body_m_s2 is None
                   else specific_force_body_m_s2, dtype=float)
    w_c, f_c = m.T @ np.asarray(body_rate_rad_s, dtype=float), m.T @ f_b
    ez = np.array([0.0, 0.0, 1.0])
    om = float(spin_rate_rad_s)
    if alternating_direction:
        sf = 0.5 * (scale_factor_pos - scale_factor_neg) * abs(om)
    else:
        sf = (scale_factor_pos if om >= 0 else scale_factor_neg) * om
    s_in = 0.5 * (inplane_scale_factor[0] + inplane_scale_factor[1])
    inplane = np.array([1.0, 1.0, 0.0])
    tilt = _rx(spin_axis_tilt_rad[0]) @ _ry(spin_axis_tilt_rad[1])
    parts_c = {
        'axial_bias': (axial_gyro_bias_rad_s * ez, axial_accel_bias_m_s2 * ez),
        'scale_factor': (sf * ez, np.zeros(3)),
        'inplane_scale_factor': (s_in * inplane * w_c, s_in * inplane * f_c),
        'spin_axis_misalignment': (tilt.T @ w_c - w_c, tilt.T @ f_c - f_c),
        'sensor_axis_misalignment': (-om * (1 - np.cos(sensor_axis_tilt_rad)) * ez, np.zeros(3)),
    }
    out = {k: (m @ dw, m @ da) for k, (dw, da) in parts_c.items()}
    out['total'] = (sum(v[0] for v in out.values()), sum(v[1] for v in out.values()))
    return out


def table3_synthetic(gyro_bias_rad_s, accel_bias_m_s2, spin_hz: float = 0.5, duration_s: float = 60.0,
                     imu_hz: float = 100.0, t_s: float = TABLE3_T_S, gyro_noise: float = 0.0,
                     accel_noise: float = 0.0, seed: int = 0) -> tuple[dict, dict]:
    """Table 3 from this demodulator on synthetic data with constant sensor biases (imu frame):
    a static IMU aligned with the body, and modulation about body z (vertical) and body x
    (horizontal), encoder present, body at rest with gravity along body z.
    Returns (table, errors) with errors[column] = (dw (3,), da (3,)) body frame."""
    from ..carousel.config import CarouselConfig
    from ..carousel.demodulator import CarouselDemodulator
    from ..carousel.synthetic import simulate, spin_rate_profile
    g = STANDARD_GRAVITY_M_S2
    bg, ba = np.asarray(gyro_bias_rad_s, dtype=float), np.asarray(accel_bias_m_s2, dtype=float)
    errors = {'static': (bg.copy(), ba.copy())}   # a static IMU aligned with the body sees its biases
    for col, m in (('vertical_axis', np.eye(3)),
                   ('horizontal_axis', np.asarray(HORIZONTAL_X_CAROUSEL_TO_BODY))):
        f_c = m.T @ np.array([0.0, 0.0, g])
        chunk, _ = simulate(duration_s, imu_hz, spin_rate_profile(spin_hz), body_force=f_c,
                            gyro_bias=bg, accel_bias=ba, gyro_noise=gyro_noise, accel_noise=accel_noise,
                            encoder_hz=imu_hz, seed=seed)
        demod = CarouselDemodulator(CarouselConfig(carousel_to_body=tuple(map(tuple, m))))
        records = demod.update(chunk).records
        errors[col] = record_errors(records, (0.0, 0.0, 0.0), (0.0, 0.0, g))
    return table3(errors, t_s), errors
