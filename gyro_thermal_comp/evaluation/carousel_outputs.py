"""Reading what carousel_node wrote (bags from `nodes.replay`) for evaluation against simulator truth.

`truth` arguments are `carousel_truth.Truth`. Imports bag I/O lazily; no ROS.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .carousel_truth import Truth


def demodulated_from_bag(bag, topic: str = '/imu/demodulated') -> dict:
    """The node's per-revolution outputs: t_s (end stamps), duration_s (from the previous stamp, records
    tile time; the first is NaN), rate_body_rad_s (N, 3), specific_force_body_m_s2 (N, 3)."""
    from ..bag_io import BagReader
    t, w, f = [], [], []
    with BagReader(bag) as reader:
        for _, _, _, m in reader.messages([topic]):
            t.append(reader.stamp_s(m.header))   # s since the bag's time origin: simulator time
            w.append((m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z))
            f.append((m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z))
    t = np.array(t)
    return {'t_s': t, 'duration_s': np.concatenate(([np.nan], np.diff(t))),
            'rate_body_rad_s': np.array(w).reshape(-1, 3), 'specific_force_body_m_s2': np.array(f).reshape(-1, 3)}


def bag_record_errors(truth: Truth, out: dict, t_from: float, t_to: float, carousel_axes=None):
    """As record_truth_errors for `demodulated_from_bag` output (all records starting >= t_from)."""
    d = out['duration_s']
    sel = np.isfinite(d) & (out['t_s'] - d >= t_from) & (out['t_s'] <= t_to)
    if not np.any(sel):
        raise ValueError(f'no records in [{t_from}, {t_to}]')
    t1, d = out['t_s'][sel], d[sel]
    w_true, f_true = truth.interval_means(t1 - d, t1)
    dw = np.average(out['rate_body_rad_s'][sel] - w_true, axis=0, weights=d)
    da = np.average(out['specific_force_body_m_s2'][sel] - f_true, axis=0, weights=d)
    if carousel_axes is not None:
        m = np.asarray(carousel_axes, dtype=float)
        dw, da = m.T @ dw, m.T @ da
    return dw, da, float(d.sum())


def axial_spin_residual(truth: Truth, out: dict, gyro_bias, t_from: float, t_to: float) -> np.ndarray:
    """Per record, relative to the true spin rate: axial output - true body axial rate - the axial
    gyro's true slow error (truth gyro_bias z minus Earth rate; includes scale factor x spin), i.e.
    what is left of the spin after its removal: (Omega_true - Omega_est) / |Omega_true|. Vertical
    table (sensor z = body z) only. gyro_bias: the run's truth VectorSamples."""
    d = out['duration_s']
    sel = np.isfinite(d) & (out['t_s'] - d >= t_from) & (out['t_s'] <= t_to)
    t1, d = out['t_s'][sel], d[sel]
    t0 = t1 - d
    w_true, _ = truth.interval_means(t0, t1)
    n = 64
    grid = (t0[:, None] + d[:, None] * ((np.arange(n) + 0.5) / n)[None, :]).ravel()
    err_z = np.interp(grid, gyro_bias.t, gyro_bias.vec[:, 2]) - truth.sensor_earth_rate(grid)[:, 2]
    err_z = err_z.reshape(-1, n).mean(axis=1)
    omega = (truth.joint_angle(t1) - truth.joint_angle(t0)) / d
    return (out['rate_body_rad_s'][sel, 2] - w_true[:, 2] - err_z) / np.abs(omega)


def diagnostics_from_bag(bag, topic: str = '/diagnostics') -> list[tuple[float, int, str, dict]]:
    """(stamp s since the bag's time origin, level, message, key -> value) of every DiagnosticStatus."""
    from ..bag_io import BagReader
    out = []
    with BagReader(bag) as reader:
        for _, _, _, m in reader.messages([topic]):
            t = reader.stamp_s(m.header)
            for s in m.status:
                level = s.level if isinstance(s.level, int) else int.from_bytes(bytes(s.level), 'little')
                out.append((t, level, s.message, {kv.key: kv.value for kv in s.values}))
    return out


def write_node_params(path, node_name: str = 'carousel_demodulator', **values) -> str:
    """A ROS parameter file for the carousel node (e.g. angle_source='gyro', carousel_to_body=[9 floats])."""
    import yaml
    text = yaml.safe_dump({node_name: {'ros__parameters': values}})
    with open(path, 'w') as fh:
        fh.write(text)
    return str(path)
