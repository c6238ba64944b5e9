"""Tiny synthetic records with exactly known truth, for tests and examples of the evaluation layer.

Not a simulator (see gyro_thermal_comp.sim for that): a level unit whose true yaw, gyro drift,
noise and magnetic interference are given directly, so every scored number can be predicted.
"""
from __future__ import annotations

from typing import Callable, Sequence

import numpy as np

from ..angles import quat_from_euler, wrap_angle
from ..constants import STANDARD_GRAVITY_M_S2
from ..heading_track import HeadingTrack
from ..samples import ImuSamples, MagSamples, PoseSamples, SensorChunk, VectorSamples

FIELD_ENU_T = (0.0, 2.0e-5, -4.0e-5)  # north 20 uT, down 40 uT


def _as_fn(x) -> Callable[[np.ndarray], np.ndarray]:
    return x if callable(x) else (lambda t, c=float(x): np.full(np.shape(t), c))


def level_unit_chunks(duration_s: float = 120.0, rate_hz: float = 100.0, *, yaw0_rad: float = 0.0,
                      yaw_rate_rad_s=0.0, yaw_fn=None, drift_rad_s=0.0, noise_rad_s: float = 0.0,
                      outages: Sequence[tuple[float, float]] = (),
                      disturbance_body_t=(1.5e-5, 0.0, 0.0), chunk_s: float = 10.0,
                      odom_rate_hz: float | None = None, mag_rate_hz: float | None = None,
                      odom_offset_s: float = 0.0, t0_s: float = 1000.0, seed: int = 0,
                      field_enu_t=FIELD_ENU_T) -> list[SensorChunk]:
    """Chunks of a level unit; returns the list (sizes here are small by design).

    yaw_rate_rad_s: constant or callable(t_rel) true yaw rate; yaw_fn(t_rel) overrides the true
        yaw (then give the matching rate too). drift_rad_s: constant or callable(t_rel) z-gyro
        drift. noise_rad_s: white gyro noise std per sample. outages: (start, end) s relative to the
        start, where `disturbance_body_t` is added to the field and reported as mag_disturbance.
    Times are t0_s + t_rel. Truth (odom) can have its own rate and a time offset from the IMU.
    """
    rng = np.random.default_rng(seed)
    rate_fn, drift_fn = _as_fn(yaw_rate_rad_s), _as_fn(drift_rad_s)
    if yaw_fn is None:
        if callable(yaw_rate_rad_s):
            raise ValueError('give yaw_fn together with a callable yaw rate')
        yaw_fn = lambda t, r=float(yaw_rate_rad_s): yaw0_rad + r * t  # noqa: E731

    def t_grid(rate, offset=0.0):
        return np.arange(0.0, duration_s, 1.0 / rate) + offset

    t_imu = t_grid(rate_hz)
    t_odom = t_grid(odom_rate_hz or rate_hz, odom_offset_s)
    t_mag = t_grid(mag_rate_hz or rate_hz)
    n = t_imu.size
    gyro = np.zeros((n, 3))
    gyro[:, 2] = rate_fn(t_imu) + drift_fn(t_imu) + rng.normal(0.0, noise_rad_s, n)
    accel = np.tile([0.0, 0.0, STANDARD_GRAVITY_M_S2], (n, 1))

    yaw_mag = yaw_fn(t_mag)
    c, s = np.cos(yaw_mag), np.sin(yaw_mag)
    east, north, up = field_enu_t
    field = np.column_stack([c * east + s * north, -s * east + c * north, np.full(t_mag.size, up)])
    disturbed = np.zeros(t_mag.size, dtype=bool)
    for a, b in outages:
        disturbed |= (t_mag >= a) & (t_mag < b)
    dist = np.where(disturbed[:, None], np.asarray(disturbance_body_t, dtype=float)[None, :], 0.0)

    yaw_odom = wrap_angle(yaw_fn(t_odom))
    quat = quat_from_euler(np.zeros(t_odom.size), np.zeros(t_odom.size), yaw_odom)
    rate_body = np.zeros((t_odom.size, 3))
    rate_body[:, 2] = rate_fn(t_odom)

    streams = {   # SensorChunk field -> (sample times, samples at some of them by index)
        'imu': (t_imu, lambda i: ImuSamples(t_imu[i] + t0_s, gyro[i], accel[i])),
        'mag': (t_mag, lambda i: MagSamples(t_mag[i] + t0_s, field[i] + dist[i])),
        'odom': (t_odom, lambda i: PoseSamples(t_odom[i] + t0_s, quat[i], np.zeros((i.size, 3)),
                                               np.zeros((i.size, 3)), rate_body[i])),
        'gyro_bias': (t_imu, lambda i: VectorSamples(t_imu[i] + t0_s, np.column_stack(
            [np.zeros(i.size), np.zeros(i.size), drift_fn(t_imu[i])]))),
        'mag_disturbance': (t_mag, lambda i: VectorSamples(t_mag[i] + t0_s, dist[i])),
    }
    chunks = []
    for k in range(int(np.ceil(duration_s / chunk_s))):
        a, b = k * chunk_s, (k + 1) * chunk_s
        parts = {}
        for name, (t, make) in streams.items():
            idx = np.flatnonzero((t >= a) & (t < b))
            if idx.size:
                parts[name] = make(idx)
        chunks.append(SensorChunk(**parts))
    return chunks


class DriftIntegrator:
    """Reference heading method for checks: integrates gyro z minus (true drift + delta_rad_s) from
    a given initial heading, with the oracle's trapezoid rule. Needs the `gyro_bias` truth stream.
    Its bias error is exactly delta and its excess over the oracle exactly -delta * t (plus the
    reference-window offset), so it calibrates the scorer.
    """

    def __init__(self, name: str, delta_rad_s: float, psi0_rad: float):
        self.name, self.delta, self.psi = name, float(delta_rad_s), float(psi0_rad)
        self.t_prev = self.r_prev = None

    def update(self, chunk: SensorChunk) -> HeadingTrack:
        t = chunk.imu.t
        drift = chunk.gyro_bias.vec[:, 2] + self.delta
        r = chunk.imu.gyro[:, 2] - drift
        t_prev = t[0] if self.t_prev is None else self.t_prev
        r_prev = r[0] if self.r_prev is None else self.r_prev
        tt, rr = np.r_[t_prev, t], np.r_[r_prev, r]
        psi = self.psi + np.cumsum(0.5 * (rr[1:] + rr[:-1]) * np.diff(tt))
        self.psi, self.t_prev, self.r_prev = float(psi[-1]), float(t[-1]), float(r[-1])
        return HeadingTrack(t.copy(), wrap_angle(psi), drift, np.full(t.size, np.nan),
                            np.zeros(t.size, dtype=bool))


def calibration_config(cfg, offset: int = 1000, scenario: str | None = None, duration_s: float | None = None):
    """The `sim.SimConfig` of a calibration run of the same unit as `cfg`: the unit (its coefficients,
    and for the second truth family its effect shapes, drawn from `cfg.unit_seed`, else `cfg.seed`)
    and the effect sizes kept; noise, motion, interference episodes (and a family-B profile) from
    seed `cfg.seed + offset`. For the calibrated `mlr`: fit on it, then evaluate `cfg`:

        cal = MlrCalibration.fit(sim.simulate(calibration_config(cfg)))

    `scenario`: another thermal profile with the same sensor (its own default params);
    `duration_s`: default `cfg`'s (the scenario's own with another scenario)."""
    from .. import sim
    same = scenario is None or scenario == cfg.scenario
    out = sim.make_config(cfg.scenario if same else scenario, seed=cfg.seed + int(offset),
                          unit_seed=cfg.seed if cfg.unit_seed is None else cfg.unit_seed,
                          duration_s=cfg.duration_s if duration_s is None and same else duration_s,
                          effects=dict(cfg.effects), params=dict(cfg.params) if same else None,
                          imu_rate_hz=cfg.imu_rate_hz, mag_rate_hz=cfg.mag_rate_hz, temp_rate_hz=cfg.temp_rate_hz,
                          truth_rate_hz=cfg.truth_rate_hz)
    if out.preset != cfg.preset:
        raise ValueError(f'scenario {scenario!r} has another sensor ({out.preset.name}) than {cfg.scenario} '
                         f'({cfg.preset.name}): not the same unit')
    return out
