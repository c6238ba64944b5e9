"""Evaluation of the demodulator on simulator runs: errors against the simulator's
truth, the paper's Table 3 from them, spin-rate removal and the thermal-link prediction check.

Truth comes from the simulator's world (rebuilt from the run's SimConfig, which every bag records as
/sim/config), so the demodulator itself never sees it. Errors are sensor errors only: the body's
true rate w.r.t. inertial space (Earth rate included) is subtracted, since a perfect gyro reads it.
Imports the simulator lazily; no ROS.
"""
from __future__ import annotations

import json
from typing import NamedTuple

import numpy as np

from ..constants import STANDARD_GRAVITY_M_S2
from .carousel_metrics import HORIZONTAL_X_CAROUSEL_TO_BODY
from .carousel_truth import Truth
# the readers of node outputs live in node_outputs.py; importable from here too
from .carousel_outputs import (axial_spin_residual, bag_record_errors, demodulated_from_bag, diagnostics_from_bag,
                           write_node_params)

__all__ = ['CAROUSEL_TO_BODY', 'config_from_bag', 'config_from_dict', 'static_twin', 'Truth', 'record_truth_errors',
           'static_errors', 'spin_rate_errors', 'DemodulatorRun', 'run_demodulator', 'sensor_drift_after',
           'axial_scale_factor_residual', 'unremoved_for_run', 'demodulated_from_bag', 'bag_record_errors',
           'axial_spin_residual', 'diagnostics_from_bag', 'write_node_params']

# scenario -> carousel_to_body of its mount (carousel frame = mount frame at theta = 0)
CAROUSEL_TO_BODY = {'carousel_vertical': np.eye(3), 'carousel_flip': np.eye(3),
                    'carousel_horizontal': np.asarray(HORIZONTAL_X_CAROUSEL_TO_BODY),
                    'carousel_wheel': np.array([[0.0, 1, 0], [0, 0, 1], [1, 0, 0]])}


def config_from_bag(bag):
    """The SimConfig a simulated bag was written from (its /sim/config record)."""
    from .. import topics
    from ..bag_io import BagReader
    with BagReader(bag) as reader:
        d = json.loads(reader.text(topics.SIM_CONFIG)[0])
    return config_from_dict(d)


def config_from_dict(d: dict, **param_overrides):
    from ..sim import make_config
    r = d['rates_hz']
    return make_config(d['scenario'], seed=d['seed'], duration_s=d['duration_s'], effects=d['effects'],
                       params={**d['params'], **param_overrides}, imu_rate_hz=r['imu'], mag_rate_hz=r['mag'],
                       temp_rate_hz=r['temperature'], truth_rate_hz=r['truth'], unit_seed=d.get('unit_seed'))


def static_twin(cfg):
    """The same unit, seed and temperature history with the turntable never turning (spin_stop_s = 0):
    the paper's static reference."""
    return config_from_dict(cfg.to_dict(), spin_stop_s=0.0)


def record_truth_errors(truth: Truth, records, t_from: float = -np.inf, t_to: float = np.inf,
                        mode: str = 'demodulated', carousel_axes: np.ndarray | None = None):
    """Duration-weighted mean (dw (3,), da (3,)) of records of `mode` ending in [t_from, t_to] minus the
    truth over each record; in carousel axes (x, y in-plane, z spin) if `carousel_axes` (the
    carousel_to_body matrix) is given, else body axes."""
    sel = [r for r in records if r.mode == mode and t_from <= r.t_s - r.duration_s and r.t_s <= t_to]
    if not sel:
        raise ValueError(f'no {mode} records in [{t_from}, {t_to}]')
    t1 = np.array([r.t_s for r in sel])
    d = np.array([r.duration_s for r in sel])
    w_true, f_true = truth.interval_means(t1 - d, t1)
    dw = np.array([r.rate_body_rad_s for r in sel]) - w_true
    da = np.array([r.specific_force_body_m_s2 for r in sel]) - f_true
    dw, da = np.average(dw, axis=0, weights=d), np.average(da, axis=0, weights=d)
    if carousel_axes is not None:
        m = np.asarray(carousel_axes, dtype=float)
        dw, da = m.T @ dw, m.T @ da
    return dw, da, float(d.sum())


def static_errors(cfg, t_from: float, t_to: float):
    """Raw (dw, da) of a non-turning IMU, imu axes: mean of (output - what a perfect IMU reads) over
    [t_from, t_to]. Simulates `cfg` (use `static_twin`)."""
    from ..sim import simulate
    truth = Truth(cfg)
    sw, sa, n = np.zeros(3), np.zeros(3), 0
    for chunk in simulate(cfg):
        t = chunk.imu.t
        sel = (t >= t_from) & (t <= t_to)
        if not np.any(sel):
            continue
        ts = t[sel]
        body = truth.world.motion.state(ts)
        rot_bs = truth.world.mount.state(ts, body).rot_bs
        w_b, f_b = truth.body(ts)
        w_s = np.einsum('nji,nj->ni', rot_bs, w_b)
        f_s = np.einsum('nji,nj->ni', rot_bs, f_b)
        sw += (chunk.imu.gyro[sel] - w_s).sum(axis=0)
        sa += (chunk.imu.accel[sel] - f_s).sum(axis=0)
        n += int(sel.sum())
    return sw / n, sa / n


def spin_rate_errors(truth: Truth, records) -> np.ndarray:
    """Relative spin-rate error (Omega_est - Omega_true) / |Omega_true| per demodulated record, with
    Omega_true = true joint angle change over the record / its duration."""
    sel = [r for r in records if r.mode == 'demodulated']
    t1 = np.array([r.t_s for r in sel])
    t0 = t1 - np.array([r.duration_s for r in sel])
    true = (truth.joint_angle(t1) - truth.joint_angle(t0)) / (t1 - t0)
    est = np.array([r.spin_rate_rad_s for r in sel])
    return (est - true) / np.abs(true)


class DemodulatorRun(NamedTuple):
    """Everything a whole (flushed) run produced; unpacks as (records, biases, flips, demodulator)."""
    records: tuple                  # RevolutionRecord
    bias_measurements: tuple        # GyroBiasMeasurement
    flip_events: tuple              # FlipEvent
    demodulator: object             # the CarouselDemodulator, for its final state (book, counts)


def _feed(chunks, config) -> tuple[list, object]:
    """(every output of a whole run, flushed; the CarouselDemodulator)."""
    from ..carousel.demodulator import CarouselDemodulator
    demod = CarouselDemodulator(config)
    return [demod.update(c) for c in chunks] + [demod.flush()], demod


def run_demodulator(chunks, config) -> DemodulatorRun:
    """All records, bias measurements and flip events of a whole run (flushed)."""
    outs, demod = _feed(chunks, config)
    return DemodulatorRun(tuple(r for o in outs for r in o.records),
                          tuple(m for o in outs for m in o.bias_measurements),
                          tuple(e for o in outs for e in o.flip_events), demod)


def run_high_rate(chunks, config) -> tuple[list, object, object]:
    """(records, the high-rate samples concatenated (records.HighRateSamples, None without any), the
    CarouselDemodulator) of a whole (flushed) run; config with high_rate on."""
    from ..carousel.records import HighRateSamples
    outs, demod = _feed(chunks, config)
    parts = [o.high_rate for o in outs if o.high_rate is not None]
    return [r for o in outs for r in o.records], HighRateSamples.concatenate(parts) if parts else None, demod


def angle_in_use_errors(truth: Truth, records, high, skip: int = 10) -> np.ndarray:
    """Per demodulated revolution after the first `skip`: mean(angle in use - true platform angle), rad."""
    err = high.theta_rad - truth.joint_angle(high.t)
    return np.array([np.mean(err[(high.t > r.t_s - r.duration_s) & (high.t <= r.t_s)])
                     for r in [r for r in records if r.mode == 'demodulated'][skip:]])


def sensor_drift_after(truth: Truth, chunks, t_from: float, t_to: float):
    """(t, drift (N, 3) rad/s): the main IMU's slow error (truth gyro_bias minus the Earth rate, which
    is a real rate) in imu axes over [t_from, t_to], from the chunks' truth stream."""
    ts, ds = [], []
    for c in chunks:
        t = c.gyro_bias.t
        sel = (t >= t_from) & (t <= t_to)
        if np.any(sel):
            ts.append(t[sel])
            ds.append(c.gyro_bias.vec[sel] - truth.sensor_earth_rate(t[sel]))
    return np.concatenate(ts), np.concatenate(ds)


def axial_scale_factor_residual(cfg, records, t_from: float = -np.inf, t_to: float = np.inf,
                                flip_axis: str = 'x') -> float:
    """Predicted duration-weighted mean of what the axial gyro's scale factor leaves after spin
    removal, s_j(T) * Omega (rad/s, carousel z), from the unit's true coefficients; j = the imu axis
    along the spin axis in each record's flip position. Shown separately: carouseling cannot remove it."""
    from ..carousel.flip import platform_axis_to_imu
    u = cfg.unit
    sel = [r for r in records if r.mode == 'demodulated' and t_from <= r.t_s - r.duration_s and r.t_s <= t_to]
    vals, w = [], []
    for r in sel:
        j, _ = platform_axis_to_imu(flip_axis, r.flip_position, 2)
        temp = 25.0 if r.temperature_c is None else r.temperature_c
        s = u.gyro_scale_factor[j] + u.gyro_scale_factor_tc_per_c[j] * (temp - 25.0)
        vals.append(s * r.spin_rate_rad_s)
        w.append(r.duration_s)
    return float(np.average(vals, weights=w))


def unremoved_for_run(cfg, records, static_dw, static_da, carousel_to_body, t_from=-np.inf, t_to=np.inf) -> dict:
    """metrics.unremoved_residuals for a simulated run, from the unit's true coefficients: carousel
    axes (x, y in-plane, z spin axis), each part (dw (3,), da (3,)). The spin-axis tilt is that of
    sensor z against the spin axis from the gyro cross-axis row (C_xz, C_yz)."""
    from .carousel_metrics import unremoved_residuals
    u = cfg.unit
    sel = [r for r in records if r.mode == 'demodulated' and t_from <= r.t_s - r.duration_s and r.t_s <= t_to]
    omega = float(np.average([r.spin_rate_rad_s for r in sel], weights=[r.duration_s for r in sel]))
    temps = [r.temperature_c for r in sel if r.temperature_c is not None]
    temp = float(np.mean(temps)) if temps else 25.0
    sf = u.gyro_scale_factor + u.gyro_scale_factor_tc_per_c * (temp - 25.0)
    m = np.asarray(carousel_to_body, dtype=float)
    truth = Truth(cfg)
    w_b, f_b = truth.body(np.array([sel[len(sel) // 2].t_s]))
    mu = float(np.hypot(u.gyro_cross_axis[0, 2], u.gyro_cross_axis[1, 2]))
    parts = unremoved_residuals(omega, axial_gyro_bias_rad_s=float(static_dw[2]),
                                axial_accel_bias_m_s2=float(static_da[2]), scale_factor_pos=float(sf[2]),
                                scale_factor_neg=float(sf[2]), inplane_scale_factor=(float(sf[0]), float(sf[1])),
                                sensor_axis_tilt_rad=mu, body_rate_rad_s=w_b[0], specific_force_body_m_s2=f_b[0],
                                carousel_to_body=m)
    out = {k: (m.T @ dw, m.T @ da) for k, (dw, da) in parts.items() if k != 'total'}
    # gyro g-sensitivity G f: with f in the rotation plane (horizontal axis) it turns in the sensor
    # frame, and the body-frame mean keeps the isotropic and antisymmetric in-plane parts of G:
    # mean_theta Rz(th) G Rz(-th) f = tr(G_pp)/2 f + (G_yx - G_xy)/2 J f (J: +90 deg about z).
    g = np.radians(u.gyro_g_sensitivity_dps_per_g) / STANDARD_GRAVITY_M_S2
    f_c = m.T @ f_b[0]
    iso, anti = 0.5 * (g[0, 0] + g[1, 1]), 0.5 * (g[1, 0] - g[0, 1])
    gs = np.array([iso * f_c[0] - anti * f_c[1], iso * f_c[1] + anti * f_c[0], g[2, 2] * f_c[2]])
    out['g_sensitivity'] = (gs - np.array([0.0, 0.0, g[2, 2] * f_c[2]]), np.zeros(3))  # axial part is in the static bias
    out['total'] = (sum(v[0] for v in out.values()), sum(v[1] for v in out.values()))
    return out
