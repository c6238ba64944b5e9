"""Noise floors of the carousel's outputs on simulator runs, and verdicts that tell a floor miss from a method miss.

A floor is what an output would show whose only errors are the sensor's white noise (and, at rest, its bias
instability), in the target's own unit: a suppression ratio |raw bias| / floor, or an error. If a target
misses where even the floor misses it, no estimator could meet it ('at the floor'); where the floor meets it,
the miss is the method's ('method', with output error / floor). Never the other way round: a target whose
floor meets it is a method miss however close. Truth-side helpers (SimConfig in, numbers out); the simulator
is imported lazily. Units: rad/s, m/s^2, rad, s.
"""
from __future__ import annotations

import numpy as np


def white_noise_floors(cfg, window_s: float) -> dict:
    """1-sigma errors a perfect demodulator still has from the sensor's white noise (sim.covariances:
    per-sample variances), in-plane norms (rms of two axes), and the still start's share:
    - 'gyro', 'accel': the window mean of the output, sigma_sample * sqrt(2 / N_window);
    - 'accel_no_encoder': plus where the body frame is anchored without an encoder: the still start's
      mean across gravity's in-plane direction (one axis, N_still samples) and the accelerometer bias
      the reference subtracts (a running mean over the spin: its window average has ~2x the variance of
      the final mean), sqrt(s_still^2 + 4 s_window^2);
    - 'gyro_still': the still start's in-plane gyro mean, per axis (what k * Omega at rest starts from)."""
    from ..sim.sensors import covariances
    cov, rate = covariances(cfg), cfg.imu_rate_hz
    sg, sa = np.sqrt(cov.gyro_rad2_s2[0]), np.sqrt(cov.accel_m2_s4[0])
    n_win, n_still = window_s * rate, cfg.params['still_s'] * rate
    win_a = sa / np.sqrt(n_win)
    return {'gyro': sg * np.sqrt(2 / n_win), 'accel': win_a * np.sqrt(2),
            'accel_no_encoder': np.sqrt(sa ** 2 / n_still + 4 * win_a ** 2), 'gyro_still': sg / np.sqrt(n_still)}


def gravity_angle_floor_rad(cfg, window_s: float, inplane_m_s2: float) -> float:
    """1-sigma offset of the encoder-free output frame from white noise alone: the reference's share of
    'accel_no_encoder' (still start across gravity, running bias) over the in-plane specific force, rad."""
    f = white_noise_floors(cfg, window_s)
    sa_win = f['accel'] / np.sqrt(2)
    return float(np.sqrt(f['accel_no_encoder'] ** 2 - 2 * sa_win ** 2) / inplane_m_s2)


def rest_information_floor(cfg, revolutions, still_s: float, rest_s: tuple[float, float]) -> np.ndarray:
    """1-sigma error (x, y, rad/s) of the in-plane bias at rest b0 for the best linear estimator given what
    the run tells: the still start (b0 at zero spin, second by second) and every revolution's in-plane mean at its
    spin (b0 + k Omega), each with the white noise alone (sigma^2 / N), the bias wandering as the simulated unit's
    Gauss-Markov bias instability (sigma, tau) plus its rate random walk, predicted to the middle of the rest.
    The thermal drift is left out (a temperature model could follow it), so this floor is low, never high.
    `revolutions`: (end time s, duration s, spin rad/s, samples) of each whole revolution before the stop."""
    from ..sim.sensors import covariances
    u, rate = cfg.unit, cfg.imu_rate_hz
    var_sample = covariances(cfg).gyro_rad2_s2[0]
    sigma = np.radians(u.gyro_bias_instability_dps[:2])
    rrw = np.radians(u.gyro_rrw_dps_rts[:2])
    tau = cfg.params['bias_instability_tau_s']
    out = np.zeros(2)
    blocks = np.arange(0.5, still_s, 1.0)          # the still start in 1 s blocks: its end tells most about the spin
    meas = [(t, 0.0, var_sample / rate) for t in blocks]
    meas += [(t - 0.5 * d, om, var_sample / n) for t, d, om, n in revolutions]
    b0 = np.array([1.0, 1.0, 0.0])
    for axis in range(2):
        # x = [turn-on bias c (constant), wander g (Gauss-Markov + rate random walk), k]; b0 = c + g
        p, t_p = np.diag([1.0, sigma[axis] ** 2, 1e-4]), 0.0     # wide priors: c 1 rad/s, k 1e-2 rad/s per rad/s
        for t, om, r in sorted(meas) + [(0.5 * (rest_s[0] + rest_s[1]), None, None)]:
            phi = np.exp(-(t - t_p) / tau)
            f = np.diag([1.0, phi, 1.0])
            p = f @ p @ f.T
            p[1, 1] += sigma[axis] ** 2 * (1 - phi ** 2) + rrw[axis] ** 2 * (t - t_p)
            t_p = t
            if om is None:
                break
            h = np.array([1.0, 1.0, om])
            k = p @ h / (h @ p @ h + r)
            p = p - np.outer(k, h @ p)
        out[axis] = np.sqrt(b0 @ p @ b0)
    return out


def verdict(values, floors, target: float, op: str, labels) -> tuple[bool, str]:
    """'met', or 'NOT MET: ...' naming why: per value (a seed, or a seed's axis), a miss is 'at the floor'
    only where the floor itself misses the target (no estimator can), else the method's. `op` '>=' for
    suppression ratios (floors: |raw| / floor), '<=' for errors (floors: 1-sigma floor, same unit)."""
    values, floors = np.asarray(values, dtype=float), np.asarray(floors, dtype=float)
    if op == '>=':
        miss, floor_miss, rel = values < target, floors < target, floors / values
    else:
        miss, floor_miss, rel = values > target, floors > target, values / floors
    if not miss.any():
        return True, 'met'
    names = lambda sel: ', '.join(str(x) for x, s in zip(labels, sel) if s)    # noqa: E731
    parts = []
    method = miss & ~floor_miss
    if method.any():
        parts.append(f'method (output/floor {rel[method].max():.2f}; {names(method)})')
    at_floor = miss & floor_miss
    if at_floor.any():
        best = floors[at_floor].max() if op == '>=' else floors[at_floor].min()
        parts.append(f'at the floor (no estimator can, floor ratio {best:.3g}; {names(at_floor)})')
    return False, 'NOT MET: ' + '; '.join(parts)
