"""Noise floors of the carousel's outputs on simulator runs, and verdicts that tell a floor miss from a method miss.

A floor is what an output would show whose only errors are the sensor's white noise (and, at rest, its bias
instability), in the target's own unit: a suppression ratio |raw bias| / floor, or an error. If a target
misses where even the floor misses it, no estimator could meet it ('at the floor'); where the floor meets it,
the miss is the method's ('method', with output error / floor). Never the other way round: a target whose
floor meets it is a method miss however close. And a floor miss must look like the floor: the output's signed
residual, in units of the floor's 1-sigma of that residual, is tested against zero (`residual_significance`);
a residual many standard errors from zero is a method error, whatever the floor ratio. Truth-side helpers
(SimConfig in, numbers out); the simulator is imported lazily. Units: rad/s, m/s^2, rad, s.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2, t as student_t

# A residual is consistent with its floor while its chi-square (sum of its components' squared z) has a
# p-value of at least this: the two-sided 3-sigma level of one Gaussian component.
CONSISTENT_P = 0.0027


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


def encoder_free_frame_floor(accel_sigma_m_s2: float, gyro_density_rad_s_rthz: float, inplane_m_s2: float,
                             spin_hz: float, imu_rate_hz: float, still_s: float, duration_s: float,
                             window: tuple[float, float]) -> float:
    """1-sigma (m/s^2) of the window-mean in-plane specific-force error across gravity of an encoder-free carousel
    (a static body, tilted: in-plane gravity `inplane_m_s2`) whose only errors are white noise: accelerometer
    `accel_sigma_m_s2` per sample and component, gyro `gyro_density_rad_s_rthz`. The best causal linear estimator:
    the gyro angle's error eps (a random walk from the gyro's white noise plus a constant rate beta, eps = 0 at the
    first sample: the frame is fixed there) and the reference's direction phi; each revolution measures
    eps + phi with the revolution's accelerometer noise across gravity, and its output is turned back by the
    filtered eps (as the demodulator does). A still start of `still_s` (> 0) gives eps at its end exactly, beta
    from the gyro over it and phi from its accelerometer mean; without one beta and phi are unknown (1 rad/s,
    1 rad priors). The spin is steady (no spin-up), beta has no random walk, the scale factor is known: the floor
    is low, never high. The output's own noise across gravity is in (the measurement noise it shares). The
    running accelerometer bias behind a still-start reference is left out (the spin cancels it but for noise).
    Exact: the error recursion is linear with the gains fixed, so the window mean's variance is propagated with
    the filter (an augmented covariance), not sampled."""
    period = 1.0 / spin_hz
    n_rev = period * imu_rate_hz
    w2 = inplane_m_s2 ** 2
    r = accel_sigma_m_s2 ** 2 / n_rev / w2                 # a revolution's angle measurement, rad^2
    q = gyro_density_rad_s_rthz ** 2 * period             # the gyro angle's random walk over a revolution, rad^2
    if still_s > 0:
        p = np.diag([0.0, gyro_density_rad_s_rthz ** 2 / still_s, accel_sigma_m_s2 ** 2 / (still_s * imu_rate_hz) / w2])
    else:
        p = np.diag([0.0, 1.0, 1.0])
    ends = np.arange(still_s + period, duration_s + 1e-9, period)
    weights = ((ends - period >= window[0]) & (ends <= window[1])).astype(float)
    if not weights.any():
        raise ValueError(f'no whole revolution inside the window {window}')
    weights /= weights.sum()
    f = np.array([[1.0, period, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    h = np.array([1.0, 0.0, 1.0])
    z = np.zeros((4, 4))                                   # covariance of (state error, weighted sum so far)
    z[:3, :3] = p
    w = np.sqrt(w2)
    for a in weights:
        pm = f @ p @ f.T + np.diag([q, 0.0, 0.0])
        k = pm @ h / (h @ pm @ h + r)
        ikh = np.eye(3) - np.outer(k, h)
        m = np.zeros((4, 4))
        m[:3, :3] = ikh @ f
        m[3, :3] = a * w * (ikh @ f)[0]
        m[3, 3] = 1.0
        n = np.zeros((4, 2))                               # (process, measurement) noise into each
        n[:3, 0], n[:3, 1] = ikh[:, 0], -k
        n[3] = a * w * np.array([ikh[0, 0], 1.0 - k[0]])   # the output: eps - its estimate + its own noise
        z = m @ z @ m.T + n @ np.diag([q, r]) @ n.T
        p = ikh @ pm
    return float(np.sqrt(z[3, 3]))


@dataclass(frozen=True)
class Significance:
    """Signed residuals in units of their floor's 1-sigma (`z`, per value and component) and what they say."""
    z: np.ndarray               # (n values, k components)
    labels: tuple

    @property
    def p_values(self) -> np.ndarray:
        """Per value: the chance of a chi-square this large were the residual the floor's noise alone."""
        return chi2.sf(np.sum(self.z ** 2, axis=1), self.z.shape[1])

    @property
    def consistent(self) -> np.ndarray:
        """Per value: the residual is consistent with its floor (p >= CONSISTENT_P)."""
        return self.p_values >= CONSISTENT_P

    def text(self) -> str:
        """mean / its standard error over the values (a shared bias: a method error), rms (1 at the floor) and the
        worst value, in the floor's sigmas."""
        z = self.z.ravel()
        n = z.size
        mean = float(np.mean(z))
        se = float(np.std(z, ddof=1) / np.sqrt(n)) if n > 1 else np.inf
        t = mean / se if se > 0 else 0.0
        p_mean = 2 * student_t.sf(abs(t), n - 1) if n > 1 else 1.0
        worst = int(np.argmin(self.p_values))
        bad = [str(x) for x, ok in zip(self.labels, self.consistent) if not ok]
        return (f'residual/floor sigma: mean {mean:+.2f} (t {t:+.1f}, p {p_mean:.2g}), rms {np.sqrt(np.mean(z ** 2)):.2f}'
                f' over {n}; worst {self.labels[worst]} p {self.p_values[worst]:.1g}'
                + (f'; not the floor\'s noise (p < {CONSISTENT_P:g}): {", ".join(bad)}' if bad else ''))


def residual_significance(residuals, sigmas, labels) -> Significance:
    """`residuals` (n, k) signed output errors (k components per value, e.g. in-plane x, y), `sigmas` their floor's
    1-sigma, broadcastable to (n, k), same unit."""
    res = np.asarray(residuals, dtype=float)
    res = res.reshape(len(res), -1)
    return Significance(res / np.broadcast_to(np.asarray(sigmas, dtype=float), res.shape), tuple(labels))


def _unit_bias_model(cfg) -> tuple[float, np.ndarray, np.ndarray, float]:
    """The simulated unit's in-plane gyro model the rest floor assumes: (white-noise variance per sample
    (rad/s)^2, bias instability sigma (x, y) rad/s, rate random walk (x, y) rad/s/sqrt(s), Gauss-Markov tau s)."""
    from ..sim.sensors import covariances
    u = cfg.unit
    return (float(covariances(cfg).gyro_rad2_s2[0]), np.radians(u.gyro_bias_instability_dps[:2]),
            np.radians(u.gyro_rrw_dps_rts[:2]), float(cfg.params['bias_instability_tau_s']))


def _rest_filter(cfg, meas, t_rest_s: float, values=None) -> tuple[np.ndarray, np.ndarray]:
    """The best linear estimator of the in-plane bias at zero spin b0 = c + g at t_rest_s, per axis, from
    measurements y = c + g(t) + k * Omega + white noise: x = [turn-on bias c (constant), wander g (Gauss-Markov
    sigma, tau plus rate random walk), k], wide priors (c 1 rad/s, k 1e-2 rad/s per rad/s). `meas`: (time s,
    spin rad/s, noise variance (rad/s)^2) per measurement; `values`: (len(meas), 2) rad/s measured (x, y), or
    None (covariance only). Returns (b0 estimate (x, y) rad/s, zeros if no values; its 1-sigma (x, y) rad/s)."""
    _, sigma, rrw, tau = _unit_bias_model(cfg)
    order = sorted(range(len(meas)), key=lambda i: meas[i][0])      # stable: ties keep their given order
    vals = np.zeros((len(meas), 2)) if values is None else np.asarray(values, dtype=float).reshape(len(meas), 2)
    b0 = np.array([1.0, 1.0, 0.0])
    est, sd = np.zeros(2), np.zeros(2)
    for axis in range(2):
        x, p, t_p = np.zeros(3), np.diag([1.0, sigma[axis] ** 2, 1e-4]), 0.0
        for i in order + [None]:
            t = t_rest_s if i is None else meas[i][0]
            phi = np.exp(-(t - t_p) / tau)
            f = np.diag([1.0, phi, 1.0])
            x, p = f @ x, f @ p @ f.T
            p[1, 1] += sigma[axis] ** 2 * (1 - phi ** 2) + rrw[axis] ** 2 * (t - t_p)
            t_p = t
            if i is None:
                break
            h = np.array([1.0, 1.0, meas[i][1]])
            k = p @ h / (h @ p @ h + meas[i][2])
            x = x + k * (vals[i, axis] - h @ x)
            p = p - np.outer(k, h @ p)
        est[axis], sd[axis] = b0 @ x, np.sqrt(b0 @ p @ b0)
    return est, sd


def rest_information_floor(cfg, revolutions, still_s: float, rest_s: tuple[float, float]) -> np.ndarray:
    """1-sigma error (x, y, rad/s) of the in-plane bias at rest b0 for the best linear estimator given what
    the run tells: the still start (b0 at zero spin, second by second) and every revolution's in-plane mean at its
    spin (b0 + k Omega), each with the white noise alone (sigma^2 / N), the bias wandering as the simulated unit's
    Gauss-Markov bias instability (sigma, tau) plus its rate random walk, predicted to the middle of the rest.
    The thermal drift is left out (a temperature model could follow it), so this floor is low, never high.
    `revolutions`: (end time s, duration s, spin rad/s, samples) of each whole revolution before the stop.
    `rest_floor_estimate` runs the same estimator on a run's own measurements."""
    var_sample, rate = _unit_bias_model(cfg)[0], cfg.imu_rate_hz
    blocks = np.arange(0.5, still_s, 1.0)          # the still start in 1 s blocks: its end tells most about the spin
    meas = [(t, 0.0, var_sample / rate) for t in blocks]
    meas += [(t - 0.5 * d, om, var_sample / n) for t, d, om, n in revolutions]
    return _rest_filter(cfg, meas, 0.5 * (rest_s[0] + rest_s[1]))[1]


def rest_floor_measurements(t_s, gyro_inplane_rad_s, revolutions, still_s: float) -> tuple[list, list]:
    """A run's own measurements in `rest_information_floor`'s model, from its samples: `t_s` (N,) s and
    `gyro_inplane_rad_s` (N, 2), the main IMU's in-plane gyro less the body's true rate in the same axes (on a
    static table: the Earth's), rad/s. Returns (still blocks: (mid time s, mean (2,) rad/s, samples) of each 1 s
    block of [0, still_s); revolutions: (end time s, duration s, spin rad/s, samples, mean (2,) rad/s) of the
    samples in (end - duration, end] of each given (end time s, duration s, spin rad/s, ...)). Empty
    intervals are left out."""
    t, g = np.asarray(t_s, dtype=float), np.asarray(gyro_inplane_rad_s, dtype=float)
    blocks = []
    for k in range(int(np.ceil(still_s))):
        s = (t >= k) & (t < min(k + 1.0, still_s))
        if s.any():
            blocks.append((0.5 * (k + min(k + 1.0, still_s)), g[s].mean(axis=0), int(s.sum())))
    revs = []
    for t_end, d, om, *_ in revolutions:
        s = (t > t_end - d) & (t <= t_end)
        if s.any():
            revs.append((t_end, d, om, int(s.sum()), g[s].mean(axis=0)))
    return blocks, revs


def rest_floor_estimate(cfg, still_blocks, revolutions, rest_s: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """`rest_information_floor`'s estimator run on a run's own measurements (`rest_floor_measurements`): the
    in-plane bias at zero spin b0 (x, y, rad/s) at the middle of the rest, and its 1-sigma (x, y, rad/s; the
    floor itself when the measurements are the ones the floor counts). A yardstick for reporting, never used
    by the demodulator: it is given the simulator's truth (the unit's bias instability sigma and tau, rate random
    walk and white-noise variance exactly, and measurements less the body's true rate), and it assumes what the
    floor does: a bias c + g(t) + k * Omega, g Gauss-Markov plus rate random walk, white noise alone on each mean
    (variance per sample / samples), no thermal drift. Where even this estimator misses a target on a run's data,
    that run's noise and wander, not the method, put the target out of reach.
    `still_blocks`: (time s, mean (2,) rad/s, samples) at zero spin; `revolutions`: (end time s, duration s,
    spin rad/s, samples, mean (2,) rad/s), each at its middle."""
    var_sample = _unit_bias_model(cfg)[0]
    meas = [(t, 0.0, var_sample / n) for t, _, n in still_blocks]
    meas += [(t - 0.5 * d, om, var_sample / n) for t, d, om, n, _ in revolutions]
    values = [y for _, y, _ in still_blocks] + [y for *_, y in revolutions]
    return _rest_filter(cfg, meas, 0.5 * (rest_s[0] + rest_s[1]), values)


def verdict(values, floors, target: float, op: str, labels, measured: bool = False,
            significance: Significance | None = None) -> tuple[bool, str]:
    """'met', or 'NOT MET: ...' naming why: per value (a seed, or a seed's axis), a miss is 'at the floor'
    only where the floor itself misses the target (no estimator can), else the method's. `op` '>=' for
    suppression ratios (floors: |raw| / floor), '<=' for errors (floors: 1-sigma floor, same unit).
    `measured`: `floors` are not a 1-sigma but what the floor's own estimator gave on the same data, same unit
    (`rest_floor_estimate`): a miss is 'at the floor' where that estimator misses too, and the text says on how
    many values of all it misses, its worst, and how far the output is from it where the output misses.
    `significance` (`residual_significance`, one row per value): a miss is 'at the floor' only where the value's
    residual is also consistent with the floor's noise; one many standard errors off it is the method's however
    the floor compares with the target."""
    values, floors = np.asarray(values, dtype=float), np.asarray(floors, dtype=float)
    if op == '>=':
        miss, floor_miss, rel = values < target, floors < target, floors / values
    else:
        miss, floor_miss, rel = values > target, floors > target, values / floors
    if not miss.any():
        return True, 'met'
    names = lambda sel: ', '.join(str(x) for x, s in zip(labels, sel) if s)    # noqa: E731
    worst = floors.min() if op == '>=' else floors.max()
    on_data = f'{int(floor_miss.sum())} of {floors.size}, worst {worst:.3g}'
    parts = []
    method = miss & ~floor_miss
    if method.any():
        if measured:
            parts.append(f'method (output/floor estimator {rel[method].max():.2f}; {names(method)}; the floor '
                         f'estimator on the same data misses on {on_data})')
        else:
            parts.append(f'method (output/floor {rel[method].max():.2f}; {names(method)})')
    off = miss & floor_miss & (~significance.consistent if significance is not None else False)
    if off.any():
        parts.append(f'method (the floor misses too, but the residual is not its noise: p '
                     f'{significance.p_values[off].min():.1g}; {names(off)})')
    at_floor = miss & floor_miss & ~off
    if at_floor.any():
        if measured:
            parts.append(f'at the floor (the floor estimator on the same data misses too, on {on_data}; '
                         f'{names(at_floor)}; output/floor estimator {rel[at_floor].max():.2f})')
        else:
            best = floors[at_floor].max() if op == '>=' else floors[at_floor].min()
            parts.append(f'at the floor (no estimator can, floor ratio {best:.3g}; {names(at_floor)})')
    return False, 'NOT MET: ' + '; '.join(parts)
