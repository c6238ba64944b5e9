"""Synthetic carousel data for tests and benchmarks (plain sinusoidal kinematics, known truth).

Not the package simulator: a minimal, exact generator of what a turning IMU measures, so the
demodulator can be checked against closed-form expectations. Body frame = carousel frame here.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..constants import STANDARD_GRAVITY_M_S2
from ..samples import ImuSamples, JointSamples, MagSamples, SensorChunk, TemperatureSamples


def spin_rate_profile(spin_hz: float, wobble: float = 0.0, wobble_hz: float = 0.2,
                      stops=(), wobble_phase_rad: float = 0.0):
    """Spin rate function t -> rad/s: 2*pi*spin_hz*(1 + wobble*sin(2*pi*wobble_hz*t + phase)),
    times an envelope that ramps to zero for each stop (t_begin, t_end, ramp_s) and back."""
    def rate(t):
        t = np.asarray(t, dtype=float)
        env = np.ones_like(t)
        for t0, t1, ramp in stops:
            down = np.clip((t - t0) / ramp, 0.0, 1.0)
            up = np.clip((t - t1) / ramp, 0.0, 1.0)
            env *= 1.0 - 0.5 * (1 - np.cos(np.pi * down)) + 0.5 * (1 - np.cos(np.pi * up))
        return 2 * np.pi * spin_hz * (1 + wobble * np.sin(2 * np.pi * wobble_hz * t + wobble_phase_rad)) * env
    return rate


def after_still_start(spin_rate, still_s: float, spinup_s: float = 2.0):
    """`spin_rate` (t -> rad/s) held at zero until still_s, then ramped in as sin^2 over spinup_s (C1, so
    the sampled rate is integrated like the true one): a start-up still stretch."""
    def rate(t):
        t = np.asarray(t, dtype=float)
        u = np.clip((t - still_s) / spinup_s, 0.0, 1.0)
        return spin_rate(t) * np.sin(0.5 * np.pi * u) ** 2
    return rate


def _as_fn(value, width=3):
    if callable(value):
        return value
    arr = np.asarray(value, dtype=float).reshape(width)
    return lambda t: np.broadcast_to(arr, (len(np.atleast_1d(t)), width)).copy()


def _rot_axis(axis: int, angle: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotations by angle about coordinate axis 0 (x) or 1 (y)."""
    c, s = np.cos(angle), np.sin(angle)
    z, o = np.zeros_like(angle), np.ones_like(angle)
    if axis == 0:
        rows = [[o, z, z], [z, c, -s], [z, s, c]]
    else:
        rows = [[c, z, s], [z, o, z], [-s, z, c]]
    return np.moveaxis(np.array(rows), (0, 1), (-2, -1))


@dataclass(frozen=True)
class CarouselTruth:
    t: np.ndarray                  # (N,) main IMU sample times, s
    theta_rad: np.ndarray          # (N,) platform angle about +z relative to the body
    spin_rate_rad_s: np.ndarray    # (N,)
    rate_body_rad_s: np.ndarray    # (N, 3)
    specific_force_body_m_s2: np.ndarray  # (N, 3)
    flip_position: np.ndarray      # (N,) quarter turns (fractional while flipping)
    theta_fine_t: np.ndarray       # fine grid for exact crossing times
    theta_fine: np.ndarray

    def boundary_times(self, phase_rad: float = 0.0) -> np.ndarray:
        """Times where theta crosses phase + 2*pi*n (monotonic rotation assumed)."""
        th = self.theta_fine - phase_rad
        m = np.floor(th / (2 * np.pi))
        idx = np.flatnonzero(np.diff(m)) + 1
        level = 2 * np.pi * np.maximum(m[idx], m[idx - 1])
        f = (level - th[idx - 1]) / (th[idx] - th[idx - 1])
        return self.theta_fine_t[idx - 1] + f * (self.theta_fine_t[idx] - self.theta_fine_t[idx - 1])


def simulate(duration_s: float, imu_hz: float = 100.0, spin_rate=None, *, t0: float = 0.0,
             theta0_rad: float = 0.0, body_rate=(0.0, 0.0, 0.0), body_force=None,
             gyro_bias=(0.0, 0.0, 0.0), accel_bias=(0.0, 0.0, 0.0), gyro_noise: float = 0.0,
             accel_noise: float = 0.0, encoder_hz: float | None = None, encoder_noise_rad: float = 0.0,
             temperature=None, temperature_hz: float = 1.0,
             flips=(), flip_axis: str = 'x', initial_position: int = 0,
             aux_hz: float | None = None, aux_gyro_bias=(0.0, 0.0, 0.0), aux_accel_bias=(0.0, 0.0, 0.0),
             aux_noise: float = 0.0, mag_field=None, mag_hz: float = 50.0, mag_hard_iron=(0.0, 0.0, 0.0),
             mag_noise: float = 0.0, seed: int = 0, oversample: int = 20):
    """One SensorChunk and its truth.

    spin_rate: t -> rad/s (default 0.5 Hz); body_rate/body_force: constants (3,) or t -> (N, 3), body
    frame; gyro_bias/accel_bias: imu-frame constants or t -> (N, 3); flips: (t_start, duration_s,
    quarter_steps) of the main IMU about `flip_axis`; temperature: t -> deg C; mag_field: the magnetic
    field, constant (3,) or t -> (N, 3), body frame, T (a magnetometer on the platform at mag_hz, with a
    sensor-fixed hard iron and white noise mag_noise, T; no flips)."""
    rng = np.random.default_rng(seed)
    spin_rate = spin_rate or spin_rate_profile(0.5)
    body_rate, body_force = _as_fn(body_rate), _as_fn(
        (0.0, 0.0, STANDARD_GRAVITY_M_S2) if body_force is None else body_force)
    gyro_bias, accel_bias = _as_fn(gyro_bias), _as_fn(accel_bias)
    n = int(round(duration_s * imu_hz)) + 1
    fine_hz = imu_hz * oversample
    tf = t0 + np.arange((n - 1) * oversample + 1) / fine_hz
    rf = spin_rate(tf)
    thf = theta0_rad + np.concatenate(([0.0], np.cumsum(0.5 * (rf[1:] + rf[:-1]) / fine_hz)))
    t = tf[::oversample]
    axis = {'x': 0, 'y': 1}[flip_axis]

    def platform(tq):
        th = np.interp(tq, tf, thf)
        c, s = np.cos(th), np.sin(th)
        wb, fb = body_rate(tq), body_force(tq)
        # v_p = Rz(-theta) v_b
        rot = lambda v: np.column_stack((c * v[:, 0] + s * v[:, 1], -s * v[:, 0] + c * v[:, 1], v[:, 2]))
        g = rot(wb)
        g[:, 2] += spin_rate(tq)
        return th, g, rot(fb), wb, fb

    def flip_state(tq):
        pos = np.full(len(tq), float(initial_position))
        rate = np.zeros(len(tq))
        for ts, dur, steps in flips:
            u = np.clip((tq - ts) / dur, 0.0, 1.0)
            pos += steps * 0.5 * (1 - np.cos(np.pi * u))
            inside = (tq > ts) & (tq < ts + dur)
            rate += np.where(inside, steps * 0.5 * np.pi * np.sin(np.pi * u) / dur, 0.0)
        return pos, rate * np.pi / 2

    th, gp, ap, wb, fb = platform(t)
    pos, pos_rate = flip_state(t)
    rt = _rot_axis(axis, pos * np.pi / 2)                       # imu -> platform
    g_imu = np.einsum('nji,nj->ni', rt, gp) + gyro_bias(t) + gyro_noise * rng.standard_normal((n, 3))
    g_imu[:, axis] += pos_rate
    a_imu = np.einsum('nji,nj->ni', rt, ap) + accel_bias(t) + accel_noise * rng.standard_normal((n, 3))
    chunk = SensorChunk(imu=ImuSamples(t, g_imu, a_imu))
    if encoder_hz:
        te = t0 + np.arange(int(duration_s * encoder_hz) + 1) / encoder_hz
        pe = np.interp(te, tf, thf) + encoder_noise_rad * rng.standard_normal(len(te))
        chunk = chunk.with_streams(joint=JointSamples(te, pe, spin_rate(te)))
    if aux_hz:
        ta = t0 + np.arange(int(duration_s * aux_hz) + 1) / aux_hz
        _, gpa, apa, _, _ = platform(ta)
        ga = gpa + np.asarray(aux_gyro_bias) + aux_noise * rng.standard_normal((len(ta), 3))
        aa = apa + np.asarray(aux_accel_bias) + aux_noise * rng.standard_normal((len(ta), 3))
        chunk = chunk.with_streams(imu_aux=ImuSamples(ta, ga, aa))
    if mag_field is not None:
        tm = t0 + np.arange(int(duration_s * mag_hz) + 1) / mag_hz
        th_m = np.interp(tm, tf, thf)
        c, s = np.cos(th_m), np.sin(th_m)
        b = _as_fn(mag_field)(tm)
        b_p = np.column_stack((c * b[:, 0] + s * b[:, 1], -s * b[:, 0] + c * b[:, 1], b[:, 2]))   # Rz(-theta)
        b_p += np.asarray(mag_hard_iron, dtype=float) + mag_noise * rng.standard_normal((len(tm), 3))
        chunk = chunk.with_streams(mag=MagSamples(tm, b_p))
    if temperature is not None:
        tt = t0 + np.arange(int(duration_s * temperature_hz) + 1) / temperature_hz
        chunk = chunk.with_streams(temperature=TemperatureSamples(tt, temperature(tt)))
    truth = CarouselTruth(t, th, spin_rate(t), wb, fb, pos, tf, thf)
    return chunk, truth


def tilted_turntable(duration_s: float, *, tilt_deg: float, tilt_azimuth_rad: float = 0.0, spin_hz: float = 0.5,
                     wobble: float = 0.03, wobble_hz: float = 0.13, still_s: float = 0.0, spinup_s: float = 2.0,
                     gyro_bias=(0.0, 0.0, 0.0), accel_bias=(0.0, 0.0, 0.0), gyro_density_rad_s_rthz: float = 0.0,
                     accel_density_m_s2_rthz: float = 0.0, imu_hz: float = 100.0, seed: int = 0):
    """A static body tilted by tilt_deg (gravity's in-plane part toward tilt_azimuth_rad from body x) on which a
    vertical turntable spins about body z at spin_hz with a relative wobble at wobble_hz, from the first sample
    (still_s 0) or after a still start (`after_still_start`); imu-frame gyro and accelerometer biases (rad/s,
    m/s^2) and white noise given as densities (rad/s/sqrt(Hz), m/s^2/sqrt(Hz)); no encoder, no Earth rate.
    (SensorChunk, CarouselTruth); the body's specific force is truth.specific_force_body_m_s2[0]."""
    tilt = np.radians(tilt_deg)
    force = STANDARD_GRAVITY_M_S2 * np.array([np.sin(tilt) * np.cos(tilt_azimuth_rad),
                                              np.sin(tilt) * np.sin(tilt_azimuth_rad), np.cos(tilt)])
    rate = spin_rate_profile(spin_hz, wobble, wobble_hz)
    if still_s > 0:
        rate = after_still_start(rate, still_s, spinup_s)
    return simulate(duration_s, imu_hz, rate, body_force=force, gyro_bias=gyro_bias, accel_bias=accel_bias,
                    gyro_noise=gyro_density_rad_s_rthz * np.sqrt(imu_hz),
                    accel_noise=accel_density_m_s2_rthz * np.sqrt(imu_hz), seed=seed)


def split_chunk(chunk: SensorChunk, edges_s) -> list[SensorChunk]:
    """Cut a chunk at the given times (each stream separately), as a live node would deliver it."""
    from dataclasses import fields
    from ..samples import slice_samples
    edges = np.concatenate(([-np.inf], np.sort(np.asarray(edges_s, dtype=float)), [np.inf]))
    out = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        parts = {}
        for f in fields(SensorChunk):
            s = getattr(chunk, f.name)
            if s is not None:
                sel = (s.t >= lo) & (s.t < hi)
                parts[f.name] = slice_samples(s, sel)
        out.append(SensorChunk(**parts))
    return out
